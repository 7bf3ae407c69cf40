"""Radau IIA order 5, the native stiff integrator: the whole step loop in numba.

The scheme is Hairer & Wanner's RADAU5 (Solving ODEs II, IV.8), with the constants and
step control of scipy's ``integrate/_ivp/radau.py``: three collocation stages solved by
simplified Newton iterations in transformed variables (one real and one complex linear
system), predictive (Gustafsson) step control, the collocation polynomial as dense output.
It also takes a mass matrix, ``M dx/dt = f(t, x)``, so a singular ``M`` makes it a DAE
solver (Hairer's ESTRAD error estimate with ``M``), of index 2 too with those states'
tolerances scaled by 1/h (``_scale``).

What keeps it fast: the Newton matrices ``mu/h M - J`` are LU-factored
(``radau5_lu``) on the Jacobian's sparsity (``sparse_lu``: on the SARIB 4128 of 23104 entries, 3-4x faster than
LAPACK's dense getrf, which takes over where static pivoting would not be stable) and
the factors kept while the step size stays; the Jacobian is recomputed only when
Newton converges slowly with the current one; the model's functions are called through
C entry points (``bgc.solvers.native``), so nothing returns to Python per step.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit
from numba.np.linalg import F_INT_nptype

from bgc.solvers import rank, sparse_lu
from bgc.solvers.radau5_lu import NO_LU, _MU_COMPLEX, _MU_REAL, _newton_matrices, _solve
from bgc.solvers.native import (
    GUARD,
    INTERRUPTED,
    MINOR,
    N_STATS,
    NOT_FINITE,
    PAUSED,
    REACHED,
    SINGULAR,
    ST_JAC,
    ST_LU,
    ST_REJECTED,
    ST_RHS,
    ST_STEPS,
    STEP_TOO_SMALL,
    Model,
    Outcome,
    call_entry,
    evaluate,
    guard_min,
    inner,
    stopped,
)

_S6 = 6.0 ** 0.5
_C = np.array([(4.0 - _S6) / 10.0, (4.0 + _S6) / 10.0, 1.0])
_E = np.array([-13.0 - 7.0 * _S6, -13.0 + 7.0 * _S6, -1.0]) / 3.0
_T = np.array([[0.09443876248897524, -0.14125529502095421, 0.03002919410514742],
               [0.25021312296533332, 0.20412935229379994, -0.38294211275726192],
               [1.0, 1.0, 0.0]])
_TI = np.array([[4.17871859155190428, 0.32768282076106237, 0.52337644549944951],
                [-4.17871859155190428, -0.32768282076106237, 0.47662355450055044],
                [0.50287263494578682, -2.57192694985560522, 0.59603920482822492]])
_P = np.array([[13.0 / 3.0 + 7.0 * _S6 / 3.0, -23.0 / 3.0 - 22.0 * _S6 / 3.0,
                10.0 / 3.0 + 5.0 * _S6],
               [13.0 / 3.0 - 7.0 * _S6 / 3.0, -23.0 / 3.0 + 22.0 * _S6 / 3.0,
                10.0 / 3.0 - 5.0 * _S6],
               [1.0 / 3.0, -8.0 / 3.0, 10.0 / 3.0]])
NEWTON_MAXITER = 6
MIN_FACTOR, MAX_FACTOR = 0.2, 10.0
# a fresh Jacobian after a step whose Newton iterations converged slower than this
# (and took more than two): Hairer's RADAU5 takes 0.001 by default and advises 0.1 where
# Jacobians are costly, as here: the SARIB's costs 27 rhs calls, and each one a new pair
# of factorizations (1 s sine dwell: 147 -> 42 Jacobians, 392 -> 200 factorizations,
# errors unchanged to three digits; Andrews 24 -> 2 Jacobians, 106 -> 107 steps)
JAC_RATE = 0.1
# the step (and the factors with it) is kept unless the error allows this many times it
# (RADAU5's WORK(5): 1.2 by default, as scipy; 2 advised for large systems): on the 28 s
# SARIB chirp 4092 -> 1028 factorizations and 495 -> 41 rejected steps (growing by 1.2
# at a time, the step kept overshooting), 7660 -> 7633 steps; Andrews 107 -> 127 steps
# (scipy's Radau: 116) for 54 -> 28 factorizations
GROW_AT = 2.0


class System(NamedTuple):
    """``M dx/dt = rhs(t, x, p)`` as the loop calls it: the model (``native.Model``),
    the mass matrix (empty: the identity), 1.0 where a state is an algebraic variable of
    index 2 (empty: none), ``sparse_lu.analyse``'s elimination plan for the Newton
    matrices (``sparse_lu.DENSE``: dense) and the rank monitor of a constrained run
    (``rank.Monitor``; ``rank.none()``: none); ``project``: the address of the module's
    projection onto its constraints (method augmented; 0: none), applied twice after
    every accepted step. ``aug_mass``: the mass matrix of the Jacobian kept open
    (``JAC_SIZE`` > n: a constraint block's unknowns as algebraic rows, zero there; empty:
    none), on which the Newton matrices are formed and factored: their solves take the
    states' rows and read the states' part. ``jacv``: the address of the Jacobian as
    values in the order of its pattern (``rows``, ``cols``: JAC_I, JAC_J), which a
    sparse plan's Newton matrices are formed from (0: the dense Jacobian, ``model.jac``)."""
    model: Model
    mass: np.ndarray
    index2: np.ndarray
    plan: tuple
    monitor: rank.Monitor
    project: int
    aug_mass: np.ndarray
    jacv: int
    rows: np.ndarray
    cols: np.ndarray


