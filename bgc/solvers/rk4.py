"""The classical fixed-step Runge-Kutta method of order 4, the paper's explicit
alternative (11.2.5.2: the parasitic method makes an explicit ODE, so RK4 can run it, as
far as its stability region allows: |R(h lambda)| <= 1 for every eigenvalue of the
Jacobian, ``stable_step``). The step loop runs in numba and calls the model through its C
entry points (``bgc.solvers.native``)."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from bgc.solvers.native import (
    GUARD,
    INTERRUPTED,
    N_STATS,
    NOT_FINITE,
    PAUSED,
    REACHED,
    ST_JAC,
    ST_RHS,
    ST_STEPS,
    UNSTABLE,
    Model,
    Outcome,
    call_entry,
    evaluate,
    guard_min,
    inner,
    stopped,
)


@njit(cache=True)
def amplification(z):
    """RK4's stability function R(z) = 1 + z + z^2/2 + z^3/6 + z^4/24 (z = h lambda)."""
    return 1.0 + z * (1.0 + z * (0.5 + z * (1.0 / 6.0 + z / 24.0)))


@njit(cache=True)
def stability_radius(d):
    """Where the ray from 0 along the complex direction ``d`` (Re d <= 0) leaves RK4's
    region of absolute stability |R(z)| <= 1: 2.785 on the negative real axis, 2.828
    on the imaginary one, as little as 2.62 between (at 125 deg), so no single bound on
    h |lambda| is safe. In the left half-plane |R| <= 1 up to r = 2.6 and the ray
    crosses once before 3.1 (checked on a fine grid): bisection there."""
    d = d / abs(d)
    lo, hi = 2.6, 3.1
    for _ in range(50):
        mid = 0.5 * (lo + hi)
        if abs(amplification(mid * d)) > 1.0:
            hi = mid
        else:
            lo = mid
    return lo


@njit(cache=True)
def _stable_step(lam):
    h, k = np.inf, -1
    for i in range(lam.shape[0]):
        m = abs(lam[i])
        if m > 0.0 and lam[i].real <= 1e-12 * m:
            hi = stability_radius(lam[i]) / m
            if hi < h:
                h, k = hi, i
    return h, k


def stable_step(eigenvalues) -> tuple[float, complex | None]:
    """The largest step that keeps h lambda inside the stability region for every
    decaying or oscillating mode (Re lambda <= 0: a growing mode is the physics, not the
    method), and the eigenvalue that sets it (inf and None if none does)."""
    lam = np.ascontiguousarray(np.atleast_1d(eigenvalues), dtype=np.complex128)
    h, k = _stable_step(lam)
    return float(h), (complex(lam[k]) if k >= 0 else None)


@inner
def _unstable(jac, t, y, p, step, stats) -> bool:
    """Whether ``step`` is beyond the stability limit of the Jacobian at (t, y)."""
    n = y.shape[0]
    J = np.empty((n, n))
    call_entry(jac, t, y, p, J)
    stats[ST_JAC] += 1
    return step > _stable_step(np.linalg.eigvals(J.astype(np.complex128)))[0]


@inner
def _axpy(y, a, x, out):
    """out = y + a x."""
    for i in range(y.shape[0]):
        out[i] = y[i] + a * x[i]


class Settings(NamedTuple):
    """The step, where to stop: a guard margin at ``guard_tol`` (0: never), the ``stop``
    flag set (a uint8 array, ``base.Interrupt``; empty: never); how often to check the
    step against the stability limit (``check_every`` steps; 0: never) and to pause
    (after ``max_steps`` steps; 0: never)."""
    step: float
    guard_tol: float
    check_every: int
    max_steps: int
    stop: np.ndarray


