"""The BondGraph: elements as nodes, bonds as edges with a power direction and a dimension.

This is what ``expand`` produces: user elements, bodies and joints in one structure, with
multibonds of dimension 3 and matrix-valued elements where bodies and joints need them.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from bgc.model.model import POWER_IN, Body, Bond, Element, Model


@dataclass(frozen=True)
class Constraint:
    """A blocked joint direction whose element L is a constraint effort source (method
    ``lagrange``): its effort is the multiplier, its flow the rate dg/dt."""
    joint: str
    label: str
    element: str          # the L element (an MSe with the multiplier as effort)
    g: object             # geometric deflection (sympy, in the states), None: none
    rotational: bool
    imposed: bool = False  # method zcp: L is a flow source (tree joint), not a break variable
    # method zcp with loops kept closed: the break variable of a loop-closing joint is an
    # algebraic state of an index-2 DAE (0 = dg/dt + alpha g), not solved for
    closed: bool = False

    @property
    def name(self) -> str:
        return f"{self.joint}.{self.label}"


@dataclass
class BondGraph:
    model: Model
    elements: dict[str, Element]
    bonds: list[Bond]
    ports: dict[str, list[int]]     # element name -> indices of its bonds, in file order
    bodies: dict[str, Body] = field(default_factory=dict)
    joints: dict[str, list] = field(default_factory=dict)   # joint -> its Directions
    method: str = "parasitic"     # the name of its constraint method (bgc.methods)
    constraints: list = field(default_factory=list)          # lagrange, zcp: [Constraint]
    # the constraint method's plan from its graph pass (``restructure``), read by its own
    # hooks only: zcp's ``zcp.Plan`` (spanning tree, loops, dependents); None: no plan
    method_plan: object = None
    port_junctions: dict[str, str] = field(default_factory=dict)   # junction -> port name

    def label(self, node: str) -> str:
        """A node's name as the model knows it: a port's junction is the port."""
        port = self.port_junctions.get(node)
        return f"{node} (port {port})" if port else node

    def other(self, b: int, node: str) -> str:
        bond = self.bonds[b]
        return bond.dst if bond.src == node else bond.src

    def points_into(self, b: int, node: str) -> bool:
        return self.bonds[b].dst == node

    def port_sign(self, b: int, node: str) -> int:
        """+1 if the bond's flow is the element's port flow, -1 if the bond is drawn
        against the element's standard direction (into C, I, R; out of sources; into a
        junction)."""
        kind = self.elements[node].kind
        into = self.points_into(b, node)
        if kind in POWER_IN or kind in ("0", "1"):  # EJS: the junctions' power goes in
            return 1 if into else -1
        return -1 if into else 1

    def two_port(self, node: str) -> tuple[int, int]:
        """(input bond, output bond) of a TF/GY-like element (checked by expand)."""
        a, b = self.ports[node]
        return (a, b) if self.points_into(a, node) else (b, a)
