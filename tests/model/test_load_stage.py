"""The load stage alone: a few lines of YAML text -> Model, checked field by field, and
its parts (the located document, the value checks, the section readers) on their own.
No graph, equations or generated code: these run in milliseconds."""

from __future__ import annotations

import math
import textwrap

import pytest
import sympy as sp

from bgc.errors import Loc, ModelError
from bgc.model import document, load, symbols, values
from bgc.model.model import Parasitic, Settings
from bgc.model.sections import bodies, joints, network, parameters
from bgc.model.sections.context import Context

RLC = textwrap.dedent("""\
    name: tiny
    description: a series RLC circuit
    parameters:
      R: 2.0
      L: {value: 0.5, unit: H}
      C: 1e-3
    signals:
      u: {type: sine, amplitude: 3, frequency: 50}
    elements:
      src: {type: Se, effort: u}
      j: {type: "1"}
      r: {type: R, R: R}
      l: {type: I, I: L, p0: 0.1}
      c: {type: C, C: C}
    bonds:
      - [src, j]
      - {name: br, from: j, to: r}
      - [j, l]
      - [j, c]
    outputs:
      i: l.f
      v_c: c.e
    simulation: {t_end: 0.2, rtol: 1e-7, solver: radau, points: 201}
    """)

PENDULUM = textwrap.dedent("""\
    name: swing
    gravity: 9.81
    parasitic: {stiffness: 2e6}
    bodies:
      arm:
        mass: 2.0
        com: [0.5, 0, 0]
        inertia: [0.01, 0.2, 0.2]
        points: {pivot: [0, 0, 0]}
    joints:
      hinge:
        type: revolute
        between: [fixed_frame, arm]
        at: arm.pivot
        axis: [0, 0, 2]
        spring: {k: 3.0, c: 0.5}
        parasitic: {damping: 7.0}
    outputs:
      angle: arm.ay
    """)


def test_a_circuit_loads_field_by_field():
    m = load.loads(RLC, "tiny.yaml")
    assert (m.name, m.file, m.description) == ("tiny", "tiny.yaml", "a series RLC circuit")
    assert {n: p.value for n, p in m.parameters.items()} == {"R": 2.0, "L": 0.5, "C": 1e-3}
    assert m.parameters["L"].unit == "H" and m.parameters["R"].loc == Loc("tiny.yaml", 4, 6)
    u = m.signals["u"]
    assert (u.kind, u.frequency, u.breakpoints) == ("sine", 50, ())
    assert u.expr == 3 * sp.sin(100 * sp.pi * symbols.t)
    assert [(e.name, e.kind) for e in m.elements.values()] == [
        ("src", "Se"), ("j", "1"), ("r", "R"), ("l", "I"), ("c", "C")]
    assert m.elements["src"].fields == {"effort": symbols.signal("u")}
    assert m.elements["r"].fields == {"R": symbols.param("R")}
    assert m.elements["l"].initial == sp.Float(0.1) and m.elements["c"].initial == 0
    assert [(b.name, b.src, b.dst, b.dim) for b in m.bonds] == [
        ("b1", "src", "j", 1), ("br", "j", "r", 1), ("b3", "j", "l", 1), ("b4", "j", "c", 1)]
    assert m.bonds[1].loc == Loc("tiny.yaml", 17, 5)
    assert [(o.name, o.expr) for o in m.outputs] == [
        ("i", symbols.ref("l", "f")), ("v_c", symbols.ref("c", "e"))]
    assert m.settings == Settings(t_end=0.2, rtol=1e-7, solver="radau", points=201)
    assert (m.bodies, m.joints, m.excitation, m.gravity) == ({}, {}, None, (0.0, 0.0, 0.0))
    assert m.digest == document.digest(document.from_text(RLC, "elsewhere.yaml"))


