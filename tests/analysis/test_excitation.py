"""The excitation (issue 5): the paper's chirp g(t) with its traps fixed, the run-time
choice of kind and direction, and the linear model's frequency response checked on a
two-mass absorber whose anti-resonance is known in closed form."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from helpers import dwell_amplitude

from bgc.errors import BgcError
from bgc.model import load, signals, symbols
from bgc.simulate import simulate

T1, T2, T3, F0, F1 = 3.0, 5.0, 25.0, 5.0, 25.0     # the SARIB rig's chirp


def _g():
    t = sp.Symbol("t")
    g = signals.chirp(t, T1, T2, T3, F0, F1)
    return (sp.lambdify(t, g, "numpy"), sp.lambdify(t, sp.diff(g, t), "numpy"))


@pytest.mark.parametrize("tk", [T1 / 2, T1, T2, T3])
def test_chirp_value_and_slope_are_continuous_at_the_joins(tk):
    g, dg = _g()
    eps = 1e-9
    assert abs(g(tk - eps) - g(tk + eps)) < 1e-6
    scale = 2 * np.pi * F1           # slopes reach 2 pi f
    assert abs(dg(tk - eps) - dg(tk + eps)) < 1e-6 * scale
    if tk == T1:                      # the ramp reaches 1 with zero slope: |g| <= 1 after
        t = np.linspace(T1, T2, 20001)
        assert np.abs(g(t)).max() == pytest.approx(1.0, abs=1e-6)
    if tk == T1 / 2:                  # the envelope: 2 t^2/t1^2, then 1 - 2 (t - t1)^2/t1^2
        for t, env in ((0.73, 2 * 0.73 ** 2 / T1 ** 2),
                       (2.21, 1 - 2 * (2.21 - T1) ** 2 / T1 ** 2)):
            assert g(t) / np.sin(2 * np.pi * F0 * t) == pytest.approx(env)


def test_chirp_instantaneous_frequency_is_t_hz_at_time_t():
    """From the zero crossings of g itself (not from the phase formula): half a period
    between crossings, so f = 1 / (2 dt) at the midpoint."""
    g, _ = _g()
    t = np.linspace(T2, T3, 4_000_001)
    y = g(t)
    k = np.nonzero(np.sign(y[:-1]) != np.sign(y[1:]))[0]
    tz = t[k] - y[k] * (t[k + 1] - t[k]) / (y[k + 1] - y[k])       # linear refinement
    mid, f = (tz[1:] + tz[:-1]) / 2, 1 / (2 * np.diff(tz))
    assert np.abs(f - mid).max() < 2e-3                              # t Hz at t s
    assert len(tz) == pytest.approx(2 * (F0 + F1) / 2 * (T3 - T2), abs=2)
    # constant frequency before t2 and after t3
    for a, b, f0 in ((T1, T2, F0), (T3, T3 + 2, F1)):
        t = np.linspace(a, b, 400_001)
        y = g(t)
        n = np.count_nonzero(np.sign(y[:-1]) != np.sign(y[1:]))
        assert n == pytest.approx(2 * f0 * (b - a), abs=1)


ABSORBER = """
name: absorber
description: two masses on prismatic joints along z, the upper tuned to 10 Hz
gravity: 0.0
bodies:
  main: {mass: 2.0, com: [0, 0, 0], inertia: [0.1, 0.1, 0.1]}
  tuned: {mass: 0.5, com: [0, 0, 0.2], inertia: [0.01, 0.01, 0.01]}
joints:
  base: {type: prismatic, between: [fixed_frame, main], at: [0, 0, 0], axis: [0, 0, 1],
         spring: {k: 20000.0, c: 2.0}}
  top: {type: prismatic, between: [main, tuned], at: [0, 0, 0.2], axis: [0, 0, 1],
        spring: {k: K_TOP, c: 0.05}}
excitation:
  directions:
    push: {joint: base, amplitude: 10.0}
  kinds:
    constant: {type: constant, value: 1.0}
    sine: {type: sine, amplitude: 1.0, frequency: 7.0}
    chirp: {type: chirp, t1: 0.2, t2: 0.3, t3: 4.0, f_start: 6.0, f_end: 14.0}
outputs:
  z: main.z
  a_z: main.accz
  g: excitation