class Settings(NamedTuple):
    """Tolerances and step limits: the first step ``h_start`` (0: estimated), a pause
    after ``max_steps`` accepted steps (0: none); a stop where a guard margin falls to
    ``guard_tol`` (0: never) or as soon as the ``stop`` flag is set (a uint8 array,
    ``base.Interrupt``; empty: never)."""
    rtol: float
    atol: float
    max_step: float
    h_start: float
    guard_tol: float
    max_steps: int
    stop: np.ndarray


# Newton steps of the projection onto the constraints after a step (method augmented):
# one leaves the positions within the square of the step's drift and the velocities
# within the regularization of the joints' rates
PROJECTIONS = 1

# the rank monitor's minor is checked every step below this (its determinant, 1 where it was
# picked), else after at most MONITOR_MAX steps (``radau5``)
MONITOR_NEAR, MONITOR_MAX = 0.5, 16


@inner
def _jacobian(system, t, y, p, J, V):
    """The Jacobian at (t, y): its values into V (a sparse plan with a values entry),
    else dense into J."""
    if system.jacv != 0 and system.plan[0].shape[0] > 0:
        call_entry(system.jacv, t, y, p, V)
    else:
        call_entry(system.model.jac, t, y, p, J)


class Carry(NamedTuple):
    """What the loop keeps across a pause (``Settings.max_steps``), so that going on from
    there costs no restart: the Jacobian, the Newton matrices' factors, the last step's
    collocation polynomial (``Q``, ``y_old``) and, in ``state``: [paused here (1.0), t
    paused at, t_old, h_last, h_abs_old, err_old, have_lu, lu_kind, current_jac,
    have_sol, faccon]. A call from (t0, x0) that is not where the last one paused starts
    fresh."""
    J: np.ndarray
    V: np.ndarray           # the Jacobian's values (``System.jacv``)
    lu_real: np.ndarray
    lu_complex: np.ndarray
    piv_real: np.ndarray
    piv_complex: np.ndarray
    Q: np.ndarray
    y_old: np.ndarray
    state: np.ndarray


def carry(n: int, na: int | None = None, nnz: int = 0) -> Carry:
    """An empty ``Carry`` for n states (a fresh start); ``na``: the size of the Jacobian
    (``JAC_SIZE``, n unless a constraint block is kept open), ``nnz`` its entries. (The
    dense arrays are allocated, not touched: a sparse run never writes most of them.)"""
    na = n if na is None else na
    return Carry(np.empty((na, na)), np.empty(max(nnz, 1)), np.empty((na, na)),
                 np.empty((na, na), dtype=np.complex128),
                 np.empty(na, dtype=F_INT_nptype), np.empty(na, dtype=F_INT_nptype),
                 np.zeros((n, 3)), np.empty(n), np.zeros(11))


# The loop below is written in scalar loops over arrays it allocates once, not numpy
# array expressions: numba compiles each array expression, slice assignment (whose shape
# check alone formats an error message: about 3 s on first use) and matrix product as
# functions of their own; the loops compile in 2/3 of the time and allocate almost
# nothing per step. Helpers called only from compiled code have no Python or C wrapper
# (``native.inner``): less to lower and optimize.

@inner
def _times_mass(M, v, out):
    """out = M v (M empty: v itself)."""
    n = v.shape[0]
    if M.shape[0] == 0:
        for i in range(n):
            out[i] = v[i]
        return
    for i in range(n):
        s = 0.0
        for j in range(n):
            s += M[i, j] * v[j]
        out[i] = s


@inner
def _scale(y, y_new, rtol, atol, index2, h, s):
    """Error scale per state, into ``s``: atol + rtol max(|y|, |y_new|); divided by h for
    algebraic states of index 2, whose local error is one order lower (Hairer & Wanner
    II, VII.8)."""
    for i in range(y.shape[0]):
        s[i] = atol + max(abs(y[i]), abs(y_new[i])) * rtol
    for i in range(index2.shape[0]):
        if index2[i] != 0.0:
            s[i] /= h