def test_a_body_and_its_joint_load_field_by_field():
    m = load.loads(PENDULUM, "swing.yaml")
    assert m.gravity == (0.0, 0.0, -9.81)
    arm = m.bodies["arm"]
    assert (arm.mass, arm.inertia, arm.com) == (2.0, (0.01, 0.2, 0.2), (0.5, 0.0, 0.0))
    assert arm.frame == ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))
    assert arm.points == {"pivot": (-0.5, 0.0, 0.0)}       # in the body frame, from G
    hinge = m.joints["hinge"]
    assert (hinge.kind, hinge.body1, hinge.body2, hinge.at) == (
        "revolute", None, "arm", (0.0, 0.0, 0.0))
    # joint frame (columns): x the axis (z of R0), y the R0 axis most nearly
    # perpendicular to it (x of R0), z = x cross y
    assert hinge.frame == ((0.0, 1.0, 0.0), (0.0, 0.0, 1.0), (1.0, 0.0, 0.0))
    assert hinge.parasitic == Parasitic(stiffness=2e6, damping=7.0)
    spring = hinge.functional["rx"]        # a revolute joint's free direction
    assert (spring.k, spring.c, spring.preload, spring.actuator) == (3.0, 0.5, 0.0, None)
    assert list(hinge.functional) == ["rx"] and spring.loc == Loc("swing.yaml", 16, 13)
    # the joint's stiffnesses, dampings and preload are parameters (changed without
    # recompiling)
    assert m.parameters["hinge__stiffness"].value == 2e6
    assert {n: p.value for n, p in m.parameters.items() if n.startswith("hinge__r")} == {
        "hinge__rot_stiffness": 1e5, "hinge__rot_damping": 10.0, "hinge__ry_load": 0.0,
        "hinge__rz_load": 0.0, "hinge__rx_k": 3.0, "hinge__rx_c": 0.5,
        "hinge__rx_preload": 0.0}
    assert [(o.name, o.expr) for o in m.outputs] == [("angle", symbols.ref("arm", "ay"))]


def test_overrides_replace_a_value_before_it_is_checked():
    m = load.loads(RLC, "tiny.yaml", overrides={"R": 5.0})
    assert m.parameters["R"].value == 5.0
    with pytest.raises(ModelError) as e:
        load.loads(RLC, "tiny.yaml", overrides={"C": 0.0})
    assert (e.value.key, e.value.loc.line) == ("elements.c.C", 14)
    assert "parameter 'C' is set by -p" in e.value.message


def test_the_document_keeps_every_position():
    doc = document.from_text("a: 1\nb:\n  - x\n  - {y: 2}\n", "d.yaml")
    assert doc == {"a": 1, "b": ["x", {"y": 2}]}
    assert (doc.key_locs["b"], doc.val_locs["a"]) == (Loc("d.yaml", 2, 1), Loc("d.yaml", 1, 4))
    assert doc["b"].item_locs == [Loc("d.yaml", 3, 5), Loc("d.yaml", 4, 5)]
    assert doc["b"][1].val_locs["y"] == Loc("d.yaml", 4, 9)


def test_a_value_check_names_its_place_key_and_hint():
    doc = document.from_text("n: 1e-3\ns: [1, 2]\nv: [1, 2, x]\n", "v.yaml")
    assert values.number(doc["n"], doc.val_locs["n"], "n") == 1e-3   # YAML 1.1's string
    three = document.from_text("[1, 2, 3]", "v.yaml")
    assert values.vector(three, None, "v") == (1.0, 2.0, 3.0)
    with pytest.raises(ModelError) as e:
        values.string(doc["s"], doc.val_locs["s"], "s", "a path")
    assert (str(e.value.loc), e.value.key, e.value.message, e.value.hint) == (
        "v.yaml:2:4", "s", "expected a path, got a list [1, 2]", "write a path as plain text")
    with pytest.raises(ModelError) as e:
        values.vector(doc["v"], doc.val_locs["v"], "v")
    assert (str(e.value.loc), e.value.key) == ("v.yaml:3:11", "v[2]")
    with pytest.raises(ModelError, match="must be > 0, got -1.0"):
        values.number(-1, None, "x", positive=True)
    with pytest.raises(ModelError, match=r"unknown key 'z'"):
        values.check_keys(document.from_text("z: 1", "k.yaml"), ("a", "b"), "m")


