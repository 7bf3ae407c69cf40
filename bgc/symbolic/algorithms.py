"""Small graph algorithms shared by the passes (iterative, so deep models cannot hit
Python's recursion limit)."""

from __future__ import annotations

from typing import Hashable, Iterable, Mapping


def strongly_connected(nodes: Iterable[Hashable],
                       deps: Mapping[Hashable, Iterable[Hashable]]) -> list[list[Hashable]]:
    """Tarjan's SCCs of the graph ``node -> deps[node]``, dependencies first.

    Each component is listed in the order its nodes were given; components come in an
    order where everything a component depends on comes before it (a BLT ordering).
    """
    nodes = list(nodes)
    order = {n: i for i, n in enumerate(nodes)}
    index: dict = {}
    low: dict = {}
    on_stack: set = set()
    stack: list = []
    out: list[list] = []
    counter = 0
    for root in nodes:
        if root in index:
            continue
        work = [(root, iter(d for d in deps.get(root, ()) if d in order))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on_stack.add(root)
        while work:
            node, it = work[-1]
            advanced = False
            for d in it:
                if d not in index:
                    index[d] = low[d] = counter
                    counter += 1
                    stack.append(d)
                    on_stack.add(d)
                    work.append((d, iter(x for x in deps.get(d, ()) if x in order)))
                    advanced = True
                    break
                if d in on_stack:
                    low[node] = min(low[node], index[d])
            if advanced:
                continue
            work.pop()
            if work:
                parent = work[-1][0]
                low[parent] = min(low[parent], low[node])
            if low[node] == index[node]:
                comp = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    comp.append(w)
                    if w == node:
                        break
                out.append(sorted(comp, key=order.__getitem__))
    return out


def is_cyclic(comp: list, deps: Mapping) -> bool:
    """True if a strongly connected component is a loop (several nodes or a self-loop)."""
    return len(comp) > 1 or comp[0] in set(deps.get(comp[0], ()))