@inner
def _rms_ratio(v, scale):
    """The root mean square of v / scale."""
    s = 0.0
    for i in range(v.shape[0]):
        r = v[i] / scale[i]
        s += r * r
    return np.sqrt(s / v.shape[0])


@inner
def _finite(v) -> bool:
    for i in range(v.shape[0]):
        if not np.isfinite(v[i]):
            return False
    return True


@inner
def _dense_into(t_old, h, y_old, Q, t, out):
    """The collocation polynomial of the step [t_old, t_old + h] at t, into ``out``."""
    x = (t - t_old) / h
    for i in range(y_old.shape[0]):
        out[i] = y_old[i] + Q[i, 0] * x + Q[i, 1] * x * x + Q[i, 2] * x * x * x


@njit(cache=True)
def dense(t_old, h, y_old, Q, t):
    """The collocation polynomial of the step [t_old, t_old + h] at t."""
    out = np.empty(y_old.shape[0])
    _dense_into(t_old, h, y_old, Q, t, out)
    return out


@inner
def _initial_step(rhs, t0, t1, y, f, p, rtol, atol, stats):
    """Hairer, Norsett & Wanner I, II.4 (error estimator of order 3), as scipy."""
    n = y.shape[0]
    scale = np.empty(n)
    y1 = np.empty(n)
    for i in range(n):
        scale[i] = atol + abs(y[i]) * rtol
    d0, d1 = _rms_ratio(y, scale), _rms_ratio(f, scale)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, t1 - t0)
    for i in range(n):
        y1[i] = y[i] + h0 * f[i]
    f1 = evaluate(rhs, t0 + h0, y1, p, n)
    stats[ST_RHS] += 1
    for i in range(n):
        f1[i] -= f[i]
    d2 = _rms_ratio(f1, scale) / h0
    h1 = max(1e-6, h0 * 1e-3) if (d1 <= 1e-15 and d2 <= 1e-15) else \
        (0.01 / max(d1, d2)) ** 0.25
    return min(100.0 * h0, h1)


@inner
def _record(out, k_out, t_eval, t_end, t_old, h_last, y_old, Q):
    """Rows of ``out`` from the polynomial at the t_eval[k_out:] up to t_end; the new
    k_out."""
    while k_out < t_eval.shape[0] and t_eval[k_out] <= t_end:
        _dense_into(t_old, h_last, y_old, Q, t_eval[k_out], out[k_out])
        k_out += 1
    return k_out


# (its arguments are the loop's own arrays, one by one: a tuple of them cost compile time,
# the note at ``radau5``; so do those of ``_newton_matrices`` and ``_guard_bisect``)
@inner
def _newton(rhs, t, h, y, p, M, Z0, Z, W, F, dW, work, f_real, f_cplx, lu_real,
            lu_complex, piv_real, piv_complex, plan, lu_kind, scale, newton_tol, stats,
            diag, faccon):
    """Simplified Newton iterations on the collocation system from Z0, in the
    transformed variables W (Z = T W). Returns (converged, iterations, rate, finite,
    faccon); not finite: the stages' rhs was not (``diag``: inf for those states).
    ``faccon``: rate / (1 - rate) of the last iterations that measured a rate (Hairer's
    FACCON), by which a first iteration may already be converged: with the collocation
    polynomial's prediction, one iteration is often enough, and scipy's rule (a rate is
    measured from the second) spent two on every step (7 rhs a step instead of 4)."""
    n = y.shape[0]
    for i in range(3):
        for k in range(n):
            W[i, k] = _TI[i, 0] * Z0[0, k] + _TI[i, 1] * Z0[1, k] + _TI[i, 2] * Z0[2, k]
            Z[i, k] = Z0[i, k]
    norm_old = -1.0
    rate = -1.0
    mu_real = _MU_REAL / h
    mu_complex = _MU_COMPLEX / h
    for it in range(NEWTON_MAXITER):
        for i in range(3):
            for k in range(n):
                work[k] = y[k] + Z[i, k]
            call_entry(rhs, t + h * _C[i], work, p, F[i])
        stats[ST_RHS] += 3
        finite = True
        for k in range(n):
            if not (np.isfinite(F[0, k]) and np.isfinite(F[1, k]) and np.isfinite(F[2, k])):
                finite = False
                break
        if not finite:
            for k in range(n):
                ok = np.isfinite(F[0, k]) and np.isfinite(F[1, k]) and np.isfinite(F[2, k])
                diag[k] = 0.0 if ok else np.inf
            return False, it + 1, rate, False, faccon
        # M W, its rows into dW (overwritten by the solves below)
        for i in range(3):
            _times_mass(M, W[i], dW[i])
        for k in range(n):
            a = F[0, k] * _TI[0, 0] + F[1, k] * _TI[0, 1] + F[2, k] * _TI[0, 2]
            f_real[k] = a - mu_real * dW[0, k]
            b = F[0, k] * _TI[1, 0] + F[1, k] * _TI[1, 1] + F[2, k] * _TI[1, 2]
            c = F[0, k] * _TI[2, 0] + F[1, k] * _TI[2, 1] + F[2, k] * _TI[2, 2]
            f_cplx[k] = complex(b, c) - mu_complex * complex(dW[1, k], dW[2, k])
        d_real = _solve(lu_real, piv_real, f_real, plan, lu_kind)
        d_cplx = _solve(lu_complex, piv_complex, f_cplx, plan, lu_kind)
        s0 = s1 = s2 = 0.0       # (summed per stage, then together, as before)
        for k in range(n):
            r0 = d_real[k] / scale[k]
            r1 = d_cplx[k].real / scale[k]
            r2 = d_cplx[k].imag / scale[k]
            s0 += r0 * r0
            s1 += r1 * r1
            s2 += r2 * r2
        dnorm = np.sqrt((s0 + s1 + s2) / (3 * n))
        if norm_old >= 0.0:
            rate = dnorm / norm_old
            if rate < 1.0:
                faccon = rate / (1.0 - rate)
        if rate >= 0.0 and (rate >= 1.0 or rate ** (NEWTON_MAXITER - it)
                            / (1.0 - rate) * dnorm > newton_tol):
            return False, it + 1, rate, True, faccon
        for k in range(n):
            W[0, k] += d_real[k]
            W[1, k] += d_cplx[k].real
            W[2, k] += d_cplx[k].imag
        for i in range(3):
            for k in range(n):
                Z[i, k] = _T[i, 0] * W[0, k] + _T[i, 1] * W[1, k] + _T[i, 2] * W[2, k]
        if dnorm == 0.0 or faccon * dnorm < newton_tol:
            return True, it + 1, rate, True, faccon
        norm_old = dnorm
    return False, NEWTON_MAXITER, rate, True, faccon


