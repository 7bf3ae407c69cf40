"""Stage **expand**: Model -> BondGraph.

For scalar models this checks the graph's structure: every element has the number of
bonds its kind takes, two-ports have one bond in and one out, nothing is left unbonded.
Bodies and joints (multibond subgraphs) will expand here too.
"""

from __future__ import annotations

from .bondgraph import BondGraph
from .errors import ModelError
from .model import KINDS, TWO_PORTS, Model


def expand(model: Model) -> BondGraph:
    ports: dict[str, list[int]] = {name: [] for name in model.elements}
    for i, b in enumerate(model.bonds):
        ports[b.src].append(i)
        ports[b.dst].append(i)
    graph = BondGraph(model, dict(model.elements), list(model.bonds), ports)
    for name, el in model.elements.items():
        n, spec = len(ports[name]), KINDS[el.kind]
        key = f"elements.{name}"
        if n == 0:
            raise ModelError(f"{el.kind} '{name}' is not connected by any bond", loc=el.loc,
                             key=key, hint="add a bond to it or remove it")
        if spec.ports is None and n < 2:
            raise ModelError(f"{el.kind}-junction '{name}' has {n} bond; a junction needs "
                             "at least 2", loc=el.loc, key=key,
                             hint="bond the element directly, or add the missing bond")
        if spec.ports is not None and n != spec.ports:
            listed = ", ".join(f"{model.bonds[i].name} (line {model.bonds[i].loc.line})"
                               for i in ports[name])
            raise ModelError(f"{el.kind} '{name}' has {n} bonds, it takes exactly "
                             f"{spec.ports}: {listed}", loc=el.loc, key=key,
                             hint="put a 0- or 1-junction in front of it to connect more")
        if el.kind in TWO_PORTS:
            n_in = sum(graph.points_into(i, name) for i in ports[name])
            if n_in != 1:
                raise ModelError(f"{el.kind} '{name}' has {n_in} bonds pointing in; a "
                                 "two-port takes one bond in and one out", loc=el.loc,
                                 key=key, hint="reverse one bond: power goes through it")
    return graph