simulation: {t_end: 1.0, rtol: 1.0e-8, atol: 1.0e-10, solver: radau}
"""
K_TOP = 0.5 * (2 * np.pi * 10.0) ** 2      # the tuned mass alone: 10 Hz


def test_excitation_section_is_lowered_to_parameters_and_an_actuator():
    m = load.loads(ABSORBER.replace("K_TOP", repr(K_TOP)), "absorber.yaml")
    exc = m.excitation
    assert set(exc.kinds) == {"constant", "sine", "chirp"}
    assert exc.directions == {"push": ("base", 10.0)}
    for name in ("excitation__push", "excitation__constant", "excitation__sine",
                 "excitation__chirp", "excitation__frequency"):
        assert name in m.parameters
    assert m.parameters["excitation__push"].value == 0.0          # off unless chosen
    assert m.joints["base"].functional["tx"].actuator is not None
    assert exc.select("sine", "push", frequency=12.0) == {
        "excitation__constant": 0.0, "excitation__sine": 1.0, "excitation__chirp": 0.0,
        "excitation__push": 10.0, "excitation__frequency": 12.0}
    assert sorted(m.signals["excitation"].breakpoints) == [0.1, 0.2, 0.3, 4.0]
    with pytest.raises(BgcError, match="unknown excitation direction 'roll'.*push"):
        exc.select("sine", "roll")
    with pytest.raises(BgcError, match="--frequency applies to the sine"):
        exc.select("chirp", "push", frequency=3.0)


GIMBAL = """
name: gimbal
gravity: 0.0
bodies:
  rod: {mass: 2.0, com: [0, 0, -0.5], inertia: [0.2, 0.2, 0.01]}
joints:
  pu: {type: prismatic_universal, between: [fixed_frame, rod], at: [0, 0, 0],
       axis: [1, 0, 0], axis2: [0, 1, 0],
       directions: {tz: {k: 200.0, c: 2.0}, rx: {k: 5.0, c: 0.1}, ry: {k: 3.0, c: 0.1}}}
excitation:
  directions:
    pumping: {joint: pu, amplitude: 20.0}
    pitch: {joint: pu, direction: ry, amplitude: 2.0}
  kinds:
    constant: {type: constant, value: 1.0}
outputs:
  x: rod.x
  y: rod.y
  z: rod.z
