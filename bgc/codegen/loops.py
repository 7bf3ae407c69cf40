"""Stage **equations**: the algebraic loops (strongly connected blocks of the causal
equations) torn and solved: symbolically where small, else as a ``LinearBlock`` the
kernels solve at run time (in all its variables, or reduced to its tearing variables);
a constraint method's loops (multipliers, dependent momenta) as the method asks."""

from __future__ import annotations

import sympy as sp
from sympy.solvers.solveset import NonlinearError

from bgc import methods
from bgc.codegen.builder import Builder
from bgc.codegen.system import Loop
from bgc.errors import EquationError
from bgc.methods.consistent import RANK_PARAM
from bgc.model import symbols
from bgc.symbolic.algorithms import is_cyclic, strongly_connected
from bgc.symbolic.forward_mode import directional, propagate
from bgc.symbolic.linear import LinearBlock

# Largest loop solved symbolically (tearing variables); larger loops become numeric blocks.
MAX_SYMBOLIC_LOOP = 6


def dependencies(eqs: dict) -> dict:
    """Each variable -> the variables its equation reads (by name: a stable order)."""
    return {v: sorted((s for s in e.free_symbols if s in eqs), key=lambda s: s.name)
            for v, e in eqs.items()}


def _tear(comp: list, deps: dict, first=()) -> list:
    """Greedy tearing: drop the variable with most loop in*out edges until acyclic
    (after the variables ``first``, torn by choice)."""
    first = set(first)
    tears = [v for v in comp if v in first]
    rest = [v for v in comp if v not in first]
    while True:
        live = set(rest)
        sub = {v: [d for d in deps[v] if d in live] for v in rest}
        cyclic = [c for c in strongly_connected(rest, sub) if is_cyclic(c, sub)]
        if not cyclic:
            return tears
        block = cyclic[0]
        indeg = {v: 0 for v in block}
        for v in block:
            for d in sub[v]:
                if d in indeg:
                    indeg[d] += 1
        best = max(block, key=lambda v: indeg[v] * sum(d in indeg for d in sub[v]))
        tears.append(best)
        rest.remove(best)


def _numeric_block(b: Builder, comp: list, index: int, refuse) -> LinearBlock:
    """The whole loop as one linear system in all its variables (simple coefficients,
    nothing substituted), to be factorized numerically in the generated code."""
    residuals = [v - b.eqs[v] for v in comp]
    try:
        A, rhs = sp.linear_eq_to_matrix(residuals, comp)
    except NonlinearError:
        raise refuse("nonlinear algebraic loop",
                     "break the loop with a small parasitic C or I") from None
    if any(e.has(*comp) for e in list(A) + list(rhs)):
        raise refuse("nonlinear algebraic loop", "break the loop with a small parasitic C or I")
    entries = tuple((i, j, A[i, j]) for i in range(A.rows) for j in range(A.cols)
                    if A[i, j] != 0)
    return LinearBlock(index, tuple(comp), entries, tuple(rhs),
                       tuple(b.eqs[v] for v in comp))


def _substituted(b: Builder, order: list) -> dict:
    """The loop variables ``order`` (causal order) as expressions of the tearing variables
    and what lies outside the loop (only where a substituted residual is wanted: they
    swell along long loops)."""
    subs: dict = {}
    for v in order:
        subs[v] = b.eqs[v].xreplace(subs)
    return subs