def test_a_section_reader_runs_alone():
    cx = Context("p.yaml")
    doc = document.from_text("g: 2.0\nh: {value: 90, unit: deg}\n", "p.yaml")
    params = parameters.parameters(cx, doc)
    assert params["h"].value == pytest.approx(math.pi / 2) and params["h"].unit == "deg"
    assert cx.pvals == {symbols.param("g"): 2.0, symbols.param("h"): params["h"].value}
    assert cx.names["g"] == ("parameter 'g'", Loc("p.yaml", 1, 1))
    with pytest.raises(ModelError) as e:        # one namespace for every section
        network.element_headers(cx, document.from_text("x: {type: C}\ng: {type: R}\n",
                                                        "e.yaml"))
    assert e.value.message == "duplicate name 'g'" and e.value.loc == Loc("e.yaml", 2, 1)
    assert e.value.hint == "already used by parameter 'g' at line 1"


def test_geometry_readers_are_exact():
    F = bodies.frame(document.from_text("{x: [1, 1, 0], y: [-1, 1, 0], z: [0, 0, 3]}",
                                        "f.yaml"), None, "frame")
    assert F == sp.Matrix([[1, -1, 0], [1, 1, 0], [0, 0, sp.sqrt(2)]]) / sp.sqrt(2)
    axis = bodies.unit_vector(document.from_text("[0, 3, 4]", "a.yaml"), None, "axis")
    assert axis == sp.Matrix([0, sp.Rational(3, 5), sp.Rational(4, 5)])
    base = Parasitic(stiffness=5.0)
    assert joints.parasitic(document.from_text("{damping: 1}", "j.yaml"), None, "j",
                            base) == Parasitic(stiffness=5.0, damping=1.0)


def test_an_output_may_declare_its_unit():
    """``outputs: {name: {expr, unit}}`` beside the plain form (issue 27): the unit is kept
    for labels (a number given as a unit is its text, as earlier bgc read it); a unit
    outside the safe characters, a list, an unknown key or a missing expr is refused at
    its line and key."""
    text = RLC.replace("  i: l.f\n", "  i: {expr: l.f, unit: A}\n").replace(
        "  v_c: c.e\n", "  v_c: {expr: c.e, unit: \"1\"}\n  charge: c.q\n")
    m = load.loads(text, "u.yaml")
    assert [(o.name, o.unit, str(o.expr)) for o in m.outputs] == [
        ("i", "A", "REF_l__f"), ("v_c", "1", "REF_c__e"), ("charge", None, "REF_c__q")]
    numbered = load.loads(text.replace("unit: A}", "unit: 1}"), "u.yaml")   # read as text
    assert numbered.outputs[0].unit == "1"
    line = text.splitlines().index("  i: {expr: l.f, unit: A}") + 1
    for form, key, says in [
            ("{expr: l.f, unit: \"A$\\\\x$\"}", "outputs.i.unit", "not a unit text"),
            ("{expr: l.f, unit: 'A\"); import os; (\"'}", "outputs.i.unit", "not a unit text"),
            ("{expr: l.f, unit: \"\\u00b5A\"}", "outputs.i.unit", "not a unit text"),
            ("{expr: l.f, unit: " + "m" * 33 + "}", "outputs.i.unit", "not a unit text"),
            ("{expr: l.f, unit: [A]}", "outputs.i.unit", "expected a unit text"),
            ("{expr: l.f, units: A}", "outputs.i.units", "unknown key 'units'"),
            ("{unit: A}", "outputs.i", "missing 'expr'"),
            ("{expr: l.nope, unit: A}", "outputs.i.expr", "nope")]:
        bad = text.replace("{expr: l.f, unit: A}", form)
        with pytest.raises(ModelError) as e:
            load.loads(bad, "u.yaml")
        assert (e.value.key, e.value.loc.line) == (key, line), (form, e.value)
        assert says in e.value.message, (form, e.value.message)
