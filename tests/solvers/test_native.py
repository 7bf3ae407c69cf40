"""The native integrators (issue 6): Radau IIA order 5 and fixed-step RK4, their step
loops in numba (``bgc/solvers/radau5.py``, ``rk4.py``, compiled once per machine) calling a
generated module through its C entry points, and SUNDIALS' CVODE/IDA. Each run is checked
against scipy on the same generated code."""

from __future__ import annotations

import json
import re
from types import SimpleNamespace

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import MODELS, T_SINGULAR, body_model, model_params
from scipy.linalg import expm

from bgc.cli import main
from bgc.errors import SimulationError
from bgc.model import load
from bgc.simulate import SOLVERS, prepare, simulate
from bgc.solvers import rk4

# (model, method, t_end): smooth and switching inputs, bodies, constraints by each method
# the four-bar under zcp, a module no other fast test compiles, in make test-all: a closed
# loop's constraint block stays here with the slider-crank's, zcp's opened loops under
# native Radau in tests/methods/test_zcp.py (test_slider_crank_loop_is_opened...[native])
CASES = [("msd_forced", "parasitic", None), ("pendulum", "parasitic", None),
         ("slider_crank", "lagrange", 1.0), ("rectifier", "parasitic", None),
         pytest.param("four_bar", "zcp", 1.0, marks=pytest.mark.slow)]


def _error(r, ref) -> float:
    return float(np.abs(r.x - ref.x).max() / np.abs(ref.x).max())


@pytest.mark.parametrize("name, method, t_end", CASES)
def test_native_radau_agrees_with_scipy(compiled, name, method, t_end):
    """Same error as scipy's Radau at the same tolerance (within a factor 10), with honest
    statistics: every rhs and Jacobian call and factorization counted, rejected steps
    reported. The reference is native Radau at rtol 1e-11 (scipy's Radau there agrees to
    ~1e-12 but takes 40 000 Python steps on the pendulum, 15 s); scipy's run at 1e-7
    must lie within 1e-5 of it, so a wrong native scheme cannot pass as its own
    reference."""
    mod = compiled(name, method)
    t_end = t_end or load.load(MODELS / f"{name}.yaml").settings.t_end
    ref = simulate(mod, t_end=t_end, rtol=1e-11, atol=1e-13, solver="native", points=101)
    runs = {s: simulate(mod, t_end=t_end, rtol=1e-7, atol=1e-9, solver=s, points=101)
            for s in ("native", "radau")}
    e_native, e_scipy = _error(runs["native"], ref), _error(runs["radau"], ref)
    assert e_scipy < 1e-5, e_scipy
    assert e_native < max(10 * e_scipy, 1e-9), (e_native, e_scipy)
    st = runs["native"].stats
    assert st.steps > 10 and st.rhs_calls > 3 * st.steps and st.jac_calls >= 1
    assert st.lu_decompositions >= 2 and st.rejected_steps is not None


# a model its default method cannot integrate (the IFToMM flyball governor under
# parasitic: unstable, its spring-dampers' law reads body velocities across the
# parasitic joints), checked under another
METHOD = {"flyball_governor": "zcp"}


# make test keeps one model of each kind (a smooth input, events, derivative causality,
# an algebraic loop, control blocks, a table, a body, a motor); make test-all every one
FAST = {"msd_forced", "rectifier", "geared_inertias", "rr_loop", "servo", "rc_table",
        "pendulum", "dc_motor"}


@pytest.mark.parametrize("name", model_params(
    [n for n in sorted(p.stem for p in MODELS.glob("*.yaml")) if n in FAST])
    + [pytest.param(n, marks=pytest.mark.slow)
       for n in sorted(p.stem for p in MODELS.glob("*.yaml")) if n not in FAST])
def test_every_shipped_model_agrees_with_scipy_at_the_tolerance_asked(compiled, name):
    """At rtol = 1e-7, atol = 1e-10 (over the model's run, at most 1 s), against a
    reference at tolerances 1000 times tighter,
    error in units of the tolerance asked (|dx| / (atol + rtol max|x|), per state): native
    Radau within 20, like scipy's Radau (the same scheme), and scipy's BDF, CVODE and
    IDA on the same generated code within their usual global-error factors (< 5e4: a
    wrong Jacobian or a lost event would be far beyond)."""
    mod = compiled(name, METHOD.get(name, "parasitic"))
    t_end = min(load.load(MODELS / f"{name}.yaml").settings.t_end, 1.0)
    rtol, atol = 1e-7, 1e-10
    ref = simulate(mod, t_end=t_end, rtol=rtol / 1000, atol=atol / 1000, solver="native",
                   points=51)
    scale = atol + rtol * np.abs(ref.x).max(axis=0)
    units = {}
    for s in ("native", "radau", "bdf", "cvode", "ida"):
        r = simulate(mod, t_end=t_end, rtol=rtol, atol=atol, solver=s, points=51)
        units[s] = float((np.abs(r.x - ref.x) / scale).max())
    assert units["native"] < 20 and units["radau"] < 20, units
    assert max(units.values()) < 5e4, units


