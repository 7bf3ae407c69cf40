"""Stage equations on its own (CausalGraph -> EquationSystem) on small scalar models: the
states, the assignments in causal order (each variable defined once, before it is read),
and the rates they give against the ODE written by hand; a derivative-causal inertia
becomes a dependent state in a derivative loop, three resistors an algebraic loop solved
symbolically."""

from __future__ import annotations

import sympy as sp

from helpers import resolved_rates

from bgc.codegen.equations import derive
from bgc.graph.causality import assign
from bgc.graph.expand import expand
from bgc.model.load import loads

SERIES_RLC = """\
name: rlc
parameters: {V: 12.0, R: 10.0, L: 0.05, C: 2.0e-5}
elements:
  source: {type: Se, effort: V}
  loop: {type: "1"}
  resistor: {type: R, R: R}
  inductor: {type: I, I: L}
  capacitor: {type: C, C: C}
bonds: [[source, loop], [loop, resistor], [loop, inductor], [loop, capacitor]]
outputs: {current: inductor.f}
"""
GEARED = """\
name: geared
parameters: {T: 1.0, J1: 0.01, J2: 0.5, n: 0.25}
elements:
  motor: {type: Se, effort: T}
  rotor: {type: "1"}
  J_r: {type: I, I: J1}
  gear: {type: TF, ratio: n}
  load: {type: "1"}
  J_l: {type: I, I: J2}
bonds: [[motor, rotor], [rotor, J_r], [rotor, gear], [gear, load], [load, J_l]]
"""
RR_LOOP = """\
name: rr
parameters: {E: 10.0, R1: 1.0e3, R2: 2.0e3, R3: 500.0, C: 1.0e-6}
elements:
  source: {type: Se, effort: E}
  s1: {type: "1"}
  r1: {type: R, R: R1}
  node: {type: "0"}
  r2: {type: R, R: R2}
  s2: {type: "1"}
  r3: {type: R, R: R3}
  cap: {type: C, C: C}
bonds: [[source, s1], [s1, r1], [s1, node], [node, r2], [node, s2], [s2, r3], [s2, cap]]
"""


def system(text):
    return derive(assign(expand(loads(text))))


def names(s) -> dict[str, sp.Symbol]:
    return {name: sym for sym, name, _ in s.params} | {st.name: st.sym for st in s.states}


def test_series_rlc_gives_its_two_state_ode():
    s = system(SERIES_RLC)
    assert [st.name for st in s.states] == ["inductor.p", "capacitor.q"]
    assert [n for _, n, _ in s.params] == ["V", "R", "L", "C"]
    assert s.loops == [] and s.dependent == {}
    n = names(s)
    p, q, V, R, L, C = (n[k] for k in ("inductor.p", "capacitor.q", "V", "R", "L", "C"))
    r = resolved_rates(s)
    assert sp.cancel(r["inductor.p"] - (V - R * p / L - q / C)) == 0
    assert sp.cancel(r["capacitor.q"] - p / L) == 0
    # the output, through the kept assignments: the current p/L
    (name, expr), = s.outputs
    assert name == "current" and sp.cancel(expr.xreplace(dict(s.assignments)) - p / L) == 0


def test_second_inertia_behind_a_gear_is_a_dependent_state_in_a_derivative_loop():
    s = system(GEARED)
    assert [st.name for st in s.states] == ["J_r.p"]
    assert s.dependent == {"J_l": "J_l.p"}
    (loop,) = s.loops
    assert loop.kind == "derivative" and {"J_l", "J_r", "gear"} <= set(loop.elements)
    n = names(s)
    # one effective inertia: J1 + J2 n^2 seen from the rotor
    T, J1, J2, g = n["T"], n["J1"], n["J2"], n["n"]
    assert sp.cancel(resolved_rates(s)["J_r.p"] - T * J1 / (J1 + J2 * g ** 2)) == 0


def test_resistor_network_is_an_algebraic_loop_solved_symbolically():
    s = system(RR_LOOP)
    assert [st.name for st in s.states] == ["cap.q"]
    (loop,) = s.loops
    assert loop.kind == "algebraic" and {"r1", "r2", "r3"} <= set(loop.elements)
    assert len(loop.tearing) == 1
    n = names(s)
    q, E, R1, R2, R3, C = (n[k] for k in ("cap.q", "E", "R1", "R2", "R3", "C"))
    # Thevenin: E R2/(R1+R2) behind R1 || R2 + R3, charging C
    thevenin = (E * R2 / (R1 + R2) - q / C) / (R1 * R2 / (R1 + R2) + R3)
    assert sp.cancel(resolved_rates(s)["cap.q"] - thevenin) == 0