def _reduced_block(b: Builder, tears: list, order: list, index: int,
                   refuse, rank=None, numeric_rhs=False) -> LinearBlock:
    """A linear loop solved numerically in its tearing variables only. ``A = I - d
    tear_eqs/du`` comes from forward-mode sensitivities to the tears carried through the
    loop's assignments (small, hoisted; never the substituted residual, which swells with
    every modulated transformer along the loop); ``b`` is the substituted residual at
    ``u = 0``. The other loop variables are computed afterwards in causal order."""
    chain = tuple((v, b.eqs[v]) for v in order)
    loop_vars = set(tears) | set(order)
    sens = {t: {k: sp.S.One} for k, t in enumerate(tears)}
    pre = propagate(chain, sens, lambda v, k: f"S{index}_{v.name}__{k}")
    entries = []
    for i, t in enumerate(tears):
        row = directional(b.eqs[t], sens)
        for k in range(len(tears)):
            a = (sp.S.One if i == k else sp.S.Zero) - row.get(k, sp.S.Zero)
            if a != 0:
                entries.append((i, k, a))
    if any(e.has(*loop_vars) for e in [e for _, e in pre] + [a for _, _, a in entries]):
        raise refuse("nonlinear algebraic loop", "break the loop with a small parasitic C or I")
    zero = {t: 0 for t in tears}
    rhs = None
    if rank is None and not numeric_rhs:
        subs = _substituted(b, order)
        rhs = tuple(b.eqs[t].xreplace(subs).xreplace(zero) for t in tears)
    return LinearBlock(index, tuple(tears), tuple(entries), rhs,
                       tuple(b.eqs[t] for t in tears), chain, tuple(pre), rank)


def _kkt_block(b: Builder, tears: list, order: list, index: int) -> LinearBlock:
    """The constraint block of method lagrange: the acceleration-level equations are
    linear in the multipliers u, ``resid = K (dp/dt) + ...`` with ``dp/dt = dp/dt|u=0 +
    B u``; K (the rates' rows on the dynamic states, from ``lagrange``) and B (the
    multipliers' rows on the dynamic states' rates, forward mode along the loop, which
    is the force path) are sparse; their product ``J M^-1 J^T`` is formed numerically at
    run time."""
    chain = tuple((v, b.eqs[v]) for v in order)
    dynamic = sorted({x for rows in b.kkt_rows.values() for x in rows},
                     key=lambda x: x.name)
    col = {x: j for j, x in enumerate(dynamic)}
    dstate = {st.dsym: st.sym for st in b.states}
    dstate.update({ds: x for x, ds, _ in b.zcp_dependent})
    dstate.update(b.kkt_rates)
    sens = {t: {k: sp.S.One} for k, t in enumerate(tears)}
    pre = propagate(chain, sens, lambda v, k: f"S{index}_{v.name}__{k}")
    B = tuple((col[dstate[dx]], k, d) for dx in sorted(sens, key=lambda s: s.name)
              if dx in dstate and dstate[dx] in col for k, d in sens[dx].items())
    K = tuple((i, col[x], d) for i, t in enumerate(tears)
              for x, d in sorted(b.kkt_rows[t].items(), key=lambda kv: kv[0].name))
    # a body of negligible mass adds its twist's rates, each one rank of the saddle point
    rank = symbols.param(RANK_PARAM) + sum(symbols.kind(t) == "acceleration" for t in tears)
    return LinearBlock(index, tuple(tears), (), None, tuple(b.eqs[t] for t in tears), chain,
                       tuple(pre), rank, (len(dynamic), K, B))


