"""Stage **equations** in its parts: the ``Builder`` surface (one definition per variable,
states added with their display names, one slot for a method's state that it never
reads), ``loops`` (a loop torn and solved symbolically, or as a numeric block in all its
variables or in its tears) and ``system`` (what a module is named by)."""

from __future__ import annotations

import pytest
import sympy as sp
from helpers import MODELS

from bgc.codegen import builder, equations, loops
from bgc.codegen.system import EquationSystem
from bgc.graph import causality, expand
from bgc.model.load import load
from bgc.symbolic.algorithms import is_cyclic, strongly_connected
from bgc.symbolic.linear import LinearBlock


@pytest.fixture(scope="module")
def rr_loop():
    """rr_loop's builder, its equations built and references resolved."""
    b = builder.Builder(causality.assign(expand.expand(load(MODELS / "rr_loop.yaml"),
                                                       "parasitic")))
    equations.build(b)
    b.resolve_refs()
    b.resolve_derivatives()
    return b


def test_builder_defines_once_adds_states_and_keeps_a_methods_slot(rr_loop):
    b = rr_loop
    v = next(iter(b.eqs))
    with pytest.raises(AssertionError, match="defined twice"):
        b.define(v, sp.S.One, "x")
    x, dx = sp.symbols("X_extra DX_extra", real=True)
    n = len(b.states)
    b.add_state("extra.q", x, dx, sp.S.Zero, "extra")
    assert b.states[-1].sym is x and b.display[dx] == "d(extra.q)/dt"
    b.states.pop()
    assert len(b.states) == n and b.method_state is None


def _loop(b):
    deps = loops.dependencies(b.eqs)
    (comp,) = [c for c in strongly_connected(list(b.eqs), deps) if is_cyclic(c, deps)]
    return comp, deps


@pytest.mark.parametrize("limit,numeric", [(6, False), (0, True)])
def test_a_loop_is_solved_symbolically_or_as_a_block(rr_loop, limit, numeric):
    comp, deps = _loop(rr_loop)
    solved, loop = loops.solve_loop(rr_loop, comp, deps, limit, block_index=4)
    blocks = [a for a in solved if isinstance(a, LinearBlock)]
    assert loop.kind == "algebraic" and loop.elements
    if numeric:                     # all its variables, numerically
        (blk,) = blocks
        assert blk.index == 4 and set(blk.unknowns) == set(comp) and len(solved) == 1
    else:                           # each variable assigned once, none reading itself
        assert not blocks and {v for v, _ in solved} == set(comp)
        assert all(v not in e.free_symbols for v, e in solved)


def test_a_torn_loop_reduces_to_its_tears(rr_loop):
    comp, deps = _loop(rr_loop)
    tears = comp[:1]
    rest = [v for v in comp if v not in tears]
    order = [c[0] for c in strongly_connected(rest, {v: [d for d in deps[v] if d in rest]
                                                     for v in rest})]
    torn = loops.Torn(rr_loop, comp, tears, order, 0, "algebraic", lambda w, h: ValueError(w))
    blk = torn.reduced_block()
    assert blk.unknowns == tuple(tears) and [v for v, _ in blk.chain] == order
    assert [v for v, _ in torn.chain()] == order


def test_a_system_is_named_by_method_closure_and_scene():
    m = load(MODELS / "pendulum.yaml")
    s = EquationSystem(m, "zcp", [], [], [], [], loops_closed=True)
    assert s.variant == "zcp_closed"
    s.scene = "drop"
    assert s.variant == "zcp_closed_drop"
    assert EquationSystem(m, "lagrange", [], [], [], []).variant == "lagrange"
