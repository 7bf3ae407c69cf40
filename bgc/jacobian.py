"""The analytic Jacobian by the chain rule through the sorted assignments.

Forward mode over the assignment list: for ``v = expr(w1, w2, ...)`` the sensitivity of
``v`` to state ``x_j`` is ``sum_k d expr/d w_k * dw_k/dx_j``. Only non-zero entries are
carried (the sparsity the graph gives), trivial ones (a number, a symbol) are inlined,
and nothing is ever substituted into one large expression. Through a numeric linear
block ``A u = b`` the sensitivities are ``du/dx_j = A^-1 (db/dx_j - dA/dx_j u)``, solved
with the block's own matrix in the generated code.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from .equations import LinearBlock


@dataclass(frozen=True)
class BlockSensitivity:
    """``D = A^-1 R`` for linear block ``index``: column c of R is d(b - A u)/dx_cols[c]."""
    index: int
    unknowns: tuple[sp.Symbol, ...]
    cols: tuple[int, ...]
    R: tuple[tuple[int, int, sp.Expr], ...]

    @property
    def free_symbols(self) -> set:
        out = set(self.unknowns)
        for _, _, e in self.R:
            out |= e.free_symbols
        return out

    @property
    def defines(self) -> list[sp.Symbol]:
        return [entry(self.index, i, c) for i in range(len(self.unknowns))
                for c in range(len(self.cols))]


def entry(index: int, i: int, c: int) -> sp.Symbol:
    """The generated-code name of D[i, c] of block ``index`` (printed verbatim)."""
    return sp.Symbol(f"_D{index}[{i}, {c}]", real=True)


def _trivial(d) -> bool:
    return d.is_Number or d.is_Symbol or (d.could_extract_minus_sign() and (-d).is_Symbol)


def chain_rule(assignments, states):
    """Return (extra items, {(i, j): expr}) for J[i, j] = d(dx_i/dt)/dx_j."""
    index = {st.sym: j for j, st in enumerate(states)}
    sens: dict[sp.Symbol, dict[int, sp.Expr]] = {x: {j: sp.S.One} for x, j in index.items()}
    extra = []

    def directional(e) -> dict[int, sp.Expr]:
        acc: dict[int, sp.Expr] = {}
        for s in sorted((s for s in e.free_symbols if s in sens), key=lambda s: s.name):
            partial = sp.diff(e, s)
            if partial == 0:
                continue
            for j, ds in sens[s].items():
                acc[j] = acc.get(j, sp.S.Zero) + partial * ds
        return {j: d for j, d in sorted(acc.items()) if d != 0}

    for item in assignments:
        if isinstance(item, LinearBlock):
            u = item.unknowns
            cols: dict[int, dict[int, sp.Expr]] = {}
            for i, bi in enumerate(item.b):
                for j, d in directional(bi).items():
                    cols.setdefault(j, {})[i] = cols.get(j, {}).get(i, 0) + d
            for i, k, a in item.A:
                for j, d in directional(a).items():
                    cols.setdefault(j, {})[i] = cols.get(j, {}).get(i, 0) - d * u[k]
            order = sorted(cols)
            R = tuple((i, c, cols[j][i]) for c, j in enumerate(order) for i in sorted(cols[j])
                      if cols[j][i] != 0)
            if not R:
                continue
            extra.append(BlockSensitivity(item.index, u, tuple(order), R))
            for i, v in enumerate(u):
                sens[v] = {j: entry(item.index, i, c) for c, j in enumerate(order)}
            continue
        v, e = item
        row = {}
        for j, d in directional(e).items():
            if _trivial(d):
                row[j] = d
            else:
                sym = sp.Symbol(f"J_{v.name}__{j}", real=True)
                extra.append((sym, d))
                row[j] = sym
        if row:
            sens[v] = row
    entries = {}
    for i, st in enumerate(states):
        for j, d in sens.get(st.dsym, {}).items():
            entries[(i, j)] = d
    return extra, entries
