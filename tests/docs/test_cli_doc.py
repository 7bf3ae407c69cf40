"""docs/cli.md stays the reference of the command line: each command's section documents
exactly the options its click definition has (the retired ones apart, as retired), every
option the section names exists, and each ``--json`` table lists the keys that its
command prints. Every ``bgc COMMAND ...`` the documents, the Makefile and bgc's docstrings
show uses options that command has (one vocabulary: issue 38, item 8). The README is a
front page: the two commands first, at most 120 lines, every command in its table."""

from __future__ import annotations

import json
import re
import shlex

import click
import pytest
from doc_examples import is_slow
from helpers import ROOT

from bgc.cli import main

CLI = ROOT / "docs" / "cli.md"
README = ROOT / "README.md"
OPTION = re.compile(r"(?<![\w<-])(--?[A-Za-z][\w-]*)")


def sections() -> dict[str, str]:
    """docs/cli.md's text under each ``## `bgc NAME` `` heading, by command name."""
    parts = re.split(r"^## `bgc (\w+)`\s*$", CLI.read_text(), flags=re.M)
    return dict(zip(parts[1::2], parts[2::2]))


def visible(cmd: click.Command) -> set[str]:
    """The options a command shows in --help (--help itself aside)."""
    return {o for p in cmd.params if isinstance(p, click.Option) and not p.hidden
            for o in p.opts + p.secondary_opts}


def retired(cmd: click.Command) -> set[str]:
    """The hidden options an earlier bgc took, refused with what to write instead."""
    return {o for p in cmd.params if isinstance(p, click.Option) and p.hidden
            for o in p.opts}


def tables(text: str):
    """(caption, header, rows) of each table in ``text``: the caption is the paragraph
    just above the table, rows are lists of cells."""
    out = []
    lines = text.splitlines()
    i = 0
    while i < len(lines):
        if lines[i].startswith("|") and i + 1 < len(lines) and lines[i + 1].startswith("|---"):
            j = i - 1
            while j >= 0 and not lines[j].strip():
                j -= 1
            para = []
            while j >= 0 and lines[j].strip():
                para.insert(0, lines[j].strip())
                j -= 1
            header = _cells(lines[i])
            rows = []
            i += 2
            while i < len(lines) and lines[i].startswith("|"):
                rows.append(_cells(lines[i]))
                i += 1
            out.append((" ".join(para), header, rows))
        else:
            i += 1
    return out


def _cells(line: str) -> list[str]:
    return [c.strip() for c in re.split(r"(?<!\\)\|", line.strip().strip("|"))]


def code_spans(text: str) -> list[str]:
    """The inline code of a Markdown text (``` blocks left out), line breaks as spaces."""
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    return [re.sub(r"\s+", " ", s) for s in re.findall(r"`([^`]+)`", text)]


def test_every_command_has_a_section():
    assert sorted(sections()) == sorted(main.commands)


@pytest.mark.parametrize("name", sorted(main.commands))
def test_a_section_documents_exactly_the_options_of_its_command(name):
    cmd, text = main.commands[name], sections()[name]
    table = [rows for _, header, rows in tables(text) if header[0] == "option"]
    assert len(table) == 1, f"{name}: one options table"
    documented = {o for row in table[0] for o in OPTION.findall(row[0].split("|")[0])}
    assert documented == visible(cmd), (
        f"bgc {name}: undocumented {sorted(visible(cmd) - documented)}, documented but not "
        f"options {sorted(documented - visible(cmd))}")
    said = set()
    for line in re.findall(r"^Retired: (.*)$", text, re.M):
        said |= {OPTION.match(s).group(1) for s in code_spans(line)
                 if OPTION.match(s) and not s.startswith("bgc ")
                 and OPTION.match(s).group(1) in retired(cmd)}
    assert said == retired(cmd), f"bgc {name}: retired options {sorted(retired(cmd))}"


@pytest.mark.parametrize("name", sorted(main.commands))
def test_every_option_a_section_names_is_an_option_of_its_command(name):
    """An option in a section's prose (a code span that starts with it) is its
    command's; a command line (``bgc OTHER ...``) is checked as any other."""
    cmd, text = main.commands[name], sections()[name]
    known = visible(cmd) | retired(cmd) | {"--help"}
    for span in code_spans(text):
        m = OPTION.match(span)
        if m and span.startswith("-") and not re.match(r"-\d", span):
            assert m.group(1) in known, f"bgc {name}: `{span}` is not one of its options"


def command_lines():
    """Every ``bgc COMMAND ...`` the documents, the Makefile and bgc's docstrings show:
    (where, the command line)."""
    found = []
    for path in [README, *sorted((ROOT / "docs").glob("*.md"))]:
        text = path.read_text()
        for span in code_spans(text):
            if span.startswith("bgc "):
                found.append((path.name, span))
        for block in re.findall(r"^```(?:console)?\n(.*?)^```", text, re.S | re.M):
            for line in block.replace("\\\n", " ").splitlines():
                line = line.lstrip("$ ").strip()
                if line.startswith("bgc "):
                    found.append((path.name, line))
    for line in (ROOT / "Makefile").read_text().replace("\\\n", " ").splitlines():
        at = line.find("bgc ")
        if at >= 0 and not line.lstrip().startswith("#"):
            found.append(("Makefile", line[at:].split(" || ")[0]))
    for path in sorted((ROOT / "bgc").rglob("*.py")):
        for span in re.findall(r"``(bgc [^`]+)``", path.read_text()):
            found.append((str(path.relative_to(ROOT)), re.sub(r"\s+", " ", span)))
    return found


