"""Method lagrange (issue 4): joint constraints as multipliers, on the benchmark mechanisms.

Each test runs the same model file under ``lagrange`` and, where it says so, under
``parasitic``: the two agree within the parasitic modelling error, which falls as 1/k."""

from __future__ import annotations

import csv

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import ANDREWS_REF, MODELS, fd_jacobian, slider_closure, stiffer

from bgc.cli import main
from bgc.simulate import simulate

@pytest.mark.parametrize("name", ["pendulum", "slider_crank"])
def test_jacobian_through_the_constraint_block_matches_finite_differences(compiled, name):
    mod = compiled(name, "lagrange")
    run = simulate(mod, t_end=0.2, rtol=1e-8, atol=1e-10, points=5)
    p = mod.PARAMS.copy()
    p[list(mod.PARAM_NAMES).index("lagrange__rank")] = run.projection.rank
    rng = np.random.default_rng(3)
    for x0 in run.x[1:]:
        x = x0 + 1e-4 * rng.uniform(-1, 1, len(x0)) * np.maximum(np.abs(x0), 1e-2)
        J = mod.jac(0.1, x, p)
        fd = fd_jacobian(mod, 0.1, x, p)
        assert np.abs(J - fd).max() / np.abs(fd).max() < 1e-5


def test_slider_crank_closes_exactly_and_names_its_redundant_constraints(compiled):
    mod = compiled("slider_crank", "lagrange")
    r = simulate(mod, t_end=1.0, rtol=1e-9, atol=1e-11, solver="radau")
    err, th = slider_closure(r)
    assert np.unwrap(th)[-1] - th[0] > 2 * np.pi                # the crank turns over
    assert err < 1e-8, err                                       # measured 3e-11
    # planar loop in 3D: 3 bodies x 6 - 20 blocked directions = -2, mobility 1
    proj = r.projection
    assert (proj.n_constraints, proj.rank) == (20, 17)
    # a minimal redundant set: exactly constraints - rank names, among the loop's joints
    assert len(proj.redundant) == 3
    assert {n.split(".")[0] for n in proj.redundant} <= {"main", "crank_pin", "wrist_pin",
                                                         "guide"}
    assert not any(n.endswith(("tx", "tz")) for n in proj.redundant if "pin" in n)
    assert r.stats.drift_position < 1e-9 and r.stats.drift_velocity < 1e-7
    energy = r.column("energy")
    assert np.abs(energy - energy[0]).max() < 1e-6 * abs(energy[0])  # measured 3e-9


@pytest.mark.slow       # five runs; lagrange against parasitic stays in make test
def test_parasitic_error_against_lagrange_falls_as_one_over_stiffness(compiled):
    """Native Radau (the errors are the models', the same to 1e-9 under scipy's Radau,
    which took 10 times longer)."""
    ref = simulate(compiled("slider_crank", "lagrange"), t_end=0.5, rtol=1e-10,
                   atol=1e-12, solver="native")
    mod = compiled("slider_crank")
    errs = []
    for f in (1.0, 10.0):
        r = simulate(mod, t_end=0.5, rtol=1e-10, atol=1e-12, solver="native",
                     params=stiffer(mod, f))
        errs.append(np.abs(r.column("slider_x") - ref.column("slider_x")).max())
    # measured: 7.5e-5 m and 7.6e-6 m: first order in 1/k
    assert errs[0] < 2e-4 and 8 < errs[0] / errs[1] < 12, errs


@pytest.mark.slow       # numba's cold compile of Andrews under lagrange: 4-5 min of CPU
def test_andrews_matches_the_published_reference_to_six_digits(gen_dir, tmp_path, compiled):
    compiled("andrews", "lagrange")          # compiled once (shared with other workers)
    out = tmp_path / "F.csv"
    res = CliRunner().invoke(main, ["simulate", str(MODELS / "andrews.yaml"), "--method",
                                    "lagrange", "--t-end", "0.03", "--rtol", "1e-10",
                                    "--atol", "1e-10", "--out", str(out), "-o",
                                    str(gen_dir)])
    assert res.exit_code == 0, res.output
    assert "41 constraints" in res.output and "redundant" not in res.output
    rows = list(csv.DictReader(out.open()))
    assert float(rows[-1]["t"]) == pytest.approx(0.03)
    for name, ref in ANDREWS_REF.items():
        got = float(rows[-1][name])
        # measured: 6e-10 .. 1.1e-8 relative
        assert abs(got - ref) <= 5e-7 * abs(ref), (name, got, ref)


@pytest.mark.slow       # redundant constraints stay in make test (A02: bgc check, augmented)
def test_bricard_runs_with_its_redundant_constraint_reported(compiled):
    """Native Radau (scipy's Radau took 4 times longer for the same numbers to 1e-9)."""
    lag = simulate(compiled("bricard", "lagrange"), t_end=10.0, rtol=1e-8, atol=1e-10,
                   solver="native")
    proj = lag.projection
    assert (proj.n_constraints, proj.rank) == (30, 29)
    assert len(proj.redundant) == 1 and proj.redundant[0].split(".")[0] in {
        f"J{k}" for k in range(1, 7)}
    # period 4.98648 s (rigid reference): P3 at t = 10 is back near its start
    p3 = np.array([lag.column(f"P3_{a}")[-1] for a in "xyz"])
    assert np.abs(p3 - [0.999282, -1.0, -0.000717]).max() < 1e-5, p3
    energy = lag.column("energy")
    assert np.abs(energy - energy[0]).max() < 1e-6 * abs(energy[0])
    par = simulate(compiled("bricard"), t_end=10.0, rtol=1e-8, atol=1e-10, solver="native")
    # the parasitic run (stiffness 1e7) follows within its modelling error
    assert np.abs(par.column("P3_x") - lag.column("P3_x")).max() < 2e-3


@pytest.mark.slow       # lagrange on a closed loop stays in make test (slider-crank, Bricard)
def test_four_bar_agrees_with_parasitic_and_keeps_its_coupler_length(compiled):
    lag = simulate(compiled("four_bar", "lagrange"), t_end=2.0, rtol=1e-8, atol=1e-10,
                   solver="radau")
    assert lag.projection.rank == lag.projection.n_constraints == 16
    assert np.abs(lag.column("coupler_length") - 0.4).max() < 1e-10
    energy = lag.column("energy")
    assert np.abs(energy - energy[0]).max() < 1e-6
    par = simulate(compiled("four_bar"), t_end=2.0, rtol=1e-8, atol=1e-10, solver="radau")
    for out in ("crank_angle", "rocker_angle"):
        assert np.abs(par.column(out) - lag.column(out)).max() < 5e-4    # measured 2.3e-4


def test_approximate_initial_state_is_projected_and_reported(compiled):
    mod = compiled("slider_crank", "lagrange")
    names = list(mod.STATE_NAMES)
    x = mod.X0.copy()
    x[names.index("rod.az")] += 0.01           # the rod turned off the loop
    x[names.index("slider.m.px")] += 0.05      # and the slider pushed
    r = simulate(mod, t_end=0.1, rtol=1e-9, atol=1e-11, x0=x)
    assert 1e-3 < r.projection.position_correction < 0.05
    assert r.projection.velocity_correction > 1e-3
    assert r.projection.iterations >= 2
    assert r.stats.drift_position < 1e-9

