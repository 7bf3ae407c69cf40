"""docs/tutorial.md: the model it shows is the file it runs (docs/tutorial/absorber.yaml),
which loads and gets its causality, and the pictures and files it links exist."""

from __future__ import annotations

import re

import yaml
from helpers import ROOT

from bgc.graph.causality import assign
from bgc.graph.expand import expand
from bgc.model.load import load

TUTORIAL = ROOT / "docs" / "tutorial.md"
MODEL = ROOT / "docs" / "tutorial" / "absorber.yaml"


def test_the_tutorials_model_is_the_file_it_runs():
    shown = re.search(r"```yaml\n(.*?)```", TUTORIAL.read_text(), re.S).group(1)
    kept = yaml.safe_load(MODEL.read_text())
    kept.pop("description")
    assert yaml.safe_load(shown) == kept
    cg = assign(expand(load(MODEL)))
    assert {"cabin__m", "absorber.mass__m"} <= {n for n, s in cg.storage.items()
                                                if s == "integral"}


def test_the_tutorials_links_exist():
    links = re.findall(r"\]\(([^)#]+)\)", TUTORIAL.read_text())
    assert links and all((TUTORIAL.parent / link).exists() for link in links), links