def test_the_documents_show_command_lines():
    where = {w for w, _ in command_lines()}
    assert {"README.md", "cli.md", "tutorial.md", "main-job.md", "Makefile"} <= where


@pytest.mark.parametrize("where, line", command_lines(), ids=lambda v: str(v)[:60])
def test_a_command_line_anywhere_uses_options_its_command_has(where, line):
    words = line.split()
    if len(words) < 2 or not re.fullmatch(r"[\w/|]+", words[1]):
        return
    names = [n for n in re.split(r"[/|]", words[1]) if n in main.commands]
    if not names:                       # `bgc --version`, `bgc COMMAND --help`, `bgc ARGS`
        assert words[1].startswith("-") or words[1].isupper(), (where, line)
        return
    for name in names:
        known = visible(main.commands[name]) | {"--help"}
        for word in words[2:]:
            m = OPTION.fullmatch(word.split("=")[0].strip("[](),.;:'\""))
            if m and not re.match(r"-\d", word):
                assert m.group(1) in known, f"{where}: `{line}`: bgc {name} has no {word}"


def json_tables():
    """docs/cli.md's ``--json`` key tables: (the command their caption names, its keys)."""
    out = []
    for caption, header, rows in tables(CLI.read_text()):
        if header[0] != "`--json` key":
            continue
        commands = [s for s in code_spans(caption) if s.startswith("bgc ") and "--json" in s]
        assert len(commands) == 1, f"a --json table names its command: {caption!r}"
        keys = {}
        for row in rows:
            key = re.fullmatch(r"`([\w.\[\]]+)`", row[0])
            assert key, f"{commands[0]}: a key is one code span, not {row[0]!r}"
            keys[key.group(1)] = row[1].startswith("(")       # conditional: may be absent
        out.append((commands[0], keys))
    return out


def test_every_command_with_json_has_its_keys_documented():
    shown = {shlex.split(c)[1] for c, _ in json_tables()}
    has = {n for n, c in main.commands.items() if "--json" in visible(c)}
    assert shown == has


def printed_keys(value, documented: set[str]) -> tuple[set[str], set[str]]:
    """The key paths a JSON value prints (``stats.steps``, ``points[].index``, ``[].pass``
    for a list at the top), going below a key only where the documentation does; and the
    paths that are objects there (whose documented keys must be printed)."""
    keys, objects = set(), set()

    def below(path: str) -> bool:
        return any(k.startswith(path + ("." if path else "")) for k in documented)

    def walk(v, path: str) -> None:
        if isinstance(v, list):
            if below(path + "[]") or any(k.startswith(path + "[].") for k in documented):
                for item in v:
                    walk(item, path + "[]")
        elif isinstance(v, dict) and (not path or below(path)):
            objects.add(path)
            for k, x in v.items():
                keys.add(f"{path}.{k}" if path else k)
                walk(x, f"{path}.{k}" if path else k)
    walk(value, "")
    return keys, objects


@pytest.mark.parametrize("command, keys", [
    pytest.param(c, k, id=c[:70], marks=[pytest.mark.slow] if is_slow(shlex.split(c)[1:])
                 else []) for c, k in json_tables()])
def test_a_json_table_lists_the_keys_its_command_prints(command, keys, doc_run):
    printed, objects = printed_keys(json.loads(doc_run(command).stdout), set(keys))
    # a key must be printed where its object is (a null object, an empty list: none)
    required = {k for k, conditional in keys.items() if not conditional
                and (k.rsplit(".", 1)[0] if "." in k else "") in objects}
    assert required <= printed, f"{command}: not printed: {sorted(required - printed)}"
    assert printed <= set(keys), f"{command}: undocumented: {sorted(printed - set(keys))}"


def test_the_readme_is_a_front_page():
    text = README.read_text()
    lines = text.splitlines()
    assert len(lines) <= 120, f"README.md is {len(lines)} lines"
    first = re.search(r"^```\n(.*?)^```", text, re.S | re.M)
    assert first.group(1).split() == ["make", "run", "make", "test"]
    assert text.index(first.group(0)) < text.index("\n## ")       # before anything else
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^run:", makefile, re.M) and re.search(r"^test:", makefile, re.M)
    pictures = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", text)
    assert len(pictures) == 1 and (ROOT / pictures[0]).stat().st_size > 10_000
    table = [rows for _, header, rows in tables(text) if header[0] == "command"]
    assert sorted(re.match(r"`bgc (\w+)", r[0]).group(1) for r in table[0]) == \
        sorted(main.commands)
    links = re.findall(r"\]\(([^)#]+)\)", text)
    for doc in ("docs/cli.md", "docs/format.md", "docs/tutorial.md", "docs/architecture.md",
                "docs/generated-modules.md", "docs/main-job.md"):
        assert doc in links, doc
    assert all((ROOT / link).exists() for link in links), links


def test_the_docs_links_exist():
    for doc in ("cli.md", "main-job.md"):
        path = ROOT / "docs" / doc
        links = re.findall(r"\]\(([^)#]+)\)", path.read_text())
        assert links and all((path.parent / link).exists() for link in links), (doc, links)
