"""Symbolic sparse elimination: the order, fill and per-pivot lists of an LU factorization
on a known structure, the shared analysis of the two sparse LUs bgc runs.

- the constraint blocks of the generated kernels (``kernels``), whose structure
  ``A = -K B`` is known when the module is written: the SARIB's 98 x 98 block has 1509
  non-zeros and eliminates in 16 thousand multiply-adds where dense LU takes 309 thousand;
- Radau's Newton matrices (``bgc.solvers.sparse_lu``), on the Jacobian's structure.

Elimination runs on the diagonal of the ordered matrix (static pivoting); the numeric
factorizations check the growth of the entries and fall back to partial pivoting. A
constraint block's diagonal may be structurally zero (a body of negligible mass: its
twist rate's row holds only the multipliers), so its rows are first matched to its
columns (a transversal, Duff's augmenting paths), then ordered by plain minimum degree
of ``A + A^T`` (George & Liu's rule, ties to the lowest index): pure Python over
integers, so a generated module's bytes do not depend on any library's version.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# static pivoting's bound: an entry grown past this many times the matrix's largest (or a
# zero pivot) hands the factorization to partial pivoting (Golub & Van Loan 3.4.5: the
# backward error of elimination grows with its entries)
GROWTH_LIMIT = 1e4


class Plan(NamedTuple):
    """Eliminate the matrix ``A[rows][:, cols]`` on its diagonal: pivot k updates the
    ordered rows ``lidx[lptr[k]:lptr[k+1]]`` (below it, in L) in the columns
    ``uidx[uptr[k]:uptr[k+1]]`` (right of it, in U)."""
    rows: np.ndarray
    cols: np.ndarray
    lptr: np.ndarray
    lidx: np.ndarray
    uptr: np.ndarray
    uidx: np.ndarray

    @property
    def entries(self) -> int:
        """Entries of L and U, the diagonal included."""
        return len(self.rows) + len(self.lidx) + len(self.uidx)


def transversal(pattern: np.ndarray) -> np.ndarray | None:
    """Rows matched to the columns, ``match[j]`` the row of column j, so that
    ``pattern[match]`` has a structurally non-zero diagonal (augmenting paths, rows and
    columns taken in index order); None if the structure is singular."""
    n = pattern.shape[0]
    rows_of = [np.flatnonzero(pattern[:, j]).tolist() for j in range(n)]
    col_of = [-1] * n                   # row -> its column
    for j0 in range(n):
        seen, stack, parent = {j0}, [j0], {}
        found = -1
        while stack and found < 0:
            j = stack.pop()
            for i in rows_of[j]:
                if col_of[i] < 0:
                    found, parent[i] = i, j
                    break
                if col_of[i] not in seen:
                    seen.add(col_of[i])
                    parent[i] = j
                    stack.append(col_of[i])
        if found < 0:
            return None
        i = found
        while True:                     # flip the path back to j0
            j = parent[i]
            prev = next((r for r, c in enumerate(col_of) if c == j), -1)
            col_of[i] = j
            if j == j0:
                break
            i = prev
    match = np.empty(n, dtype=np.int64)
    for i, j in enumerate(col_of):
        match[j] = i
    return match


def minimum_degree(pattern: np.ndarray) -> np.ndarray:
    """An elimination order of the symmetric structure ``pattern | pattern^T``: each time
    the node of fewest neighbours (ties: lowest index), its neighbours made a clique."""
    n = pattern.shape[0]
    sym = pattern | pattern.T
    adj = [set(np.flatnonzero(sym[i]).tolist()) - {i} for i in range(n)]
    left = set(range(n))
    order = []
    while left:
        v = min(left, key=lambda i: (len(adj[i]), i))
        order.append(v)
        left.discard(v)
        near = adj[v]
        for u in near:
            adj[u] |= near
            adj[u].discard(u)
            adj[u].discard(v)
    return np.asarray(order, dtype=np.int64)


def fill(pattern: np.ndarray) -> np.ndarray | None:
    """The filled structure of elimination in the given order (boolean, n x n); None if a
    pivot is structurally zero (no static pivot there)."""
    f = pattern.copy()
    n = f.shape[0]
    for k in range(n):
        if not f[k, k]:
            return None
        rows = k + 1 + np.flatnonzero(f[k + 1:, k])
        cols = k + 1 + np.flatnonzero(f[k, k + 1:])
        if rows.size and cols.size:
            f[np.ix_(rows, cols)] = True
    return f


def work(filled: np.ndarray) -> int:
    """Multiply-adds of elimination on a filled structure."""
    n = filled.shape[0]
    return int(sum(np.count_nonzero(filled[k + 1:, k]) * np.count_nonzero(filled[k, k + 1:])
                   for k in range(n)))


def dense_work(n: int) -> int:
    """Multiply-adds of dense LU of order n."""
    return (n - 1) * n * (2 * n - 1) // 6


def lists(filled: np.ndarray) -> tuple[np.ndarray, ...]:
    """``(lptr, lidx, uptr, uidx)``, the per-pivot lists of a filled structure."""
    n = filled.shape[0]
    lptr, lidx, uptr, uidx = [0], [], [0], []
    for k in range(n):
        lidx += (k + 1 + np.flatnonzero(filled[k + 1:, k])).tolist()
        uidx += (k + 1 + np.flatnonzero(filled[k, k + 1:])).tolist()
        lptr.append(len(lidx))
        uptr.append(len(uidx))
    return tuple(np.asarray(v, dtype=np.int64) for v in (lptr, lidx, uptr, uidx))


# a matching takes entries of at least this share of their row's largest at the start,
# the first of these that matches every column (0: any structural non-zero)
MATCH_LEVELS = (1e-2, 1e-6, 0.0)


def analyse(pattern: np.ndarray, max_work: float, start: np.ndarray | None = None,
            diagonal: bool = False) -> Plan | None:
    """The elimination plan of a structure: its rows matched to its columns, then in
    minimum-degree order; None where the structure is singular or elimination would take
    more than ``max_work`` times dense LU's multiply-adds. ``start``: the matrix's values
    at the model's start, so that the pivots are entries that are not zero there (a term
    in the sine of an angle that starts at 0 is structurally non-zero). ``diagonal``: the
    pivots on the diagonal, each row matched to its own column (a symmetric positive
    definite matrix, as a regularized constraint block: stable, as Cholesky is)."""
    pattern = np.asarray(pattern, dtype=bool)
    if diagonal:
        pattern = pattern | np.eye(pattern.shape[0], dtype=bool)
        start = None
    match = np.arange(pattern.shape[0], dtype=np.int64) if diagonal else None
    for level in (() if diagonal else MATCH_LEVELS if start is not None else (0.0,)):
        allowed = pattern
        if level:
            mag = np.abs(start)
            allowed = pattern & (mag > level * mag.max(axis=1, keepdims=True))
        match = transversal(allowed)
        if match is not None:
            break
    if match is None:
        return None
    matched = pattern[match]
    perm = minimum_degree(matched)
    filled = fill(matched[np.ix_(perm, perm)])
    if filled is None or work(filled) > max_work * dense_work(pattern.shape[0]):
        return None
    return Plan(match[perm], perm, *lists(filled))
