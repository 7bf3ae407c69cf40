"""Symbolic forward-mode differentiation through sorted assignments.

Used where a few seeds meet a short chain: a numeric loop block's matrix, as the loop's
sensitivities to its tearing variables (the model Jacobian, with many seeds, is a run-time
tape instead: ``jacobian``). For ``v = expr(w1, w2, ...)`` the sensitivity of ``v`` to seed
``j`` is ``sum_k d expr/d w_k * dw_k/dj``. Only non-zero entries are carried; a
sensitivity that is not a number or a (negated) symbol gets its own assignment, so no
expression is ever substituted into another and the emitted code grows with the number
of assignments, not with the depth of the graph.
"""

from __future__ import annotations

from collections.abc import Callable

import sympy as sp


def trivial(d) -> bool:
    """A number or a (negated) symbol: printed inline, never hoisted. (``-s`` is the Mul
    ``(-1, s)``; asking sympy ``could_extract_minus_sign`` instead negates the whole
    expression, which costs most on the large sums that are never trivial.)"""
    return (d.is_Number or d.is_Symbol
            or (d.is_Mul and len(d.args) == 2 and d.args[0] is sp.S.NegativeOne
                and d.args[1].is_Symbol))


def derivative(e, s, free: dict | None = None):
    """``sp.diff(e, s)``, the same expression, faster: sums and products are
    differentiated here as sympy does (sum rule; product rule in the order of the factors,
    the terms added at once; sin and cos by the chain rule), skipping sympy's per-node Derivative construction and its
    ``is_zero`` assumption queries, and subtrees without ``s`` (``free``: a memo of free
    symbols, shared between the calls on one expression). Anything else goes to sympy."""
    if e is s:
        return sp.S.One
    if free is None:
        free = {}
    fs = free.get(e)
    if fs is None:
        fs = free[e] = e.free_symbols
    if s not in fs:
        return sp.S.Zero
    if e.is_Add:
        return _sum([derivative(a, s, free) for a in e.args])
    if e.is_Mul:
        args = e.args
        terms = []
        for i, a in enumerate(args):
            d = derivative(a, s, free)
            if d is not sp.S.Zero:
                factors = [f for f in (*args[:i], d, *args[i + 1:]) if f is not sp.S.One]
                terms.append(factors[0] if len(factors) == 1 else
                             sp.Mul(*factors, _sympify=False))
        return _sum(terms)
    if e.func in _CHAIN:                # sin, cos (the poses' rotations): the chain rule
        da = derivative(e.args[0], s, free)
        if da is sp.S.Zero:
            return da
        outer = _CHAIN[e.func](e.args[0])
        return outer if da is sp.S.One else sp.Mul(outer, da, _sympify=False)
    return sp.diff(e, s)


# d f(a)/da of the functions the kinematics call, as sympy's diff writes it (its
# Derivative objects and assumption queries were a quarter of the constraints' rows)
_CHAIN = {sp.sin: sp.cos, sp.cos: lambda a: -sp.sin(a)}


def _sum(terms):
    """``sp.Add(*terms)``, short-cut where sympy's is (no term or one other than 0)."""
    terms = [t for t in terms if t is not sp.S.Zero]
    if len(terms) < 2:
        return terms[0] if terms else sp.S.Zero
    return sp.Add(*terms, _sympify=False)


def times(a, b):
    """``sp.Mul(a, b)``, the same expression; the rows' most common products (a symbol
    times a symbol, a rational number times a symbol: two of three) ordered as sympy's
    ``Mul.flatten`` orders them (the number first, symbols by ``Basic.compare``) without
    its general pass, the rest by sympy."""
    if type(a) is sp.Symbol and type(b) is not sp.Symbol:
        a, b = b, a
    if type(b) is sp.Symbol:
        if type(a) is sp.Symbol and a is not b:
            return sp.Mul._from_args((a, b) if a.compare(b) < 0 else (b, a), True)
        if a.is_Rational and a is not sp.S.Zero and a is not sp.S.One:
            return sp.Mul._from_args((a, b), True)
    return sp.Mul(a, b, _sympify=False)


def directional(e, sens: dict) -> dict[int, sp.Expr]:
    """{seed: d e / d seed} through the symbols of ``e`` that have sensitivities."""
    acc: dict[int, list] = {}
    free = {e: e.free_symbols}
    one = sp.S.One
    for s in sorted((s for s in free[e] if s in sens), key=lambda s: s.name):
        partial = derivative(e, s, free)
        if partial is sp.S.Zero:        # (sympy's zero is one object: no == 0 to ask)
            continue
        for j, ds in sens[s].items():
            # partial * ds, without sympy's work for 1 * x; each seed's terms added at
            # once (one after the other rebuilds the sum each time: quadratic)
            acc.setdefault(j, []).append(ds if partial is one else partial if ds is one
                                         else times(partial, ds))
    out = {}
    for j in sorted(acc):
        d = _sum(acc[j])
        if d is not sp.S.Zero:
            out[j] = d
    return out


def propagate(assignments, sens: dict, name: Callable[[sp.Symbol, int], str]) -> list:
    """Carry ``sens`` through ``(v, expr)`` assignments in order (``sens`` is extended in
    place); return the hoisted ``(symbol, expr)`` assignments, named ``name(v, seed)``."""
    hoisted = []
    for v, e in assignments:
        row = {}
        for j, d in directional(e, sens).items():
            if trivial(d):
                row[j] = d
            else:
                sym = sp.Symbol(name(v, j), real=True)
                hoisted.append((sym, d))
                row[j] = sym
        if row:
            sens[v] = row
    return hoisted
