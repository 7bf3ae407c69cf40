"""Control blocks compiled and run (issue 26, item 3): a PI position loop on a DC motor,
with a sensor lag, an error sum, a PID and a clamping integrator beside it, against the
same equations written out by hand and integrated by scipy; the analytic Jacobian against
finite differences, saturated and not; ``-p`` retunes the controller without a
recompile. One compile for the whole file."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import fd_jacobian
from scipy.integrate import solve_ivp

from bgc.cli.options import check_overrides, parse_params
from bgc.errors import BgcError, EquationError
from bgc.model.load import loads
from bgc.pipeline import build, ensure_module
from bgc.simulate import simulate

MOTOR = """\
name: pi_motor
parameters:
  Ra: 1.0
  La: 2.0e-3
  km: 0.05
  b_m: 1.0e-5
  ratio: 0.1          # load speed = ratio * motor speed
  J_l: 2.0e-3
  b_l: 1.0e-3
  x_set: 2.0          # rad, the load angle's setpoint
  kp: 40.0
  ki: 20.0
  U_max: 12.0
  T_s: 0.005
  kd: 0.5
elements:
  supply: {type: MSe, effort: ctrl.y}
  arm: {type: "1"}
  R_a: {type: R, R: Ra}
  L_a: {type: I, I: La}
  motor: {type: GY, r: km}
  shaft: {type: "1"}
  bearing: {type: R, R: b_m}
  gear: {type: TF, ratio: ratio}
  load: {type: "1"}
  J: {type: I, I: J_l}
  friction: {type: R, R: b_l}
  angle: {type: C, k: 0}
bonds:
  - [supply, arm]
  - [arm, R_a]
  - [arm, L_a]
  - [arm, motor]
  - [motor, shaft]
  - [shaft, bearing]
  - [shaft, gear]
  - [gear, load]
  - [load, J]
  - [load, friction]
  - [load, angle]
blocks:
  sensor: {type: lag, input: angle.q, T: T_s}
  err: {type: sum, inputs: [x_set, -sensor.y]}
  ctrl: {type: PI, input: err.y, kp: kp, ki: ki, limits: [-U_max, U_max]}
  pid: {type: PID, input: err.y, kp: 2 * kp, ki: ki, kd: kd, n: 8, limits: [-U_max, U_max]}
  wind: {type: integrator, input: err.y, k: 10, limits: [-0.5, 0.5]}
  drop: {type: gain, input: L_a.f, k: Ra, limits: [-5, 5]}
outputs:
  theta: angle.q
  voltage: ctrl.y
  pid_out: pid.y
  wound: wind.y
  current: L_a.f
  ra_drop: drop.y
