"""The analytic Jacobian as a compressed forward-mode tape through the sorted assignments.

Every assigned variable that depends on the states gets a row of sensitivities; the
columns are compressed by a colouring of the Jacobian's sparsity pattern (Curtis-Powell-
Reid: columns that share no row share a colour), so a row holds one number per colour.
For ``v = expr(w1, w2, ...)`` the generated code evaluates each partial ``d expr/d w_k``
at run time (by reverse-mode differentiation of ``expr``'s tree in the emitted code,
``bgc.codegen.kernels``: no symbolic derivative is formed) into a slot of ``pv``, and a short loop
accumulates ``row(v) += pv[slot] * row(w_k)``. The emitted code grows with the number of
edges in the graph, not with edges x columns, and nothing is ever substituted into one
large expression. The result is exact (no differencing).

Through a numeric linear block ``A u = b`` the rows of ``u`` are ``A^-1 R`` with
``R = d(b - A u)/dx`` at fixed ``u``: the loop's own equations differentiated through
its chain with the tears held fixed, then one LU solve with the block's matrix. Those
rows are dense wherever the block couples the whole model (a closed-loop mechanism's
multipliers): the Jacobian then has n^2 entries. A block that is regular by construction
(``LinearBlock.regularize``: method augmented) is instead kept **open**: its unknowns
are extra columns (the rows after it depend on them, ``Fu``) and its equations extra
rows ``[R, -A]``, a sparse Jacobian of the DAE ``x' = f(x, u), 0 = b(x) - A(x) u``
whose Schur complement ``Fx + Fu A^-1 R`` is the model's. Radau factors its Newton
matrices on that augmented structure (``radau5``); ``jac`` forms the complement.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import sympy as sp

from bgc.codegen.equations import LinearBlock


@dataclass
class Block:
    """Rows ``start .. start+n`` hold R of linear block ``index``; the next n rows, u."""
    index: int
    start: int
    n: int


@dataclass
class JacobianTape:
    """The compressed Jacobian: ``J[i, j] = d[row_of_dx_i, colour[j]]`` on the pattern."""
    colours: list[int]                       # per state column
    n_colours: int
    n_rows: int
    ptr: list[int]                           # entries of row r: ptr[r] .. ptr[r+1]
    src: list[int]                           # >= 0: a row; < 0: state colour -src-1
    # per differentiated expression e: [(m, w)], pv[m] = d e / d w at run time is the
    # partial of entry m
    partials: list[tuple[sp.Expr, list[tuple[int, sp.Symbol]]]]
    blocks: list[Block]
    pattern: list[tuple[int, int, int]]      # (i, j, row of dx_i)
    # open blocks (index, first row of their R, size, their first column and row in the
    # augmented Jacobian: n + offset); the extra columns and rows they add
    opened: list[tuple[int, int, int, int]] = None
    n_aug: int = 0

    @property
    def segments(self) -> list:
        """``("tape", start, stop)`` and ``("solve", Block)`` steps in evaluation order."""
        out, at = [], 0
        for blk in self.blocks:
            out.append(("tape", at, blk.start + blk.n))
            out.append(("solve", blk))
            at = blk.start + 2 * blk.n
        out.append(("tape", at, self.n_rows))
        return [s for s in out if s[0] == "solve" or s[2] > s[1]]


class _Recorder:
    def __init__(self, states):
        self.cols: dict[sp.Symbol, frozenset] = {st.sym: frozenset([j])
                                                 for j, st in enumerate(states)}
        self.state_index = {st.sym: j for j, st in enumerate(states)}
        self.rows: dict[sp.Symbol, int] = {}
        # per row: (e, [(row or -1-state, w)]), the row of d e, through e's symbols w
        self.entries: list[tuple[sp.Expr | None, list[tuple[int, sp.Symbol]]]] = []
        self.row_cols: list[frozenset] = []
        self.blocks: list[Block] = []

    def new_row(self, edges, cols) -> int:
        self.entries.append(edges)
        self.row_cols.append(cols)
        return len(self.entries) - 1

    def record(self, e, rows: dict) -> tuple[tuple, frozenset] | None:
        """The edges of ``e`` to symbols with sensitivities (states or rows in ``rows``)."""
        edges, cols = [], frozenset()
        for s in sorted(e.free_symbols, key=lambda s: s.name):
            if s in rows or s in self.state_index:
                edges.append((rows[s] if s in rows else -1 - self.state_index[s], s))
                cols |= self.cols[s]
        return ((e, edges), cols) if edges else None

    def assign(self, v, e, rows: dict):
        got = self.record(e, rows)
        if got:
            rows[v] = self.new_row(got[0], got[1])
            self.cols[v] = got[1]


def tape(assignments, states, a_patterns: dict | None = None) -> JacobianTape:
    """Record the Jacobian tape of ``assignments`` (in causal order) w.r.t. ``states``.
    A regularized block is kept open (module docstring); ``a_patterns``: each such
    block's structure of A (index -> boolean matrix), for the pattern of its rows."""
    rec = _Recorder(states)
    n = len(states)
    opened, n_aug = [], 0
    for item in assignments:
        if isinstance(item, LinearBlock):
            fixed = dict(rec.rows)          # the tears have no rows yet: held fixed
            for v, e in item.chain:         # (their columns are reset when assigned after)
                rec.assign(v, e, fixed)
            got = [rec.record(e, fixed) for e in item.tear_eqs]
            if item.regularize is not None:     # open: u are columns n + ...
                start = len(rec.entries)
                for g in got:
                    rec.new_row(g[0] if g else (None, []), g[1] if g else frozenset())
                for k, u in enumerate(item.unknowns):
                    rec.state_index[u] = n + n_aug + k
                    rec.cols[u] = frozenset([n + n_aug + k])
                opened.append((item.index, start, len(item.unknowns), n + n_aug))
                n_aug += len(item.unknowns)
                continue
            if not any(got):
                continue
            cols = frozenset().union(*(g[1] for g in got if g))
            start = len(rec.entries)
            for g in got:
                rec.new_row(g[0] if g else (None, []), g[1] if g else frozenset())
            for u in item.unknowns:
                rec.rows[u] = rec.new_row((None, []), cols)
                rec.cols[u] = cols
            rec.blocks.append(Block(item.index, start, len(item.unknowns)))
            continue
        rec.assign(item[0], item[1], rec.rows)
    # the pattern: rows of dx_i, then the open blocks' rows (R from the tape; A's
    # entries, row -1, from the block's own matrix); then colour the columns
    pattern = []
    for i, st in enumerate(states):
        if st.dsym in rec.rows:
            r = rec.rows[st.dsym]
            pattern += [(i, j, r) for j in sorted(rec.row_cols[r])]
    for index, start, m, at in opened:
        a = a_patterns[index]
        for i in range(m):
            cols = set(rec.row_cols[start + i]) | {at + k for k in np.flatnonzero(a[i])}
            cols.add(at + i)
            pattern += [(at + i, j, start + i if j < at or j >= at + m else -1)
                        for j in sorted(cols)]
    colours, n_colours = _colour(n + n_aug, [e for e in pattern if e[2] >= 0])
    # flatten the tape: each edge its own run-time partial
    ptr, src, partials = [0], [], []
    for e, edges in rec.entries:
        if edges:
            partials.append((e, [(len(src) + k, w) for k, (_, w) in enumerate(edges)]))
        src += [r if r >= 0 else -1 - colours[-1 - r] for r, _ in edges]
        ptr.append(len(src))
    return JacobianTape(colours, n_colours, len(rec.entries), ptr, src, partials,
                        rec.blocks, pattern, opened, n_aug)


def _colour(n: int, pattern) -> tuple[list[int], int]:
    """Greedy distance-2 colouring: columns sharing a row of the pattern get different
    colours (largest columns first, which keeps the count near the densest row)."""
    rows_of: dict[int, set] = {}
    for i, j, _ in pattern:
        rows_of.setdefault(j, set()).add(i)
    colour = [0] * n
    in_row: dict[int, set] = {}      # row -> the colours of its columns coloured so far
    for j in sorted(range(n), key=lambda j: (-len(rows_of.get(j, ())), j)):
        rows = rows_of.get(j, ())
        taken = set().union(*(in_row.get(i, ()) for i in rows))
        c = 0
        while c in taken:
            c += 1
        colour[j] = c
        for i in rows:
            in_row.setdefault(i, set()).add(c)
    return colour, max(colour, default=0) + 1
