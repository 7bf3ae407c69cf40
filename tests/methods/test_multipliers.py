"""What the methods with multipliers share (``methods.multipliers``), on its own: the
state a method keeps on the builder (``MultiplierState``) after its hooks ran, the loop
variables it tears first, and its constraint block ``A = -K B`` (``kkt_block``)."""

from __future__ import annotations

import pytest
from helpers import MODELS

from bgc import methods
from bgc.codegen import equations
from bgc.graph import causality, expand
from bgc.methods.multipliers import MultiplierState, kkt_block
from bgc.model import symbols
from bgc.model.load import load
from bgc.symbolic.algorithms import is_cyclic, strongly_connected


def _builder(model: str, method: str):
    """The equations builder of ``model`` after the method's hooks, as ``derive`` has it
    before sorting."""
    m = methods.get(method)
    graph = m.restructure(expand.expand(load(MODELS / f"{model}.yaml"), method))
    b = equations.Builder(causality.assign(graph))
    b.method_state = m.new_state(b)
    equations.build(b)
    b.resolve_refs()
    b.resolve_derivatives()
    m.embed(b)
    return m, b, m.constraint_equations(b)


def _loops(b):
    deps = equations.dependencies(b.eqs)
    return [c for c in strongly_connected(list(b.eqs), deps) if is_cyclic(c, deps)], deps


def test_lagrange_keeps_each_multipliers_rows_and_constraint_in_its_state():
    m, b, cons = _builder("pendulum", "lagrange")
    st = b.method_state
    assert isinstance(st, MultiplierState) and not st.dependent and not st.pose_rows
    lams = [symbols.multiplier("hinge", c.label) for c in b.g.constraints]
    assert len(cons) == 5 and set(st.rows) == set(lams) == set(st.constraint)
    assert all(st.rows[lam] for lam in lams)           # each row reaches a momentum
    (comp,), deps = _loops(b)
    assert set(m.tear_first(b, comp)) == set(lams)
    rest = [v for v in comp if v not in lams]       # the rest in causal order
    order = [c[0] for c in strongly_connected(rest, {v: [d for d in deps[v] if d in rest]
                                                     for v in rest})]
    blk = kkt_block(b, m.tear_first(b, comp), order, 3)
    d, K, B = blk.factors
    assert blk.index == 3 and blk.unknowns == tuple(m.tear_first(b, comp))
    assert d == len({x for r in st.rows.values() for x in r})
    assert {i for i, _, _ in K} == set(range(5)) and {k for _, k, _ in B} == set(range(5))
    assert blk.rank == symbols.param("lagrange__rank")


def test_zcp_records_its_dependent_momenta_and_tears_them_first():
    m, b, _ = _builder("pendulum", "zcp")
    st = b.method_state
    assert len(st.dependent) == 5                  # the hinge fixes 5 velocity components
    dependent = {x for x, _, _ in st.dependent}
    assert not dependent & {s.sym for s in b.states}
    loops, _ = _loops(b)
    firsts = [m.tear_first(b, c) for c in loops]
    assert dependent <= {v for f in firsts for v in f}


def test_augmented_keeps_the_pose_rows_for_its_projection():
    _, b, _ = _builder("pendulum", "augmented")
    poses = {s.sym for s in b.states if s.element in b.g.bodies}
    assert set(b.method_state.pose_rows) == poses


@pytest.mark.parametrize("method", ["parasitic"])
def test_a_method_without_multipliers_keeps_no_state(method):
    m, b, cons = _builder("pendulum", method)
    assert b.method_state is None and not cons and m.tear_first(b, list(b.eqs)) == []