simulation: {t_end: 0.6}
"""
T_END = 0.6
ORDER = ("L_a.p", "J.p", "angle.q", "sensor.x", "ctrl.xi", "pid.xi", "pid.xd", "wind.x")


def hand_rhs(P):
    """The model's equations written out: the motor (current i, load speed w, angle),
    the sensor lag, the PI (back-calculation, Tt = kp/ki), the PID (Tt = sqrt(kd/ki),
    derivative filter Tf = kd/(kp n)) and the clamping integrator."""
    kp2, n = 2 * P["kp"], 8.0
    tf = P["kd"] / (kp2 * n)
    U = P["U_max"]

    def f(t, x):
        Lp, Jp, th, s, xi, xi2, xd, w = x
        i, wl = Lp / P["La"], Jp / P["J_l"]
        wm = wl / P["ratio"]
        e = P["x_set"] - s
        v = P["kp"] * e + xi
        V = min(max(v, -U), U)
        v2 = kp2 * e + xi2 + P["kd"] / tf * (e - xd)
        y2 = min(max(v2, -U), U)
        rw = 10 * e
        rw = min(rw, 0.0) if w >= 0.5 else max(rw, 0.0) if w <= -0.5 else rw
        return [V - P["Ra"] * i - P["km"] * wm,
                (P["km"] * i - P["b_m"] * wm) / P["ratio"] - P["b_l"] * wl,
                wl, (th - s) / P["T_s"],
                P["ki"] * e + (V - v) * P["ki"] / P["kp"],
                P["ki"] * e + (y2 - v2) * np.sqrt(P["ki"] / P["kd"]),
                (e - xd) / tf, rw]
    return f


@pytest.fixture(scope="module")
def motor(tmp_path_factory):
    """(model path, output directory, generated module)."""
    root = tmp_path_factory.mktemp("blocks")
    path = root / "pi_motor.yaml"
    path.write_text(MOTOR)
    mod, _, compiled = ensure_module(path, root / "gen")
    assert compiled is not None
    return path, root / "gen", mod


def _run(mod, p):
    """bgc's run at rtol 1e-10 and scipy's on the hand-written equations: their
    states (in ``ORDER``) on the same grid."""
    r = simulate(mod, t_end=T_END, rtol=1e-10, atol=1e-12, points=301, params=p,
                 solver="native")
    P = dict(zip(mod.PARAM_NAMES, p))
    ref = solve_ivp(hand_rhs(P), (0, T_END), np.zeros(8), method="Radau", t_eval=r.t,
                    rtol=1e-11, atol=1e-13)
    idx = [list(mod.STATE_NAMES).index(n) for n in ORDER]
    return r, r.x[:, idx], ref.y.T


def _agreement(x, ref) -> float:
    """Largest deviation, each state relative to its largest magnitude."""
    return float(np.max(np.abs(x - ref) / np.abs(ref).max(axis=0)))


def test_pi_loop_with_saturation_matches_hand_written_equations(motor):
    _, _, mod = motor
    assert set(mod.STATE_NAMES) == set(ORDER)
    r, x, ref = _run(mod, mod.PARAMS)
    assert _agreement(x, ref) < 1e-7
    volts, wound = r.column("voltage"), r.column("wound")
    at_limit = np.isclose(np.abs(volts), 12.0, rtol=0, atol=1e-12)
    assert 0.05 < at_limit.mean() < 0.6          # saturated part of the time, not all
    assert abs(volts[-1]) < 1.0 and abs(r.column("theta")[-1] - 2.0) < 0.05
    assert np.max(wound) == pytest.approx(0.5, abs=1e-12)     # the integrator clamped
    assert np.max(np.abs(r.column("ra_drop"))) == pytest.approx(5.0, abs=1e-12)
    assert np.max(np.abs(r.column("pid_out"))) == pytest.approx(12.0, abs=1e-12)


def test_jacobian_matches_finite_differences_saturated_and_not(motor):
    _, _, mod = motor
    P = dict(zip(mod.PARAM_NAMES, mod.PARAMS))
    idx = {n: list(mod.STATE_NAMES).index(n) for n in ORDER}
    saturated = np.zeros(len(ORDER))             # at the start: error 2 rad, every limit hit
    inside = np.zeros(len(ORDER))                # near the setpoint: every block linear
    for name, val in (("angle.q", 1.999), ("sensor.x", 1.998), ("ctrl.xi", 0.3),
                      ("pid.xi", 0.1), ("pid.xd", 0.0015), ("wind.x", 0.2),
                      ("L_a.p", 1e-3 * P["La"]), ("J.p", 1e-3 * P["J_l"])):
        inside[idx[name]] = val
    saturated[idx["wind.x"]] = 0.7
    for x in (saturated, inside):
        J, fd = mod.jac(0.1, x, mod.PARAMS), fd_jacobian(mod, 0.1, x, mod.PARAMS)
        assert np.abs(J - fd).max() <= 1e-6 * np.abs(fd).max()
    ctrl_xi = idx["ctrl.xi"]      # d(L_a.p)'/d(ctrl.xi): 1 inside the limits, 0 beyond
    assert mod.jac(0.1, inside, mod.PARAMS)[idx["L_a.p"], ctrl_xi] == 1.0
    assert mod.jac(0.1, saturated, mod.PARAMS)[idx["L_a.p"], ctrl_xi] == 0.0


def test_minus_p_retunes_the_controller_without_recompiling(motor):
    path, gen, mod = motor
    stamp = (gen / "pi_motor.py").stat().st_mtime_ns
    check_overrides(path, [("kp", 60.0), ("ki", 5.0)])
    again, _, compiled = ensure_module(path, gen)
    assert compiled is None and (gen / "pi_motor.py").stat().st_mtime_ns == stamp
    assert again.MODEL_HASH == mod.MODEL_HASH
    p = parse_params(again, [("kp", 60.0), ("ki", 5.0)])
    r, x, ref = _run(again, p)
    assert _agreement(x, ref) < 1e-7
    base = simulate(mod, t_end=T_END, rtol=1e-10, atol=1e-12, points=301)
    assert np.abs(r.column("theta") - base.column("theta")).max() > 1e-2
    with pytest.raises(BgcError, match="T = 0"):
        check_overrides(path, [("T_s", 0.0)])


LOOP = """\
name: loop
elements:
  drive: {{type: MSe, effort: "1 + g.y"}}
  R: {{type: R, R: 2.0}}
  node: {{type: "1"}}
  L: {{type: I, I: 1.0}}
bonds:
  - [drive, node]
  - [node, R]
  - [node, L]
blocks:
  g: {{type: gain, input: L.e, k: 0.5{limits}}}
"""


def test_an_algebraic_loop_through_the_graph_and_a_block():
    """drive.e = 1 + g.y, g.y = 0.5 L.e, L.e = drive.e - R.e: linear, solved; saturated,
    refused as a nonlinear loop naming the block (the equations stage's rule)."""
    c = build(loads(LOOP.format(limits=""), "loop.yaml"))
    (loop,) = c.system.loops
    assert "g" in loop.elements and "drive" in loop.elements
    with pytest.raises(EquationError, match="nonlinear algebraic loop: .*drive, g") as e:
        build(loads(LOOP.format(limits=", limits: [-1, 1]"), "loop.yaml"))
    assert e.value.key == "elements.drive" and e.value.loc.line == 3
