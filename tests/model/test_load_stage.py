"""Stage load on its own (model text -> Model) on a small model: parameters with units,
a signal, elements whose laws become sympy expressions in parameter, signal and local
symbols, bonds in file order, outputs as references, run settings, every part located by
its line; the digest follows the content, not the comments. (Refused input:
test_bad_input.py, test_hostile_input.py.)"""

from __future__ import annotations

import math

import pytest
import sympy as sp

from bgc.model import symbols
from bgc.model.load import loads

TINY = """\
name: tiny
parameters:
  m: {value: 2.0, unit: kg}
  k: 50.0
signals:
  push: {type: sine, amplitude: 3.0, frequency: 1.5}
elements:
  force: {type: Se, effort: push}
  v: {type: "1"}
  mass: {type: I, I: m, p0: "m*0.5"}
  spring: {type: C, effort: "k*q + q**3"}   # hardening
bonds:
  - [force, v]
  - [v, mass]
  - [v, spring]
outputs:
  x: spring.q
  energy: "mass.p**2/(2*m)"
simulation: {t_end: 3.0, solver: radau}
"""


def test_a_small_model_is_read_into_its_parts():
    model = loads(TINY, "tiny.yaml")
    P = symbols.param
    assert model.name == "tiny"
    assert {n: (p.value, p.unit, p.loc.line) for n, p in model.parameters.items()} == {
        "m": (2.0, "kg", 3), "k": (50.0, None, 4)}
    push = model.signals["push"]
    assert push.kind == "sine" and float(push.frequency) == 1.5
    assert float(push.expr.subs(symbols.t, 0.1)) == pytest.approx(3 * math.sin(0.3 * math.pi))
    els = model.elements
    assert {n: e.kind for n, e in els.items()} == {
        "force": "Se", "v": "1", "mass": "I", "spring": "C"}
    assert els["force"].fields == {"effort": symbols.signal("push")}
    assert els["mass"].fields == {"I": P("m")} and els["mass"].initial == 0.5 * P("m")
    q = symbols.LOCAL["q"]
    assert sp.expand(els["spring"].fields["effort"] - (P("k") * q + q ** 3)) == 0
    assert els["spring"].initial == 0                               # q0 defaults to 0
    assert els["spring"].field_locs["effort"].line == 11
    assert [(b.name, b.src, b.dst, b.dim, b.loc.line) for b in model.bonds] == [
        ("b1", "force", "v", 1, 13), ("b2", "v", "mass", 1, 14), ("b3", "v", "spring", 1, 15)]
    outputs = {o.name: o.expr for o in model.outputs}
    assert outputs["x"] == symbols.ref("spring", "q")
    assert sp.simplify(outputs["energy"] - symbols.ref("mass", "p") ** 2 / (2 * P("m"))) == 0
    assert (model.settings.t_end, model.settings.solver) == (3.0, "radau")
    assert model.bodies == {} and model.joints == {} and model.excitation is None


def test_the_digest_follows_the_content_not_the_comments():
    digest = loads(TINY).digest
    assert loads(TINY.replace("# hardening", "# stiffer than linear")).digest == digest
    assert loads(TINY.replace("k: 50.0", "k: 51.0")).digest != digest
    assert loads(TINY.replace("[v, spring]", "[spring, v]")).digest != digest