def test_rk4_converges_at_fourth_order_and_fails_loudly_past_its_stability_limit(compiled):
    """msd_free (a lightly damped oscillator): halving the step divides the error by
    about 16. A step past the stability limit (h lambda outside |R(z)| <= 1) is refused
    before the run, naming the largest stable step; let through, it diverges and the
    failure says so. The reference is exact: the model is linear and free, x(t) =
    expm(J t) x0."""
    mod = compiled("msd_free")
    J = mod.jac(0.0, mod.X0, mod.PARAMS)
    ref = SimpleNamespace(x=np.array([expm(J * t) @ mod.X0 for t in np.linspace(0, 2, 41)]))
    eig = np.linalg.eigvals(J)
    h_max, lam = rk4.stable_step(eig)
    errs = [_error(simulate(mod, t_end=2.0, solver="rk4", step=f * h_max, points=41), ref)
            for f in (0.07, 0.035)]
    assert errs[0] / errs[1] == pytest.approx(16, rel=0.25)
    with pytest.raises(SimulationError, match="beyond its stability limit") as err:
        simulate(mod, t_end=50.0, solver="rk4", step=1.05 * h_max, points=101)
    assert f"--step {h_max:.3g}" in err.value.hint
    with pytest.raises(SimulationError, match="non-finite: the step .* is beyond the "
                                              "stability limit"):
        simulate(mod, t_end=200.0, solver="rk4", step=1.5 * h_max, points=101,
                 check_stability=False)
    with pytest.raises(SimulationError, match="--step"):
        simulate(mod, t_end=1.0, solver="rk4")


def test_rk4_stability_region_between_the_axes():
    """The region reaches 2.785 on the negative real axis and 2 sqrt 2 on the imaginary,
    but only 2.62 at 125 deg: the limit is taken per eigenvalue, on its own ray."""
    r = [rk4.stability_radius(d) for d in np.exp(1j * np.radians([180, 90, 125]))]
    assert r == pytest.approx([2.7853, 2 * np.sqrt(2), 2.6197], abs=1e-3)
    for z in r * np.exp(1j * np.radians([180, 90, 125])):
        assert abs(rk4.amplification(0.999 * z)) <= 1 < abs(rk4.amplification(1.001 * z))
    h, lam = rk4.stable_step([-1.0, -300.0 * np.exp(1j * np.radians(-55)), 5.0])
    assert h == pytest.approx(2.6197 / 300, rel=1e-3) and abs(lam) == pytest.approx(300)


@pytest.mark.slow       # the same run as tests/mechanics/test_bodies.py's (to 1e-6 there)
def test_native_guard_stops_at_the_gimbal_lock(tmp_path):
    mod = body_model(tmp_path, "lock", "{mass: 1, com: [0, 0, 0], inertia: [0.1, 0.2, 0.3], "
                     "omega: [0, 2.0, 0]}")
    with pytest.raises(SimulationError, match="gimbal lock") as exc:
        simulate(mod, t_end=2.0, solver="native")
    t_lock = float(str(exc.value).split("t = ")[1].split()[0])
    assert abs(t_lock - np.arccos(1e-3) / 2.0) < 1e-6


def _loop_calls(monkeypatch):
    """Record every call of the native loops that integrates (t1 > t0: (t0, t1, status))
    and the rank monitors they were given (``rank.Monitor``, its ``counts[0]``: the minors
    picked again inside the loop)."""
    from bgc.solvers.native_solver import NativeRadau, NativeSolver
    calls, monitors = [], []
    run, monitor = NativeSolver._run, NativeRadau._monitor

    def counted_run(self, t0, t1, *args, **kw):
        res = run(self, t0, t1, *args, **kw)
        if t1 > t0:
            calls.append((t0, t1, res.status))
        return res

    def kept_monitor(self, *args):
        mon = monitor(self, *args)
        monitors.append(mon)
        return mon
    monkeypatch.setattr(NativeSolver, "_run", counted_run)
    monkeypatch.setattr(NativeRadau, "_monitor", kept_monitor)
    return calls, monitors


def test_native_rank_monitor_repicks_inside_the_loop(compiled, monkeypatch):
    """The slider-crank's crank turns over under lagrange: its monitored minor crosses
    zero again and again, and each time the loop picks another itself (the constraints
    stay well conditioned), so the whole run is one call of the loop, with no pause."""
    from bgc.solvers import native
    calls, monitors = _loop_calls(monkeypatch)
    r = simulate(compiled("slider_crank", "lagrange"), t_end=1.0, rtol=1e-6, atol=1e-8,
                 solver="native")
    th = np.unwrap(np.arctan2(r.column("A_z"), r.column("A_x")))
    assert r.success and th[-1] - th[0] > 2 * np.pi
    assert calls == [(0.0, 1.0, native.REACHED)]
    assert sum(int(m.counts[0]) for m in monitors if m.con) >= 2


