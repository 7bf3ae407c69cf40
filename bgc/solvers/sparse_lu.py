"""Sparse LU of Radau's Newton matrices ``mu/h M - J``, on the Jacobian's structure.

A multibody model's Jacobian is sparse (the SARIB's: 2031 of 23104 entries), and the
Newton matrices were most of the native integrator's work when factored dense. The
structure is known at compile time (the generated ``JAC_I``, ``JAC_J``), so it is analysed
once per run (``analyse``): a minimum-degree ordering of ``A + A^T`` (SuperLU's MMD, through
scipy) and the symbolic fill of elimination in that order (``bgc.codegen.elimination``,
shared with the generated kernels' sparse LU), as per-pivot lists of the rows
of L and the columns of U. Each factorization (``factor``) then touches only those
entries, held **packed** in one array in the order elimination reads them: the diagonal,
L's lists, U's lists (``n + nl + nu`` values, the first entries of the array it is given),
each update's target found in a table made with the plan (``upd``). Forming a matrix, its
factorization and every solve read and write that array in order, where a dense n x n
held in the ordered matrix spread them over megabytes at random (IFToMM A02 at N = 40
under method augmented: 31 thousand entries in a 1577 x 1577 matrix, 20 MB real and 40
complex; its Newton linear algebra was 45 % of a run).

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
from numba import njit, types
from numba.core import cgutils
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic

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
DENSE = (_EMPTY,) * 8 + (np.empty(0, dtype=np.int32), np.empty(0))


def analyse(n: int, rows, cols, mass: np.ndarray | None = None):
    """The elimination plan ``(perm, lptr, lidx, uptr, uidx, dpos, lpos, upos, upd, mv)``
    for Newton matrices with the structure of the Jacobian entries (rows, cols), the mass
    matrix's nonzeros and the diagonal; ``DENSE`` (empty arrays) where sparse elimination
    would not pay. ``dpos``, ``lpos``, ``upos``: where each entry the elimination reads
    (pivot k, its L and U lists) is among the Jacobian's entries, in the order (rows,
    cols) lists them (-1: not one, a fill-in or a mass term), so that the Newton matrices
    are formed from the Jacobian's values alone (``newton_matrix_values``). ``upd``
    (int32): each update's target in the packed factors, pivot by pivot, L's row by U's
    column (empty: ``factor`` searches the lists). ``mv``: the mass matrix's values
    packed as the factors are (empty: none given, M = I; the Newton matrices then read
    M itself, as a plan made without them does)."""
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
    mv = np.empty(0)
    if mass is not None and mass.size:      # (a dense n x n read at random per entry)
        ks = np.repeat(np.arange(n), np.diff(lptr))
        kr = np.repeat(np.arange(n), np.diff(uptr))
        mv = np.concatenate((mass[perm, perm], mass[perm[lidx], perm[ks]],
                             mass[perm[kr], perm[uidx]])).astype(np.float64)
    return (perm.astype(np.int64), lptr, lidx, uptr, uidx, dpos, lpos, upos,
            _updates(n, lptr, lidx, uptr, uidx), mv)


def _updates(n, lptr, lidx, uptr, uidx) -> np.ndarray:
    """Each update's target in the packed factors (``factor``): pivot k's rows i in L
    by its columns j in U, (i, j) at the diagonal, in L (column j) or in U (row i)."""
    nl = len(lidx)
    slot = np.full((n, n), -1, dtype=np.int64)
    slot[np.arange(n), np.arange(n)] = np.arange(n)
    for k in range(n):
        slot[lidx[lptr[k]:lptr[k + 1]], k] = n + np.arange(lptr[k], lptr[k + 1])
        slot[k, uidx[uptr[k]:uptr[k + 1]]] = n + nl + np.arange(uptr[k], uptr[k + 1])
    out = [slot[np.ix_(lidx[lptr[k]:lptr[k + 1]], uidx[uptr[k]:uptr[k + 1]])].ravel()
           for k in range(n)]
    upd = np.concatenate(out) if out else np.empty(0, dtype=np.int64)
    if upd.size and upd.min() < 0:          # (the fill is closed: never)
        raise AssertionError("sparse_lu: an update outside the filled structure")
    return upd.astype(np.int32)


@intrinsic
def _flat(typingctx, a):
    """A contiguous array's flat view (numba's reshape calls a helper of its run time
    that the FMU's Radau object does not have: ``bgc.export.radau``)."""
    if not isinstance(a, types.Array) or a.layout != "C":
        return None
    flat = types.Array(a.dtype, 1, "C")

    def codegen(context, builder, sig, args):
        src = context.make_array(sig.args[0])(context, builder, args[0])
        out = context.make_array(flat)(context, builder)
        size = context.get_constant(types.intp, 1)
        for extent in cgutils.unpack_tuple(builder, src.shape):
            size = builder.mul(size, extent)
        context.populate_array(out, data=src.data, shape=[size], strides=[src.itemsize],
                               itemsize=src.itemsize, meminfo=src.meminfo,
                               parent=src.parent)
        return impl_ret_borrowed(context, builder, flat, out._getvalue())
    return flat(a), codegen


@njit(cache=True)
def _packed(a):
    """The packed factors' array: ``a`` as a flat view (a dense n x n the integrator
    also factors with LAPACK, or a vector)."""
    return _flat(a)


@njit(cache=True)
def _entry(v, k):
    return v[k] if k >= 0 else 0.0


