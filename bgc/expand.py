"""Stage **expand**: Model -> BondGraph.

Bodies become the Tiernego-Bos rigid-body graph (paper 11.2.3, Fig. 11.1), written out
component by component: a translational part in R0 (three 1-junctions for the velocity of
G, the mass on each, gravity as effort sources) and a rotational part in the principal body
frame (three 1-junctions for omega, the principal moments, and the Eulerian junction
structure, a 3-port that receives omega and returns omega x (J omega)). Positions and XYZ
Cardan angles are kinematic states added by ``equations``.

Then the graph's structure is checked: every element has the number of bonds its kind
takes, two-ports have one bond in and one out, nothing is left unbonded.
"""

from __future__ import annotations

from .bondgraph import BondGraph
from .errors import ModelError
import sympy as sp

from .model import KINDS, TWO_PORTS, Body, Bond, Element, Model


AXES = "xyz"


def body_junction(body: str, part: str, axis: int) -> str:
    """Name of the 1-junction of a body's velocity (part 'v', R0) or omega ('w', body)."""
    return f"{body}__{part}{AXES[axis]}"


def _body_graph(body: Body, gravity) -> tuple[list[Element], list[Bond]]:
    n, loc = body.name, body.loc
    els, bonds = [], []
    frame = sp.Matrix(body.frame)
    omega_body = frame.T * sp.Matrix(body.omega)
    ejs = Element(f"{n}__EJS", "EJS", loc, fields={"J": sp.Matrix(body.inertia)})
    for k, ax in enumerate(AXES):
        v, w = body_junction(n, "v", k), body_junction(n, "w", k)
        els += [Element(v, "1", loc), Element(w, "1", loc),
                Element(f"{n}__m{ax}", "I", loc, fields={"I": sp.Float(body.mass)},
                        initial=sp.Float(body.mass * body.velocity[k])),
                Element(f"{n}__J{ax}", "I", loc, fields={"I": sp.Float(body.inertia[k])},
                        initial=sp.Float(body.inertia[k] * float(omega_body[k])))]
        bonds += [Bond(f"{n}__bm{ax}", v, f"{n}__m{ax}", loc),
                  Bond(f"{n}__bJ{ax}", w, f"{n}__J{ax}", loc),
                  Bond(f"{n}__bE{ax}", w, ejs.name, loc)]
        if gravity[k] != 0:
            els.append(Element(f"{n}__g{ax}", "Se", loc,
                               fields={"effort": sp.Float(body.mass * gravity[k])}))
            bonds.append(Bond(f"{n}__bg{ax}", f"{n}__g{ax}", v, loc))
    els.append(ejs)
    return els, bonds


def expand(model: Model) -> BondGraph:
    elements, bonds = dict(model.elements), list(model.bonds)
    for body in model.bodies.values():
        els, bds = _body_graph(body, model.gravity)
        elements.update({e.name: e for e in els})
        bonds += bds
    ports: dict[str, list[int]] = {name: [] for name in elements}
    for i, b in enumerate(bonds):
        ports[b.src].append(i)
        ports[b.dst].append(i)
    graph = BondGraph(model, elements, bonds, ports, dict(model.bodies))
    for name, el in elements.items():
        n, spec = len(ports[name]), KINDS[el.kind]
        key = f"elements.{name}"
        if n == 0:
            raise ModelError(f"{el.kind} '{name}' is not connected by any bond", loc=el.loc,
                             key=key, hint="add a bond to it or remove it")
        if spec.ports is None and n < 2 and name in model.elements:   # a body's own
            # velocity junction may carry only its mass
            raise ModelError(f"{el.kind}-junction '{name}' has {n} bond; a junction needs "
                             "at least 2", loc=el.loc, key=key,
                             hint="bond the element directly, or add the missing bond")
        if spec.ports is not None and n != spec.ports:
            listed = ", ".join(f"{bonds[i].name} (line {bonds[i].loc.line})"
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
