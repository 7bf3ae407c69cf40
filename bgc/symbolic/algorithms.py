"""Small graph algorithms shared by the passes (iterative, so deep models cannot hit
Python's recursion limit)."""

from __future__ import annotations

from typing import Hashable, Iterable, Mapping

from sympy.core.basic import _args_sortkey


def strongly_connected(nodes: Iterable[Hashable],
                       deps: Mapping[Hashable, Iterable[Hashable]]) -> list[list[Hashable]]:
    """Tarjan's SCCs of the graph ``node -> deps[node]``, dependencies first.

    Each component is listed in the order its nodes were given; components come in an
    order where everything a component depends on comes before it (a BLT ordering).
    The search runs on the nodes' positions: a sympy symbol's hash and equality are
    Python methods, and the search asks for them many times per edge.
    """
    nodes = list(nodes)
    order = {n: i for i, n in enumerate(nodes)}
    at = order.get
    adj = []
    for n in nodes:
        row = []
        for d in deps.get(n, ()):
            j = at(d)
            if j is not None:
                row.append(j)
        adj.append(row)
    index = [-1] * len(nodes)
    low = [0] * len(nodes)
    on_stack = [False] * len(nodes)
    stack: list[int] = []
    out: list[list] = []
    counter = 0
    for root in range(len(nodes)):
        if index[root] >= 0:
            continue
        work = [(root, iter(adj[root]))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack[root] = True
        while work:
            node, it = work[-1]
            advanced = False
            for d in it:
                if index[d] < 0:
                    index[d] = low[d] = counter
                    counter += 1
                    stack.append(d)
                    on_stack[d] = True
                    work.append((d, iter(adj[d])))
                    advanced = True
                    break
                if on_stack[d] and index[d] < low[node]:
                    low[node] = index[d]
            if advanced:
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                if low[node] < low[parent]:
                    low[parent] = low[node]
            if low[node] == index[node]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack[w] = False
                    comp.append(w)
                    if w == node:
                        break
                out.append([nodes[i] for i in sorted(comp)])
    return out


def is_cyclic(comp: list, deps: Mapping) -> bool:
    """True if a strongly connected component is a loop (several nodes or a self-loop)."""
    return len(comp) > 1 or comp[0] in set(deps.get(comp[0], ()))


def reads(e, memo: dict) -> frozenset:
    """The symbols ``e`` reads (sympy's ``free_symbols``), memoized on the
    subexpressions by identity (``memo``: whoever asks about many expressions that share
    subtrees keeps one, e.g. the programs of a module: ``emit.cone`` and
    ``instances.schedule``)."""
    hit = memo.get(id(e))
    if hit is not None and hit[0] is e:
        return hit[1]
    if e.is_Symbol:
        out = frozenset((e,))
    elif not e.args:
        out = frozenset()
    else:
        out = frozenset().union(*(reads(a, memo) for a in e.args))
    memo[id(e)] = (e, out)
    return out


def substitute(e, mapping: Mapping, memo: dict):
    """``e.xreplace(mapping)`` (``memo``: by identity, for expressions that share
    subtrees), the same expression, faster where the replacements only rename: a sum or
    product rebuilt with its arguments still distinct (no two terms of one monomial, no
    two factors of one base) and none of the new ones a number, a sum in a sum or a
    product in a product, keeps all its terms, so it only needs them in the order
    ``Add.flatten`` and ``Mul.flatten`` sort them (``_args_sortkey``, the number first),
    not their general pass (most of xreplace's time); any other node by its
    constructor, as xreplace does."""
    hit = memo.get(id(e))
    if hit is not None and hit[0] is e:
        return hit[1]
    out = mapping.get(e)
    if out is None:
        if not e.args:
            out = e
        else:
            args = [substitute(a, mapping, memo) for a in e.args]
            new = [a for a, old in zip(args, e.args) if a is not old]
            if not new:
                out = e
            elif (e.is_Add or e.is_Mul) and _keeps_terms(e, args, new):
                out = e.func._from_args(sorted(args, key=_args_sortkey))
            else:
                out = e.func(*args)
    memo[id(e)] = (e, out)
    return out


def _keeps_terms(e, args: list, new: list) -> bool:
    """Whether flattening sum or product ``e`` rebuilt of ``args`` (``new``: those that
    changed) would keep every argument as it is."""
    if any(a.is_Number or a.func is e.func or (e.is_Mul and a.is_Add) for a in new):
        return False
    if e.is_Add:
        keys = [a.as_coeff_Mul()[1] for a in args if not a.is_Number]
    else:
        keys = [a.as_base_exp()[0] for a in args if not a.is_Number]
    return len(set(keys)) == len(keys)
