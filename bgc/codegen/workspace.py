"""Stage **kernels**: the workspace of a generated module's programs.

Values cross the kernels' functions through one array of doubles ``w``: a slot per
assigned symbol (a linear block's unknowns side by side), then a region per linear block
(``Block``: its matrix, right-hand sides, factors and the rest of its solve), then each
table's value and slope at the current t. ``Layout`` places them, and chooses a block's
solve: sparse LU on an ``elimination.Plan`` from ``SPARSE_MIN`` unknowns where it pays,
packed for a regularized constraint block on a symmetric plan (its lower triangle and its
fill only, factored as L D L^T: ``linalg.ldl_ir``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp
from scipy import sparse

from bgc.codegen import elimination
from bgc.codegen.equations import LinearBlock
from bgc.codegen.start import block_matrices

# a block is solved on its structure from this size, where elimination in the plan's
# order takes at most this share of dense LU's multiply-adds
SPARSE_MIN, SPARSE_WORK = 24, 0.5


@dataclass
class Block:
    """Where linear block ``index`` lives in the workspace: A (n x n, row-major), b (n),
    u (n, the unknowns' slots), the rank's slot (-1: full rank, LU) and, for a block
    ``A = -K B``, K (n x d) and B (d x n), only their non-zeros written (``k_at``, ``b_at``:
    their positions); ``plan``: sparse LU's (None: dense)."""
    index: int
    n: int
    a: int
    b: int
    u: int
    rank: int = -1
    d: int = 0
    k: int = 0
    kb: int = 0
    lu: int = 0         # room for its LU factors (and a column, sparse)
    reg: int = -1       # regularized (``equations.Regularized``): eps's slot (-1: none)
    reg_rows: tuple = ()
    columns: int = 1    # right-hand sides (b: n x columns, row-major)
    # packed (a regularized constraint block on a symmetric plan, ``symmetric``): K, B
    # and A hold only their entries, K's and B's in their lists' order, A's lower triangle
    # in the factors' order (``a_slot``: an entry and its mirror -> its slot: the diagonal
    # first, then L's lists), and so do its factors: a few hundred kB where n x n regions
    # spread over megabytes that each rhs touched at random and allocated (IFToMM A02,
    # N = 40: 2.9 MB for A, 4.7 MB for K, 2.9 MB for the factors)
    packed: bool = False
    a_slot: dict | None = None
    ls: int = 0         # rank < n: room for the least-squares solve (``lstsq_work``)
    k_at: tuple = ()
    b_at: tuple = ()
    a_at: tuple = ()    # a block that stores A itself: its entries' positions
    plan: elimination.Plan | None = None

    def touched(self) -> set:
        """The entries (row, column) of A that sparse LU reads: A's and its fill's."""
        pl = self.plan
        out = set(zip(*np.nonzero(self.pattern())))
        if pl is not None:
            for k in range(self.n):
                out.add((pl.rows[k], pl.cols[k]))
                out |= {(pl.rows[i], pl.cols[k]) for i in pl.lidx[pl.lptr[k]:pl.lptr[k + 1]]}
                out |= {(pl.rows[k], pl.cols[j]) for j in pl.uidx[pl.uptr[k]:pl.uptr[k + 1]]}
        return {(int(r), int(c)) for r, c in out}

    def symmetric(self) -> bool:
        """Whether the plan eliminates a symmetric structure symmetrically (the rows'
        order the columns', L's lists U's): L D L^T then holds the factors."""
        pl = self.plan
        return (pl is not None and np.array_equal(pl.rows, pl.cols)
                and np.array_equal(pl.lptr, pl.uptr) and np.array_equal(pl.lidx, pl.uidx))

    def lower_slots(self) -> dict:
        """A packed block's slots: (row, column) -> its place in the lower triangle of
        the ordered matrix, the diagonal first (pivot k at k), then L's lists (n + q), an
        entry above the diagonal at its mirror's."""
        pl, n = self.plan, self.n
        out = {(int(pl.rows[k]), int(pl.rows[k])): k for k in range(n)}
        for k in range(n):
            for q in range(pl.lptr[k], pl.lptr[k + 1]):
                i, j = int(pl.rows[pl.lidx[q]]), int(pl.rows[k])
                out[(i, j)] = out[(j, i)] = n + q
        return out

    def pattern(self) -> np.ndarray:
        """A's structure: K B's, or the entries the block stores."""
        if not self.d:
            a = np.zeros((self.n, self.n), dtype=bool)
            a[tuple(np.array(self.a_at, dtype=np.int64).reshape(-1, 2).T)] = True
            return a
        return product_pattern(self.n, self.d, self.k_at, self.b_at)


def product_pattern(n: int, d: int, k_at, b_at) -> np.ndarray:
    """The structure (n x n, bool) of K B from the places ``(i, j, ...)`` of K's (n x d)
    and B's (d x n) non-zeros: a sparse product (exact integer counts; a dense one of
    A02's 40 windows took 0.13 s)."""
    def ones(at, shape):
        ij = np.array([(i, j) for i, j, *_ in at], dtype=np.int64).reshape(-1, 2)
        return sparse.csr_matrix((np.ones(len(ij), dtype=np.int64), (ij[:, 0], ij[:, 1])),
                                 shape=shape)
    out = np.zeros((n, n), dtype=bool)
    coo = (ones(k_at, (n, d)) @ ones(b_at, (d, n))).tocoo()
    out[coo.row, coo.col] = True
    return out


def factor_pattern(n: int, d: int, K, B) -> np.ndarray:
    """The structure of ``A = -K B`` (n x n) from the non-zeros of K (n x d) and B (d x
    n), as ``(i, j, ...)`` triples, with its diagonal."""
    return product_pattern(n, d, K, B) | np.eye(n, dtype=bool)


def lstsq_work(n: int, m: int) -> int:
    """Doubles of workspace the least-squares solve (``linalg.lstsq_ir``) needs: A^T, U',
    V'^T, s, W, dgesdd's work for jobz 'A' (LAPACK asks 3 n^2 + max(n, 4 n^2 + 4 n) at
    most; 8 n to spare) and its 8n int32 iwork."""
    return 3 * n * n + n + n * m + (7 * n * n + 12 * n) + 4 * n


class Layout:
    """Workspace slots: one per assigned symbol (a block's unknowns side by side), then a
    region per linear block, then each table's value and slope at the current t."""

    def __init__(self, system, columns: int):
        """``columns``: the most right-hand sides a block is solved for at once (the
        Jacobian's colours)."""
        self.slot: dict[sp.Symbol, int] = {}
        self.blocks: dict[int, Block] = {}
        self.size = 0
        for item in system.assignments:
            if isinstance(item, LinearBlock):
                for u in item.unknowns:
                    self._take(u)
                for v, _ in item.pre + item.chain:
                    self._take(v)
            else:
                self._take(item[0])
        start = None
        for item in system.assignments:
            if isinstance(item, LinearBlock):
                start = self._block(system, item, columns, start)
        self.tables = {tb.index: (self.region(1), self.region(1))
                       for tb in system.tables}

    def _block(self, system, item: LinearBlock, columns: int, start):
        """Block ``item``'s regions and its solve's plan (``start``: the blocks' values
        at the model's start, computed once when a plan first needs them)."""
        n = len(item.unknowns) // item.columns
        blk = Block(item.index, n, -1, self.region(n * item.columns),
                    self.slot[item.unknowns[0]], columns=item.columns)
        if item.rank is not None:
            blk.rank = self.region(1)
        if item.regularize is not None:
            blk.reg = self.region(len(item.regularize.rows))
            blk.reg_rows = item.regularize.rows
        if item.factors is not None:
            blk.d = item.factors[0]
            blk.k_at = tuple((i, j) for i, j, _ in item.factors[1])
            blk.b_at = tuple((i, j) for i, j, _ in item.factors[2])
        else:
            blk.a_at = tuple((i, j) for i, j, _ in item.A)
        if n >= SPARSE_MIN and item.regularize is not None:   # pivots: its diagonal
            blk.plan = elimination.analyse(blk.pattern(), SPARSE_WORK, diagonal=True)
        elif n >= SPARSE_MIN:
            start = start if start is not None else block_matrices(system)
            blk.plan = elimination.analyse(blk.pattern(), SPARSE_WORK,
                                           start.get(item.index))
        blk.packed = bool(item.regularize is not None and item.factors is not None
                          and blk.symmetric())
        if blk.packed:
            blk.a_slot = blk.lower_slots()
            blk.a = self.region(n + len(blk.plan.lidx))
            blk.k, blk.kb = self.region(len(blk.k_at)), self.region(len(blk.b_at))
            blk.lu = self.region(n + len(blk.plan.lidx) + 2 * n)   # + a column, a row
        else:
            blk.a = self.region(n * n)
            if item.factors is not None:
                blk.k, blk.kb = (self.region(n * blk.d),
                                 self.region(blk.d * n))
            blk.lu = self.region(n * n + (n if blk.plan is not None else 0))
        if item.rank is not None:
            blk.ls = self.region(lstsq_work(n, columns))
        self.blocks[item.index] = blk
        return start

    def _take(self, v):
        if v not in self.slot:
            self.slot[v] = self.size
            self.size += 1

    def region(self, n: int) -> int:
        """``n`` consecutive slots at the end; their first."""
        self.size += n
        return self.size - n
