"""Each solver alone, through the ``Solver`` interface (``integrate`` over one segment),
on a hand-written problem: no model is compiled. A damped oscillator whose rhs and
Jacobian count their calls, as Python functions for scipy and SUNDIALS and as C
functions (ctypes callbacks) for the native loops, so the statistics a solver reports
are checked against the work it did: what it counts is what happened, what it does not
report is None."""

from __future__ import annotations

import ctypes
import types

import numpy as np
import pytest

from bgc.simulate import SOLVERS
from bgc.solvers import native
from bgc.solvers.base import Problem

K, C = 4.0, 0.5                                 # x'' + C x' + K x = 0
A = np.array([[0.0, 1.0], [-K, -C]])
X0 = np.array([1.0, 0.0])
T_END = 2.0
_ENTRY = ctypes.CFUNCTYPE(None, ctypes.c_double, ctypes.POINTER(ctypes.c_double),
                          ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double))


def oscillator():
    """A module-like namespace with ``calls`` counting its rhs and Jacobian evaluations
    (Python or C entry points alike)."""
    calls = {"rhs": 0, "jac": 0}

    def rhs(t, x, p):
        calls["rhs"] += 1
        return A @ np.asarray(x, dtype=float)

    def jac(t, x, p):
        calls["jac"] += 1
        return A.copy()

    @_ENTRY
    def rhs_entry(t, x, p, out):
        calls["rhs"] += 1
        out[0], out[1] = x[1], -K * x[0] - C * x[1]

    @_ENTRY
    def jac_entry(t, x, p, out):
        calls["jac"] += 1
        for i, a in enumerate(A.ravel()):
            out[i] = a

    entries = tuple(ctypes.cast(f, ctypes.c_void_p).value for f in (rhs_entry, jac_entry))
    module = types.SimpleNamespace(
        rhs=rhs, jac=jac, STATE_NAMES=("x", "v"), GUARD_NAMES=(),
        JAC_I=np.array([0, 1, 1]), JAC_J=np.array([1, 0, 1]),
        native_entry_points=lambda: (*entries, 0), calls=calls,
        _keep=(rhs_entry, jac_entry))        # the callbacks live as long as the module
    return module


def exact(t):
    """x(t) of the oscillator from X0 (eigen-decomposition of A)."""
    lam, V = np.linalg.eig(A)
    return np.real(V @ (np.exp(lam * t) * np.linalg.solve(V, X0)))


def step_counter():
    """A non-terminal event that never fires: solve_ivp asks it once at the start and
    once per accepted step, so its calls count the steps."""
    def event(t, x):
        event.calls += 1
        return 1.0
    event.calls, event.terminal, event.direction = 0, False, 0
    return event


@pytest.mark.parametrize("name", ["bdf", "radau", "lsoda", "rk45"])
def test_scipy_solvers_report_the_work_they_did(name, monkeypatch):
    import scipy.integrate._ivp.bdf
    import scipy.integrate._ivp.radau
    factored = [0]
    for mod in (scipy.integrate._ivp.bdf, scipy.integrate._ivp.radau):
        def counted(a, *args, _lu=mod.lu_factor, **kw):
            factored[0] += 1
            return _lu(a, *args, **kw)
        monkeypatch.setattr(mod, "lu_factor", counted)
    module, counter = oscillator(), step_counter()
    solver = SOLVERS[name](Problem(module, np.zeros(0), rtol=1e-8, atol=1e-10))
    stats = solver.counts
    t_eval = np.linspace(0.0, T_END, 5)
    seg = solver.integrate(0.0, T_END, X0, t_eval, [counter])
    assert seg.ok and seg.t_reached == T_END
    assert np.allclose(seg.x_eval[-1], exact(T_END), atol=1e-6)
    assert stats.steps == counter.calls - 1 > 0
    assert stats.rhs_calls == module.calls["rhs"] > 0
    assert stats.jac_calls == module.calls["jac"]
    assert stats.rejected_steps is None                 # solve_ivp does not say
    if name == "rk45":                                  # explicit: no Jacobian, no LU
        assert stats.jac_calls == 0 and stats.lu_decompositions is None
    elif name == "lsoda":                # ODEPACK factors once per Jacobian (scipy says)
        assert stats.lu_decompositions == stats.jac_calls
    else:                                # BDF and Radau factor through lu_factor: counted
        assert stats.lu_decompositions == factored[0] > 0 and stats.jac_calls >= 1


