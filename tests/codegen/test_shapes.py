"""Element equations derived once per shape (bgc.codegen.shapes): the equation system is
the one the rules write element by element, up to the order of the terms of a sum."""

from __future__ import annotations

import pytest
import sympy as sp
from helpers import MODELS

from bgc.codegen import equations, shapes
from bgc.codegen.equations import LinearBlock
from bgc.graph import causality, expand
from bgc.model import load


def _flat(item) -> list:
    """An assignment's expressions (a block's, all of them)."""
    if not isinstance(item, LinearBlock):
        return [item]
    return ([(u, sp.S.Zero) for u in item.unknowns] + list(item.chain) + list(item.pre)
            + [((i, j), e) for i, j, e in item.A] + [(k, e) for k, e in
                                                     enumerate(item.tear_eqs)])


@pytest.mark.parametrize("name, constants", [("n_four_bar", {"N": 6}), ("four_bar", None)])
def test_an_equation_system_by_shapes_is_the_one_element_by_element(name, constants,
                                                                    monkeypatch):
    m = load.load(MODELS / f"{name}.yaml", constants=constants)
    cg = causality.assign(expand.expand(m))
    memo = equations.derive(cg)
    monkeypatch.setattr(shapes, "KINDS", ())
    plain = equations.derive(cg)
    assert [st.name for st in memo.states] == [st.name for st in plain.states]
    assert memo.display == plain.display and memo.outputs == plain.outputs
    assert len(memo.assignments) == len(plain.assignments)
    for a, b in zip(memo.assignments, plain.assignments):
        for (v, e), (w, f) in zip(_flat(a), _flat(b)):
            assert v == w and (e == f or sp.expand(e - f) == 0), (v, e, f)
