"""The rank monitor of a constrained run (methods lagrange, zcp) in compiled code, checked
by native Radau after every accepted step without leaving its loop.

It is ``consistent.RankMonitor`` (which scipy's solvers call as a Python event) on the
same quantities: the constraint rows acting on the states that are not poses, K =
d(dg/dt)/dv, from the module's constraints kernel (dg/dt is linear in v: one forward
difference per column is exact to round-off), scaled by the row and column scales of
the start (kept fixed, so that a row vanishing at a dead point still shows). The loop
watches the determinant of an r x r minor of K (r: the rank at the start), normalised
to 1 where the minor was picked. Where it falls through zero, the constraints there are
either as well conditioned as at the start (within ``consistent.LOST_RANK``: only the
minor went singular, as every turn of a rotating mechanism), and another minor is
picked on the spot, or they may have lost rank: the loop returns from the start of
that step (status ``native.MINOR``) and Python locates the crossing by re-integration,
as it does its other events (``native_solver``), to name the singular configuration.
Located on the step's collocation polynomial instead, the isosceles slider-crank's dead
point (rtol 1e-6) was not told from a minor's zero: the polynomial's state there was not
singular enough (its conditioning well above 1e-6 of the start's), and the run went
through the dead point.

Rows and columns of a minor are picked greedily, as pivoted QR does (the row, then the
column, with the largest norm left after projecting out those picked); the conditioning
is the r-th singular value over the largest (one-sided Jacobi: accurate to round-off
where the Gram matrix would square it away below 1e-8).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from bgc.solvers.native import call_kernel, inner


class Monitor(NamedTuple):
    """What the loop needs of a rank monitor (``con`` = 0: none). ``con``: the address of
    the module's constraints kernel f(t, x, p, w, out) (``n_out`` values: g, then dg/dt;
    ``w``: its workspace of ``n_work``), ``rates``: where each measured row sits in its output,
    ``cols``: the states the rows act on, ``row_scale``, ``col_scale``: the start's
    scales, ``rank``: r, ``floor``: the conditioning below which the rank may be lost,
    ``picks``: the minor's rows and columns (2 x r, into ``rates`` and ``cols``; the loop
    writes its own picks there), ``counts``: [minors picked again in the loop]."""
    con: int
    n_work: int
    n_out: int
    rates: np.ndarray
    cols: np.ndarray
    row_scale: np.ndarray
    col_scale: np.ndarray
    rank: int
    floor: float
    picks: np.ndarray
    counts: np.ndarray


def none() -> Monitor:
    """No monitor (the types the loop is compiled for)."""
    ints, floats = np.zeros(0, dtype=np.int64), np.zeros(0)
    return Monitor(0, 0, 0, ints, ints, floats, floats, 0, 0.0, np.zeros((2, 0), dtype=np.int64),
                   np.zeros(1, dtype=np.int64))


class Scratch(NamedTuple):
    """The monitor's work arrays, allocated once per loop call."""
    w: np.ndarray          # the kernel's workspace
    c0: np.ndarray         # the kernel's output at x
    c1: np.ndarray         # ... at x moved along one column
    xw: np.ndarray         # x moved
    K: np.ndarray          # the scaled rows (rows x cols)
    A: np.ndarray          # the minor (r x r), eliminated in place


@inner
def scratch(mon, n):
    m = mon.rates.shape[0]
    k = mon.cols.shape[0]
    return Scratch(np.empty(max(mon.n_work, 1)), np.empty(mon.n_out), np.empty(mon.n_out),
                   np.empty(n), np.zeros((m, k)), np.empty((mon.rank, mon.rank)))


@inner
def fill(mon, s, t, x, p, only_picked):
    """K (scaled) at (t, x) into ``s.K``: every column, or the picked ones only."""
    for i in range(x.shape[0]):
        s.xw[i] = x[i]
    call_kernel(mon.con, t, s.xw, p, s.w, s.c0)
    r = mon.rank
    ncols = r if only_picked else mon.cols.shape[0]
    for q in range(ncols):
        jc = mon.picks[1, q] if only_picked else q
        j = mon.cols[jc]
        h = 1e-7 * max(1.0, abs(x[j]))
        s.xw[j] = x[j] + h
        call_kernel(mon.con, t, s.xw, p, s.w, s.c1)
        s.xw[j] = x[j]
        for i in range(mon.rates.shape[0]):
            k = mon.rates[i]
            s.K[i, jc] = (s.c1[k] - s.c0[k]) / h * mon.row_scale[i] * mon.col_scale[jc]


@inner
def determinant(mon, s):
    """The determinant of the picked minor of ``s.K`` (Gaussian elimination with partial
    pivoting, in ``s.A``)."""
    r = mon.rank
    A = s.A
    for a in range(r):
        for b in range(r):
            A[a, b] = s.K[mon.picks[0, a], mon.picks[1, b]]
    det = 1.0
    for k in range(r):
        piv, big = k, abs(A[k, k])
        for i in range(k + 1, r):
            if abs(A[i, k]) > big:
                piv, big = i, abs(A[i, k])
        if big == 0.0:
            return 0.0
        if piv != k:
            det = -det
            for j in range(k, r):
                A[k, j], A[piv, j] = A[piv, j], A[k, j]
        det *= A[k, k]
        for i in range(k + 1, r):
            f = A[i, k] / A[k, k]
            if f != 0.0:
                for j in range(k + 1, r):
                    A[i, j] -= f * A[k, j]
    return det


