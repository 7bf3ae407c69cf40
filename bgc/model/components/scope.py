"""Components, what their assembly shares: the keys and limits, the names it makes
(``QName``), where a value came from (``InstanceLoc``), an instance and its ports, the
``Scope`` a model or an instance is written out in, and small helpers on located YAML
values and expression nodes."""

from __future__ import annotations

import ast
from dataclasses import dataclass, field

import sympy as sp

from bgc.errors import Loc
from bgc.mechanics import exact
from bgc.model.document import YList, YMap

COMPONENT_KEYS = ("description", "parameters", "constants", "ports", "signals", "bodies",
                  "joints", "elements", "bonds", "blocks", "outputs", "instances")
INSTANCE_KEYS = ("component", "for", "origin", "rotate", "parameters", "constants",
                 "connect", "description")
PORT_KINDS = ("external", "body", "point", "direction", "element", "signal")
# the sections whose entries are named: merged into the flat document in this order
NAMED = ("parameters", "signals", "bodies", "joints", "elements", "blocks", "outputs")
LITERAL = ("type", "description", "unit", "anti_windup", "loads")
MAX_INSTANCES = 10_000       # instances in one model, nested ones included
FIXED_FRAME = "fixed_frame"


class QName(str):
    """A name the assembly made (``leg_2.beater``): ``Context.declare`` accepts its dots,
    which no name written in a model may contain."""


@dataclass(frozen=True)
class InstanceLoc(Loc):
    """The location of a value that came from a component: its own file:line:col, and
    the instance (or chain of instances) it was instantiated by."""
    via: str = ""

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col} (in {self.via})"


@dataclass
class Port:
    """An instance's port: its ``kind`` (PORT_KINDS; an external port's is ``external
    body``, ``external element`` or ``external signal``), the flat name it stands for (``target``) or, for a
    signal, its expression; ``power`` of an element port (in, out or None)."""
    name: str
    kind: str
    target: str | None = None
    expr: ast.AST | None = None
    power: str | None = None
    loc: Loc | None = None


@dataclass
class Instance:
    """One instance in the flat model: its flat name, its component, where it is
    instantiated (``loc``) and where its component is defined (``definition``)."""
    name: str
    component: str
    loc: Loc
    definition: Loc
    ports: dict[str, Port] = field(default_factory=dict)
    library: bool = False
    names: set = field(default_factory=set)     # the names its component declares

    def where(self) -> str:
        return (f"instance '{self.name}' ({self.loc.file}:{self.loc.line}) of component "
                f"'{self.component}' ({self.definition.file}:{self.definition.line})")


@dataclass
class Scope:
    """What a model or one instance's component sees while it is written out."""
    file: str                                   # where its component names resolve
    prefix: str = ""                            # '' (the model) or 'leg_1.'
    R: sp.Matrix = field(default_factory=lambda: sp.eye(3))   # its frame in R0
    o: sp.Matrix = field(default_factory=lambda: sp.zeros(3, 1))
    via: str = ""                               # the instance chain ('' for the model)
    rename: dict = field(default_factory=dict)  # local name -> flat name
    subst: dict = field(default_factory=dict)   # local name -> expression (ast)
    consts: dict = field(default_factory=dict)  # constant -> exact value
    insts: dict = field(default_factory=dict)   # local instance name -> Instance
    points: dict = field(default_factory=dict)  # point name -> local body (bare 'at:')
    declared: set = field(default_factory=set)  # the names declared here

    @property
    def placed(self) -> bool:
        return self.R != sp.eye(3) or any(x != 0 for x in self.o)

    def loc(self, loc):
        if not self.via or loc is None:
            return loc
        return InstanceLoc(loc.file, loc.line, loc.col, self.via)


def _ymap(loc=None) -> YMap:
    m = YMap()
    m.loc, m.key_locs, m.val_locs = loc, {}, {}
    return m


def _ylist(items, locs, loc=None) -> YList:
    out = YList(items)
    out.loc, out.item_locs = loc, list(locs)
    return out


def _chain(node) -> list[str] | None:
    """``a.b.c`` as ['a', 'b', 'c'] (a Name and its Attributes), else None."""
    parts = []
    while isinstance(node, ast.Attribute):
        parts.append(node.attr)
        node = node.value
    if not isinstance(node, ast.Name):
        return None
    parts.append(node.id)
    return parts[::-1]


def _dotted(name: str) -> ast.AST:
    """The expression node of a (flat, dotted) name."""
    parts = name.split(".")
    node: ast.AST = ast.Name(parts[0], ast.Load())
    for p in parts[1:]:
        node = ast.Attribute(node, p, ast.Load())
    return node


def _literal(value: sp.Expr) -> ast.AST:
    """An exact value as an expression node (its sympy text, parsed)."""
    return ast.parse(sp.sstr(value), mode="eval").body


def _names(node) -> set[str]:
    """The bare names an expression reads (not the functions it calls)."""
    called = {id(n.func) for n in ast.walk(node) if isinstance(n, ast.Call)}
    return {n.id for n in ast.walk(node) if isinstance(n, ast.Name) and id(n) not in called}


def _exact(value: sp.Expr) -> sp.Expr:
    """Floats of a parsed constant read as the decimals they were written as."""
    return value.xreplace({f: exact.rational(f) for f in value.atoms(sp.Float)})


def _rotation(axis: str, angle: sp.Expr) -> sp.Matrix:
    c, s = sp.cos(angle), sp.sin(angle)
    return {"x": sp.Matrix([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": sp.Matrix([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": sp.Matrix([[c, -s, 0], [s, c, 0], [0, 0, 1]])}[axis]


def _const_node(value) -> ast.AST:
    """A number as an expression node (a negative one as unary minus)."""
    return ast.parse(repr(value), mode="eval").body


def _xyz(loc: Loc) -> tuple:
    return loc.file, loc.line, loc.col


def _number(e: sp.Rational):
    """An exact rational as a YAML number: an int, or the float that reads back as it
    (``exact.rational``) where its decimal terminates, else its text (``1/3``)."""
    if e.is_Integer:
        return int(e)
    f = float(e)
    return f if exact.rational(f) == e else sp.sstr(e)