def solve_loop(b: Builder, comp: list, deps: dict, max_symbolic: int = MAX_SYMBOLIC_LOOP,
                block_index: int = 0) -> tuple[list, Loop]:
    eqs = b.eqs
    multipliers = [v for v in comp if symbols.kind(v) in ("multiplier", "acceleration")]
    zcp_dependent = {x for x, _, _ in b.zcp_dependent}
    dependent = [v for v in comp if v in zcp_dependent]
    tears = _tear(comp, deps, multipliers + dependent)
    torn = set(tears)
    rest = [v for v in comp if v not in torn]
    live = set(rest)
    sub_deps = {v: [d for d in deps[v] if d in live] for v in rest}
    order = [c[0] for c in strongly_connected(rest, sub_deps)]
    elements = sorted({b.origin[v][0] for v in comp if b.origin[v][0]})
    bonds = sorted({b.origin[v][1] for v in comp if b.origin[v][1]})
    kind = "derivative" if any(symbols.kind(v) == "rate" for v in comp) else "algebraic"
    loop = Loop(kind, [b.display.get(v, v.name) for v in comp], bonds, elements,
                [b.display.get(v, v.name) for v in tears])
    placed = [e for e in elements if e in b.g.elements]     # not a control block
    where = b.g.elements[placed[0]] if placed else None

    def refuse(why, hint):
        return EquationError(f"{why}: {loop.kind} loop through elements "
                             f"{', '.join(elements)} and bonds {', '.join(bonds)}",
                             loc=where.loc if where else None,
                             key=f"elements.{placed[0]}" if placed else None, hint=hint)

    if multipliers and set(tears) == set(multipliers):
        loop.kind = "constraint"
        n_acc = sum(symbols.kind(v) == "acceleration" for v in tears)
        loop.tearing = [f"numeric SVD of the {len(tears) - n_acc} Lagrange multipliers"
                        + (f" and {n_acc} twist rates of bodies of negligible mass"
                           if n_acc else "")]
        block = _kkt_block(b, tears, order, block_index)
        before, block, after = methods.get(b.g.method).constraint_block(b, block)
        return before + [block] + [(v, eqs[v]) for v in order] + after, loop
    if multipliers:
        loop.kind = "constraint"
        loop.tearing = [f"numeric SVD of {len(tears)} unknowns "
                        f"({len(multipliers)} Lagrange multipliers)"]
        # the constraints' rank at run time, plus the other tears (a storage in
        # derivative causality on the mechanism's ports), which are never redundant
        regular = sum(symbols.kind(v) != "multiplier" for v in tears)
        block = _reduced_block(b, tears, order, block_index, refuse,
                               rank=symbols.param(RANK_PARAM) + regular)
        return [block] + [(v, eqs[v]) for v in order], loop
    if dependent:
        loop.kind = "imposed-flow"
        loop.tearing = [f"numeric LU of the {len(dependent)} dependent momenta (class-1 "
                        "ZCP: velocities imposed by the flow sources)"]
        block = _reduced_block(b, tears, order, block_index, refuse, numeric_rhs=True)
        return [block] + [(v, eqs[v]) for v in order], loop
    if kind == "derivative" and any(b.g.elements[e].kind == "XTF" or b.g.elements[e].orthogonal
                                    for e in placed):
        # a storage geared rigidly to the mechanism through a port: its loop runs through
        # the bodies' rotations (orthogonal MTFs, cross-product TFs), whose substituted
        # residual would swell (and expanding it take most of a compile); solved
        # numerically in its tears
        loop.tearing = [f"numeric LU of {len(tears)} tearing variables"]
        block = _reduced_block(b, tears, order, block_index, refuse)
        return [block] + [(v, eqs[v]) for v in order], loop
    if any(symbols.kind(v) == "unknown" for v in comp):
        loop.kind = "negligible-mass"
        loop.tearing = [f"numeric LU of {len(tears)} tearing variables"]
        block = _reduced_block(b, tears, order, block_index, refuse)
        return [block] + [(v, eqs[v]) for v in order], loop
    if len(tears) > max_symbolic:
        loop.tearing = ["numeric LU of all " + str(len(comp)) + " loop variables"]
        return [_numeric_block(b, comp, block_index, refuse)], loop
    subs = _substituted(b, order)
    residuals = [sp.expand(t - eqs[t].xreplace(subs)) for t in tears]
    try:
        A, rhs = sp.linear_eq_to_matrix(residuals, tears)
    except NonlinearError:
        raise refuse("nonlinear algebraic loop",
                     "make a loop element linear, or break the loop with a small parasitic "
                     "C or I (its value sets how stiff the result is)") from None
    if any(e.has(*tears) for e in list(A) + list(rhs)):
        raise refuse("nonlinear algebraic loop", "break the loop with a small parasitic C or I")
    if A.det() == 0:
        raise refuse("singular algebraic loop (the loop equations are dependent)",
                     "check for redundant sources or a junction structure without elements")
    sol = [sp.cancel(e) for e in A.LUsolve(rhs)] if len(tears) > 1 else [rhs[0] / A[0, 0]]
    out = list(zip(tears, sol)) + [(v, eqs[v]) for v in order]
    return out, loop