@pytest.mark.parametrize("rtol", [1e-6, 1e-8])
def test_native_rank_monitor_stops_at_the_singular_configuration(compiled, monkeypatch,
                                                                  rtol):
    """At the dead point the run stops naming the joint directions that became
    dependent: at rtol 1e-6 the loop's minor crosses zero where the constraints are ill
    conditioned, the loop hands the crossing back (status MINOR) and its location by
    re-integration meets the dead point; at 1e-8 the loop's steps collapse short of it
    and the failed run is diagnosed."""
    from bgc.solvers import native
    calls, _ = _loop_calls(monkeypatch)
    mod = compiled("isosceles_slider_crank", "lagrange")
    with pytest.raises(SimulationError, match="singular configuration") as err:
        simulate(mod, t_end=0.3, rtol=rtol, atol=rtol / 100, solver="native")
    t_stop = float(re.search(r"at t = ([0-9.]+): ", str(err.value)).group(1))
    assert t_stop == pytest.approx(T_SINGULAR, abs=1e-3)
    assert "main.tz, crank_pin.tz, wrist_pin.tz, guide.tz became dependent" in str(err.value)
    assert calls[0][2] == (native.MINOR if rtol == 1e-6 else native.STEP_TOO_SMALL)


def test_cli_lists_the_solvers_and_reports_native_statistics(compiled, gen_dir):
    r = CliRunner().invoke(main, ["simulate", "--help"])
    for name in SOLVERS:
        assert name in r.output
    compiled("msd_forced")          # the session's module: its native loop compiles once
    r = CliRunner().invoke(main, ["simulate", str(MODELS / "msd_forced.yaml"), "--solver",
                                  "native", "--json", "-o", str(gen_dir)])
    assert r.exit_code == 0, r.output
    st = json.loads(r.output)["stats"]
    assert st["steps"] > 0 and st["rhs_calls"] > 0 and st["lu_decompositions"] > 0
    assert st["rejected_steps"] is not None and st["wall_time"] > 0


def test_rk4_divergence_at_a_singular_configuration_is_reported_not_raised():
    """The last finite state of a diverging rk4 run can sit where the Jacobian itself is
    not finite (Andrews' mechanism past a singular configuration under lagrange): bgc says
    so instead of failing in the eigenvalue check of its stability limit."""
    from types import SimpleNamespace

    from bgc.solvers.base import Problem
    module = SimpleNamespace(jac=lambda t, x, p: np.full((2, 2), np.nan))
    why = SOLVERS["rk4"](Problem(module, np.zeros(0), step=1e-3))._diverged(0.25, np.zeros(2),
                                                                          None)
    assert "non-finite after t = 0.25" in why and "Jacobian" in why


@pytest.mark.parametrize("method", ["zcp", "lagrange"])
def test_linear_blocks_give_nan_not_an_exception_at_a_non_finite_state(compiled, method):
    """The algebraic loops (zcp) and constraint blocks (lagrange) of a closed loop are
    solved in compiled code: at a state gone non-finite (rk4 past its limit, a dead point)
    each generated function returns NaN, which the run reports where it happened;
    LAPACK's exception would be lost inside the native loop and crash the drift check."""
    mod = compiled("slider_crank", method)
    x = np.full(len(mod.STATE_NAMES), np.nan)
    p = np.array(mod.PARAMS, dtype=np.float64)
    for f in (mod.rhs, mod.jac, mod.outputs, mod.constraints):
        assert np.isnan(f(0.0, x, p)).any()
    x0, p, _ = prepare(mod, mod.initial_state(p), p, 0.0)
    h_max = rk4.stable_step(np.linalg.eigvals(mod.jac(0.0, x0, p)))[0]
    with pytest.raises(SimulationError) as err:
        simulate(mod, t_end=0.2, solver="rk4", step=3 * h_max, check_stability=False)
    r = err.value.result
    assert len(r.t) and np.isfinite(r.x[0]).all() and r.t[-1] <= 0.2


@pytest.mark.parametrize("solver", ["native", "radau", "bdf", "lsoda", "rk45", "cvode", "ida"])
def test_a_segment_with_no_output_point_in_it_yields_no_rows(compiled, solver):
    """A run is split into segments (at breakpoints, where the rank monitor re-picks its
    minor); with few output points one may hold none: the solver returns no rows and the
    state it reached (scipy's dense output fails on an empty time array)."""
    from bgc.solvers.base import Problem
    mod = compiled("msd_forced")
    p = np.array(mod.PARAMS, dtype=np.float64)
    x0 = np.array(mod.initial_state(p), dtype=np.float64)
    seg = SOLVERS[solver](Problem(mod, p, rtol=1e-8, atol=1e-8)).integrate(0.0, 0.5, x0,
                                                                          np.empty(0))
    assert seg.ok and seg.x_eval.shape == (0, len(x0)) and seg.t_reached == 0.5
    ref = simulate(mod, t_end=0.5, rtol=1e-10, atol=1e-10, solver="native", points=2)
    assert np.allclose(seg.x_end, ref.x[-1], rtol=1e-5, atol=1e-7)
