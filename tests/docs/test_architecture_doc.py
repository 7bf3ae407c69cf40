"""docs/architecture.md stays true to the tree: every file or directory it names exists,
and every ``bgc check --stage`` it shows is a stage the command has."""

from __future__ import annotations

import re

from helpers import ROOT

from bgc.cli.stages import STAGES

DOC = ROOT / "docs" / "architecture.md"


def test_every_path_the_map_names_exists():
    text = DOC.read_text()
    paths = set(re.findall(r"`((?:bgc|tests|models|docs|generated)/[\w./<>\[\]-]*)`", text))
    paths = {p for p in paths if "<" not in p and "[" not in p}     # patterns, not files
    assert len(paths) > 20
    missing = sorted(p for p in paths if not (ROOT / p).exists())
    assert not missing, f"docs/architecture.md names missing paths: {missing}"


def test_every_stage_command_exists():
    text = DOC.read_text()
    shown = set(re.findall(r"bgc check --stage (\w+)", text))
    assert shown == set(STAGES), shown