@inner
def _guard_bisect(guards, n_guards, t_old, t, h_last, y_old, Q, p, guard_tol, kg, work):
    """Where on the polynomial of the last step a guard margin reaches its tolerance
    (bisection): (time, guard index)."""
    a, b = t_old, t
    for _ in range(60):
        m = 0.5 * (a + b)
        _dense_into(t_old, h_last, y_old, Q, m, work)
        km, lm = guard_min(guards, n_guards, m, work, p, guard_tol)
        if lm <= 0.0:
            b, kg = m, km
        else:
            a = m
    return b, kg


# The step loop in named parts: each part below is a function the loop calls, inlined into
# it by numba (``part``: ``inline='always'``, at numba's IR level, before typing), so the
# loop still compiles as one function. A part compiled on its own (``inner``) is typed,
# lowered and cached apart and takes the loop's state as arguments: the Newton solve, error
# estimate, predictor and work arrays as ``inner`` functions of a tuple of the work arrays
# cost +17% of the loop's cold compile (13.1 s against 11.2 s). Inlined, the arguments,
# tuples and records included, cost nothing measurable (issue 41, alternating with the
# single-function loop, fresh caches, on a loaded 2-core machine: cold ``compile_loop``
# with its dependencies 30.9 and 34.3 s CPU against 32.3 and 35.3 s; the SARIB main job's
# loop, 16 pairs alternating, new/old CPU time 0.99 (median of the pairs), the states
# bitwise identical). ``_newton`` and the linear algebra stay ``inner``: large enough to
# compile apart, at no cost measured.
part = njit(inline="always")


class Work(NamedTuple):
    """The loop's work arrays for n states: the stages ``Z``, their predictor ``Z0``, the
    transformed variables ``W`` and Newton increments ``dW``, the stages' rhs ``F``, a
    scratch row ``work``, ``M`` times the error estimate's stage combination ``ZE``, the
    right-hand sides of the real and complex systems, the error ``scale``, and the
    projection's correction of the last step's end (``shift``)."""
    Z: np.ndarray
    Z0: np.ndarray
    W: np.ndarray
    dW: np.ndarray
    F: np.ndarray
    work: np.ndarray
    ZE: np.ndarray
    f_real: np.ndarray
    f_cplx: np.ndarray
    scale: np.ndarray
    shift: np.ndarray


@part
def _work(n):
    return Work(np.zeros((3, n)), np.empty((3, n)), np.empty((3, n)), np.empty((3, n)),
                np.empty((3, n)), np.empty(n), np.empty(n), np.empty(n),
                np.empty(n, dtype=np.complex128), np.empty(n), np.zeros(n))


