"""Small graph algorithms shared by the passes (iterative, so deep models cannot hit
Python's recursion limit)."""

from __future__ import annotations

from typing import Hashable, Iterable, Mapping


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