@pytest.mark.parametrize("name", ["cvode", "ida"])
def test_sundials_solvers_report_evaluations_and_no_steps(name):
    module = oscillator()
    solver = SOLVERS[name](Problem(module, np.zeros(0), rtol=1e-8, atol=1e-10))
    stats = solver.counts
    seg = solver.integrate(0.0, T_END, X0, np.linspace(0.0, T_END, 5))
    assert seg.ok and np.allclose(seg.x_end, exact(T_END), atol=1e-6)
    assert stats.rhs_calls == module.calls["rhs"] > 0
    assert stats.jac_calls == module.calls["jac"] > 0
    assert stats.steps is None and stats.lu_decompositions is None
    assert stats.rejected_steps is None


def test_native_radau_counts_in_its_loop_what_it_calls():
    module = oscillator()
    solver = SOLVERS["native"](Problem(module, np.zeros(0), rtol=1e-8, atol=1e-10))
    stats = solver.counts
    t_eval = np.linspace(0.0, T_END, 5)
    seg = solver.integrate(0.0, T_END, X0, t_eval)
    assert seg.ok and seg.x_eval.shape == (5, 2)
    assert np.allclose(seg.x_eval, [exact(t) for t in t_eval], atol=1e-6)
    assert stats.rhs_calls == module.calls["rhs"] > 0
    assert stats.jac_calls == module.calls["jac"] >= 1
    assert stats.steps > 0
    # the two Newton matrices (real and complex) are factored together
    assert stats.lu_decompositions >= 2 and stats.lu_decompositions % 2 == 0


def test_native_radau_counts_every_rejected_step():
    """An rhs that is not finite after t = 1: every step from there fails its Newton
    iterations at their first evaluation of the stages, and is rejected with half the
    step, until the step is below 10 spacings of t. Each attempt is one rejected step,
    one pair of factorizations and three rhs calls (one more at the start); the Jacobian
    is the start's."""
    module = oscillator()
    good = module.native_entry_points()

    @_ENTRY
    def rhs_nan_after_1(t, x, p, out):
        module.calls["rhs"] += 1
        out[0], out[1] = (x[1], -K * x[0] - C * x[1]) if t <= 1.0 else (np.nan, np.nan)
    module.native_entry_points = lambda: (ctypes.cast(rhs_nan_after_1, ctypes.c_void_p).value,
                                          *good[1:])
    module._keep += (rhs_nan_after_1,)
    solver = SOLVERS["native"](Problem(module, np.zeros(0), rtol=1e-8, atol=1e-10))
    res = solver._run(1.0, 2.0, X0, np.empty(0), h_start=0.5)
    h, attempts, min_step = 0.5, 0, 10 * (np.nextafter(1.0, 2.0) - 1.0)
    while h >= min_step:
        attempts, h = attempts + 1, h * 0.5
    assert res.status == native.STEP_TOO_SMALL and res.t == 1.0 and attempts == 48
    assert np.isinf(res.error_share).all()            # both states' d/dt not finite
    counts = solver.counts
    assert counts.steps == 0 and counts.rejected_steps == attempts
    assert counts.lu_decompositions == 2 * attempts and counts.jac_calls == 1
    assert counts.rhs_calls == module.calls["rhs"] == 1 + 3 * attempts


def test_rk4_counts_its_steps_and_the_jacobians_of_its_stability_check():
    """Fixed steps: T / h of them, four rhs each and one at the start; the stability
    check (every n^2 / 4 steps, here every step) evaluates the Jacobian: counted too."""
    module, h = oscillator(), 0.01
    solver = SOLVERS["rk4"](Problem(module, np.zeros(0), step=h))
    stats = solver.counts
    seg = solver.integrate(0.0, T_END, X0, np.array([T_END]))
    steps = round(T_END / h)
    assert seg.ok and np.allclose(seg.x_end, exact(T_END), atol=1e-6)
    assert stats.steps == steps
    assert stats.rhs_calls == module.calls["rhs"] == 1 + 4 * steps
    assert stats.jac_calls == module.calls["jac"] == steps
    assert stats.lu_decompositions == 0 and stats.rejected_steps == 0