@part
def _begin(system, settings, keep, t0, t1, y, f, p, stats):
    """The loop's state at its start: going on from where the last call paused (``keep``),
    else fresh (the first step estimated unless given, a Jacobian at the start). Returns
    the step ``h_abs``, the step control's memory ``(h_abs_old, err_old)``, the Newton
    state ``(have_lu, lu_kind, current_jac, faccon)``, whether the last step's polynomial
    predicts the next stages (``have_sol``) and that polynomial's ``(t_old, h_last,
    y_old)`` (its coefficients are ``keep.Q``)."""
    kept, h_start, max_step = keep.state, settings.h_start, settings.max_step
    if kept[0] == 1.0 and kept[1] == t0 and h_start > 0.0:     # going on from a pause
        h_abs = min(h_start, t1 - t0, max_step)
        have_lu = kept[6] == 1.0 and h_abs == h_start
        return (h_abs, (kept[4], kept[5]), (have_lu, int(kept[7]), kept[8] == 1.0, kept[10]),
                kept[9] == 1.0, (kept[2], kept[3], keep.y_old.copy()))
    if h_start > 0.0:
        h_abs = h_start
    else:
        h_abs = _initial_step(system.model.rhs, t0, t1, y, f, p, settings.rtol,
                              settings.atol, stats)
    h_abs = min(h_abs, t1 - t0, max_step)
    _jacobian(system, t0, y, p, keep.J, keep.V)
    stats[ST_JAC] += 1
    Q = keep.Q
    for i in range(y.shape[0]):
        Q[i, 0] = Q[i, 1] = Q[i, 2] = 0.0
    return h_abs, (-1.0, -1.0), (False, NO_LU, True, 1.0), False, (t0, 0.0, y.copy())


@part
def _pause(keep, t, control, newton, have_sol, poly):
    """Keep the loop's state in ``keep`` for the next call to go on from t."""
    kept = keep.state
    have_lu, lu_kind, current_jac, faccon = newton
    kept[0], kept[1], kept[2], kept[3] = 1.0, t, poly[0], poly[1]
    kept[4], kept[5] = control
    kept[6], kept[7] = 1.0 if have_lu else 0.0, float(lu_kind)
    kept[8], kept[9] = 1.0 if current_jac else 0.0, 1.0 if have_sol else 0.0
    kept[10] = faccon
    y_old = poly[2]
    for i in range(y_old.shape[0]):
        keep.y_old[i] = y_old[i]


@part
def _predict(have_sol, poly, Q, t, h, y, Z0):
    """The stages' first guess: the last step's collocation polynomial at the new
    collocation times (dense output extrapolated), else zero."""
    n = y.shape[0]
    for i in range(3):
        if have_sol:
            _dense_into(poly[0], poly[1], poly[2], Q, t + h * _C[i], Z0[i])
            for k in range(n):
                Z0[i, k] -= y[k]
        else:
            for k in range(n):
                Z0[i, k] = 0.0


@part
def _collocation(system, keep, t, h, y, p, wk, newton, newton_tol, stats, diag):
    """Solve the collocation system of a step of size h: Newton iterations on factors of
    the Newton matrices (formed again where there are none), with a fresh Jacobian once
    when they converge slowly on an old one. Returns (converged, singular, iterations,
    rate, the Newton state)."""
    have_lu, lu_kind, current_jac, faccon = newton
    M = system.mass
    singular = False
    converged = False
    n_iter, rate = 0, 0.0
    while not converged:
        if not have_lu:
            stats[ST_LU] += 2
            lu_kind = _newton_matrices(keep.J, keep.V, system,
                                       system.aug_mass if system.aug_mass.shape[0] > 0
                                       else M, h, keep.lu_real, keep.lu_complex,
                                       keep.piv_real, keep.piv_complex, system.plan)
            if lu_kind == NO_LU:
                singular = True
                break      # a smaller step shifts the spectrum
            have_lu = True
        faccon = max(faccon, 2.220446049250313e-16) ** 0.8   # (Hairer's decay)
        converged, n_iter, rate, finite, faccon = _newton(
            system.model.rhs, t, h, y, p, M, wk.Z0, wk.Z, wk.W, wk.F, wk.dW, wk.work,
            wk.f_real, wk.f_cplx, keep.lu_real, keep.lu_complex, keep.piv_real,
            keep.piv_complex, system.plan, lu_kind, wk.scale, newton_tol, stats, diag,
            faccon)
        if converged or not finite or current_jac:
            break
        _jacobian(system, t, y, p, keep.J, keep.V)    # slow convergence: a fresh Jacobian
        stats[ST_JAC] += 1
        current_jac = True
        have_lu = False
    return converged, singular, n_iter, rate, (have_lu, lu_kind, current_jac, faccon)