@njit(cache=True)
def newton_matrix_values(V, M, c, plan, a):
    """``newton_matrix`` from the Jacobian's values ``V`` (in the order of its pattern,
    the plan's ``dpos``, ``lpos``, ``upos``) instead of a dense J; M's values from the
    plan's ``mv`` where it has them."""
    perm, lptr, lidx, uptr, uidx, dpos, lpos, upos = plan[:8]
    mv = plan[9]
    v = _packed(a)
    n, nl = perm.shape[0], lidx.shape[0]
    if M.shape[0] != 0 and mv.shape[0] == n + nl + uidx.shape[0]:
        for e in range(n):
            v[e] = c * mv[e] - _entry(V, dpos[e])
        for q in range(nl):
            v[n + q] = c * mv[n + q] - _entry(V, lpos[q])
        for r in range(uidx.shape[0]):
            v[n + nl + r] = c * mv[n + nl + r] - _entry(V, upos[r])
        return
    for k in range(n):
        pk = perm[k]
        v[k] = (c if M.shape[0] == 0 else c * M[pk, pk]) - _entry(V, dpos[k])
        for q in range(lptr[k], lptr[k + 1]):
            v[n + q] = (0.0 if M.shape[0] == 0 else c * M[perm[lidx[q]], pk]) \
                - _entry(V, lpos[q])
        for r in range(uptr[k], uptr[k + 1]):
            v[n + nl + r] = (0.0 if M.shape[0] == 0 else c * M[pk, perm[uidx[r]]]) \
                - _entry(V, upos[r])


@njit(cache=True)
def newton_matrix(J, M, c, plan, a):
    """``c M - J`` (M empty: the identity) in the plan's order, packed into ``a`` (the
    diagonal, L's lists, U's lists: only the entries elimination reads)."""
    perm, lptr, lidx, uptr, uidx = plan[0], plan[1], plan[2], plan[3], plan[4]
    v = _packed(a)
    n, nl = perm.shape[0], lidx.shape[0]
    for k in range(n):
        pk = perm[k]
        v[k] = c - J[pk, pk] if M.shape[0] == 0 else c * M[pk, pk] - J[pk, pk]
        for q in range(lptr[k], lptr[k + 1]):
            pi = perm[lidx[q]]
            v[n + q] = -J[pi, pk] if M.shape[0] == 0 else c * M[pi, pk] - J[pi, pk]
        for r in range(uptr[k], uptr[k + 1]):
            pj = perm[uidx[r]]
            v[n + nl + r] = -J[pk, pj] if M.shape[0] == 0 else c * M[pk, pj] - J[pk, pj]


@njit(cache=True)
def _mag(v):
    """|re| + |im|: within sqrt(2) of |v|, without a square root per entry."""
    return abs(v.real) + abs(v.imag)


@njit(cache=True)
def _find(idx, lo, hi, key):
    """The position of ``key`` in the ascending ``idx[lo:hi]`` (bisection)."""
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if idx[mid] <= key:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def _target(plan, i, j):
    """The packed position of the ordered entry (i, j) (a plan without ``upd``)."""
    lptr, lidx, uptr, uidx = plan[1], plan[2], plan[3], plan[4]
    n, nl = lptr.shape[0] - 1, lidx.shape[0]
    if i == j:
        return i
    if i > j:
        return n + _find(lidx, lptr[j], lptr[j + 1], i)
    return n + nl + _find(uidx, uptr[i], uptr[i + 1], j)


@njit(cache=True)
def factor(a, plan):
    """LU-factor the packed matrix ``a`` (``newton_matrix``; overwritten by its factors:
    unit L's lists, U's diagonal and lists) along ``plan``. False on a zero pivot or an
    entry grown past ``GROWTH_LIMIT`` times the largest of ``a``."""
    lptr, lidx, uptr, uidx, upd = plan[1], plan[2], plan[3], plan[4], plan[8]
    v = _packed(a)
    n, nl = lptr.shape[0] - 1, lidx.shape[0]
    size = n + nl + uidx.shape[0]
    big = 0.0
    for e in range(size):
        big = max(big, _mag(v[e]))
    limit = GROWTH_LIMIT * big
    mapped = upd.shape[0] > 0
    base = 0                                # pivot k's first update in ``upd``
    for k in range(n):
        piv = v[k]
        if piv == 0 or not _mag(piv) <= limit:
            return False
        u0, u1 = uptr[k], uptr[k + 1]
        for q in range(lptr[k], lptr[k + 1]):
            lik = v[n + q] / piv
            v[n + q] = lik
            if lik != 0:
                at = base + (q - lptr[k]) * (u1 - u0) - u0
                for r in range(u0, u1):
                    t = upd[at + r] if mapped else _target(plan, lidx[q], uidx[r])
                    w = v[t] - lik * v[n + nl + r]
                    v[t] = w
                    if _mag(w) > limit:
                        return False
        base += (lptr[k + 1] - lptr[k]) * (u1 - u0)
    return True


@njit(cache=True)
def solve(lu, plan, b):
    """Solve A x = b with ``factor``'s packed factors of A's ordered matrix."""
    perm, lptr, lidx, uptr, uidx = plan[0], plan[1], plan[2], plan[3], plan[4]
    v = _packed(lu)
    n, nl = b.shape[0], lidx.shape[0]
    x = np.empty_like(b)
    for i in range(n):
        x[i] = b[perm[i]]
    for k in range(n):
        xk = x[k]
        if xk != 0:
            for q in range(lptr[k], lptr[k + 1]):
                x[lidx[q]] -= v[n + q] * xk
    for k in range(n - 1, -1, -1):
        s = x[k]
        for r in range(uptr[k], uptr[k + 1]):
            s -= v[n + nl + r] * x[uidx[r]]
        x[k] = s / v[k]
    out = np.empty_like(b)
    for i in range(n):
        out[perm[i]] = x[i]
    return out
