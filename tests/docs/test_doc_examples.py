"""Every command the README, docs/cli.md, docs/tutorial.md and docs/main-job.md show in a
```console block runs, and prints what the document shows (``doc_examples``): each in a
temporary directory of its own; those on the SARIB (and the benchmarks) are slow."""

from __future__ import annotations

import re
from dataclasses import replace

import pytest
from doc_examples import DOCS, check_shown, examples

EXAMPLES = [ex for doc in DOCS for ex in examples(doc)]
EXIT = re.compile(r"\(exit status (\d+)\)")


def test_the_documents_show_examples():
    shown = {ex.doc for ex in EXAMPLES}
    assert shown >= {"docs/cli.md", "docs/tutorial.md", "docs/main-job.md"}, shown
    assert {ex.argv[0] for ex in EXAMPLES if ex.doc == "docs/cli.md"} >= {
        "check", "compile", "simulate", "report", "frf", "modes", "tune", "sweep", "run",
        "draw", "export", "bench"}


@pytest.mark.parametrize("example", [
    pytest.param(ex, id=ex.id, marks=[pytest.mark.slow] if ex.slow else [])
    for ex in EXAMPLES])
def test_an_example_prints_what_its_document_shows(example, doc_run):
    ran = doc_run(example.command)
    shown = list(example.shown)
    status = 0
    if shown and EXIT.fullmatch(shown[-1].strip()):
        status = int(EXIT.fullmatch(shown.pop().strip()).group(1))
    assert ran.exit_code == status, (example.id, ran.stdout, ran.stderr)
    if shown:
        check_shown(replace(example, shown=tuple(shown)), ran.stdout)
