"""Method pass zcp on its own (``zcp.assign``: the expanded BondGraph -> a copy of it with
its spanning tree, loops and dependent velocity components): a tree joint's flow sources
fix one velocity component of its child per blocked direction; a joint closing a
kinematic loop is the tree's chord, opened with break variables (or kept closed)."""

from __future__ import annotations

import pytest
from helpers import HINGE, MODELS

from bgc.graph.expand import expand
from bgc.methods import zcp
from bgc.model.load import load, loads


def test_a_hinge_fixes_all_but_the_rotation_about_its_axis():
    expanded = expand(loads(HINGE), "zcp")
    g = zcp.assign(expanded)
    assert expanded.method_plan is None and not any(c.imposed for c in expanded.constraints)
    (tree,) = g.method_plan.tree
    assert (tree.joint, tree.parent, tree.child) == ("hinge", None, "rod")
    # the rod's three translations and its rotations about body x and z (the axis is y)
    assert tree.dependent == [("rod__m", 0), ("rod__m", 1), ("rod__m", 2),
                              ("rod__J", 0), ("rod__J", 2)]
    assert g.method_plan.loops == []
    assert all(c.imposed and not c.closed for c in g.constraints) and len(g.constraints) == 5


@pytest.mark.parametrize("open_loops", [True, False])
def test_the_four_bars_loop_is_cut_at_a_chord_of_the_joint_tree(open_loops):
    model = load(MODELS / "four_bar.yaml")
    g = zcp.assign(expand(model, "zcp"), open_loops)
    tree = {t.joint: t for t in g.method_plan.tree}
    (loop,) = g.method_plan.loops
    # three bodies: three tree joints; the fourth joint closes the loop through all four
    assert len(tree) == 3 and loop.cut not in tree
    assert set(tree) | {loop.cut} == set(model.joints) == set(loop.joints)
    for t in tree.values():       # one fixed component per blocked direction
        assert len(t.dependent) == sum(d.blocked for d in g.joints[t.joint])
    assert tree["crank_pivot"].parent is None and tree["rocker_pivot"].parent is None
    cut = [c for c in g.constraints if c.joint == loop.cut]
    assert cut and all(not c.imposed and c.closed != open_loops for c in cut)
    assert all(c.imposed and not c.closed for c in g.constraints if c.joint != loop.cut)
    assert g.method_plan.closed != open_loops
