"""Stage causality on its own (BondGraph -> CausalGraph, SCAP) on small hand-built scalar
bond graphs: where the strokes go, which storage takes derivative causality, which R is a
free choice (an algebraic loop follows), and a conflict between two sources."""

from __future__ import annotations

import pytest

from bgc.errors import CausalityError, Loc
from bgc.graph.bondgraph import BondGraph
from bgc.graph.causality import assign
from bgc.model.model import Bond, Element


def graph(elements: str, bonds: str) -> BondGraph:
    """A scalar bond graph from ``name:kind`` words and ``src>dst`` words (bond i is the
    i-th word, named b<i+1>). Causality reads the elements' kinds and law keys (an R's law
    is written as a resistance), the bonds and the ports; the Model is not needed."""
    laws = {"Se": "effort", "Sf": "flow", "R": "R", "C": "C", "I": "I"}
    els = {}
    for i, word in enumerate(elements.split()):
        name, kind = word.split(":")
        fields = {laws[kind]: 1} if kind in laws else {}
        els[name] = Element(name, kind, Loc("<test>", i + 1), fields=fields)
    bs = [Bond(f"b{i + 1}", *word.split(">"), Loc("<test>", i + 1))
          for i, word in enumerate(bonds.split())]
    ports = {name: [i for i, b in enumerate(bs) if name in (b.src, b.dst)] for name in els}
    return BondGraph(None, els, bs, ports)


def test_series_rlc_takes_integral_causality_and_resistance_form():
    g = graph("source:Se loop:1 resistor:R inductor:I capacitor:C",
              "source>loop loop>resistor loop>inductor loop>capacitor")
    cg = assign(g)
    assert cg.storage == {"inductor": "integral", "capacitor": "integral"}
    assert cg.r_form == {"resistor": "resistance"}
    # the inductor alone sets the junction's flow; every other bond brings it an effort
    assert cg.effort_in == ["loop", "loop", "inductor", "loop"]
    assert cg.choices == []


def test_second_inertia_on_a_one_junction_takes_derivative_causality():
    g = graph("motor:Se shaft:1 rotor:I load:I", "motor>shaft shaft>rotor shaft>load")
    cg = assign(g)
    assert cg.storage == {"rotor": "integral", "load": "derivative"}
    assert cg.effort_in == ["shaft", "rotor", "shaft"]      # load's flow is imposed


def test_resistors_left_free_by_the_storage_are_free_choices():
    """E - R1 - (R2 to ground) - R3 - C: with the capacitor in integral causality nothing
    fixes the resistors, so SCAP chooses their form: a causal loop through R1, R2, R3."""
    g = graph("source:Se s1:1 r1:R node:0 r2:R s2:1 r3:R cap:C",
              "source>s1 s1>r1 s1>node node>r2 node>s2 s2>r3 s2>cap")
    cg = assign(g)
    assert cg.storage == {"cap": "integral"}
    assert set(cg.r_form) == {"r1", "r2", "r3"}
    free = [c for c in cg.choices if c.startswith("R '")]
    assert free and all("free choice" in c for c in free), cg.choices
    # the 0-junction receives its effort on exactly one bond, a 1-junction its flow
    assert sum(cg.effort_in[b] == "node" for b in g.ports["node"]) == 1
    for one in ("s1", "s2"):
        assert sum(cg.effort_in[b] != one for b in g.ports[one]) == 1


def test_two_effort_sources_on_a_zero_junction_conflict_naming_both():
    g = graph("e1:Se e2:Se node:0 r:R", "e1>node e2>node node>r")
    with pytest.raises(CausalityError) as err:
        assign(g)
    msg = str(err.value)
    assert "node" in msg and "b1" in msg and "b2" in msg, msg
