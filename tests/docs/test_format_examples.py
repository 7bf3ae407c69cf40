"""Every complete model in docs/format.md (a ```yaml block with a ``name:``) loads, expands
and gets its causality: the documentation's examples are models, not sketches."""

from __future__ import annotations

import re

import pytest
from helpers import ROOT

from bgc.graph.causality import assign
from bgc.graph.expand import expand
from bgc.model.load import loads

EXAMPLES = [block for block in re.findall(r"```yaml\n(.*?)```",
                                          (ROOT / "docs" / "format.md").read_text(), re.S)
            if re.match(r"name: \w+", block)]


def test_the_format_has_complete_examples():
    names = {re.match(r"name: (\w+)", b).group(1) for b in EXAMPLES}
    assert {"dc_motor", "pi_servo", "screw_lift", "screw_servo", "pendulum_row"} <= names


@pytest.mark.parametrize("text", EXAMPLES, ids=lambda b: re.match(r"name: (\w+)", b).group(1))
def test_an_example_of_the_format_is_a_model(text):
    cg = assign(expand(loads(text, "format.md")))
    assert cg.storage
