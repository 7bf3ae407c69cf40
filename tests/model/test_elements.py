"""Every scalar element kind, signal kind and law form, on small inline models."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import rel_err
from scipy.integrate import solve_ivp

from bgc.codegen.emit import import_module
from bgc.errors import EquationError
from bgc.pipeline import build, compile_model
from bgc.simulate import simulate

TIGHT = dict(rtol=1e-11, atol=1e-13, solver="radau")


def make(tmp_path, text, name="m"):
    f = tmp_path / f"{name}.yaml"
    f.write_text(text)
    _, path = compile_model(f, tmp_path / "gen")
    return import_module(path)


def test_flow_source_charges_rc(tmp_path):
    mod = make(tmp_path, """
name: sf_rc
parameters: {I0: 2.0e-3, R: 1000.0, C: 1.0e-6}
elements:
  src: {type: Sf, flow: I0}
  node: {type: "0"}
  r: {type: R, R: R}
  cap: {type: C, C: C}
bonds: [[src, node], [node, r], [node, cap]]
outputs: {v: node.e, power: src.e * src.f}
""", "sf_rc")
    r = simulate(mod, t_end=0.01, **TIGHT)
    v = 2e-3 * 1000 * (1 - np.exp(-r.t / 1e-3))
    assert rel_err(r.column("v"), v) < 1e-7
    assert rel_err(r.column("power"), 2e-3 * v) < 1e-7


def test_modulated_flow_source_and_reversed_bond(tmp_path):
    """MSf with a sine; the capacitor's bond is drawn out of it, which changes the sign of
    the bond's flow but not the physics: the capacitor still charges with the source."""
    mod = make(tmp_path, """
name: msf_c
parameters: {A: 1.0e-3, C: 1.0e-6}
signals: {u: {type: sine, amplitude: A, frequency: 50}}
elements:
  src: {type: MSf, flow: "u * (1 + 0*t)"}
  node: {type: "0"}
  cap: {type: C, C: C}
bonds: [[src, node], [cap, node]]
outputs: {charge: cap.q}
""", "msf_c")
    r = simulate(mod, t_end=0.04, **TIGHT)
    w = 2 * np.pi * 50
    q = 1e-3 * (1 - np.cos(w * r.t)) / w
    assert rel_err(r.column("charge"), q) < 1e-7


def test_mtf_with_time_varying_ratio(tmp_path):
    """An effort source through a lever whose ratio changes in time drives a damped mass:
    m dv/dt = E / n(t) - c v."""
    mod = make(tmp_path, """
name: mtf_lever
parameters: {E: 3.0, m: 0.5, c: 2.0}
elements:
  src: {type: Se, effort: E}
  lever: {type: MTF, ratio: "1 + 0.5*sin(4*t)"}
  j: {type: "1"}
  mass: {type: I, I: m}
  damper: {type: R, R: c}
bonds: [[src, lever], [lever, j], [j, mass], [j, damper]]
outputs: {v: j.f, f_src: src.f}
""", "mtf_lever")
    r = simulate(mod, t_end=3.0, **TIGHT)
    n = lambda t: 1 + 0.5 * np.sin(4 * t)  # noqa: E731
    ref = solve_ivp(lambda t, v: [(3.0 / n(t) - 2.0 * v[0]) / 0.5], (0, 3), [0.0],
                    method="Radau", rtol=1e-12, atol=1e-14, t_eval=r.t)
    assert rel_err(r.column("v"), ref.y[0]) < 1e-7
    assert rel_err(r.column("f_src"), ref.y[0] / n(r.t)) < 1e-7  # f1 = f2 / n


def test_gy_and_mgy_agree(tmp_path):
    """The same DC motor twice in one model (one module), through a GY and through an MGY
    with the same modulus: the two rotors turn alike."""
    motor = """\
  src_X: {type: Se, effort: U}
  a_X: {type: "1"}
  r_X: {type: R, R: R}
  l_X: {type: I, I: L}
  g_X: {type: KIND, r: km}
  s_X: {type: "1"}
  rotor_X: {type: I, I: J}
"""
    bonds = "[src_X, a_X], [a_X, r_X], [a_X, l_X], [a_X, g_X], [g_X, s_X], [s_X, rotor_X]"
    mod = make(tmp_path, f"""
name: gy_mgy
parameters: {{U: 5.0, R: 1.0, L: 1.0e-3, km: 0.1, J: 1.0e-4}}
elements:
{motor.replace("X", "gy").replace("KIND", "GY")}{motor.replace("X", "mgy").replace("KIND", "MGY")}
bonds: [{bonds.replace("X", "gy")}, {bonds.replace("X", "mgy")}]
outputs: {{w_gy: s_gy.f, w_mgy: s_mgy.f}}
""", "gy_mgy")
    r = simulate(mod, t_end=0.1, **TIGHT)
    assert rel_err(r.column("w_mgy"), r.column("w_gy")) < 1e-9
    assert abs(r.column("w_gy")[-1] - 5.0 / 0.1) / 50 < 1e-3   # no-load speed U / km