@part
def _error_estimate(system, keep, settings, t, h, y, f, p, wk, lu_kind, rejected, stats):
    """The step's end ``y_new`` and its error norm (Hairer's ESTRAD with M; after a
    rejected step, an error above 1 is estimated again from one more rhs)."""
    M, plan, rhs = system.mass, system.plan, system.model.rhs
    Z, work, ZE, scale = wk.Z, wk.work, wk.ZE, wk.scale
    n = y.shape[0]
    y_new = np.empty(n)
    for k in range(n):
        y_new[k] = y[k] + Z[2, k]
        work[k] = (Z[0, k] * _E[0] + Z[1, k] * _E[1] + Z[2, k] * _E[2]) / h
    _times_mass(M, work, ZE)
    for k in range(n):
        work[k] = f[k] + ZE[k]
    error = _solve(keep.lu_real, keep.piv_real, work, plan, lu_kind)
    _scale(y, y_new, settings.rtol, settings.atol, system.index2, h, scale)
    err_norm = _rms_ratio(error, scale)
    if rejected and err_norm > 1.0:
        for k in range(n):
            work[k] = y[k] + error[k]
        call_entry(rhs, t, work, p, wk.F[0])
        for k in range(n):
            work[k] = wk.F[0, k] + ZE[k]
        error = _solve(keep.lu_real, keep.piv_real, work, plan, lu_kind)
        stats[ST_RHS] += 1
        err_norm = _rms_ratio(error, scale)
    return y_new, error, err_norm


@part
def _mult(h_abs, err_norm, control):
    """Gustafsson's predictive factor from the last accepted step (1: none)."""
    h_abs_old, err_old = control
    return 1.0 if (err_old < 0.0 or h_abs_old < 0.0) else \
        h_abs / h_abs_old * (err_old / err_norm) ** 0.25


@part
def _next_step(h_abs, err_norm, control, safety, n_iter, rate, max_step):
    """After an accepted step: the next step size (kept unless it may grow by
    ``GROW_AT``, or the Jacobian is renewed) and whether the Jacobian is renewed."""
    recompute_jac = n_iter > 2 and rate > JAC_RATE
    if err_norm == 0.0:
        factor = MAX_FACTOR
    else:
        factor = min(MAX_FACTOR, safety * min(1.0, _mult(h_abs, err_norm, control))
                     * err_norm ** -0.25)
    if not recompute_jac and factor < GROW_AT:
        factor = 1.0
    return min(h_abs * factor, max_step), recompute_jac


@part
def _step(system, settings, keep, t, t1, y, f, p, wk, h_abs, min_step, control, newton,
          have_sol, poly, newton_tol, stats, diag):
    """One step from (t, y), tried with h_abs and made smaller until its Newton
    iterations converge and its error is within the tolerances. Returns (status, the
    step taken, t_new, y_new, err_norm, iterations, rate, safety, the Newton state):
    status REACHED for a step taken, else STEP_TOO_SMALL or SINGULAR."""
    rejected = False
    while True:
        if h_abs < min_step:
            return (STEP_TOO_SMALL, h_abs, t, y, 0.0, 0, 0.0, 0.9, newton)
        if t + h_abs >= t1:     # landing on t1: a shorter step, new factors
            t_new = t1
            if t1 - t != h_abs:
                newton = (False, newton[1], newton[2], newton[3])
            h_abs = t1 - t
        else:                   # (t + h) - t differs from h by round-off: not a new h
            t_new = t + h_abs
        h = h_abs
        _predict(have_sol, poly, keep.Q, t, h, y, wk.Z0)
        _scale(y, y, settings.rtol, settings.atol, system.index2, h, wk.scale)
        converged, singular, n_iter, rate, newton = _collocation(
            system, keep, t, h, y, p, wk, newton, newton_tol, stats, diag)
        if not converged:
            h_abs *= 0.5
            newton = (False, newton[1], newton[2], newton[3])
            stats[ST_REJECTED] += 1
            if singular and h_abs < min_step:
                return (SINGULAR, h_abs, t, y, 0.0, n_iter, rate, 0.9, newton)
            continue
        y_new, error, err_norm = _error_estimate(system, keep, settings, t, h, y, f, p, wk,
                                                 newton[1], rejected, stats)
        safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
        if err_norm <= 1.0:
            return (REACHED, h_abs, t_new, y_new, err_norm, n_iter, rate, safety, newton)
        for k in range(y.shape[0]):
            diag[k] = abs(error[k] / wk.scale[k])
        factor = min(1.0, _mult(h_abs, err_norm, control)) * err_norm ** -0.25
        h_abs *= max(MIN_FACTOR, safety * factor)
        newton = (False, newton[1], newton[2], newton[3])
        rejected = True
        stats[ST_REJECTED] += 1


@part
def _dense_coefficients(Z, Q):
    """The collocation polynomial of the step just taken (dense output), from its stages."""
    for k in range(Q.shape[0]):
        for j in range(3):
            Q[k, j] = Z[0, k] * _P[0, j] + Z[1, k] * _P[1, j] + Z[2, k] * _P[2, j]


