"""Stage **equations**: the algebraic loops (strongly connected blocks of the causal
equations) torn and solved: symbolically where small, else as a ``LinearBlock`` the
kernels solve at run time (in all its variables, or reduced to its tearing variables);
a constraint method's loops (its multipliers, say) as the method asks (``loop_block``)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import sympy as sp
from sympy.solvers.solveset import NonlinearError

from bgc import methods
from bgc.codegen.builder import Builder
from bgc.codegen.system import Loop
from bgc.errors import EquationError
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


@dataclass
class Torn:
    """An algebraic loop torn (``methods.base.TornLoop``: what a method's ``loop_block``
    is given): its variables, tears and the rest in causal order, the index of its first
    block, and what the stage builds for a method."""
    b: Builder
    comp: list
    tears: list
    order: list
    index: int
    kind: str                   # as ``bgc check`` reports it; a method may rename it
    refuse: Callable = None

    def chain(self) -> list:
        """The loop's other variables' assignments, in causal order (after its block)."""
        return [(v, self.b.eqs[v]) for v in self.order]

    def reduced_block(self, rank=None, numeric_rhs: bool = False) -> LinearBlock:
        """The loop as a block in its tears (``_reduced_block``)."""
        return _reduced_block(self.b, self.tears, self.order, self.index, self.refuse,
                              rank=rank, numeric_rhs=numeric_rhs)


def solve_loop(b: Builder, comp: list, deps: dict, max_symbolic: int = MAX_SYMBOLIC_LOOP,
               block_index: int = 0) -> tuple[list, Loop]:
    """Loop ``comp`` torn (the method's ``tear_first`` first) and solved: as the method
    asks (``loop_block``), else numerically in its tears where it runs through the bodies'
    rotations or a body of negligible mass, else symbolically where it has at most
    ``max_symbolic`` tears, else numerically in all its variables."""
    eqs = b.eqs
    method = methods.get(b.g.method)
    tears = _tear(comp, deps, method.tear_first(b, comp))
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

    torn = Torn(b, comp, tears, order, block_index, kind)

    def refuse_torn(why, hint):
        loop.kind = torn.kind
        return refuse(why, hint)
    torn.refuse = refuse_torn
    solved = method.loop_block(b, torn)
    if solved is not None:
        loop.kind, loop.tearing = torn.kind, list(solved.tearing)
        return list(solved.items), loop
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
