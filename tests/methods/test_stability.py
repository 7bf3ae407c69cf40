"""Where each method fails, and that bgc says so (issue 6, stability maps): RK4 past its
stability limit as the spectrum moves, lagrange without Baumgarte stabilisation, redundant
constraints without redundancy handling. (zcp with a loop kept closed: test_zcp.py.)"""

from __future__ import annotations

import re

import numpy as np
import pytest

from bgc.errors import SimulationError
from bgc.solvers import consistent
from bgc.simulate import prepare, simulate
from bgc.solvers import rk4


def test_rk4_is_stopped_where_the_spectrum_moves_past_its_step(compiled):
    """The undamped Duffing oscillator started at q = 0 with its energy in the momentum:
    |lambda| = 20 1/s there, 100 1/s at the turning points (k + 3 k3 q^2). A step of
    0.035 s passes the check at the start (h |lambda| = 0.7) but not at the turning
    points (2.9 > 2 sqrt 2): unchecked, the run neither blows up nor stays right (its
    amplitude decays by 18 %); bgc stops it at the first turning point, keeping the run
    so far."""
    mod = compiled("duffing")
    x0 = np.array([np.sqrt(0.5 * 2 * 0.2), 0.0])           # p = sqrt(2 m E), E = 0.2 J
    h_start = rk4.stable_step(np.linalg.eigvals(mod.jac(0.0, x0, mod.PARAMS)))[0]
    assert 0.035 < h_start
    silent = simulate(mod, t_end=5.0, solver="rk4", step=0.035, x0=x0, points=501,
                      check_stability=False)
    assert np.isfinite(silent.x).all() and np.abs(silent.x[:, 1]).max() < 0.9 * 0.02
    with pytest.raises(SimulationError, match=r"beyond its stability limit at t = ") as err:
        simulate(mod, t_end=5.0, solver="rk4", step=0.035, x0=x0, points=501)
    t_stop = float(re.search(r"at t = ([0-9.]+):", str(err.value)).group(1))
    assert 0.0 < t_stop < 0.1                               # the first quarter period
    assert err.value.result.t[-1] <= t_stop + 1e-12 and len(err.value.result.t) > 1
    ok = simulate(mod, t_end=2.0, solver="rk4", step=0.001, x0=x0, points=201)
    ref = simulate(mod, t_end=2.0, solver="native", rtol=1e-10, atol=1e-12, x0=x0,
                   points=201)
    assert np.abs(ok.x - ref.x).max() < 1e-3 * np.abs(ref.x).max()


def test_lagrange_without_stabilisation_fails_where_the_joints_come_apart(compiled):
    """The slider-crank under lagrange with alpha = 0: the drift grows until the joints
    are open by more than 100 tolerance units at the mechanism's size; bgc stops there,
    says why and keeps the run so far. With the default alpha the drift stays near one
    unit."""
    mod = compiled("slider_crank", "lagrange")
    p = mod.PARAMS.copy()
    ia = list(mod.PARAM_NAMES).index("lagrange__alpha")
    p[ia] = 0.0
    with pytest.raises(SimulationError, match="constraint drift") as err:
        simulate(mod, t_end=10.0, rtol=1e-6, atol=1e-8, solver="native", params=p)
    assert "lagrange__alpha = 0: no Baumgarte stabilisation" in str(err.value)
    assert "lagrange__alpha=10" in err.value.hint
    res = err.value.result
    t_stop = float(re.search(r"at t = ([0-9.]+) ", str(err.value)).group(1))
    assert 1.0 < t_stop < 10.0 and res.t[-1] == pytest.approx(t_stop)
    limit = consistent.drift_limit(mod, res.x[0], 1e-6, 1e-8)
    g = consistent.drift_history(mod, res.x, res.params)[0]
    assert g[-1] > limit and g[:-1].max() <= limit
    unchecked = simulate(mod, t_end=10.0, rtol=1e-6, atol=1e-8, solver="native", params=p,
                         check_drift=False)
    assert unchecked.stats.drift_position > 100 * limit     # it only gets worse
    good = simulate(mod, t_end=10.0, rtol=1e-6, atol=1e-8, solver="native")
    assert good.stats.drift_position < limit / 100


# the slider-crank (its planar loop in 3D: 20 constraints of rank 17) in make test, under
# lagrange the session's module; Bricard's mechanism, whose lagrange module only this
# test compiles, in make test-all
@pytest.mark.parametrize("name, redundant, rank, constraints", [
    ("slider_crank",
     r"3 redundant constraint\(s\) \(((main|crank_pin|wrist_pin|guide)\.\w+(, )?){3}\)",
     17, 20),
    pytest.param("bricard", r"1 redundant constraint\(s\) \(J\d\.\w+\)", 29, 30,
                 marks=pytest.mark.slow)])
def test_redundant_constraints_without_redundancy_handling_are_refused(
        compiled, name, redundant, rank, constraints):
    """A mechanism with redundant constraints (Bricard's: 30 of rank 29) without
    redundancy handling: its constraint block is singular (the LU meets a zero pivot: the
    right-hand side is NaN from t = 0, which is what a run would get); bgc refuses before
    the run, naming the constraints. With the handling it runs."""
    mod = compiled(name, "lagrange")
    with pytest.raises(SimulationError, match=redundant) as err:
        simulate(mod, t_end=0.5, solver="native", redundancy=False)
    assert f"rank {rank} of {constraints}" in str(err.value)
    assert "nothing was run" in str(err.value)
    assert err.value.result is None
    x, p, proj = prepare(mod, mod.initial_state(mod.PARAMS), mod.PARAMS)
    assert (proj.rank, proj.n_constraints) == (rank, constraints)
    p[list(mod.PARAM_NAMES).index(consistent.RANK_PARAM)] = proj.n_constraints
    assert not np.isfinite(mod.rhs(0.0, x, p)).all()
    simulate(mod, t_end=0.5, solver="native", rtol=1e-6, atol=1e-8)