@part
def _watch_minor(mon, msc, t, y, p, watch):
    """The rank monitor after an accepted step (``watch``: its scale, last value, steps
    between checks and left until the next): where the monitored minor went through zero,
    another is picked. Returns (lost, watch); lost: no minor is well conditioned there
    (a possibly singular configuration, handed back from the step's start)."""
    m_scale, m_last, m_wait, m_left = watch
    m_left -= 1
    if m_scale == 0.0 or m_left > 0:
        return False, (m_scale, m_last, m_wait, m_left)
    d = rank.minor(mon, msc, t, y, p) / m_scale
    if d <= 0.0:
        m_scale = rank.settle(mon, msc, t, y, p)
        if m_scale == 0.0:
            return True, (m_scale, m_last, m_wait, m_left)
        d = 1.0
    fall = (m_last - d) / m_wait            # per step, since the last check
    m_wait = 1
    if d > MONITOR_NEAR:
        m_wait = MONITOR_MAX if fall <= 0.0 else int(
            max(1.0, min(MONITOR_MAX, 0.25 * (d - MONITOR_NEAR) / fall)))
    return False, (m_scale, d, m_wait, m_wait)


@part
def _shift(y_old, shift):
    """The last step's polynomial moved by its end's projection (``y_old``, its start,
    by ``shift``), once its outputs are recorded: the next stages are predicted from the
    projected state onwards, not from the drifted one (the drift, of the order of the
    tolerance, was each first Newton iteration's to remove)."""
    for k in range(shift.shape[0]):
        y_old[k] += shift[k]


@part
def _first_rows(out, t_eval, t0, x0):
    """The output rows at or before t0: the initial state. Returns how many."""
    k_out = 0
    while k_out < t_eval.shape[0] and t_eval[k_out] <= t0:
        for i in range(x0.shape[0]):
            out[k_out, i] = x0[i]
        k_out += 1
    return k_out


