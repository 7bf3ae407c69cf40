"""The IFToMM basic benchmark problems (the library of computational benchmark problems
of González, Dopico, Lugrís & Cuadrado, Multibody System Dynamics 16, 2006) against
their published or exact references: A01 simple pendulum, A02 N-four-bar (any N: the
constant of ``models/n_four_bar.yaml``; its exact reference ``models/n_four_bar.py``),
A03 Andrews' mechanism and A04 Bricard's mechanism (their own tests: ``tests/methods``),
A05 flyball governor.

A02 is the hard one: every time the cranks pass horizontal the mobility jumps from 1 to
N + 1; bgc's method ``augmented`` passes those singular configurations and keeps B0 within
the benchmark's 1e-3 m of the exact solution over its 20 s, lagrange and zcp stop there
and say so. The long runs (N = 10 and 40, every method) are marked slow; ``bgc bench
--part iftomm`` measures them against time."""

from __future__ import annotations

import importlib.util
import json

import numpy as np
import pytest

from bgc.errors import SimulationError
from bgc.mechanics import mobility
from bgc.pipeline import build
from bgc.simulate import prepare, simulate
from helpers import MODELS, bgc

LIMIT = 1e-3            # the benchmark's high-precision limit on B0 (m)


def _a02():
    spec = importlib.util.spec_from_file_location("n_four_bar", MODELS / "n_four_bar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


A02 = _a02()


def b0_error(result, n: int) -> np.ndarray:
    """|B0 - exact| at the run's output times."""
    x, y = A02.reference(n, result.t)
    return np.hypot(result.column("B0_x") - x, result.column("B0_y") - y)


def test_a02_reference_is_the_reduced_equation_in_closed_form():
    """The exact reference: the reduced equation integrated to 1e-13 agrees with its
    elliptic closed form (``reference`` checks that itself), and with the same equation
    as an independent integrator (implicit, scipy's Radau) takes it; B0 stays on the unit
    circle about the first pivot."""
    from scipy.integrate import solve_ivp
    t = np.linspace(0.0, 20.0, 801)
    for n in (2, 10, 40):
        x, y = A02.reference(n, t)
        assert np.allclose(np.hypot(x, y), 1.0, atol=1e-12)
        th = A02.theta_exact(n, t)
        assert th[-1] / (2 * np.pi) > 10          # it goes round ten times in 20 s
    a, b = A02.coefficients(2)
    other = solve_ivp(lambda _, z: [z[1], b / a * np.sin(z[0])], (0.0, 20.0), [0.0, 1.0],
                      method="LSODA", t_eval=t, rtol=1e-11, atol=1e-11).y[0]
    assert np.abs(other - A02.theta_exact(2, t)).max() < 1e-6


def test_a02_any_n_by_its_constant():
    """The model for N = 3 (``-p N=3``): 7 bodies, 10 revolute joints, the mechanism's
    rank and mobility at the start (1 whatever N: the cranks stay parallel)."""
    c = build(MODELS / "n_four_bar.yaml", "lagrange", constants={"N": 3})
    assert len(c.model.bodies) == 7 and len(c.model.joints) == 10
    found = mobility.analyse(c.causal.graph, c.system)
    assert (found["coordinates"], found["constraints"]) == (42, 50)
    assert (found["rank"], found["mobility"]) == (41, 1)
    assert len(found["redundant"]) == 9               # 3N: the out-of-plane ones


def test_a02_check_reports_rank_mobility_and_a_minimal_redundant_set():
    """``bgc check --json``: 35 constraints of rank 29 on 30 coordinates (mobility 1),
    exactly 35 - 29 = 6 redundant directions, whose removal leaves the others
    independent; the same under every method."""
    out = bgc("check", str(MODELS / "n_four_bar.yaml"), "--method", "augmented", "--json",
              "--quiet", cwd=MODELS, timeout=60)
    assert out.returncode == 0, out.stderr
    rep = json.loads(out.stdout)
    assert (rep["rank"], rep["mobility"], rep["constraints"]) == (29, 1, 35)
    assert len(rep["redundant"]) == 6
    c = build(MODELS / "n_four_bar.yaml", "zcp")
    J, names, first = mobility.constraint_rows(c.causal.graph, c.system)
    keep = [i for i, n in enumerate(names) if n not in set(rep["redundant"])]
    s = np.linalg.svd(J[keep], compute_uv=False)
    assert len(keep) == 29 and s[-1] > 1e-6 * s[0]      # the rest independent
    assert mobility.analyse(c.causal.graph, c.system)["mobility"] == 1


def test_a02_augmented_passes_every_singular_configuration(compiled):
    """N = 2 through all 20 s (20 horizontal crossings) at rtol 1e-6: B0 within the
    benchmark's 1e-3 m of the exact solution (measured 3.7e-5; at rtol 1e-5 it is
    1.2e-4 .. 1.05e-3 depending on where the steps land, so not asserted there), the
    joints closed to round-off, and the projection of the start names the same minimal
    redundant set as ``bgc check``."""
    mod = compiled("n_four_bar", "augmented")
    assert mod.PASSES_SINGULAR and mod.PROJECTS and mod.JAC_SIZE > len(mod.STATE_NAMES)
    r = simulate(mod, t_end=20.0, rtol=1e-6, atol=1e-8, points=801)
    err = b0_error(r, 2)
    assert err.max() < 1e-4, err.max()
    assert r.stats.drift_position < 1e-5
    c = build(MODELS / "n_four_bar.yaml", "augmented")
    assert r.projection.redundant == mobility.analyse(c.causal.graph, c.system)["redundant"]
    assert (r.projection.rank, r.projection.n_constraints) == (29, 35)
    # the Jacobian kept open is the model's: its Schur complement against differences
    x, p, _ = prepare(mod, r.x[400], r.params, r.t[400])
    J = mod.jac(r.t[400], x, p)
    k = 3                                               # a crank's momentum
    h = 1e-6 * max(1.0, abs(x[k]))
    xp, xm = x.copy(), x.copy()
    xp[k] += h
    xm[k] -= h
    fd = (mod.rhs(r.t[400], xp, p) - mod.rhs(r.t[400], xm, p)) / (2 * h)
    assert np.abs(J[:, k] - fd).max() < 1e-5 * max(1.0, np.abs(fd).max())


@pytest.mark.slow
@pytest.mark.parametrize("method", ["lagrange", "zcp"])
def test_a02_lagrange_and_zcp_stop_at_the_first_crossings_and_say_why(compiled, method):
    """They stop where the cranks pass horizontal, name the singular configuration and
    the method that passes it, and keep the results so far."""
    mod = compiled("n_four_bar", method)
    with pytest.raises(SimulationError, match="singular configuration") as err:
        simulate(mod, t_end=20.0, rtol=1e-6, atol=1e-8)
    assert "--method augmented" in err.value.hint
    r = err.value.result
    assert 0.6 < r.t[-1] < 2.0
    assert b0_error(r, 2).max() < 1e-5


# A02's first crossing of the horizontal (the exact solution's), by N
CROSSING = {2: 0.71436, 10: 0.72031, 40: 0.72158}


def assert_stopped_at_the_crossing(err, n: int, solver: str = "native"):
    """A run of lagrange or zcp that stopped where the constraints lose rank: named a
    singular configuration whose joint directions are the mechanism's (x translations of
    its pins), the method that passes it named, short of the crossing, the results up to
    there kept (within the benchmark's limit, rtol 1e-4 .. 1e-6) and the statistics
    counted."""
    msg = str(err.value)
    assert msg.startswith("singular configuration at t = "), msg
    assert ".tx" in msg.split("joint directions ")[1].split(" became dependent")[0], msg
    assert "--method augmented" in err.value.hint
    t_stop = float(msg.split("at t = ")[1].split(":")[0])
    r = err.value.result
    assert 0.55 < t_stop < CROSSING[n] + 0.01, t_stop
    assert 0.5 < r.t[-1] <= t_stop + 1e-6, (t_stop, r.t[-1])
    assert b0_error(r, n).max() < LIMIT
    if solver not in ("cvode", "ida"):          # SUNDIALS does not report its steps
        assert r.stats.steps > 0
    assert r.stats.rhs_calls > 0


# zcp's block (its cut joints', solved by the same kernels) refuses the same way: its N = 2
# run in make test-all (A02 under zcp costs a module no other fast test compiles); zcp's
# stop at a singular configuration stays in make test with the isosceles slider-crank's
# (tests/methods/test_loud_failure.py)
@pytest.mark.parametrize("method", ["lagrange", pytest.param("zcp", marks=pytest.mark.slow)])
def test_a02_stop_where_the_constraint_block_refuses_is_a_singular_configuration(
        compiled, monkeypatch, method):
    """The generated constraint block, J M^-1 J^T kept at the start's rank, refuses (NaN)
    where its last kept singular value falls below 1e-10 of its largest: with A02's axial
    moments of 1e-6 it does so short of the crossing, and at N = 10 and 40 the
    constraints' own conditioning has then fallen only 9 and 2.4-fold, less than
    ``LOST_RANK``: the run said "the step size collapsed" and named nothing. The block's
    refusal there, where it solves at a lower rank, is the rank loss itself. N = 2 (a
    47-fold fall) with ``LOST_RANK`` out of reach takes that path."""
    from bgc.solvers import consistent
    monkeypatch.setattr(consistent, "LOST_RANK", 1e12)
    mod = compiled("n_four_bar", method)
    with pytest.raises(SimulationError) as err:
        simulate(mod, t_end=1.0, rtol=1e-6, atol=1e-8, points=101)
    assert_stopped_at_the_crossing(err, 2)


@pytest.mark.parametrize("solver", ["bdf", "lsoda", "cvode"])
def test_a02_lagrange_stops_at_the_crossing_under_the_other_solvers(compiled, solver):
    """Each integrator fails its own way at the block's refusal: BDF's LU raised on a NaN
    Jacobian (the run kept no results and no statistics), LSODA went on through NaN to
    the end (reported as "the solution became non-finite"), CVODE took steps of 1e-18 s
    with t + h = t for ever. Each now stops and names the singular configuration."""
    mod = compiled("n_four_bar", "lagrange")
    with pytest.raises(SimulationError) as err:
        simulate(mod, t_end=1.0, rtol=1e-5, atol=1e-7, points=101, solver=solver)
    assert_stopped_at_the_crossing(err, 2, solver)
    assert np.isfinite(err.value.result.x).all()


@pytest.mark.slow
@pytest.mark.parametrize("method", ["lagrange", "zcp"])
def test_a02_lagrange_and_zcp_stop_at_the_crossing_at_n_10_and_40(tmp_path, method):
    """N = 10 and 40 under native Radau at rtol 1e-4 .. 1e-6 (the block refuses at
    t = 0.6956 and 0.6144: their crossings are at 0.7203 and 0.7216), and N = 10 under
    every other solver: a singular configuration, named, the results kept."""
    from bgc.pipeline import ensure_module
    from bgc.simulate import SOLVERS
    for n in (10, 40):
        mod = ensure_module(MODELS / "n_four_bar.yaml", tmp_path / "gen", method,
                            constants={"N": n})[0]
        for rtol in (1e-4, 1e-5, 1e-6):
            with pytest.raises(SimulationError) as err:
                simulate(mod, t_end=20.0, rtol=rtol, atol=rtol / 100, points=201)
            assert_stopped_at_the_crossing(err, n)
        if n == 10:
            for solver in SOLVERS:
                if solver != "native":
                    with pytest.raises(SimulationError) as err:
                        simulate(mod, t_end=2.0, rtol=1e-5, atol=1e-7, points=101,
                                 solver=solver, step=1e-3 if solver == "rk4" else None)
                    assert_stopped_at_the_crossing(err, n, solver)


@pytest.mark.slow
@pytest.mark.parametrize("n", [10, 40])
def test_a02_augmented_at_n(tmp_path, n):
    """N = 10 and 40 through 20 s at rtol 1e-5 and 1e-6, within the benchmark's limit."""
    from bgc.pipeline import ensure_module
    mod = ensure_module(MODELS / "n_four_bar.yaml", tmp_path / "gen", "augmented",
                        constants={"N": n})[0]
    for rtol in (1e-5, 1e-6):
        r = simulate(mod, t_end=20.0, rtol=rtol, atol=rtol * 1e-2, points=801)
        assert b0_error(r, n).max() < LIMIT, (rtol, b0_error(r, n).max())


@pytest.mark.slow
def test_a02_failed_run_json_keeps_stats_projection_and_partial_results(tmp_path):
    """``bgc simulate --json`` of a run that stops: the error, how far it got, its
    statistics, the projection of its start and where its results so far were written."""
    out = tmp_path / "partial.csv"
    proc = bgc("simulate", str(MODELS / "n_four_bar.yaml"), "--method", "lagrange", "--json",
               "--quiet", "--out", str(out), "-o", str(tmp_path / "gen"), cwd=tmp_path,
               timeout=600)
    assert proc.returncode == 2
    rep = json.loads(proc.stdout)
    assert rep["error"] == "SimulationError" and "singular configuration" in rep["message"]
    assert rep["stats"]["steps"] > 0 and 0.6 < rep["t_reached"] < 2.0
    assert rep["projection"]["rank"] == 29 and len(rep["projection"]["redundant"]) == 6
    assert rep["partial_results"] == str(out) and out.exists()


def a01_reference(t, inertia: float):
    """A01: (m L^2 + I) phi'' = -m g L sin phi from phi = 90 deg at rest, to 1e-13; P1."""
    from scipy.integrate import solve_ivp
    m, length, g = 1.0, 1.0, 9.81
    s = solve_ivp(lambda _, z: [z[1], -m * g * length * np.sin(z[0]) /
                                (m * length ** 2 + inertia)], (0.0, float(t[-1])),
                  [np.pi / 2, 0.0], method="DOP853", t_eval=t, rtol=1e-13, atol=1e-13)
    return -length * np.sin(s.y[0]), -length * np.cos(s.y[0])


@pytest.mark.slow
@pytest.mark.parametrize("method", ["augmented", "lagrange", "zcp", "parasitic"])
def test_a01_simple_pendulum_against_its_exact_solution(compiled, method):
    """P1 through 10 s of swinging from the horizontal: the ideal-joint methods within
    2e-5 m at rtol 1e-8 (augmented: its regularization's bias, eps times the ball's l^2/I
    against its mass, measured 1.4e-5; lagrange 1e-9), parasitic within its modelling
    error (the default stiffness: 1e-4)."""
    mod = compiled("simple_pendulum", method)
    r = simulate(mod, t_end=10.0, rtol=1e-8, atol=1e-10, points=501)
    x, y = a01_reference(r.t, 4e-4)
    err = np.hypot(r.column("P1_x") - x, r.column("P1_y") - y).max()
    assert err < (2e-4 if method == "parasitic" else 2e-5), err


@pytest.mark.slow
def test_a05_flyball_governor_every_ideal_method_agrees():
    """A05: the slider's height s rises from 0.5 m as the governor's balls fly out and the
    shaft's spin slows (its angular momentum conserved about the axis): lagrange at rtol
    1e-9 is the reference (s(10 s) = 0.61962423 m); augmented and zcp at 1e-6 within
    2e-5 m of it over the 10 s. (The library's reference files are not reachable offline;
    the definition is the OpenSim reimplementation's, cited in the model.)"""
    from bgc.pipeline import ensure_module
    import tempfile
    with tempfile.TemporaryDirectory() as gen:
        ref = simulate(ensure_module(MODELS / "flyball_governor.yaml", gen, "lagrange")[0],
                       t_end=10.0, rtol=1e-9, atol=1e-11, points=201)
        s = ref.column("s")
        assert abs(s[-1] - 0.61962423) < 1e-6 and s[0] == pytest.approx(0.5)
        assert ref.column("spin_rate")[-1] < 2 * np.pi
        for method in ("augmented", "zcp"):
            r = simulate(ensure_module(MODELS / "flyball_governor.yaml", gen, method)[0],
                         t_end=10.0, rtol=1e-6, atol=1e-8, points=201)
            assert np.abs(r.column("s") - s).max() < 2e-5, method


def test_a_failed_run_says_where_its_model_starts_unstable():
    """A run that spends its steps or whose step collapses, on a model whose linearisation
    at the start grows by more than ``UNSTABLE_EFOLDS`` e-folds by then, says so: the
    growth rate and the states it moves (A05 under parasitic: below). A stable model's,
    or a slow growth's over that time, does not."""
    from types import SimpleNamespace

    from bgc.simulate import _unstable
    A = np.array([[0.0, 1.0, 0.0], [4.0e8, -1.0e3, 0.0], [0.0, 0.0, -5.0]])  # +1.95e4 1/s
    mod = SimpleNamespace(jac=lambda t, x, p: A, STATE_NAMES=("q", "p", "z"))
    why = _unstable(mod, None, 0.0, np.zeros(3), 1e-3)
    assert why.startswith("the model is unstable at t = 0: its linearisation there grows "
                          "e-fold every 5.1e-05 s (eigenvalue 1.95e+04 1/s, mostly in p, q")
    assert _unstable(mod, None, 0.0, np.zeros(3), 1e-4) is None        # 2 e-folds
    B = A * [[1, 1, 1], [-1, 1, 1], [1, 1, 1]]                  # a damped oscillator
    stable = SimpleNamespace(jac=lambda t, x, p: B, STATE_NAMES=("q", "p", "z"))
    assert _unstable(stable, None, 0.0, np.zeros(3), 1.0) is None


@pytest.mark.slow
def test_a05_under_parasitic_stops_saying_its_model_is_unstable(compiled):
    """A05's spring-dampers are joint actuators whose law reads the bodies' velocities:
    under parasitic they measure the joints' stiff directions too but act along the free
    ones only, and their damping (4e4 N s/m) feeds the stiff modes: eigenvalues up to
    +4.3e4 1/s at t = 0 (with c_s = 0 none above 0.12 1/s). The slider's momentum grows
    from 0 to 4e4 N s within a millisecond and the steps follow it: the run spent its
    budget there, saying only that. It says why now."""
    mod = compiled("flyball_governor", "parasitic")
    p = np.array(mod.PARAMS, dtype=np.float64)
    x, p, _ = prepare(mod, mod.initial_state(p), p, 0.0)
    grow = np.linalg.eigvals(mod.jac(0.0, x, p)).real.max()
    assert 4e4 < grow < 5e4
    q = p.copy()
    q[list(mod.PARAM_NAMES).index("c_s")] = 0.0
    assert np.linalg.eigvals(mod.jac(0.0, x, q)).real.max() < 1.0
    with pytest.raises(SimulationError) as err:
        simulate(mod, t_end=10.0, max_steps=5000)
    msg = str(err.value)
    assert "the step budget (5000 steps) is spent at t = 0.000" in msg, msg
    assert "the model is unstable at t = 0: its linearisation there grows e-fold every " \
           "2.3e-05 s (eigenvalue 4.33e+04 1/s" in msg, msg
    assert "--method parasitic, a joint actuator whose law reads body velocities" in \
        err.value.hint
