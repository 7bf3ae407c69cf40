"""The analytic Jacobian by the chain rule through the sorted assignments.

Forward mode over the assignment list: for ``v = expr(w1, w2, ...)`` the sensitivity of
``v`` to state ``x_j`` is ``sum_k d expr/d w_k * dw_k/dx_j``. Only non-zero entries are
carried (the sparsity the graph gives), trivial ones (a number, a symbol) are inlined,
and nothing is ever substituted into one large expression.
"""

from __future__ import annotations

import sympy as sp


def chain_rule(assignments, states):
    """Return (extra assignments, {(i, j): expr}) for J[i, j] = d(dx_i/dt)/dx_j."""
    index = {st.sym: j for j, st in enumerate(states)}
    sens: dict[sp.Symbol, dict[int, sp.Expr]] = {x: {j: sp.S.One} for x, j in index.items()}
    extra = []
    for v, e in assignments:
        acc: dict[int, sp.Expr] = {}
        for s in sorted((s for s in e.free_symbols if s in sens), key=lambda s: s.name):
            partial = sp.diff(e, s)
            if partial == 0:
                continue
            for j, ds in sens[s].items():
                acc[j] = acc.get(j, sp.S.Zero) + partial * ds
        row = {}
        for j in sorted(acc):
            d = acc[j]
            if d == 0:
                continue
            if d.is_Number or d.is_Symbol or (d.could_extract_minus_sign()
                                               and (-d).is_Symbol):
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
