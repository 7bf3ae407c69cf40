"""Sparse LU of Radau's Newton matrices ``mu/h M - J``, on the Jacobian's structure.

A multibody model's Jacobian is sparse (the SARIB's: 2031 of 23104 entries), and the
Newton matrices were most of the native integrator's work when factored dense. The
structure is known at compile time (the generated ``JAC_I``, ``JAC_J``), so it is analysed
once per run (``analyse``): a minimum-degree ordering of ``A + A^T`` (SuperLU's MMD, through
scipy) and the symbolic fill of elimination in that order (``bgc.codegen.elimination``,
shared with the generated kernels' sparse LU), as per-pivot lists of the rows
of L and the columns of U. Each factorization (``factor``) then touches only those
entries, in the ordered matrix held dense (n^2 storage, a fraction of the flops).

The pivots are taken on the diagonal of the ordered matrix (static pivoting, as in
SuperLU's symmetric mode). A column threshold would refuse nearly every mechanical model
(a spring's stiffness, 1e7, stands in the column of its deflection, whose pivot is mu/h,
1e3, and yet eliminating it is harmless), so what is checked is what bounds the backward
error of elimination, the growth factor (Golub & Van Loan 3.4.5): an entry growing past
``GROWTH_LIMIT`` times the matrix's largest, or a zero pivot, makes ``factor`` return
False, and the integrator factors that matrix dense with partial pivoting (LAPACK).
"""

from __future__ import annotations

import numpy as np
from numba import njit

from bgc.codegen import elimination

GROWTH_LIMIT = elimination.GROWTH_LIMIT
# dense is as fast below this size, or where elimination on the structure saves less
# than 10x dense LU's multiply-adds: LAPACK's blocked dense LU does each several times
# faster than this loop over index lists (the SARIB's Newton matrices, factored both
# ways: parasitic 0.026 of dense's work, 4.9x faster sparse; zcp 0.077, 1.7x; lagrange
# 0.12, 0.94x)
MIN_SIZE = 24
MAX_WORK = 0.1

_EMPTY = np.empty(0, dtype=np.int64)
DENSE = (_EMPTY,) * 8


def analyse(n: int, rows, cols, mass: np.ndarray | None = None):
    """The elimination plan ``(perm, lptr, lidx, uptr, uidx, dpos, lpos, upos)`` for
    Newton matrices with the structure of the Jacobian entries (rows, cols), the mass
    matrix's nonzeros and the diagonal; ``DENSE`` (empty arrays) where sparse
    elimination would not pay. ``dpos``, ``lpos``, ``upos``: where each entry the
    elimination reads (pivot k, its L and U lists) is among the Jacobian's entries, in
    the order (rows, cols) lists them (-1: not one, a fill-in or a mass term), so that
    the Newton matrices are formed from the Jacobian's values alone
    (``newton_matrix_values``)."""
    if n < MIN_SIZE:
        return DENSE
    pattern = np.zeros((n, n), dtype=bool)
    pattern[np.asarray(rows, dtype=np.int64), np.asarray(cols, dtype=np.int64)] = True
    if mass is not None and mass.size:
        pattern |= mass != 0.0
    else:                                   # M = I
        pattern[np.arange(n), np.arange(n)] = True
    # the ordering: values that make the diagonal the pivots, so SuperLU's row order is
    # its column order (the ordering of the structure alone)
    import scipy.sparse as sp  # only the symbolic analysis needs scipy
    import scipy.sparse.linalg as spl
    a = sp.csc_matrix(pattern.astype(np.float64) + n * np.eye(n))
    lu = spl.splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                  options={"SymmetricMode": True})
    best = None
    for perm in (np.asarray(lu.perm_c), np.argsort(lu.perm_c)):
        f = elimination.fill(pattern[np.ix_(perm, perm)])
        if f is not None and (best is None or f.sum() < best[1].sum()):
            best = (perm, f)
    if best is None or elimination.work(best[1]) > MAX_WORK * elimination.dense_work(n):
        return DENSE
    perm, f = best
    lptr, lidx, uptr, uidx = elimination.lists(f)
    at = {(int(i), int(j)): k for k, (i, j) in enumerate(zip(rows, cols))}
    dpos = np.array([at.get((int(perm[k]), int(perm[k])), -1) for k in range(n)],
                    dtype=np.int64)
    lpos = np.empty(len(lidx), dtype=np.int64)
    upos = np.empty(len(uidx), dtype=np.int64)
    for k in range(n):
        for q in range(lptr[k], lptr[k + 1]):
            lpos[q] = at.get((int(perm[lidx[q]]), int(perm[k])), -1)
        for r in range(uptr[k], uptr[k + 1]):
            upos[r] = at.get((int(perm[k]), int(perm[uidx[r]])), -1)
    return (perm.astype(np.int64), lptr, lidx, uptr, uidx, dpos, lpos, upos)


