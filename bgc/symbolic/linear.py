"""The linear blocks of an equation system: linear loops and constraint blocks that the
generated kernels solve at run time (``LinearBlock``), and their regularization
(``Regularized``, method augmented's). Built by the equations stage (``codegen.loops``)
or declared by a constraint method (``ConstraintMethod.constraint_block``); solved by
``codegen.kernels``."""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp


@dataclass(frozen=True)
class LinearBlock:
    """A linear loop solved numerically at run time: ``A(w) u = b(w)`` by LU, for loops
    too large to solve symbolically without expression swell. ``A`` holds the non-zero
    entries only; ``b`` is None where it is evaluated numerically, as ``tear_eqs`` with
    ``u = 0`` and the chain run once at that point (no substituted expression); ``pre``
    are assignments that ``A`` reads (the loop's sensitivities to ``u``). For the Jacobian: ``u = tear_eqs(u, chain)``, where ``chain`` are the loop's
    other variables in causal order (computed after the block), both unsubstituted."""
    index: int
    unknowns: tuple[sp.Symbol, ...]
    A: tuple[tuple[int, int, sp.Expr], ...]
    b: tuple[sp.Expr, ...] | None
    tear_eqs: tuple[sp.Expr, ...]
    chain: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    pre: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    # None: LU. An expression: the constraint block of method lagrange, solved by SVD
    # keeping that many singular values (the rank of the constraints at the initial state,
    # plus the twist rates of bodies of negligible mass)
    rank: sp.Expr | None = None
    # constraint blocks: A = -K B with K (n x d) and B (d x n) sparse, d dynamic states
    factors: tuple | None = None
    # a block solved with the diagonal of A raised by eps times itself on these rows
    # (``Regularized``: method augmented's projections), regular whatever the rank
    regularize: "Regularized | None" = None
    # right-hand sides solved at once (``b`` holds n x columns, row-major; the unknowns
    # likewise): method augmented's projection solves its velocities and positions so
    columns: int = 1

    @property
    def free_symbols(self) -> set:
        out = set(self.rank.free_symbols) if self.rank is not None else set()
        if self.regularize is not None:
            out |= self.regularize.free_symbols
        exprs = [e for _, _, e in self.A] + [e for _, e in self.pre]
        if self.factors is not None:
            exprs += [e for _, _, e in self.factors[1] + self.factors[2]]
        if self.b is None:      # b = tear_eqs at u = 0, the chain evaluated in the block
            exprs += list(self.tear_eqs) + [e for _, e in self.chain]
        else:
            exprs += list(self.b)
        for e in exprs:
            out |= e.free_symbols
        inner = set(self.unknowns) | {v for v, _ in self.chain} if self.b is None else set()
        return out - {v for v, _ in self.pre} - inner

    def xreplace(self, mapping) -> "LinearBlock":
        """Apply ``mapping`` (aliases: symbol -> symbol or number) everywhere; chain
        variables that are aliases themselves are dropped from the chain."""
        def pairs(items):
            return tuple((v, e.xreplace(mapping)) for v, e in items if v not in mapping)
        return LinearBlock(self.index, self.unknowns,
                           tuple((i, j, e.xreplace(mapping)) for i, j, e in self.A),
                           None if self.b is None else
                           tuple(e.xreplace(mapping) for e in self.b),
                           tuple(e.xreplace(mapping) for e in self.tear_eqs),
                           pairs(self.chain), pairs(self.pre), self.rank,
                           None if self.factors is None else
                           (self.factors[0],
                            tuple((i, j, e.xreplace(mapping)) for i, j, e in self.factors[1]),
                            tuple((i, j, e.xreplace(mapping)) for i, j, e in self.factors[2])),
                           None if self.regularize is None else
                           self.regularize.xreplace(mapping), self.columns)


@dataclass(frozen=True)
class Regularized:
    """A linear block solved as ``(A + diag(w)) u = b``, ``w[k]`` added on row
    ``rows[k]`` (Tikhonov, each row in its own scale: method augmented), regular where A
    is not (redundant constraints, a singular configuration), within the weights of A's
    solution on its well-conditioned part."""
    weights: tuple[sp.Expr, ...]
    rows: tuple[int, ...]

    @property
    def free_symbols(self) -> set:
        return set().union(*(w.free_symbols for w in self.weights))

    def xreplace(self, mapping) -> "Regularized":
        return Regularized(tuple(w.xreplace(mapping) for w in self.weights), self.rows)