"""


def test_excitation_acts_on_the_free_direction_it_names(tmp_path):
    """One joint, several free directions: a direction's excitation goes on the first
    unless it names another (the SARIB's attach chain as one prismatic_universal: pumping
    along tz, roll and pitch about rx and ry). A constant force along the slide lifts the
    rod straight up (z only); a constant moment about axis2 = y swings its lower end
    along x (x only)."""
    from bgc.codegen.emit import import_module
    from bgc.pipeline import compile_model
    m = load.loads(GIMBAL, "gimbal.yaml")
    assert m.excitation.directions == {"pumping": ("pu", 20.0), "pitch": ("pu", 2.0)}
    fun = m.joints["pu"].functional
    assert fun["tz"].actuator.has(symbols.param("excitation__pumping"))
    assert fun["ry"].actuator.has(symbols.param("excitation__pitch"))
    assert fun["rx"].actuator is None
    f = tmp_path / "gimbal.yaml"
    f.write_text(GIMBAL)
    _, path = compile_model(f, tmp_path / "gen")
    mod = import_module(path)
    moved = {}
    for direction in ("pumping", "pitch"):
        p = np.array(mod.PARAMS, dtype=np.float64)
        names = list(mod.PARAM_NAMES)
        for k, v in m.excitation.select("constant", direction).items():
            p[names.index(k)] = v
        r = simulate(mod, t_end=0.5, rtol=1e-9, atol=1e-11, solver="native", params=p)
        moved[direction] = {o: np.ptp(r.column(o)) for o in ("x", "y", "z")}
    up, swing = moved["pumping"], moved["pitch"]
    assert up["z"] > 0.05 and up["x"] < 1e-6 * up["z"] and up["y"] < 1e-6 * up["z"]
    assert swing["x"] > 0.05 and swing["y"] < 1e-6 * swing["x"]
    bad = GIMBAL.replace("direction: ry", "direction: tx")
    line = next(i for i, ln in enumerate(bad.splitlines(), 1) if "direction: tx" in ln)
    with pytest.raises(BgcError, match=rf"gimbal.yaml:{line}:\d+: excitation.directions.pitch"
                                       r".direction: 'tx' is not a free direction.*tz, rx, ry"):
        load.loads(bad, "gimbal.yaml")


@pytest.fixture(scope="module")
def absorber(tmp_path_factory):
    from bgc.codegen.emit import import_module
    from bgc.pipeline import compile_model
    d = tmp_path_factory.mktemp("absorber")
    (d / "absorber.yaml").write_text(ABSORBER.replace("K_TOP", repr(K_TOP)))
    c, path = compile_model(d / "absorber.yaml", d)
    return import_module(path), c.model


def test_frf_finds_the_tuned_absorbers_anti_resonance(absorber):
    from bgc.analysis import frf
    mod, model = absorber
    lin = frf.linearize(mod, model, "push")
    anti, res = frf.extrema(lin, "z", 2.0, 20.0)
    assert anti == [pytest.approx(10.0, abs=0.01)]     # sqrt(k_top / m_top), lightly damped
    # the two resonances of the undamped 2-dof system
    k1, k2, m1, m2 = 20000.0, K_TOP, 2.0, 0.5
    ev = np.linalg.eigvals(np.array([[(k1 + k2) / m1, -k2 / m1], [-k2 / m2, k2 / m2]]))
    assert res == pytest.approx(sorted(np.sqrt(ev) / (2 * np.pi)), abs=0.02)
    # static gain: 1/k1 per newton
    assert abs(lin.response([1e-4], "z")[0]) == pytest.approx(1 / k1, rel=1e-3)


@pytest.mark.slow       # a 5 s dwell; the FRF and the chirp run stay in make test
def test_sine_dwell_matches_the_frequency_response(absorber):
    """A sine dwell (nonlinear run, transients decayed) against |H(f)| within 1 %, with
    more damping (parameters, no recompilation) so the transient dies in the run."""
    from bgc.analysis import frf
    mod, model = absorber
    names = list(mod.PARAM_NAMES)
    p = np.array(mod.PARAMS)
    p[names.index("base__tx_c")], p[names.index("top__tx_c")] = 20.0, 2.0   # tau <= 0.5 s
    lin = frf.linearize(mod, model, "push", p)
    for f in (7.0, 12.0):
        q = p.copy()
        for name, value in model.excitation.select("sine", "push", frequency=f).items():
            q[names.index(name)] = value
        r = simulate(mod, t_end=6.0, rtol=1e-9, atol=1e-12, solver="radau", params=q,
                     points=12001)
        for out in ("z", "a_z"):
            h = abs(lin.response([f], out)[0]) * 10.0
            assert dwell_amplitude(r.t, r.column(out), f) == pytest.approx(h, rel=0.01)


def test_step_limit_keeps_the_integrator_from_striding_over_the_excitation(absorber):
    """At rest, a 20 Hz sine is zero at t = 0 and after each half period: an adaptive step
    that samples it only there sees no input at all (under lagrange the SARIB's BDF took
    one 0.5 s step). The module limits the step to 1/8 of the fastest selected input's
    period; a constant input leaves it free."""
    mod, model = absorber
    names = list(mod.PARAM_NAMES)
    for kind, f, limit in (("sine", 20.0, 1 / 160), ("chirp", None, 1 / 112),
                           ("constant", None, np.inf)):
        q = np.array(mod.PARAMS)
        for name, value in model.excitation.select(kind, "push", frequency=f).items():
            q[names.index(name)] = value
        assert mod.max_step(q) == pytest.approx(limit)
    r = simulate(mod, t_end=0.5, rtol=1e-5, atol=1e-5, solver="bdf", params=q)
    assert r.stats.max_step is None
    q = np.array(mod.PARAMS)
    for name, value in model.excitation.select("sine", "push", frequency=20.0).items():
        q[names.index(name)] = value
    r = simulate(mod, t_end=0.5, rtol=1e-5, atol=1e-5, solver="bdf", params=q, points=2001)
    assert r.stats.max_step == pytest.approx(1 / 160) and r.stats.steps >= 80
    assert np.abs(r.column("a_z")).max() > 1.0          # 10 N on 2.5 kg, off resonance


def test_cli_chirp_run_and_frf_report_the_anti_resonance(absorber, tmp_path):
    """The main job's path on a small model: a chirp through the absorber's 10 Hz
    anti-resonance (CSV without states, plots, envelope minima) and `bgc frf --json`."""
    import json

    from click.testing import CliRunner

    from bgc.analysis.results import read_csv
    from bgc.cli import main
    mod, model = absorber
    src = Path(model.file)
    run = CliRunner().invoke
    r = run(main, ["simulate", str(src), "--excitation", "chirp", "--direction", "push",
                   "--t-end", "4.0", "--points", "40001", "--no-states", "--json",
                   "--out", str(tmp_path / "c.csv"), "--plot", str(tmp_path / "c.png"),
                   "--zoom", "2.0", "2.3", "-p", "top__tx_c=2.0", "-p", "base__tx_c=60.0",
                   "-o", str(src.parent)])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert rep["excitation"] == {"kind": "chirp", "direction": "push", "amplitude": 10.0,
                                 "frequency": None}
    assert rep["compiled"] is False                       # the fixture's module is fresh
    # 2.2 Hz/s through 10 Hz, damped so the transients die within the sweep (linear
    # model: 10.1 Hz): the envelope's deepest minimum comes ~0.5 Hz late (10.63 measured)
    assert 10.0 < rep["envelope_minima_hz"]["z"][0] < 10.8
    for f in ("csv", "png", "envelope_png", "zoom_png"):
        assert Path(rep["files"][f]).exists()
    names, _ = read_csv(tmp_path / "c.csv")
    assert names == ["t", "z", "a_z", "g"]
    r = run(main, ["frf", str(src), "--input", "push", "--output", "z", "--f-min", "2",
                   "--f-max", "20", "--json", "--out", str(tmp_path / "h.csv"),
                   "-o", str(src.parent)])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert rep["antiresonances_hz"] == [10.0] and len(rep["resonances_hz"]) == 2
    r = run(main, ["simulate", str(src), "--excitation", "chirp", "--direction", "roll",
                   "-o", str(src.parent)])
    assert r.exit_code == 2 and "unknown excitation direction 'roll'" in r.output
    assert "valid directions: push" in r.output
