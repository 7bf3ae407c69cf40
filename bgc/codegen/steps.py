"""Stage **kernels**: a program's work as a list of steps, each a small typed record.

``program_steps`` turns a program's assignments (in causal order, linear blocks among
them) and its outputs into the steps the module assembly lowers one by one: values
assigned (``Set``), a block's matrix and right-hand side written into its workspace
region (``Store``, ``Zero``), the block solved (``Solve``: where a program's straight-line
chunks are cut), results written (``Out``) and an expression's partials (``Grad``, the
Jacobian's run-time partials). ``instances.schedule`` may replace some straight-line
steps by a ``LoopOver`` the instances of one component.
"""

from __future__ import annotations

from typing import NamedTuple

import sympy as sp

from bgc.codegen.equations import LinearBlock


class Set(NamedTuple):
    """``v = e``: the value kept for what follows and stored in v's workspace slot."""
    v: sp.Symbol
    e: sp.Expr


class Store(NamedTuple):
    """``w[slot] = e``: an entry of a linear block's region."""
    slot: int
    e: sp.Expr


class Zero(NamedTuple):
    """``w[at:at + count] = 0``."""
    at: int
    count: int


class Solve(NamedTuple):
    """Linear block ``index`` solved, its unknowns copied to their slots."""
    index: int


class Out(NamedTuple):
    """``out[slot] = e``: a program's result."""
    slot: int
    e: sp.Expr


class Grad(NamedTuple):
    """``out[slot] = d e / d w`` for each ``(slot, w)`` of ``partials``."""
    e: sp.Expr
    partials: list


class LoopOver(NamedTuple):
    """Instances of one component computing the same steps: an ``instances.Loop``."""
    loop: object


# the steps instances may share in a loop (the others stay where they are)
STRAIGHT = (Set, Grad, Out, Store)


def program_steps(items, outputs, layout):
    """A program's work as steps (``layout``: the ``workspace.Layout``): each assignment
    a ``Set``; each linear block its ``pre`` assignments, its matrix (``A = -K B`` formed
    from K's and B's non-zeros, else A's entries) and right-hand side (at u = 0 through
    its chain, where it has no b) stored, its rank and regularization weights stored, then
    ``Solve``; then the outputs (``(slot, e)``: ``Out``, ``(e, [(slot, w)])``: ``Grad``)."""
    for item in items:
        if not isinstance(item, LinearBlock):
            yield Set(item[0], item[1])
            continue
        blk = layout.blocks[item.index]
        n = blk.n
        for v, e in item.pre:
            yield Set(v, e)
        if item.factors is not None:        # A = -K B, formed from their non-zeros
            _, K, B = item.factors
            for k, (i, j, e) in enumerate(K):
                yield Store(blk.k + (k if blk.packed else i * blk.d + j), e)
            for k, (i, j, e) in enumerate(B):
                yield Store(blk.kb + (k if blk.packed else i * n + j), e)
        else:
            yield Zero(blk.a, n * n)
            for i, j, e in item.A:
                yield Store(blk.a + i * n + j, e)
        if item.b is None:      # the right-hand side at u = 0, through the chain
            for u in item.unknowns:
                yield Set(u, sp.S.Zero)
            for v, e in item.chain:
                yield Set(v, e)
            for i, e in enumerate(item.tear_eqs):
                yield Store(blk.b + i, e)
        else:
            for i, e in enumerate(item.b):
                yield Store(blk.b + i, e)
        if item.rank is not None:
            yield Store(blk.rank, item.rank)
        if item.regularize is not None:
            for k, w in enumerate(item.regularize.weights):
                yield Store(blk.reg + k, w)
        yield Solve(item.index)
    for out in outputs:
        if isinstance(out[1], list):          # (e, [(slot, w)]): pv[slot] = d e / d w
            yield Grad(out[0], out[1])
        else:
            yield Out(out[0], out[1])
