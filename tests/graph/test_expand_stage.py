"""Stage expand on its own (Model -> BondGraph): one rigid body hung on a revolute joint
from the fixed frame, the smallest model with both a body and a joint. The graph must be
the paper's: the body's translational and rotational 1-junctions with their multibond
(dimension 3) inertias, EJS and weight; per blocked direction of the joint a scalar
0-junction fed by a projection MTF, closed by the constraint element L the method asks
for; and the structure checks (ports per kind, rule C1) hold."""

from __future__ import annotations

from collections import Counter

import pytest
import sympy as sp
from helpers import HINGE

from bgc.graph.expand import expand
from bgc.model.load import loads
from bgc.model.model import KINDS

BLOCKED = ["tx", "ty", "tz", "ry", "rz"]      # a revolute leaves only rx (its axis) free


@pytest.fixture(scope="module")
def model():
    return loads(HINGE)


def _dims(graph, name):
    return {graph.bonds[b].dim for b in graph.ports[name]}


def test_the_body_becomes_its_multibond_graph(model):
    g = expand(model)
    kinds = {n: e.kind for n, e in g.elements.items()}
    assert {n: kinds[n] for n in ("rod__v", "rod__w", "rod__m", "rod__J", "rod__EJS",
                                  "rod__g")} == {
        "rod__v": "1", "rod__w": "1", "rod__m": "I", "rod__J": "I", "rod__EJS": "EJS",
        "rod__g": "Se"}
    # the mass on the velocity of G, the inertia tensor and EJS on omega: dimension 3
    for el, junction in (("rod__m", "rod__v"), ("rod__J", "rod__w"), ("rod__EJS", "rod__w"),
                         ("rod__g", "rod__v")):
        (b,) = g.ports[el]
        assert {g.bonds[b].src, g.bonds[b].dst} == {el, junction} and g.bonds[b].dim == 3
    assert g.elements["rod__J"].fields["I"] == sp.diag(sp.Rational(1, 5), sp.Rational(1, 5),
                                                      sp.Rational(1, 100))
    # the weight m g, pointing down (gravity 9.81 along -z)
    assert list(g.elements["rod__g"].fields["effort"]) == [0, 0, -sp.Rational(981, 50)]
    # the hinge point's velocity: omega x r (XTF) turned into R0 (MTF) plus v_G (0-junction)
    assert [kinds[n] for n in ("rod__hinge__x", "rod__hinge__R", "rod__hinge__0",
                               "rod__hinge")] == ["XTF", "MTF", "0", "1"]


@pytest.mark.parametrize("method, per_direction", [
    ("parasitic", Counter({"0": 1, "1": 1, "MTF": 1, "MSe": 1, "R": 1})),   # k g || c
    ("lagrange", Counter({"0": 1, "MTF": 1, "MSe": 1}))])                  # the multiplier
def test_each_blocked_direction_is_a_scalar_junction_closed_by_l(model, method, per_direction):
    g = expand(model, method)
    dirs = g.joints["hinge"]
    assert [d.label for d in dirs if d.blocked] == BLOCKED
    assert [d.label for d in dirs if not d.blocked] == ["rx"]
    for label in BLOCKED:
        own = Counter(e.kind for n, e in g.elements.items()
                      if n == f"hinge__{label}" or n.startswith(f"hinge__{label}__"))
        assert own == per_direction, (label, own)
        assert _dims(g, f"hinge__{label}") == {1}       # scalar: the projection's output
    # no element for the free direction: it carries no functional element
    assert not any(n.startswith("hinge__rx") for n in g.elements)
    assert [c.name for c in g.constraints] == (
        [f"hinge.{d}" for d in BLOCKED] if method == "lagrange" else [])
    # body: 4 multibonds, omega in R0: 2, the hinge point: 5; per direction one multibond
    # into its MTF and the scalar rest (parasitic: 0 -> 1 -> L, Lc; lagrange: 0 -> L)
    scalar = 4 if method == "parasitic" else 2
    assert Counter(b.dim for b in g.bonds) == {3: 4 + 2 + 5 + 5, 1: 5 * scalar}


def test_the_graphs_structure_holds(model):
    """Every element has its kind's number of bonds, each bond its two ends' port lists,
    and the bonds at a junction share one dimension (rule C1)."""
    g = expand(model)
    for name, el in g.elements.items():
        ports = KINDS[el.kind].ports
        assert len(g.ports[name]) == ports if ports else len(g.ports[name]) >= 2, name
        if el.kind in ("0", "1"):
            assert len(_dims(g, name)) == 1, name
    for i, b in enumerate(g.bonds):
        assert i in g.ports[b.src] and i in g.ports[b.dst]
