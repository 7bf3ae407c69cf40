"""The documentation's commands, run once per test session (``doc_examples.DocRuns``)."""

from __future__ import annotations

import pytest
from doc_examples import DocRuns


@pytest.fixture(scope="session")
def doc_run(gen_dir):
    """doc_run(command) -> Ran: ``bgc ...`` as a document shows it, run once per session
    in a directory of its own (its files stay there: ``Ran.cwd``)."""
    runs = DocRuns(gen_dir)
    yield runs
    runs.close()