@inner
def minor(mon, s, t, x, p):
    """The picked minor's determinant at (t, x), unnormalised."""
    fill(mon, s, t, x, p, True)
    return determinant(mon, s)


@inner
def _oriented(K, transposed):
    """A copy of K, or of its transpose."""
    m, k = K.shape
    if not transposed:
        V = np.empty((m, k))
        for i in range(m):
            for j in range(k):
                V[i, j] = K[i, j]
        return V
    V = np.empty((k, m))
    for i in range(m):
        for j in range(k):
            V[j, i] = K[i, j]
    return V


@inner
def _greedy(V, r, out_row, picks):
    """Pick r columns of V greedily (the largest norm left after projecting out those
    picked, as pivoted QR), into picks[out_row] sorted; V is overwritten."""
    a, b = V.shape
    taken = np.zeros(b, dtype=np.bool_)
    for k in range(r):
        best, jb = -1.0, 0
        for j in range(b):
            if not taken[j]:
                s = 0.0
                for i in range(a):
                    s += V[i, j] * V[i, j]
                if s > best:
                    best, jb = s, j
        taken[jb] = True
        norm = np.sqrt(best)
        if norm > 0.0:
            for i in range(a):
                V[i, jb] /= norm
        for j in range(b):
            if not taken[j]:
                d = 0.0
                for i in range(a):
                    d += V[i, jb] * V[i, j]
                for i in range(a):
                    V[i, j] -= d * V[i, jb]
    k = 0
    for j in range(b):
        if taken[j]:
            picks[out_row, k] = j
            k += 1


@inner
def repick(mon, s):
    """Pick the minor anew on ``s.K`` (filled in full): rows, then columns among them."""
    m, k = s.K.shape
    r = mon.rank
    _greedy(_oriented(s.K, True), r, 0, mon.picks)
    V = np.empty((r, k))
    for a in range(r):
        for j in range(k):
            V[a, j] = s.K[mon.picks[0, a], j]
    _greedy(V, r, 1, mon.picks)


@inner
def conditioning(K, rank):
    """The rank-th singular value of K over its largest (one-sided Jacobi on the shorter
    side; 1.0 where rank < 1, 0.0 where K has fewer)."""
    if rank < 1:
        return 1.0
    V = _oriented(K, K.shape[1] > K.shape[0])
    a, b = V.shape
    if rank > b:
        return 0.0
    for _ in range(60):
        rotated = False
        for i in range(b - 1):
            for j in range(i + 1, b):
                al = be = ga = 0.0
                for k in range(a):
                    al += V[k, i] * V[k, i]
                    be += V[k, j] * V[k, j]
                    ga += V[k, i] * V[k, j]
                if abs(ga) <= 1e-15 * np.sqrt(al * be) or ga == 0.0:
                    continue
                rotated = True
                zeta = (be - al) / (2.0 * ga)
                tn = (1.0 if zeta >= 0 else -1.0) / (abs(zeta) + np.sqrt(1.0 + zeta * zeta))
                c = 1.0 / np.sqrt(1.0 + tn * tn)
                sn = c * tn
                for k in range(a):
                    vi, vj = V[k, i], V[k, j]
                    V[k, i] = c * vi - sn * vj
                    V[k, j] = sn * vi + c * vj
        if not rotated:
            break
    sv = np.empty(b)
    for j in range(b):
        q = 0.0
        for k in range(a):
            q += V[k, j] * V[k, j]
        sv[j] = np.sqrt(q)
    for j in range(1, b):           # descending (insertion: numba's sort costs compile time)
        v, i = sv[j], j
        while i > 0 and sv[i - 1] < v:
            sv[i] = sv[i - 1]
            i -= 1
        sv[i] = v
    return sv[rank - 1] / sv[0] if sv[0] > 0.0 else 0.0


@inner
def start(mon, s, t, x, p):
    """Pick a minor at (t, x): its determinant there (the normalisation; 0.0: none to
    watch)."""
    fill(mon, s, t, x, p, False)
    repick(mon, s)
    d = determinant(mon, s)
    return d if np.isfinite(d) else 0.0


@inner
def settle(mon, s, t, x, p):
    """The minor changed sign by (t, x): if the constraints there are as well conditioned
    as ``mon.floor`` asks, pick another (its determinant, the new normalisation), else
    0.0 (the crossing may be a singular configuration: to be located)."""
    fill(mon, s, t, x, p, False)
    if not conditioning(s.K, mon.rank) > mon.floor:
        return 0.0
    repick(mon, s)
    mon.counts[0] += 1
    d = determinant(mon, s)
    return d if np.isfinite(d) else 0.0