@njit(cache=True)
def rk4(model, settings, t0, t1, x0, t_eval, stats):
    """Integrate ``model`` (``native.Model``) in steps of ``settings.step`` from t0 to
    t1 (the last one shortened to land on t1); states at ``t_eval`` by cubic Hermite
    interpolation. Every ``check_every`` steps (0: never) the step is checked against
    the stability limit of the Jacobian there, since the spectrum moves with the state:
    a step just beyond it grows slowly, with no overflow to give it away. Stops there
    (UNSTABLE), where the state becomes non-finite or where a guard margin reaches
    ``guard_tol``.

    Returns a ``native.Outcome`` (states at t_eval and how many were reached, t reached,
    state there, status, guard index, the step); status PAUSED after ``max_steps`` steps,
    INTERRUPTED as soon as the ``stop`` flag is set.
    (Scalar loops, not array expressions: they compile in a fraction of the time,
    ``radau5``.)"""
    rhs, jac, guards, n_guards, p = model
    step, guard_tol, check_every, max_steps, stop = settings
    n = x0.shape[0]
    out = np.empty((t_eval.shape[0], n))
    k_out = 0
    while k_out < t_eval.shape[0] and t_eval[k_out] <= t0:
        for i in range(n):
            out[k_out, i] = x0[i]
        k_out += 1
    t, y = t0, x0.copy()
    if t1 <= t0:
        return Outcome(out, k_out, t, y, REACHED, -1, step)
    f = evaluate(rhs, t, y, p, n)
    stats[ST_RHS] += 1
    work = np.empty(n)
    k2 = np.empty(n)
    k3 = np.empty(n)
    k4 = np.empty(n)
    taken = 0
    while t < t1:
        if stopped(stop):
            return Outcome(out, k_out, t, y, INTERRUPTED, -1, step)
        h = min(step, t1 - t)
        if t1 - (t + h) < 1e-9 * step:
            h = t1 - t
        _axpy(y, 0.5 * h, f, work)
        call_entry(rhs, t + 0.5 * h, work, p, k2)
        _axpy(y, 0.5 * h, k2, work)
        call_entry(rhs, t + 0.5 * h, work, p, k3)
        _axpy(y, h, k3, work)
        call_entry(rhs, t + h, work, p, k4)
        y_new = np.empty(n)
        finite = True
        for i in range(n):
            y_new[i] = y[i] + h / 6.0 * (f[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            finite = finite and np.isfinite(y_new[i])
        t_new = t + h if t1 - (t + h) >= 1e-9 * step else t1
        stats[ST_STEPS] += 1
        stats[ST_RHS] += 3
        if not finite:
            return Outcome(out, k_out, t, y, NOT_FINITE, -1, step)
        f_new = evaluate(rhs, t_new, y_new, p, n)
        stats[ST_RHS] += 1
        while k_out < t_eval.shape[0] and t_eval[k_out] <= t_new:
            s = (t_eval[k_out] - t) / h
            for i in range(n):
                out[k_out, i] = ((1.0 + 2.0 * s) * (1.0 - s) ** 2 * y[i]
                                 + s * s * (3.0 - 2.0 * s) * y_new[i]
                                 + s * (1.0 - s) ** 2 * h * f[i]
                                 - s * s * (1.0 - s) * h * f_new[i])
            k_out += 1
        t, y, f = t_new, y_new, f_new
        if guard_tol > 0.0 and n_guards > 0:
            kg, low = guard_min(guards, n_guards, t, y, p, guard_tol)
            if low <= 0.0:
                return Outcome(out, k_out, t, y, GUARD, kg, step)
        taken += 1
        if (check_every > 0 and taken % check_every == 0
                and _unstable(jac, t, y, p, step, stats)):
            return Outcome(out, k_out, t, y, UNSTABLE, -1, step)
        if max_steps > 0 and taken >= max_steps and t < t1:
            return Outcome(out, k_out, t, y, PAUSED, -1, step)
    return Outcome(out, k_out, t, y, REACHED, -1, step)


def settings(step, guard_tol, check_every, max_steps, stop) -> Settings:
    """``Settings`` with the types ``compile_loop`` compiled for (one specialization)."""
    return Settings(float(step), float(guard_tol), int(check_every), int(max_steps), stop)


def compile_loop():
    """Compile ``rk4`` for the argument types ``native_solver.NativeSolver`` passes, into
    numba's cache (``native.Precompile`` runs this in a separate process); it returns at
    once (t1 = t0), calling none of the entry points."""
    n = 1
    flag = np.zeros(0, dtype=np.uint8)
    rk4(Model(0, 0, 0, 0, np.zeros(1)), settings(0.1, 1e-3, 0, 0, flag), 0.0, 0.0,
        np.zeros(n), np.empty(0), np.zeros(N_STATS, dtype=np.int64))
