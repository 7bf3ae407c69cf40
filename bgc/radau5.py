"""Radau IIA order 5, the native stiff integrator: the whole step loop in numba.

The scheme is Hairer & Wanner's RADAU5 (Solving ODEs II, IV.8), with the constants and
step control of scipy's ``integrate/_ivp/radau.py``: three collocation stages solved by
simplified Newton iterations in transformed variables (one real and one complex linear
system), predictive (Gustafsson) step control, the collocation polynomial as dense output.
It also takes a mass matrix, ``M dx/dt = f(t, x)``, so a singular ``M`` makes it a DAE
solver (Hairer's ESTRAD error estimate with ``M``), of index 2 too with those states'
tolerances scaled by 1/h (``_scale``).

What keeps it fast: the Newton matrices ``mu/h M - J`` are LU-factored on the
Jacobian's sparsity (``sparse_lu``: on the SARIB 4128 of 23104 entries, 3-4x faster than
LAPACK's dense getrf, which takes over where static pivoting would not be stable) and
the factors kept while the step size stays; the Jacobian is recomputed only when
Newton converges slowly with the current one; the model's functions are called through
C entry points (``bgc.native``), so nothing returns to Python per step.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.np.linalg import F_INT_nptype, _LAPACK

from . import sparse_lu
from .native import (GUARD, INTERRUPTED, NOT_FINITE, PAUSED, REACHED, SINGULAR, ST_JAC,
                     ST_LU, ST_REJECTED, ST_RHS, ST_STEPS, STEP_TOO_SMALL, call_entry,
                     evaluate, guard_min, stopped)

_S6 = 6.0 ** 0.5
_C = np.array([(4.0 - _S6) / 10.0, (4.0 + _S6) / 10.0, 1.0])
_E = np.array([-13.0 - 7.0 * _S6, -13.0 + 7.0 * _S6, -1.0]) / 3.0
_MU_REAL = 3.0 + 3.0 ** (2.0 / 3.0) - 3.0 ** (1.0 / 3.0)
_MU_COMPLEX = (3.0 + 0.5 * (3.0 ** (1.0 / 3.0) - 3.0 ** (2.0 / 3.0))
               - 0.5j * (3.0 ** (5.0 / 6.0) + 3.0 ** (7.0 / 6.0)))
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
NO_LU, DENSE_LU, SPARSE_LU = 0, 1, 2
MIN_FACTOR, MAX_FACTOR = 0.2, 10.0

# LU factors with partial pivoting from LAPACK's getrf, through the binding numba itself
# uses for np.linalg (scipy's LAPACK, resolved by symbol name, so the loop is cacheable).
# numba offers no factor/solve pair: inverting the Newton matrices instead cost 2.3x the
# whole run on the SARIB (n = 152), where factorizations are most of the work.
_GETRF_REAL = _LAPACK().numba_xxgetrf(types.float64)
_GETRF_COMPLEX = _LAPACK().numba_xxgetrf(types.complex128)


# (one function each: the two share the symbol numba_xxgetrf with different signatures,
# which one LLVM module cannot declare twice)
@njit(cache=True)
def _getrf_real(a, piv):
    n = a.shape[0]
    return _GETRF_REAL(100, n, n, a.ctypes, n, piv.ctypes)


@njit(cache=True)
def _getrf_complex(a, piv):
    n = a.shape[0]
    return _GETRF_COMPLEX(122, n, n, a.ctypes, n, piv.ctypes)


@njit(cache=True)
def _lu_solve(lu, piv, b):
    """Solve with getrf's factors of A (``lu`` holds them transposed, LAPACK's column-major
    order): row swaps, then the unit lower and the upper triangle."""
    n = b.shape[0]
    x = b.copy()
    for i in range(n):
        k = piv[i] - 1
        if k != i:
            x[i], x[k] = x[k], x[i]
    for j in range(n):
        xj = x[j]
        if xj != 0:
            for i in range(j + 1, n):
                x[i] -= lu[j, i] * xj
    for j in range(n - 1, -1, -1):
        x[j] /= lu[j, j]
        xj = x[j]
        if xj != 0:
            for i in range(j):
                x[i] -= lu[j, i] * xj
    return x


@njit(cache=True)
def _newton_matrices(J, M, h, lu_real, lu_complex, piv_real, piv_complex, plan):
    """Factor mu_real/h M - J and mu_complex/h M - J (M empty: the identity): along the
    sparse ``plan`` if there is one and both pass its growth check (returns SPARSE_LU),
    else dense, stored transposed for LAPACK (DENSE_LU); NO_LU if either is exactly
    singular."""
    n = J.shape[0]
    if plan[0].shape[0] > 0:
        sparse_lu.newton_matrix(J, M, _MU_REAL / h, plan, lu_real)
        if sparse_lu.factor(lu_real, plan):
            sparse_lu.newton_matrix(J, M, _MU_COMPLEX / h, plan, lu_complex)
            if sparse_lu.factor(lu_complex, plan):
                return SPARSE_LU
    for i in range(n):
        for j in range(n):
            lu_real[i, j] = -J[j, i]
            lu_complex[i, j] = -J[j, i]
    if M.shape[0] == 0:
        for i in range(n):
            lu_real[i, i] += _MU_REAL / h
            lu_complex[i, i] += _MU_COMPLEX / h
    else:
        for i in range(n):
            for j in range(n):
                if M[j, i] != 0.0:
                    lu_real[i, j] += _MU_REAL / h * M[j, i]
                    lu_complex[i, j] += _MU_COMPLEX / h * M[j, i]
    if _getrf_real(lu_real, piv_real) == 0 and _getrf_complex(lu_complex, piv_complex) == 0:
        return DENSE_LU
    return NO_LU


@njit(cache=True)
def _solve(lu, piv, b, plan, kind):
    """Solve with the factors ``_newton_matrices`` made (of either kind)."""
    if kind == SPARSE_LU:
        return sparse_lu.solve(lu, plan, b)
    return _lu_solve(lu, piv, b)


@njit(cache=True)
def _times_mass(M, v):
    """M v (M empty: v itself)."""
    return v.copy() if M.shape[0] == 0 else M @ v


@njit(cache=True)
def _scale(y, y_new, rtol, atol, index2, h):
    """Error scale per state: atol + rtol max(|y|, |y_new|); divided by h for algebraic
    states of index 2, whose local error is one order lower (Hairer & Wanner II, VII.8)."""
    s = atol + np.maximum(np.abs(y), np.abs(y_new)) * rtol
    for i in range(index2.shape[0]):
        if index2[i] != 0.0:
            s[i] /= h
    return s


@njit(cache=True)
def _rms(v):
    return np.sqrt(np.mean(v * v))


@njit(cache=True)
def dense(t_old, h, y_old, Q, t):
    """The collocation polynomial of the step [t_old, t_old + h] at t."""
    x = (t - t_old) / h
    return y_old + Q[:, 0] * x + Q[:, 1] * x * x + Q[:, 2] * x * x * x


@njit(cache=True)
def _initial_step(rhs, t0, t1, y, f, p, rtol, atol, stats):
    """Hairer, Norsett & Wanner I, II.4 (error estimator of order 3), as scipy."""
    scale = atol + np.abs(y) * rtol
    d0, d1 = _rms(y / scale), _rms(f / scale)
    h0 = 1e-6 if (d0 < 1e-5 or d1 < 1e-5) else 0.01 * d0 / d1
    h0 = min(h0, t1 - t0)
    f1 = evaluate(rhs, t0 + h0, y + h0 * f, p, y.shape[0])
    stats[ST_RHS] += 1
    d2 = _rms((f1 - f) / scale) / h0
    h1 = max(1e-6, h0 * 1e-3) if (d1 <= 1e-15 and d2 <= 1e-15) else \
        (0.01 / max(d1, d2)) ** 0.25
    return min(100.0 * h0, h1)


@njit(cache=True)
def radau5(rhs, jac, guards, n_guards, t0, t1, x0, t_eval, p, M, index2, plan, rtol, atol,
           max_step, h_start, guard_tol, max_steps, stats, stop, diag):
    """Integrate ``M dx/dt = rhs(t, x, p)`` from t0 to t1 (``M`` empty: the identity);
    ``index2`` (empty, or 1.0 where a state is an algebraic variable of index 2) scales
    those states' error tolerances by 1/h, as RADAU5 does for index-2 DAEs; ``plan``
    is ``sparse_lu.analyse``'s elimination plan for the Newton matrices (empty: dense);
    ``rhs``, ``jac``, ``guards`` are C entry-point addresses. States at ``t_eval`` come
    from the collocation polynomial. ``h_start`` > 0 is the first step (a continuation
    keeps its step size), else it is estimated. Stops where a guard margin falls to
    ``guard_tol`` (located by bisection on the polynomial).

    Returns (states at t_eval, how many were reached, t reached, state there, status,
    guard index, the next step size); status PAUSED after ``max_steps`` accepted steps
    (0: no limit), so that Python can watch its events and go on from there, INTERRUPTED
    as soon as ``stop`` (a uint8 flag, ``solver.Interrupt``; empty: none) is set. ``diag``
    (length n) holds each state's share of the last rejected step's error (error over its
    scale; inf where the stages were not finite), to name the states that made a step
    size collapse (STEP_TOO_SMALL)."""
    n = x0.shape[0]
    out = np.empty((t_eval.shape[0], n))
    k_out = 0
    while k_out < t_eval.shape[0] and t_eval[k_out] <= t0:
        out[k_out] = x0
        k_out += 1
    t, y = t0, x0.copy()
    if t1 <= t0:
        return out, k_out, t, y, REACHED, -1, h_start
    f = evaluate(rhs, t, y, p, n)
    stats[ST_RHS] += 1
    if not np.all(np.isfinite(f)):     # no step size follows from it (a NaN one never ends)
        for i in range(n):
            diag[i] = np.inf if not np.isfinite(f[i]) else 0.0
        return out, k_out, t, y, NOT_FINITE, -1, h_start
    if h_start > 0.0:
        h_abs = h_start
    else:
        h_abs = _initial_step(rhs, t0, t1, y, f, p, rtol, atol, stats)
    h_abs = min(h_abs, t1 - t0, max_step)
    h_abs_old, err_old = -1.0, -1.0
    newton_tol = max(10.0 * 2.220446049250313e-16 / rtol, min(0.03, rtol ** 0.5))
    J = np.empty((n, n))
    call_entry(jac, t, y, p, J)
    stats[ST_JAC] += 1
    current_jac = True
    lu_real = np.empty((n, n))
    lu_complex = np.empty((n, n), dtype=np.complex128)
    piv_real = np.empty(n, dtype=F_INT_nptype)
    piv_complex = np.empty(n, dtype=F_INT_nptype)
    have_lu = False
    lu_kind = NO_LU
    Q = np.zeros((n, 3))
    have_sol = False
    t_old, h_last, y_old = t, 0.0, y.copy()
    F = np.empty((3, n))
    dW = np.empty((3, n))
    taken = 0
    while t < t1:
        if stopped(stop):
            return out, k_out, t, y, INTERRUPTED, -1, h_abs
        min_step = 10.0 * abs(np.nextafter(t, np.inf) - t)
        if h_abs > max_step:
            h_abs, h_abs_old, err_old = max_step, -1.0, -1.0
            have_lu = False
        elif h_abs < min_step:
            h_abs, h_abs_old, err_old = min_step, -1.0, -1.0
            have_lu = False
        rejected = False
        accepted = False
        Z = np.zeros((3, n))
        n_iter, rate, err_norm, safety = 0, 0.0, 0.0, 0.9
        y_new = y
        t_new = t
        while not accepted:
            if h_abs < min_step:
                return out, k_out, t, y, STEP_TOO_SMALL, -1, h_abs
            if t + h_abs >= t1:     # landing on t1: a shorter step, new factors
                t_new = t1
                if t1 - t != h_abs:
                    have_lu = False
                h_abs = t1 - t
            else:                   # (t + h) - t differs from h by round-off: not a new h
                t_new = t + h_abs
            h = h_abs
            Z0 = np.zeros((3, n))
            if have_sol:
                for i in range(3):
                    Z0[i] = dense(t_old, h_last, y_old, Q, t + h * _C[i]) - y
            scale = _scale(y, y, rtol, atol, index2, h)
            converged = False
            singular = False
            while not converged:
                if not have_lu:
                    stats[ST_LU] += 2
                    lu_kind = _newton_matrices(J, M, h, lu_real, lu_complex, piv_real,
                                               piv_complex, plan)
                    if lu_kind == NO_LU:
                        singular = True
                        break      # a smaller step shifts the spectrum
                    have_lu = True
                # simplified Newton iterations on the collocation system
                W = _TI @ Z0
                Z = Z0.copy()
                norm_old = -1.0
                rate = -1.0
                converged = False
                n_iter = 0
                finite = True
                for it in range(NEWTON_MAXITER):
                    n_iter = it + 1
                    for i in range(3):
                        call_entry(rhs, t + h * _C[i], y + Z[i], p, F[i])
                    stats[ST_RHS] += 3
                    if not np.all(np.isfinite(F)):
                        finite = False
                        for i in range(n):
                            ok_i = True
                            for j in range(3):
                                ok_i = ok_i and np.isfinite(F[j, i])
                            diag[i] = 0.0 if ok_i else np.inf
                        break
                    FT = np.ascontiguousarray(F.T)
                    f_real = FT @ _TI[0] - _MU_REAL / h * _times_mass(M, W[0])
                    f_cplx = (FT @ _TI[1] + 1j * (FT @ _TI[2])
                              - _MU_COMPLEX / h * (_times_mass(M, W[1])
                                                   + 1j * _times_mass(M, W[2])))
                    dW[0] = _solve(lu_real, piv_real, f_real, plan, lu_kind)
                    dc = _solve(lu_complex, piv_complex, f_cplx, plan, lu_kind)
                    dW[1] = dc.real
                    dW[2] = dc.imag
                    dnorm = 0.0
                    for i in range(3):
                        dnorm += np.sum((dW[i] / scale) ** 2)
                    dnorm = np.sqrt(dnorm / (3 * n))
                    if norm_old >= 0.0:
                        rate = dnorm / norm_old
                    if rate >= 0.0 and (rate >= 1.0 or rate ** (NEWTON_MAXITER - it)
                                        / (1.0 - rate) * dnorm > newton_tol):
                        break
                    W += dW
                    Z = _T @ W
                    if dnorm == 0.0 or (rate >= 0.0 and rate / (1.0 - rate) * dnorm
                                        < newton_tol):
                        converged = True
                        break
                    norm_old = dnorm
                if converged or not finite or current_jac:
                    break
                call_entry(jac, t, y, p, J)    # slow convergence: a fresh Jacobian
                stats[ST_JAC] += 1
                current_jac = True
                have_lu = False
            if not converged:
                h_abs *= 0.5
                have_lu = False
                stats[ST_REJECTED] += 1
                if singular and h_abs < min_step:
                    return out, k_out, t, y, SINGULAR, -1, h_abs
                continue
            y_new = y + Z[2]
            ZE = _times_mass(M, (np.ascontiguousarray(Z.T) @ _E) / h)
            error = _solve(lu_real, piv_real, f + ZE, plan, lu_kind)
            scale = _scale(y, y_new, rtol, atol, index2, h)
            err_norm = _rms(error / scale)
            safety = 0.9 * (2 * NEWTON_MAXITER + 1) / (2 * NEWTON_MAXITER + n_iter)
            if rejected and err_norm > 1.0:
                error = _solve(lu_real, piv_real, evaluate(rhs, t, y + error, p, n) + ZE,
                               plan, lu_kind)
                stats[ST_RHS] += 1
                err_norm = _rms(error / scale)
            if err_norm > 1.0:
                diag[:] = np.abs(error / scale)
                mult = 1.0 if (err_old < 0.0 or h_abs_old < 0.0) else \
                    h_abs / h_abs_old * (err_old / err_norm) ** 0.25
                factor = min(1.0, mult) * err_norm ** -0.25
                h_abs *= max(MIN_FACTOR, safety * factor)
                have_lu = False
                rejected = True
                stats[ST_REJECTED] += 1
            else:
                accepted = True
        stats[ST_STEPS] += 1
        recompute_jac = n_iter > 2 and rate > 1e-3
        if err_norm == 0.0:
            factor = MAX_FACTOR
        else:
            mult = 1.0 if (err_old < 0.0 or h_abs_old < 0.0) else \
                h_abs / h_abs_old * (err_old / err_norm) ** 0.25
            factor = min(MAX_FACTOR, safety * min(1.0, mult) * err_norm ** -0.25)
        if not recompute_jac and factor < 1.2:
            factor = 1.0
        # the factors depend on h: keep them while the step stays (also when the input
        # signals' max_step clips it back to where it was)
        h_next = min(h_abs * factor, max_step)
        if recompute_jac or h_next != h_abs:
            have_lu = False
        f_new = evaluate(rhs, t_new, y_new, p, n)
        stats[ST_RHS] += 1
        if not np.all(np.isfinite(y_new)):
            return out, k_out, t, y, NOT_FINITE, -1, h_abs
        if recompute_jac:
            call_entry(jac, t_new, y_new, p, J)
            stats[ST_JAC] += 1
            current_jac = True
        else:
            current_jac = False
        h_abs_old, err_old = h_abs, err_norm
        Q = np.ascontiguousarray(Z.T) @ _P
        have_sol = True
        t_old, h_last, y_old = t, t_new - t, y
        t, y, f = t_new, y_new, f_new
        h_abs = h_next
        # a guard margin reaching its tolerance: locate it on the polynomial (bisection)
        if guard_tol > 0.0 and n_guards > 0:
            kg, low = guard_min(guards, n_guards, t, y, p, guard_tol)
            if low <= 0.0:
                a, b = t_old, t
                for _ in range(60):
                    m = 0.5 * (a + b)
                    km, lm = guard_min(guards, n_guards, m,
                                       dense(t_old, h_last, y_old, Q, m), p, guard_tol)
                    if lm <= 0.0:
                        b, kg = m, km
                    else:
                        a = m
                while k_out < t_eval.shape[0] and t_eval[k_out] <= b:
                    out[k_out] = dense(t_old, h_last, y_old, Q, t_eval[k_out])
                    k_out += 1
                return (out, k_out, b, dense(t_old, h_last, y_old, Q, b), GUARD, kg,
                        h_abs)
        while k_out < t_eval.shape[0] and t_eval[k_out] <= t:
            out[k_out] = dense(t_old, h_last, y_old, Q, t_eval[k_out])
            k_out += 1
        taken += 1
        if max_steps > 0 and taken >= max_steps and t < t1:
            return out, k_out, t, y, PAUSED, -1, h_abs
    return out, k_out, t, y, REACHED, -1, h_abs