def test_signals(tmp_path):
    mod = make(tmp_path, """
name: sigs
parameters: {A: 2.0}
signals:
  k: {type: constant, value: A}
  s: {type: step, time: 0.25, initial: -1, final: 3}
  w: {type: sine, amplitude: A, frequency: 2, phase: 0.5, offset: 1}
  r: {type: ramp, slope: 4, time: 0.5, initial: 1}
  tb: {type: table, t: [0, 0.2, 0.6], values: [1, -1, 2]}
  ex: {type: expression, expr: "A*t**2"}
elements:
  src: {type: Se, effort: "k + s + w + r + tb + ex"}
  cap: {type: C, C: 1}
  res: {type: R, R: 1}
  j: {type: "1"}
bonds: [[src, j], [j, cap], [j, res]]
outputs: {o_k: k, o_s: s, o_w: w, o_r: r, o_tb: tb, o_ex: ex}
""", "sigs")
    assert list(mod.BREAKPOINTS) == [0.0, 0.2, 0.25, 0.5, 0.6]
    r = simulate(mod, t_end=1.0, points=101)
    t = r.t
    assert np.allclose(r.column("o_k"), 2.0)
    assert np.allclose(r.column("o_s"), np.where(t < 0.25, -1, 3))
    assert np.allclose(r.column("o_w"), 1 + 2 * np.sin(2 * np.pi * 2 * t + 0.5))
    assert np.allclose(r.column("o_r"), np.where(t < 0.5, 1, 1 + 4 * (t - 0.5)))
    assert np.allclose(r.column("o_tb"), np.interp(t, [0, 0.2, 0.6], [1, -1, 2]))
    assert np.allclose(r.column("o_ex"), 2 * t ** 2)


def test_law_written_for_the_other_causality_is_inverted(tmp_path):
    """An R given as flow(e) but forced into resistance causality (a flow source drives
    it): bgc inverts e = R f symbolically."""
    mod = make(tmp_path, """
name: inv
parameters: {I0: 0.5, G: 4.0}
elements:
  src: {type: Sf, flow: I0}
  r: {type: R, flow: "G*e"}
  j: {type: "1"}
  cap: {type: C, C: 1.0}
bonds: [[src, j], [j, r], [j, cap]]
outputs: {v_r: r.e}
""", "inv")
    r = simulate(mod, t_end=0.1)
    assert np.allclose(r.column("v_r"), 0.5 / 4.0)


def test_law_that_cannot_be_inverted_is_refused(tmp_path):
    f = tmp_path / "cubic.yaml"
    f.write_text("""
elements:
  src: {type: Sf, flow: 1.0}
  r: {type: R, flow: "e**3 - e"}
  j: {type: "1"}
  cap: {type: C, C: 1.0}
bonds: [[src, j], [j, r], [j, cap]]
""")
    with pytest.raises(EquationError, match="cannot be inverted uniquely"):
        build(f)


def test_nonlinear_algebraic_loop_is_refused_naming_its_elements(tmp_path):
    f = tmp_path / "nl.yaml"
    f.write_text("""
elements:
  src: {type: Se, effort: 1.0}
  s1: {type: "1"}
  d: {type: R, effort: "f + f**3"}
  node: {type: "0"}
  r2: {type: R, R: 1.0}
  s2: {type: "1"}
  r3: {type: R, R: 1.0}
  cap: {type: C, C: 1.0}
bonds: [[src, s1], [s1, d], [s1, node], [node, r2], [node, s2], [s2, r3], [s2, cap]]
""")
    with pytest.raises(EquationError, match="nonlinear algebraic loop") as exc:
        build(f)
    msg = str(exc.value)
    assert "r2" in msg and "b3" in msg and "nl.yaml:" in msg


def test_two_inertias_on_one_junction_give_derivative_causality(tmp_path):
    mod = make(tmp_path, """
name: two_masses
parameters: {F: 3.0, m1: 1.0, m2: 2.0, k: 50.0}
elements:
  push: {type: Se, effort: F}
  j: {type: "1"}
  a: {type: I, I: m1}
  b: {type: I, I: m2}
  spring: {type: C, k: k}
bonds: [[push, j], [j, a], [j, b], [j, spring]]
outputs: {x: spring.q, p_b: b.p}
""", "two_masses")
    assert mod.STATE_NAMES == ("a.p", "spring.q")
    r = simulate(mod, t_end=2.0, **TIGHT)
    w = np.sqrt(50.0 / 3.0)
    x = 3.0 / 50.0 * (1 - np.cos(w * r.t))
    assert rel_err(r.column("x"), x) < 1e-7
    assert rel_err(r.column("p_b"), 2.0 * 3.0 / 50.0 * w * np.sin(w * r.t)) < 1e-7