@njit(cache=True)
def radau5(system, settings, t0, t1, x0, t_eval, stats, diag, keep):
    """Integrate ``system`` (``M dx/dt = rhs(t, x, p)``, ``System``) from t0 to t1 as
    ``settings`` (``Settings``) ask (``index2`` states: their error tolerances scaled by
    1/h, as RADAU5 does for index-2 DAEs); states at ``t_eval`` from the collocation
    polynomial. ``settings.h_start`` > 0 is the first step (a continuation keeps its step
    size), else it is estimated. Stops where a guard margin falls to ``guard_tol``
    (located by bisection on the polynomial).

    Returns a ``native.Outcome``; status PAUSED after ``max_steps`` accepted steps (0: no
    limit), for Python to watch its events and go on, INTERRUPTED as soon as the ``stop``
    flag is set. ``stats`` counts the work (``native.ST_*``); ``diag`` (length n) holds
    each state's share of the last rejected step's error (inf where the stages were not
    finite), to name the states that made a step size collapse. ``keep`` (a ``Carry``)
    holds the loop's state across a pause: a call that starts where the last one paused
    goes on as if it had not (same Jacobian, factors and predictor).

    The rank monitor (``system.monitor``) is checked after accepted steps
    (``_watch_minor``): every step while the minor's determinant (1 where it was picked)
    is below ``MONITOR_NEAR`` or falling fast, else after as many steps as a quarter of
    the fall to ``MONITOR_NEAR`` would take, at most ``MONITOR_MAX``; status MINOR where
    no other minor is well conditioned (returned at the start of that step)."""
    rhs, _, guards, n_guards, p = system.model
    guard_tol, max_steps, max_step = settings.guard_tol, settings.max_steps, settings.max_step
    n = x0.shape[0]
    out = np.empty((t_eval.shape[0], n))
    k_out = _first_rows(out, t_eval, t0, x0)
    t, y = t0, x0.copy()
    if t1 <= t0:
        return Outcome(out, k_out, t, y, REACHED, -1, settings.h_start)
    f = evaluate(rhs, t, y, p, n)
    stats[ST_RHS] += 1
    if not _finite(f):     # no step size follows from it (a NaN one never ends)
        for i in range(n):
            diag[i] = np.inf if not np.isfinite(f[i]) else 0.0
        return Outcome(out, k_out, t, y, NOT_FINITE, -1, settings.h_start)
    Q = keep.Q
    newton_tol = max(10.0 * 2.220446049250313e-16 / settings.rtol,
                     min(0.03, settings.rtol ** 0.5))
    h_abs, control, newton, have_sol, poly = _begin(system, settings, keep, t0, t1, y, f,
                                                    p, stats)
    keep.state[0] = 0.0
    mon = system.monitor
    msc = rank.scratch(mon, n)
    watch = (rank.start(mon, msc, t, y, p) if mon.con != 0 else 0.0, 1.0, 1, 1)
    wk = _work(n)
    taken = 0
    while t < t1:
        if stopped(settings.stop):
            return Outcome(out, k_out, t, y, INTERRUPTED, -1, h_abs)
        min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
        if h_abs > max_step or h_abs < min_step:    # clipped: no prediction, new factors
            h_abs = max_step if h_abs > max_step else min_step
            control, newton = (-1.0, -1.0), (False, newton[1], newton[2], newton[3])
        status, h_abs, t_new, y_new, err_norm, n_iter, rate, safety, newton = _step(
            system, settings, keep, t, t1, y, f, p, wk, h_abs, min_step, control, newton,
            have_sol, poly, newton_tol, stats, diag)
        if status != REACHED:
            return Outcome(out, k_out, t, y, status, -1, h_abs)
        stats[ST_STEPS] += 1
        # the factors depend on h: keep them while the step stays (also when the input
        # signals' max_step clips it back to where it was)
        h_next, recompute_jac = _next_step(h_abs, err_norm, control, safety, n_iter, rate,
                                           max_step)
        if recompute_jac or h_next != h_abs:
            newton = (False, newton[1], newton[2], newton[3])
        if system.project != 0:         # back onto the constraints (Newton steps)
            for k in range(n):
                wk.shift[k] = 0.0
            for _ in range(PROJECTIONS):
                call_entry(system.project, t_new, y_new, p, wk.work)
                for k in range(n):
                    y_new[k] += wk.work[k]
                    wk.shift[k] += wk.work[k]
        f_new = evaluate(rhs, t_new, y_new, p, n)
        stats[ST_RHS] += 1
        if not _finite(y_new):
            return Outcome(out, k_out, t, y, NOT_FINITE, -1, h_abs)
        if recompute_jac:
            _jacobian(system, t_new, y_new, p, keep.J, keep.V)
            stats[ST_JAC] += 1
        newton = (newton[0], newton[1], recompute_jac, newton[3])
        control = (h_abs, err_norm)
        _dense_coefficients(wk.Z, Q)
        have_sol = True
        poly = (t, t_new - t, y)
        t, y, f = t_new, y_new, f_new
        h_abs = h_next
        # a guard margin reaching its tolerance: locate it on the polynomial (bisection)
        if guard_tol > 0.0 and n_guards > 0:
            kg, low = guard_min(guards, n_guards, t, y, p, guard_tol)
            if low <= 0.0:
                b, kg = _guard_bisect(guards, n_guards, poly[0], t, poly[1], poly[2], Q, p,
                                      guard_tol, kg, wk.work)
                k_out = _record(out, k_out, t_eval, b, poly[0], poly[1], poly[2], Q)
                return Outcome(out, k_out, b, dense(poly[0], poly[1], poly[2], Q, b), GUARD,
                               kg, h_abs)
        lost, watch = _watch_minor(mon, msc, t, y, p, watch)
        if lost:
            return Outcome(out, k_out, poly[0], poly[2].copy(), MINOR, -1, poly[1])
        k_out = _record(out, k_out, t_eval, t, poly[0], poly[1], poly[2], Q)
        if system.project != 0:         # the polynomial through the projected end
            _shift(poly[2], wk.shift)
        taken += 1
        if max_steps > 0 and taken >= max_steps and t < t1:
            _pause(keep, t, control, newton, have_sol, poly)
            return Outcome(out, k_out, t, y, PAUSED, -1, h_abs)
    return Outcome(out, k_out, t, y, REACHED, -1, h_abs)


def settings(rtol, atol, max_step, h_start, guard_tol, max_steps, stop) -> Settings:
    """``Settings`` with the types ``compile_loop`` compiled for (one specialization)."""
    return Settings(float(rtol), float(atol), float(max_step), float(h_start),
                    float(guard_tol), int(max_steps), stop)


def compile_loop():
    """Compile ``radau5`` for the argument types ``native_solver.NativeSolver`` passes,
    into numba's cache (``native.Precompile`` runs this in a separate process); it
    returns at once (t1 = t0), calling none of the entry points."""
    n = 1
    system = System(Model(0, 0, 0, 0, np.zeros(1)), np.empty((0, 0)), np.empty(0),
                    sparse_lu.DENSE, rank.none(), 0, np.empty((0, 0)), 0,
                    np.empty(0, dtype=np.int64), np.empty(0, dtype=np.int64))
    radau5(system, settings(1e-6, 1e-6, np.inf, 0.0, 1e-3, 0, np.zeros(0, dtype=np.uint8)),
           0.0, 0.0, np.zeros(n), np.empty(0), np.zeros(N_STATS, dtype=np.int64), np.zeros(n),
           carry(n))