@njit(cache=True)
def _entry(v, k):
    return v[k] if k >= 0 else 0.0


@njit(cache=True)
def newton_matrix_values(V, M, c, plan, a):
    """``newton_matrix`` from the Jacobian's values ``V`` (in the order of its pattern,
    the plan's ``dpos``, ``lpos``, ``upos``) instead of a dense J."""
    perm, lptr, lidx, uptr, uidx, dpos, lpos, upos = plan
    n = a.shape[0]
    for k in range(n):
        pk = perm[k]
        a[k, k] = (c if M.shape[0] == 0 else c * M[pk, pk]) - _entry(V, dpos[k])
        for q in range(lptr[k], lptr[k + 1]):
            a[lidx[q], k] = (0.0 if M.shape[0] == 0 else c * M[perm[lidx[q]], pk]) \
                - _entry(V, lpos[q])
        for r in range(uptr[k], uptr[k + 1]):
            a[k, uidx[r]] = (0.0 if M.shape[0] == 0 else c * M[pk, perm[uidx[r]]]) \
                - _entry(V, upos[r])


@njit(cache=True)
def newton_matrix(J, M, c, plan, a):
    """``c M - J`` (M empty: the identity) in the plan's order, into ``a``: only the
    entries elimination reads (the filled pattern); the others are left as they are."""
    perm, lptr, lidx, uptr, uidx = plan[0], plan[1], plan[2], plan[3], plan[4]
    n = J.shape[0]
    for k in range(n):
        pk = perm[k]
        a[k, k] = c - J[pk, pk] if M.shape[0] == 0 else c * M[pk, pk] - J[pk, pk]
        for q in range(lptr[k], lptr[k + 1]):
            pi = perm[lidx[q]]
            a[lidx[q], k] = -J[pi, pk] if M.shape[0] == 0 else c * M[pi, pk] - J[pi, pk]
        for r in range(uptr[k], uptr[k + 1]):
            pj = perm[uidx[r]]
            a[k, uidx[r]] = -J[pk, pj] if M.shape[0] == 0 else c * M[pk, pj] - J[pk, pj]


@njit(cache=True)
def _mag(v):
    """|re| + |im|: within sqrt(2) of |v|, without a square root per entry."""
    return abs(v.real) + abs(v.imag)


@njit(cache=True)
def factor(a, plan):
    """LU-factor ``a`` (the ordered matrix, overwritten by its factors: unit L below the
    diagonal, U on and above) along ``plan``. False on a zero pivot or an entry grown
    past ``GROWTH_LIMIT`` times the largest of ``a``."""
    lptr, lidx, uptr, uidx = plan[1], plan[2], plan[3], plan[4]
    n = a.shape[0]
    big = 0.0
    for k in range(n):
        big = max(big, _mag(a[k, k]))
        for q in range(lptr[k], lptr[k + 1]):
            big = max(big, _mag(a[lidx[q], k]))
        for r in range(uptr[k], uptr[k + 1]):
            big = max(big, _mag(a[k, uidx[r]]))
    limit = GROWTH_LIMIT * big
    for k in range(n):
        piv = a[k, k]
        if piv == 0 or not _mag(piv) <= limit:
            return False
        for q in range(lptr[k], lptr[k + 1]):
            i = lidx[q]
            lik = a[i, k] / piv
            a[i, k] = lik
            if lik != 0:
                for r in range(uptr[k], uptr[k + 1]):
                    j = uidx[r]
                    v = a[i, j] - lik * a[k, j]
                    a[i, j] = v
                    if _mag(v) > limit:
                        return False
    return True


@njit(cache=True)
def solve(lu, plan, b):
    """Solve A x = b with ``factor``'s factors of A's ordered matrix."""
    perm, lptr, lidx, uptr, uidx = plan[0], plan[1], plan[2], plan[3], plan[4]
    n = b.shape[0]
    x = np.empty_like(b)
    for i in range(n):
        x[i] = b[perm[i]]
    for k in range(n):
        xk = x[k]
        if xk != 0:
            for q in range(lptr[k], lptr[k + 1]):
                i = lidx[q]
                x[i] -= lu[i, k] * xk
    for k in range(n - 1, -1, -1):
        s = x[k]
        for r in range(uptr[k], uptr[k + 1]):
            j = uidx[r]
            s -= lu[k, j] * x[j]
        x[k] = s / lu[k, k]
    out = np.empty_like(b)
    for i in range(n):
        out[perm[i]] = x[i]
    return out
