"""Radau IIA's Newton matrices: ``mu/h M - J`` for its real eigenvalue and its complex
pair, factored and solved (``radau5``'s simplified Newton iterations and error estimate
call these). Along the Jacobian's sparsity where static pivoting is stable
(``sparse_lu``), else dense LU with partial pivoting: LAPACK's getrf, or getrf's algorithm
in numba for small matrices.
"""

from __future__ import annotations

import numpy as np
from numba import njit, types
from numba.np.linalg import _LAPACK

from bgc.solvers import sparse_lu
from bgc.solvers.native import inner

# Radau IIA's eigenvalues of A^-1 (Hairer & Wanner IV.8): one real, a complex pair
_MU_REAL = 3.0 + 3.0 ** (2.0 / 3.0) - 3.0 ** (1.0 / 3.0)
_MU_COMPLEX = (3.0 + 0.5 * (3.0 ** (1.0 / 3.0) - 3.0 ** (2.0 / 3.0))
               - 0.5j * (3.0 ** (5.0 / 6.0) + 3.0 ** (7.0 / 6.0)))
NO_LU, DENSE_LU, SPARSE_LU = 0, 1, 2     # what _newton_matrices made


# LU factors with partial pivoting from LAPACK's getrf, through the binding numba itself
# uses for np.linalg (scipy's LAPACK, resolved by symbol name, so the loop is cacheable).
# numba offers no factor/solve pair: inverting the Newton matrices instead cost 2.3x the
# whole run on the SARIB (n = 152), where factorizations are most of the work. The
# binding is declared without instantiating numba's _LAPACK (which imports scipy.linalg,
# 0.4 s): numba's helper finds scipy's getrf when it is first called, and a model of up to
# SMALL_LU states never calls it (``_getrf_small``), so a small model's run imports no scipy.
_GETRF_REAL = _LAPACK.numba_xxgetrf(types.float64)
_GETRF_COMPLEX = _LAPACK.numba_xxgetrf(types.complex128)
SMALL_LU = 16


# (one function each: the two share the symbol numba_xxgetrf with different signatures,
# which one LLVM module cannot declare twice)
@njit(cache=True)
def _getrf_real(a, piv):
    n = a.shape[0]
    if n <= SMALL_LU:
        return _getrf_small(a, piv)
    return _GETRF_REAL(100, n, n, a.ctypes, n, piv.ctypes)


@njit(cache=True)
def _getrf_complex(a, piv):
    n = a.shape[0]
    if n <= SMALL_LU:
        return _getrf_small(a, piv)
    return _GETRF_COMPLEX(122, n, n, a.ctypes, n, piv.ctypes)


@inner
def _getrf_small(a, piv):
    """getrf's LU with partial pivoting in getrf's own layout (``a`` holds the matrix
    transposed, LAPACK's column-major order: A[r, c] is a[c, r]; ``piv`` 1-based), for
    small matrices, where the call into LAPACK costs more than the work. The pivot is
    the largest |re| + |im| in the column, as LAPACK's i?amax picks it. Returns getrf's
    info: 0, or k + 1 where the k-th pivot is exactly zero."""
    n = a.shape[0]
    info = 0
    for k in range(n):
        p, big = k, abs(a[k, k].real) + abs(a[k, k].imag)
        for r in range(k + 1, n):
            v = abs(a[k, r].real) + abs(a[k, r].imag)
            if v > big:
                p, big = r, v
        piv[k] = p + 1
        if p != k:
            for c in range(n):
                a[c, k], a[c, p] = a[c, p], a[c, k]
        if a[k, k] == 0:
            if info == 0:
                info = k + 1
            continue
        for r in range(k + 1, n):
            a[k, r] /= a[k, k]
        for c in range(k + 1, n):
            akc = a[c, k]
            if akc != 0:
                for r in range(k + 1, n):
                    a[c, r] -= a[k, r] * akc
    return info


@inner
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


@inner
def _newton_matrices(J, V, system, M, h, lu_real, lu_complex, piv_real, piv_complex,
                     plan):
    """Factor mu_real/h M - J and mu_complex/h M - J (M empty: the identity): along the
    sparse ``plan`` if there is one and both pass its growth check (returns SPARSE_LU),
    else dense, stored transposed for LAPACK (DENSE_LU); NO_LU if either is exactly
    singular. The Jacobian is the values V where ``_jacobian`` took them, else J."""
    n = J.shape[0]
    values = system.jacv != 0 and plan[0].shape[0] > 0
    if plan[0].shape[0] > 0:
        if values:
            sparse_lu.newton_matrix_values(V, M, _MU_REAL / h, plan, lu_real)
        else:
            sparse_lu.newton_matrix(J, M, _MU_REAL / h, plan, lu_real)
        if sparse_lu.factor(lu_real, plan):
            if values:
                sparse_lu.newton_matrix_values(V, M, _MU_COMPLEX / h, plan, lu_complex)
            else:
                sparse_lu.newton_matrix(J, M, _MU_COMPLEX / h, plan, lu_complex)
            if sparse_lu.factor(lu_complex, plan):
                return SPARSE_LU
        if values:              # the dense fallback reads J: from the values
            for i in range(n):
                for j in range(n):
                    J[i, j] = 0.0
            for k in range(system.rows.shape[0]):
                J[system.rows[k], system.cols[k]] = V[k]
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


@inner
def _solve_full(lu, piv, b, plan, kind):
    if kind == SPARSE_LU:
        return sparse_lu.solve(lu, plan, b)
    return _lu_solve(lu, piv, b)


@inner
def _solve(lu, piv, b, plan, kind):
    """Solve with the factors ``_newton_matrices`` made (of either kind); factors of the
    open Jacobian (larger than b) take b on the states' rows, zero on the others, and
    give the states' part."""
    n, na = b.shape[0], lu.shape[0]
    if na == n:
        return _solve_full(lu, piv, b, plan, kind)
    full = np.zeros(na, dtype=b.dtype)
    for i in range(n):
        full[i] = b[i]
    x = _solve_full(lu, piv, full, plan, kind)
    out = np.empty(n, dtype=b.dtype)
    for i in range(n):
        out[i] = x[i]
    return out
