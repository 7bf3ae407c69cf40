"""Stage **load**, between the YAML and the section readers: a model that is an assembly
of components -> the flat document the readers take (issue 40; the paper's "assembly of
modules ... with a well-structured library of components", 11.6).

A **component** is a named part of a model: parameters (defaults, units), compile-time
``constants``, declared ``ports`` and its own bodies, joints, signals, elements, bonds,
blocks, outputs and nested ``instances``. An **instance** places it (``origin``, ``rotate``:
its frame in the frame of what contains it), overrides its parameters and constants, and
``connect``s its external ports (the bodies its joints attach to, the signals it reads);
the outside joins its exported ports with ordinary joints and bonds. An instance array
(``for: {i: [1, 4]}``) makes ``leg_1`` ... ``leg_4``, the index usable in every key of the
instance.

``flatten`` writes every instance out as if its contents were in the model with their
names prefixed (``leg_2.beater``, ``leg_2.hinge``), placed (positions, axes and frames in
R0, exact: ``bgc.mechanics.exact``), its parameters either its own model parameters
(``leg_2.k_hinge``, changeable by ``-p``) or, where the instance gives an expression of the
outer model's parameters, that expression (so ``-p beater_mass`` reaches every leg without
recompiling). Constants, indices and placements are compile-time: they are in the model's
digest (``bgc.model.library.digest``), numeric parameters are not. The readers then check
everything as in a flat model; a value that came from a component carries an
``InstanceLoc``: its own file:line and the instance's.
"""

from __future__ import annotations

import ast
import copy
import re
from dataclasses import dataclass, field

import sympy as sp

from bgc.errors import Loc, ModelError
from bgc.mechanics import exact
from bgc.model import expr as bexpr
from bgc.model.document import YList, YMap
from bgc.model.library import ASSEMBLY_KEYS, Definition, Sources, is_assembly
from bgc.model.values import IDENT, check_keys, fail, kind_of

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


def flatten(doc, file: str, constants: dict | None = None) -> tuple[YMap, dict]:
    """The flat document of a model document and its instances (flat name ->
    Instance); a document without components (and no ``constants`` given) comes back as
    it is. ``constants``: compile-time values given on the command line (``-p N=40``)."""
    if not is_assembly(doc) and not constants:
        return doc, {}
    a = _Assembler(file, doc)
    return a.model(doc, constants or {}), a.instances


# ---------------------------------------------------------------------------- helpers
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


# ------------------------------------------------------------------------- the assembler
class _Assembler:
    def __init__(self, file: str, doc):
        self.file = file
        self.src = Sources(file, doc)
        self.instances: dict[str, Instance] = {}
        self.flat: dict[str, YMap] = {}
        self.bonds: list[tuple] = []            # (value, loc)
        self.excitation = None
        self.stack: list[Definition] = []
        self.geometry: dict = {}        # a geometry text -> its exact value

    # -- the model -------------------------------------------------------------------
    def model(self, doc, given: dict) -> YMap:
        if not isinstance(doc, YMap):
            return doc
        scope = Scope(self.file)
        for k in ("components", "uses"):      # read by the lookups; checked there
            if k in doc and doc[k] is not None and not isinstance(doc[k], YMap):
                fail(f"'{k}' must be a mapping, got {kind_of(doc[k])}", doc.val_locs[k], k)
        declared = self._entries(doc, "constants")
        unknown = sorted(set(given) - set(declared))
        if unknown:
            raise ModelError(f"-p {unknown[0]}: the model declares no constant "
                             f"'{unknown[0]}'", loc=Loc(self.file, 1), key="constants",
                             hint="constants: " + (", ".join(declared) or "none"))
        self._constants(doc, scope, {k: exact.rational(v) for k, v in given.items()},
                        "constants")
        self._namespace(doc, scope, model=True)
        own: dict = {}
        params = self._entries(doc, "parameters")
        if params:
            out = own.setdefault("parameters", self._copy(params, scope))
            for name, v in params.items():
                k, loc = f"parameters.{name}", params.val_locs[name]
                out[name] = self._map_exprs(v, scope, k) if isinstance(v, YMap) else (
                    self._rewrite(v, scope, loc, k) if isinstance(v, str) else v)
        self._instances(doc, scope)
        own_bonds = self._contents(doc, scope, own, model=True)
        out = _ymap(doc.loc)
        for k, v in doc.items():
            if k in ASSEMBLY_KEYS:
                continue
            if k in NAMED or (k == "bonds" and own_bonds is not None):
                continue
            out[k] = self._rewrite_top(k, v, doc.val_locs[k], scope)
            out.key_locs[k], out.val_locs[k] = doc.key_locs[k], doc.val_locs[k]
        for k in NAMED:
            merged = _ymap(doc.val_locs.get(k, doc.loc))
            for part in (own.get(k), self.flat.get(k)):
                for name, v in (part or _ymap()).items():
                    merged[name] = v
                    merged.key_locs[name] = part.key_locs[name]
                    merged.val_locs[name] = part.val_locs[name]
            raw = doc.get(k)
            if raw is not None and not isinstance(raw, YMap):
                out[k] = raw                # the reader refuses it
            elif merged or k in doc:
                out[k] = merged
            if k in out:
                out.key_locs[k] = doc.key_locs.get(k, doc.loc)
                out.val_locs[k] = doc.val_locs.get(k, doc.loc)
        bonds = (own_bonds or []) + self.bonds
        if bonds and own_bonds is not None:
            out["bonds"] = _ylist([b for b, _ in bonds], [lc for _, lc in bonds],
                                  doc.val_locs.get("bonds", doc.loc))
            out.key_locs["bonds"] = doc.key_locs.get("bonds", doc.loc)
            out.val_locs["bonds"] = doc.val_locs.get("bonds", doc.loc)
        return out

    @staticmethod
    def _entries(body, sec) -> YMap:
        v = body.get(sec) if isinstance(body, YMap) else None
        return v if isinstance(v, YMap) else _ymap()

    def _rewrite_top(self, k, v, loc, scope):
        """A model section that is not merged: gravity (constants), the rest as is."""
        if k == "gravity" and isinstance(v, (str, YList)):
            return self._vector(v, loc, "gravity", scope, "expr")
        if k in ("simulation", "parasitic") and isinstance(v, YMap):
            return self._map_exprs(v, scope, k)
        if k == "excitation":
            return self._excitation(v, scope)
        return v

    # -- names ---------------------------------------------------------------------
    def _namespace(self, body: YMap, scope: Scope, model: bool, inst: Instance | None = None):
        """Every name ``body`` declares (the model's or a component's), checked for a
        clash (one error naming both places and, in a component, the instance), and
        the component's renamed to the instance's flat names."""
        seen: dict[str, tuple[str, Loc]] = {}

        def declare(name, what, loc, key):
            if not isinstance(name, str) or not IDENT.match(name) or "__" in name:
                return          # the reader refuses it with its own message
            if name in seen:
                other, oloc = seen[name]
                raise ModelError(
                    f"duplicate name '{name}': {what} clashes with {other} "
                    f"({oloc.file}:{oloc.line})", loc=scope.loc(loc), key=key,
                    hint=(f"in {inst.where()}; " if inst else "")
                    + "names share one namespace: rename one")
            seen[name] = (what, loc)

        for sec, what in (("constants", "constant"), ("parameters", "parameter"),
                          ("signals", "signal"), ("bodies", "body"), ("joints", "joint"),
                          ("elements", "element"), ("blocks", "block"),
                          ("outputs", "output")):
            entries = self._entries(body, sec)
            for name in entries:
                declare(name, f"{what} '{name}'", entries.key_locs[name], f"{sec}.{name}")
                if not model and sec != "constants":
                    scope.rename[name] = scope.prefix + name
        bonds = body.get("bonds")
        if isinstance(bonds, YList):
            for i, b in enumerate(bonds):
                if isinstance(b, YMap) and isinstance(b.get("name"), str):
                    declare(b["name"], f"bond '{b['name']}'", b.val_locs["name"],
                            f"bonds[{i}].name")
                    if not model:
                        scope.rename[b["name"]] = scope.prefix + b["name"]
                elif not model and f"b{i + 1}" not in seen:    # unnamed: NAME.b<k>
                    scope.rename[f"b{i + 1}"] = f"{scope.prefix}b{i + 1}"
        if not model:
            for pname, p in self._entries(body, "ports").items():
                if isinstance(p, YMap) and "external" in p:
                    declare(pname, f"external port '{pname}'",
                            self._entries(body, "ports").key_locs[pname], f"ports.{pname}")
            for bname, b in self._entries(body, "bodies").items():
                pts = b.get("points") if isinstance(b, YMap) else None
                for pt in pts if isinstance(pts, YMap) else ():
                    scope.points.setdefault(pt, []).append(bname)
        scope.declared = set(seen)
        for name, v in self._entries(body, "instances").items():
            for flat, _ in self._expand_names(name, v, self._entries(body, "instances"),
                                              scope):
                declare(flat, f"instance '{flat}'",
                        self._entries(body, "instances").key_locs[name],
                        f"instances.{name}")
        return seen

    # -- constants -------------------------------------------------------------------
    def _constants(self, body: YMap, scope: Scope, given: dict, key: str,
                   inst: Instance | None = None):
        """The constants of ``body`` (its own values, or ``given``: exact values that
        override them), each usable by the later ones; into ``scope``."""
        entries = self._entries(body, "constants")
        for name in given:
            if name not in entries:
                raise ModelError(f"{inst.where() if inst else 'the model'} has no constant "
                                 f"'{name}'", loc=inst.loc if inst else Loc(self.file, 1),
                                 key=f"{key}.{name}", hint="constants: " + (
                                     ", ".join(entries) or "none"))
        for name, v in entries.items():
            loc, k = entries.val_locs[name], f"constants.{name}"
            if isinstance(v, YMap):
                check_keys(v, ("value", "description"), k)
                if "value" not in v:
                    fail("missing 'value'", scope.loc(v.loc), k, "write {value: 40}")
                loc, v = v.val_locs["value"], v["value"]
            value = given[name] if name in given else self._constant(v, loc, k, scope)
            scope.consts[name] = value
            scope.subst[name] = _literal(value)

    def _constant(self, v, loc, key, scope: Scope) -> sp.Expr:
        """A compile-time value: a number or an expression of numbers, constants and
        indices (exact)."""
        if isinstance(v, bool) or not isinstance(v, (int, float, str)):
            fail(f"expected a number or an expression of constants, got {kind_of(v)}",
                 scope.loc(loc), key, "a constant is compile-time: e.g. 40 or \"2 * N\"")
        if not isinstance(v, str):
            try:
                return exact.rational(bexpr.number(v))
            except ValueError as exc:
                fail(f"expected a finite number: {exc}", scope.loc(loc), key)
        text = self._rewrite(v, scope, loc, key, numeric=False)
        e = bexpr.parse(text, loc=scope.loc(loc), key=key, names={})
        return _exact(sp.sympify(e))

    def _integer(self, v, loc, key, scope) -> int:
        e = self._constant(v, loc, key, scope)
        if not (e.is_Integer or (e.is_number and e == int(e))):
            fail(f"expected a whole number, got {v!r} = {sp.sstr(e)}", scope.loc(loc), key,
                 "an index range and a count are whole numbers")
        return int(e)

    # -- instances -------------------------------------------------------------------
    def _expand_names(self, name, v, sec: YMap, scope: Scope):
        """The flat names of an instance entry (an array: one per index) with the
        index values: [(local name, {index: value})]."""
        if not isinstance(name, str) or not IDENT.match(name) or "__" in name:
            fail(f"{name!r} is not a valid instance name", scope.loc(sec.key_locs[name]),
                 f"instances.{name}", "use letters, digits and single '_'")
        if not isinstance(v, YMap) or "for" not in v:
            return [(name, {})]
        rng = v["for"]
        key = f"instances.{name}.for"
        if not isinstance(rng, YMap) or not rng:
            fail("'for' maps an index to its range: {i: [first, last]}",
                 scope.loc(v.val_locs["for"]), key, "for: {i: [1, 4]} makes NAME_1 ... "
                 "NAME_4")
        combos = [({}, name)]
        for idx, r in rng.items():
            k = f"{key}.{idx}"
            if not isinstance(idx, str) or not IDENT.match(idx) or "__" in idx or \
                    idx in bexpr.RESERVED:
                fail(f"{idx!r} is not a valid index name", scope.loc(rng.key_locs[idx]), k)
            if idx in scope.consts or idx in scope.rename or idx in scope.subst or \
                    idx in scope.declared:
                fail(f"index '{idx}' is already a name here", scope.loc(rng.key_locs[idx]),
                     k, "give the index a name of its own")
            if not isinstance(r, YList) or len(r) != 2:
                fail("an index range is [first, last] (both included)",
                     scope.loc(rng.val_locs[idx]), k, "e.g. [1, 4] or [1, N]")
            lo, hi = (self._integer(x, r.item_locs[j], f"{k}[{j}]", scope)
                      for j, x in enumerate(r))
            if lo < 0:
                fail(f"an index starts at 0 or more, got {lo}", scope.loc(r.item_locs[0]),
                     k, "instance names are NAME_<index>")
            if hi - lo + 1 > MAX_INSTANCES:
                fail(f"{hi - lo + 1} instances are more than bgc's limit of "
                     f"{MAX_INSTANCES}", scope.loc(rng.val_locs[idx]), k)
            combos = [({**vals, idx: i}, f"{nm}_{i}") for vals, nm in combos
                      for i in range(lo, hi + 1)]
        return [(nm, vals) for vals, nm in combos]

    def _instances(self, body: YMap, scope: Scope):
        """Every instance of ``body``: its component found, its ports known (so that
        another instance or the body's own joints and bonds may name them), then each
        written out."""
        sec = self._entries(body, "instances")
        todo = []
        for name, v in sec.items():
            key = f"instances.{name}"
            if not isinstance(v, YMap):
                fail(f"expected a mapping with 'component', got {kind_of(v)}",
                     scope.loc(sec.val_locs[name]), key,
                     "NAME: {component: dc_motor, parameters: {...}, connect: {...}}")
            check_keys(v, INSTANCE_KEYS, key)
            if "component" not in v:
                fail("missing 'component'", scope.loc(v.loc), key,
                     "component: the name of a component (bgc library lists bgc's)")
            loc = scope.loc(sec.key_locs[name])
            where = f"instance '{scope.prefix}{name}' ({loc.file}:{loc.line})"
            d = self.src.lookup(v["component"], scope.file, scope.loc(v.val_locs["component"]),
                                f"{key}.component", where)
            for local, idx in self._expand_names(name, v, sec, scope):
                flat = scope.prefix + local
                inst = Instance(QName(flat), d.name, loc, d.loc, library=d.library)
                if flat in self.instances:
                    other = self.instances[flat]
                    raise ModelError(f"duplicate instance name '{flat}'", loc=loc, key=key,
                                     hint=f"already {other.where()}")
                if len(self.instances) >= MAX_INSTANCES:
                    fail(f"more than bgc's limit of {MAX_INSTANCES} instances", loc, key)
                self.instances[flat] = inst
                scope.insts[local] = inst
                todo.append((inst, d, v, idx, key))
        for inst, d, v, idx, key in todo:
            inst.ports = self._ports(d, inst)
            inst.names = {n for sec in NAMED + ("constants", "instances")
                          for n in self._entries(d.body, sec)}
        for inst, d, v, idx, key in todo:
            self._instantiate(inst, d, v, idx, key, scope)

    def _ports(self, d: Definition, inst: Instance, depth: int = 0) -> dict[str, Port]:
        """The ports ``d`` declares, their targets as ``inst``'s flat names (an
        external port's binding comes with ``connect``)."""
        body, out = d.body, {}
        ports = self._entries(body, "ports")
        via = f"{inst.name} ({inst.loc.file}:{inst.loc.line})"
        for pname, p in ports.items():
            loc = InstanceLoc(*_xyz(ports.key_locs[pname]), via)
            key = f"components.{d.name}.ports.{pname}"
            if not isinstance(pname, str) or not IDENT.match(pname) or "__" in pname:
                fail(f"{pname!r} is not a valid port name", loc, key)
            if not isinstance(p, YMap):
                fail(f"a port is a mapping such as {{body: NAME}}, got {kind_of(p)}", loc, key,
                     "kinds: " + ", ".join(PORT_KINDS))
            kinds = [k for k in p if k in PORT_KINDS]
            check_keys(p, PORT_KINDS + ("power", "description"), key)
            if len(kinds) != 1:
                fail(f"a port has one kind ({', '.join(PORT_KINDS)}), got "
                     f"{', '.join(kinds) or 'none'}", loc, key)
            kind, target = kinds[0], p[kinds[0]]
            if kind == "external":
                if target not in ("body", "element", "signal"):
                    fail(f"an external port is a body, an element or a signal, got "
                         f"{target!r}", loc, key,
                         "external: body (a body the instance's joints attach to), "
                         "external: element (an element its bonds end on) or "
                         "external: signal (an input it reads)")
                out[pname] = Port(pname, f"external {target}", loc=loc)
                continue
            if "power" in p and (kind != "element" or p["power"] not in ("in", "out")):
                fail("'power' is 'in' or 'out', on an element port", loc, f"{key}.power")
            if kind == "signal":
                out[pname] = Port(pname, kind, power=None, loc=loc,
                                  target=target if isinstance(target, str) else None)
                continue
            if not isinstance(target, str):
                fail(f"a {kind} port names a {kind} of the component, got {kind_of(target)}",
                     loc, key)
            out[pname] = Port(pname, kind, self._port_target(d, inst, kind, target, loc, key,
                                                             depth),
                              power=p.get("power"), loc=loc)
        return out

    def _port_target(self, d: Definition, inst: Instance, kind, target, loc, key,
                     depth: int = 0) -> str:
        """The flat name an exported port stands for: the component's own body, point
        (``body.P``), joint direction (``joint.tx``) or element, or a nested instance's
        port of that kind (``motor.shaft``)."""
        parts = target.split(".")
        sec = {"body": "bodies", "point": "bodies", "direction": "joints",
               "element": "elements"}[kind]
        want = {"body": 1, "point": 2, "direction": 2, "element": 1}[kind]
        own = self._entries(d.body, sec)
        nested = self._entries(d.body, "instances")
        if parts[0] in own and len(parts) == want:
            if kind == "point":
                pts = own[parts[0]].get("points") if isinstance(own[parts[0]], YMap) else None
                if not isinstance(pts, YMap) or parts[1] not in pts:
                    fail(f"port target '{target}': body '{parts[0]}' has no point "
                         f"'{parts[1]}'", loc, key, "a point port is body.point")
            return f"{inst.name}.{target}"
        entry = re.sub(r"(_[0-9]+)+$", "", parts[0]) if parts[0] not in nested else parts[0]
        sub = nested.get(entry) if len(parts) == 2 else None
        if isinstance(sub, YMap) and ((entry == parts[0]) == ("for" not in sub)):
            if depth > 32:
                fail("a cycle of components through their ports", loc, key,
                     "a component cannot contain itself")
            nd = self.src.lookup(sub.get("component"), d.file, loc, key,
                                 f"port '{target}' of component '{d.name}'")
            ports = self._ports(nd, Instance(QName(f"{inst.name}.{parts[0]}"), nd.name,
                                             inst.loc, nd.loc), depth + 1)
            p = ports.get(parts[1])
            if p is not None and p.kind == kind:
                return p.target
            fail(f"port target '{target}': component '{nd.name}' has no {kind} port "
                 f"'{parts[1]}'", loc, key, f"its {kind} ports: " + (", ".join(
                     n for n, q in ports.items() if q.kind == kind) or "none"))
        what = {"body": "body", "point": "body.point", "direction": "joint.direction",
                "element": "element"}[kind]
        fail(f"port target '{target}' is no {what} of component '{d.name}'", loc, key,
             f"a {kind} port names a {what} the component declares (or a nested "
             f"instance's {kind} port, instance.port)")

    def _instantiate(self, inst: Instance, d: Definition, v: YMap, idx: dict, key: str,
                     outer: Scope):
        """Write out one instance of ``d`` (its entry ``v`` in ``outer``; ``idx``: its
        index values)."""
        if any(x.file == d.file and x.name == d.name for x in self.stack):
            chain = " -> ".join(f"{x.name} ({x.loc.file}:{x.loc.line})"
                                for x in self.stack + [d])
            raise ModelError(f"a cycle of components: {chain}", loc=inst.loc, key=key,
                             hint="a component cannot contain itself, directly or through "
                                  "others")
        here = Scope(outer.file, outer.prefix, outer.R, outer.o, outer.via,
                     dict(outer.rename), dict(outer.subst), dict(outer.consts),
                     outer.insts, outer.points)
        for i, val in idx.items():
            here.consts[i] = sp.Integer(val)
            here.subst[i] = ast.Constant(val)
            here.rename.pop(i, None)
        R, o = self._placement(v, key, here)
        via = f"{inst.name} ({inst.loc.file}:{inst.loc.line})"
        scope = Scope(d.file, inst.name + ".", outer.R * R, outer.o + outer.R * o,
                      via if not outer.via else f"{via} in {outer.via}")
        body = d.body
        check_keys(body, COMPONENT_KEYS, f"components.{d.name}")
        self.stack.append(d)
        given = {n: x for n, (x, _) in
                 self._overrides(v, "constants", key, here, exact_values=True).items()}
        self._constants(body, scope, given, f"{key}.constants", inst)
        self._namespace(body, scope, model=False, inst=inst)
        self._parameters(body, scope, self._overrides(v, "parameters", key, here), inst, key)
        self._connect(body, scope, inst, v, key, here)
        self._instances(body, scope)
        self._contents(body, scope, self.flat, model=False)
        for p in inst.ports.values():        # signal outputs: expressions of the instance
            if p.kind == "signal":
                ploc = p.loc
                if p.target is None:
                    fail("a signal port is an expression of the component's variables",
                         ploc, f"components.{d.name}.ports.{p.name}",
                         "e.g. speed: {signal: rotor.f}")
                p.expr = ast.parse(self._rewrite(p.target, scope, ploc, p.name),
                                   mode="eval").body
        self.stack.pop()

    def _placement(self, v: YMap, key, scope: Scope) -> tuple[sp.Matrix, sp.Matrix]:
        """An instance's frame in its container's: ``origin`` [x, y, z] and ``rotate``
        ({x|y|z: degrees} or a list of them, each about the frame's axes as turned by
        the ones before), exact."""
        o = sp.zeros(3, 1)
        if "origin" in v:
            o = self._exact_vector(v["origin"], v.val_locs["origin"], f"{key}.origin", scope)
        R = sp.eye(3)
        if "rotate" in v:
            rot, loc = v["rotate"], v.val_locs["rotate"]
            items = list(zip(rot, rot.item_locs)) if isinstance(rot, YList) else [(rot, loc)]
            for j, (r, rloc) in enumerate(items):
                k = f"{key}.rotate" + (f"[{j}]" if isinstance(rot, YList) else "")
                if not isinstance(r, YMap) or len(r) != 1 or next(iter(r)) not in "xyz" \
                        or len(next(iter(r))) != 1:
                    fail("a rotation is {x|y|z: degrees}", scope.loc(rloc), k,
                         "rotate: {z: 45}, or a list [{z: 45}, {x: 20}] (each about the "
                         "frame's own axes, in order)")
                axis = next(iter(r))
                deg = self._constant(r[axis], r.val_locs[axis], f"{k}.{axis}", scope)
                R = R * _rotation(axis, deg * sp.pi / 180)
        return R, o

    def _overrides(self, v: YMap, sec, key, scope: Scope, exact_values=False) -> dict:
        """An instance's ``parameters:`` or ``constants:``: name -> value, rewritten in
        the scope that contains the instance (constants: exact values; parameters: a
        number, or an expression node of the outer model's names)."""
        if sec not in v:
            return {}
        m = v[sec]
        if not isinstance(m, YMap):
            fail(f"'{sec}' maps names to values, got {kind_of(m)}",
                 scope.loc(v.val_locs[sec]), f"{key}.{sec}")
        out = {}
        for name, x in m.items():
            loc, k = m.val_locs[name], f"{key}.{sec}.{name}"
            if exact_values:
                out[name] = (self._constant(x, loc, k, scope), scope.loc(loc))
                continue
            if isinstance(x, bool) or not isinstance(x, (int, float, str)):
                fail(f"expected a number or an expression of parameters, got {kind_of(x)}",
                     scope.loc(loc), k, "e.g. k: 700 or k: \"2 * k_leg\"")
            if isinstance(x, str):
                out[name] = (self._node(x, scope, loc, k), scope.loc(loc))
            else:
                out[name] = (x, scope.loc(loc))
        return out

    def _parameters(self, body: YMap, scope: Scope, given: dict, inst: Instance, key):
        """A component's parameters: each the instance's own model parameter
        (``leg_1.k``: its default or the number the instance gives), or the
        instance's expression of the outer model's parameters, put in where it is read."""
        entries = self._entries(body, "parameters")
        for name, (x, loc) in given.items():
            if name not in entries:
                consts = self._entries(body, "constants")
                raise ModelError(
                    f"{inst.where()} has no parameter '{name}'", loc=loc,
                    key=f"{key}.parameters.{name}",
                    hint=("it is a constant: give it under constants:" if name in consts
                          else "its parameters: " + (", ".join(entries) or "none")))
        out = self.flat.setdefault("parameters", _ymap())
        for name, v in entries.items():
            loc = entries.val_locs[name]
            if name in given:
                x, gloc = given[name]
                if isinstance(x, ast.AST):
                    value = self._evaluate(x)
                    if value is None:           # an expression of outer parameters
                        scope.subst[name] = x
                        scope.rename.pop(name, None)
                        continue
                    x = value
                if isinstance(v, YMap):
                    v = self._copy(v, scope)
                    v["value"] = x
                    v.val_locs["value"] = gloc
                else:
                    v = x
                    loc = gloc
            elif isinstance(v, YMap):
                v = self._map_exprs(v, scope, f"parameters.{name}")
            elif isinstance(v, str):
                v = self._rewrite(v, scope, loc, f"parameters.{name}")
            flat = QName(scope.prefix + name)
            out[flat] = v
            out.key_locs[flat] = scope.loc(entries.key_locs[name])
            out.val_locs[flat] = scope.loc(loc)

    def _evaluate(self, node) -> float | None:
        """The value of an expression that reads no names (but pi), else None."""
        if _names(node) - {"pi"}:
            return None
        e = bexpr.parse(ast.unparse(node), loc=Loc(self.file, 1), key="value", names={})
        return float(e)

    def _connect(self, body: YMap, scope: Scope, inst: Instance, v: YMap, key, outer: Scope):
        """Bind the component's external ports: a body to a body of the outside (or
        another instance's body port, or fixed_frame), a signal to an expression of the
        outside. Every external port must be connected."""
        m = v.get("connect")
        if m is not None and not isinstance(m, YMap):
            fail(f"'connect' maps external ports to what they join, got {kind_of(m)}",
                 outer.loc(v.val_locs["connect"]), f"{key}.connect")
        m = m if m is not None else _ymap()
        for name in m:
            p = inst.ports.get(name)
            if p is None or not p.kind.startswith("external"):
                ext = [n for n, q in inst.ports.items() if q.kind.startswith("external")]
                what = (f"'{name}' is a {p.kind} port, which the outside joins with a joint "
                        "or a bond, not in connect:" if p else f"no external port '{name}'")
                raise ModelError(f"{inst.where()}: {what}", loc=outer.loc(m.key_locs[name]),
                                 key=f"{key}.connect.{name}",
                                 hint="its external ports: " + (", ".join(ext) or "none"))
        for pname, p in inst.ports.items():
            if not p.kind.startswith("external"):
                continue
            if pname not in m:
                raise ModelError(f"{inst.where()}: external port '{pname}' "
                                 f"({p.kind}) is not connected", loc=inst.loc,
                                 key=f"{key}.connect",
                                 hint=f"connect: {{{pname}: "
                                      + {"external body": "a body}",
                                         "external element": "an element}"}.get(
                                          p.kind, "an expression}"))
            x, loc, k = m[pname], m.val_locs[pname], f"{key}.connect.{pname}"
            if isinstance(x, str):
                x = self._interpolate(x, outer, loc, k)
            if p.kind == "external body":
                if not isinstance(x, str):
                    fail(f"expected the name of a body, got {kind_of(x)}", outer.loc(loc), k,
                         "a body of the model, another instance's body port, or "
                         "fixed_frame")
                scope.rename[pname] = self._conn(x, outer, "body", loc, k)
            elif p.kind == "external element":
                if not isinstance(x, str):
                    fail(f"expected the name of an element, got {kind_of(x)}",
                         outer.loc(loc), k, "an element of the model (a junction most "
                         "often), another instance's element port, or a port of the "
                         "mechanism (joint.tx)")
                scope.rename[pname] = self._conn(x, outer, "end", loc, k)
            else:
                if isinstance(x, bool) or not isinstance(x, (int, float, str)):
                    fail(f"expected an expression, got {kind_of(x)}", outer.loc(loc), k)
                scope.subst[pname] = (self._node(x, outer, loc, k) if isinstance(x, str)
                                      else ast.Constant(x))
                scope.rename.pop(pname, None)

    def _interpolate(self, text: str, scope: Scope, loc, key) -> str:
        """``{expr}`` in a name: the whole number the expression of indices and constants
        gives (``w_{i - 1}.crank`` in a connect value, ``c_{N}.v`` in a bond)."""
        def one(m):
            return str(self._integer(m.group(1), loc, key, scope))
        return re.sub(r"\{([^{}]*)\}", one, text)

    # -- the contents of a model or component ---------------------------------------
    def _contents(self, body: YMap, scope: Scope, into: dict, model: bool):
        """Its signals, bodies, joints, elements, blocks and outputs (renamed, rewritten,
        placed) into ``into`` (section -> mapping); its bonds: returned (the model's)
        or added to the flat document's (None: the model's bonds are not a list; the
        reader refuses them)."""
        for sec in NAMED:
            if sec == "parameters":
                continue
            if sec in body and body[sec] is not None and not isinstance(body[sec], YMap):
                if model:
                    continue        # the reader refuses it
                fail(f"expected a mapping, got {kind_of(body[sec])}",
                     scope.loc(body.val_locs[sec]), sec)
            entries = self._entries(body, sec)
            if not entries:
                continue
            out = into.setdefault(sec, _ymap(scope.loc(entries.loc)))
            for name, v in entries.items():
                flat = name if model else QName(scope.prefix + name)
                nv = getattr(self, "_" + sec)(v, entries.val_locs[name], f"{sec}.{flat}",
                                              scope)
                out[flat] = nv
                out.key_locs[flat] = scope.loc(entries.key_locs[name])
                out.val_locs[flat] = scope.loc(entries.val_locs[name])
        bonds = body.get("bonds")
        if not isinstance(bonds, YList):
            return [] if bonds is None or not model else None
        made = [(self._bond(b, bonds.item_locs[i], i, scope, model),
                 scope.loc(bonds.item_locs[i])) for i, b in enumerate(bonds)]
        if model:
            return made
        self.bonds.extend(made)
        return []

    # per section: an entry rewritten
    def _signals(self, v, loc, key, scope):
        return self._map_exprs(v, scope, key) if isinstance(v, YMap) else v

    def _bodies(self, v, loc, key, scope):
        if not isinstance(v, YMap):
            return v
        out = self._copy(v, scope)
        for k in v:
            kk, kloc = f"{key}.{k}", v.val_locs[k]
            x = v[k]
            if k == "mass":
                out[k] = self._rewrite(x, scope, kloc, kk) if isinstance(x, str) else x
            elif k == "com":
                out[k] = self._vector(x, kloc, kk, scope, "point")
            elif k == "frame":
                out[k] = self._frame(x, kloc, kk, scope)
            elif k in ("points", "directions") and isinstance(x, YMap):
                m = self._copy(x, scope)
                for pn in x:
                    m[pn] = self._vector(x[pn], x.val_locs[pn], f"{kk}.{pn}", scope,
                                         "point" if k == "points" else "direction")
                out[k] = m
            elif k in ("velocity", "omega"):
                out[k] = self._vector(x, kloc, kk, scope, "turn")
            elif k == "inertia":
                out[k] = self._exprs(x, scope, kloc, kk)
        if scope.placed and "frame" not in v:
            out["frame"] = self._axes(scope, v.loc)
            out.key_locs["frame"] = out.val_locs["frame"] = scope.loc(v.loc)
        return out

    def _joints(self, v, loc, key, scope):
        if not isinstance(v, YMap):
            return v
        out = self._copy(v, scope)
        for k in v:
            kk, kloc, x = f"{key}.{k}", v.val_locs[k], v[k]
            if k == "between" and isinstance(x, YList):
                out[k] = _ylist([self._conn(b, scope, "body", x.item_locs[i], f"{kk}[{i}]")
                                 for i, b in enumerate(x)],
                                [scope.loc(lc) for lc in x.item_locs], scope.loc(x.loc))
            elif k == "at":
                out[k] = (self._conn(x, scope, "at", kloc, kk) if isinstance(x, str)
                          else self._vector(x, kloc, kk, scope, "point"))
            elif k in ("axis", "axis2"):
                out[k] = self._vector(x, kloc, kk, scope, "direction")
            elif k == "frame":
                out[k] = self._frame(x, kloc, kk, scope)
            elif k not in LITERAL:
                out[k] = self._exprs(x, scope, kloc, kk)
        if scope.placed:
            self._default_axes(v, out, key, scope)
        return out

    def _default_axes(self, v: YMap, out: YMap, key, scope: Scope):
        """In a placed component the defaults are the component frame's: axis [1, 0,
        0], axis2 the frame's axis most nearly perpendicular to axis (as
        ``sections.joints`` chooses in R0), both written out turned."""
        try:
            x = exact.unit(self._exact_vector(v["axis"], v.val_locs["axis"], f"{key}.axis",
                                              scope) if "axis" in v else sp.Matrix([1, 0, 0]))
        except ModelError:
            return                      # the reader reports it
        if "axis" not in v:
            out["axis"] = self._text_vector(scope.R * x)
            out.key_locs["axis"] = out.val_locs["axis"] = scope.loc(v.loc)
        if "axis2" not in v and exact.to_float(exact.norm(x)) > 1e-12:
            xf = [abs(c) for c in exact.floats(x)]
            e = sp.Matrix([int(i == xf.index(min(xf))) for i in range(3)])
            y = exact.unit(e - e.dot(x) * x)
            out["axis2"] = self._text_vector(scope.R * y)
            out.key_locs["axis2"] = out.val_locs["axis2"] = scope.loc(v.loc)

    def _elements(self, v, loc, key, scope):
        return self._map_exprs(v, scope, key) if isinstance(v, YMap) else v

    def _blocks(self, v, loc, key, scope):
        return self._map_exprs(v, scope, key) if isinstance(v, YMap) else v

    def _outputs(self, v, loc, key, scope):
        if isinstance(v, YMap):
            return self._map_exprs(v, scope, key)
        return self._rewrite(v, scope, loc, key) if isinstance(v, str) else v

    def _bond(self, b, loc, i, scope: Scope, model: bool):
        key = f"bonds[{i}]"
        if isinstance(b, YList) and len(b) == 2:
            ends = [self._conn(e, scope, "end", b.item_locs[j], f"{key}[{j}]")
                    for j, e in enumerate(b)]
            self._check_power(b[0], b[1], scope, loc, key)
            if model:
                return _ylist(ends, b.item_locs, b.loc)
            out = _ymap(scope.loc(b.loc))      # a component's bond: named NAME.b<k>
            for k, x, xl in (("name", QName(f"{scope.prefix}b{i + 1}"), b.loc),
                             ("from", ends[0], b.item_locs[0]), ("to", ends[1],
                                                                 b.item_locs[1])):
                out[k] = x
                out.key_locs[k] = out.val_locs[k] = scope.loc(xl)
            return out
        if isinstance(b, YMap):
            out = self._copy(b, scope)
            for k in ("from", "to"):
                if k in b:
                    out[k] = self._conn(b[k], scope, "end", b.val_locs[k], f"{key}.{k}")
            if "from" in b and "to" in b:
                self._check_power(b["from"], b["to"], scope, loc, key)
            if "name" in b and isinstance(b["name"], str) and not model:
                out["name"] = QName(scope.prefix + b["name"])
            elif not model and "name" not in b:
                out["name"] = QName(f"{scope.prefix}b{i + 1}")
                out.key_locs["name"] = out.val_locs["name"] = scope.loc(b.loc)
            return out
        return b

    def _check_power(self, src, dst, scope: Scope, loc, key):
        """A bond to an element port that declares its ``power`` must draw it that way."""
        for end, into in ((src, False), (dst, True)):
            p = self._port_of(end, scope)
            if p is None or p.power is None:
                continue
            if (p.power == "in") != into:
                inst = end.split(".")[0]
                raise ModelError(
                    f"port '{end}' takes power {p.power}, but this bond draws it "
                    f"{'in' if into else 'out'}", loc=scope.loc(loc), key=key,
                    hint=f"write the bond {'[' + end + ', ...]' if p.power == 'out' else '[..., ' + end + ']'}"
                         f" (power flows from -> to); {scope.insts[inst].where()}")

    def _port_of(self, name, scope: Scope) -> Port | None:
        if not isinstance(name, str) or "." not in name:
            return None
        head, port = name.split(".")[:2]
        inst = scope.insts.get(head)
        return inst.ports.get(port) if inst is not None else None

    def _excitation(self, v, scope: Scope):
        if not isinstance(v, YMap):
            return v
        out = self._copy(v, scope)
        dirs = v.get("directions")
        if isinstance(dirs, YMap):
            d_out = self._copy(dirs, scope)
            for name, d in dirs.items():
                if isinstance(d, YMap):
                    m = self._map_exprs(d, scope, f"excitation.directions.{name}",
                                        skip=("joint", "direction"))
                    if isinstance(d.get("joint"), str):
                        m["joint"] = self._conn(d["joint"], scope, "joint",
                                                d.val_locs["joint"],
                                                f"excitation.directions.{name}.joint")
                    d_out[name] = m
            out["directions"] = d_out
        kinds = v.get("kinds")
        if isinstance(kinds, YMap):
            k_out = self._copy(kinds, scope)
            for name, s in kinds.items():
                k_out[name] = self._map_exprs(s, scope, f"excitation.kinds.{name}") \
                    if isinstance(s, YMap) else s
            out["kinds"] = k_out
        return out

    # -- connections -----------------------------------------------------------------
    def _conn(self, name, scope: Scope, want: str, loc, key) -> str:
        """A name in a place that connects (a joint's bodies, its point, a bond's end,
        an excitation's joint) as its flat name: an instance's name must go through one
        of its ports of the right kind."""
        if not isinstance(name, str) or name == FIXED_FRAME:
            return name
        if "{" in name:
            name = self._interpolate(name, scope, loc, key)
        parts = name.split(".")
        head = parts[0]
        if head in scope.insts and (want != "joint" or len(parts) == 1):
            inst = scope.insts[head]
            kinds = {"body": ("body",), "at": ("point", "body"),
                     "end": ("element", "direction", "point", "body"),
                     "joint": ()}[want]
            ports = [n for n, p in inst.ports.items() if p.kind in kinds]
            if len(parts) < 2 or parts[1] not in inst.ports:
                what = (f"no port '{parts[1]}'" if len(parts) >= 2 else "is an instance")
                raise ModelError(f"'{name}': {inst.where()} has {what}" if len(parts) >= 2
                                 else f"'{name}' {what}, not a "
                                      f"{ {'body': 'body', 'at': 'point', 'end': 'bond end', 'joint': 'joint'}[want]}",
                                 loc=scope.loc(loc), key=key,
                                 hint="an instance is joined through its ports: " + (
                                     ", ".join(f"{head}.{n}" for n in ports) or "none here"))
            p = inst.ports[parts[1]]
            rest = parts[2:]
            ok = {"body": p.kind == "body" and not rest,
                  "at": (p.kind == "point" and not rest) or (p.kind == "body"
                                                              and len(rest) == 1),
                  "end": (p.kind in ("element", "direction") and not rest)
                  or (p.kind == "point" and len(rest) == 1)
                  or (p.kind == "body" and len(rest) == 2)}.get(want, False)
            if not ok:
                use = {"body": "a body port", "at": "a point port (or body port.point)",
                       "end": "an element or direction port, point port.direction or "
                              "body port.point.direction"}[want]
                raise ModelError(f"'{name}': port '{parts[1]}' of {inst.where()} is a "
                                 f"{p.kind} port; here {use} is needed", loc=scope.loc(loc),
                                 key=key, hint="its ports here: " + (
                                     ", ".join(f"{head}.{n}" for n in ports) or "none"))
            return QName(".".join([p.target, *rest]))
        if head in scope.rename:
            return QName(".".join([scope.rename[head], *parts[1:]]))
        if want == "at" and len(parts) == 1 and head in scope.points:
            owners = scope.points[head]
            if len(owners) == 1:
                return QName(f"{scope.prefix}{owners[0]}.{head}")
        return name

    # -- expressions -----------------------------------------------------------------
    def _node(self, text: str, scope: Scope, loc, key) -> ast.AST:
        """An expression of ``scope`` as a node in flat names."""
        rewritten = self._rewrite(text, scope, loc, key)
        if not isinstance(rewritten, str):
            return _const_node(rewritten)
        try:
            return ast.parse(rewritten.strip(), mode="eval").body
        except SyntaxError:
            fail(f"cannot parse expression {text!r}", scope.loc(loc), key,
                 "use Python syntax: + - * / ** and function calls")

    def _rewrite(self, text, scope: Scope, loc, key, numeric: bool = True):
        """An expression text in flat names: the scope's constants, indices, inlined
        parameters and signal inputs put in, its local names prefixed, instances' signal
        ports replaced by their expressions. Text that is not an expression, or that
        names nothing of the scope, comes back as it is (its reader judges it); one that
        reads no name once rewritten is its value (a number) where ``numeric``."""
        if not isinstance(text, str) or len(text) > bexpr.MAX_CHARS:
            return text
        if "{" in text:         # no expression holds braces: names made of constants
            text = self._interpolate(text, scope, loc, key)
        try:
            tree = ast.parse(text.strip(), mode="eval")
        except (SyntaxError, RecursionError, MemoryError, ValueError):
            return text
        changed = [False]

        def visit(node):
            if isinstance(node, ast.Call):
                node.args = [visit(a) for a in node.args]
                return node
            parts = _chain(node) if isinstance(node, (ast.Name, ast.Attribute)) else None
            if parts is not None:
                new = self._ref(parts, scope, loc, key)
                if new is not None:
                    changed[0] = True
                    return new
                return node
            for name, value in ast.iter_fields(node):
                if isinstance(value, ast.AST):
                    setattr(node, name, visit(value))
                elif isinstance(value, list):
                    setattr(node, name, [visit(x) if isinstance(x, ast.AST) else x
                                         for x in value])
            return node

        try:
            body = visit(tree.body)
        except RecursionError:
            return text
        if not changed[0]:
            return text
        if numeric and not (_names(body) - {"pi"}):
            value = self._try_value(body)
            if value is not None:
                return value
        return ast.unparse(body)

    def _try_value(self, node):
        """A constant expression's number (a float), or None if it has none."""
        try:
            e = bexpr.parse(ast.unparse(node), loc=Loc(self.file, 1), key="value", names={})
            v = float(e)
        except (ModelError, TypeError, ValueError, OverflowError):
            return None
        return int(v) if v.is_integer() and abs(v) < 2 ** 53 and \
            isinstance(e, sp.Integer) else v

    def _ref(self, parts: list[str], scope: Scope, loc, key) -> ast.AST | None:
        """The flat form of a name or reference ``parts`` in ``scope`` (None: as is)."""
        head = parts[0]
        if head in scope.subst:
            if len(parts) == 1:
                return copy.deepcopy(scope.subst[head])
            return None
        if head in scope.insts:
            inst = scope.insts[head]
            if len(parts) >= 2 and parts[1] in inst.ports and (
                    parts[1] not in inst.names or inst.ports[parts[1]].kind == "signal"):
                p = inst.ports[parts[1]]
                if p.kind == "signal":
                    if p.expr is None:
                        fail(f"'{head}.{parts[1]}': the signal port of {inst.where()} is "
                             "read before the instance is written out", scope.loc(loc), key,
                             "instances are written out in file order; read another's "
                             "signal port after it")
                    return copy.deepcopy(p.expr) if len(parts) == 2 else None
                if p.target is not None:
                    return _dotted(".".join([p.target, *parts[2:]]))
            if scope.prefix:
                return _dotted(".".join([inst.name, *parts[1:]]))
            return None
        if head in scope.rename:
            return _dotted(".".join([scope.rename[head], *parts[1:]]))
        return None

    def _exprs(self, x, scope: Scope, loc, key):
        """A value that is an expression, or a list (vector, matrix) or mapping of
        them, rewritten."""
        if isinstance(x, str):
            return self._rewrite(x, scope, loc, key)
        if isinstance(x, YList):
            return _ylist([self._exprs(y, scope, x.item_locs[i], f"{key}[{i}]")
                           for i, y in enumerate(x)],
                          [scope.loc(lc) for lc in x.item_locs], scope.loc(x.loc))
        if isinstance(x, YMap):
            return self._map_exprs(x, scope, key)
        return x

    def _map_exprs(self, m: YMap, scope: Scope, key, skip=()) -> YMap:
        out = self._copy(m, scope)
        for k in m:
            if k in LITERAL or k in skip:
                continue
            out[k] = self._exprs(m[k], scope, m.val_locs[k], f"{key}.{k}")
        return out

    def _copy(self, m: YMap, scope: Scope) -> YMap:
        """A shallow copy of a mapping with its locations as the scope shows them."""
        out = _ymap(scope.loc(m.loc))
        for k, v in m.items():
            out[k] = v
            out.key_locs[k] = scope.loc(m.key_locs[k])
            out.val_locs[k] = scope.loc(m.val_locs[k])
        return out

    # -- geometry ----------------------------------------------------------------------
    def _exact_vector(self, v, loc, key, scope: Scope) -> sp.Matrix:
        """[x, y, z] of numbers or expressions of constants and indices, exact."""
        if not isinstance(v, YList) or len(v) != 3:
            fail(f"expected [x, y, z], got {kind_of(v)}", scope.loc(loc), key)
        out = []
        for i, x in enumerate(v):
            k, xl = f"{key}[{i}]", v.item_locs[i]
            if isinstance(x, bool) or not isinstance(x, (int, float, str)):
                fail(f"expected a number, got {kind_of(x)}", scope.loc(xl), k)
            if isinstance(x, str):
                text = self._rewrite(x, scope, xl, k, numeric=False)
                hit = self.geometry.get(text)       # the instances of an array: one text
                if hit is None:
                    try:
                        e = bexpr.parse(text, loc=scope.loc(xl), key=k, names={})
                    except ModelError as exc:
                        raise ModelError(exc.message, loc=exc.loc, key=k,
                                         hint="positions, axes and angles are compile-time: "
                                              "numbers, constants and indices (not "
                                              "parameters)") from None
                    hit = self.geometry[text] = _exact(sp.sympify(e))
                out.append(hit)
            else:
                out.append(exact.rational(x))
        return sp.Matrix(out)

    def _text_vector(self, m: sp.Matrix, loc=None) -> YList:
        """An exact vector as the values a reader takes: a rational as itself (a number,
        or its text where its decimal does not end), an irrational as its correctly
        rounded double (``exact.to_float``: canonical, the same on every machine; the
        readers keep a body's and a joint's geometry as such doubles anyway)."""
        scale = max((abs(exact.to_float(e)) for e in m), default=1.0) or 1.0
        items = [_number(e) if e.is_Rational else exact.to_float(e, scale) for e in m]
        return _ylist(items, [loc] * 3, loc)

    def _vector(self, v, loc, key, scope: Scope, kind: str):
        """A position (``point``: R x + o), a direction (``direction``: R x) or a vector
        of R0 (``turn``: a velocity; expressions of parameters allowed) of a component,
        in R0; as it is where nothing changes it."""
        if not isinstance(v, YList) or len(v) != 3:
            return self._exprs(v, scope, loc, key)      # the reader reports it
        has_text = any(isinstance(x, str) for x in v)
        if kind == "expr":
            return self._exprs(v, scope, loc, key)
        if not scope.placed and not has_text:
            return v
        if kind == "turn":
            items = [self._rewrite(x, scope, v.item_locs[i], f"{key}[{i}]")
                     if isinstance(x, str) else x for i, x in enumerate(v)]
            if not scope.placed:
                return _ylist(items, [scope.loc(lc) for lc in v.item_locs], scope.loc(loc))
            if all(not isinstance(x, str) for x in items):
                return self._text_vector(scope.R * sp.Matrix([exact.rational(x)
                                                              for x in items]),
                                         scope.loc(loc))
            rows = []
            for r in range(3):
                terms = [f"({sp.sstr(scope.R[r, c])})*({items[c]})" for c in range(3)
                         if scope.R[r, c] != 0 and items[c] != 0]
                rows.append(" + ".join(terms) if terms else 0)
            return _ylist(rows, [scope.loc(loc)] * 3, scope.loc(loc))
        x = self._exact_vector(v, loc, key, scope)
        w = scope.R * x + (scope.o if kind == "point" else sp.zeros(3, 1))
        return self._text_vector(w, scope.loc(loc))

    def _frame(self, v, loc, key, scope: Scope):
        if not isinstance(v, YMap):
            return v
        out = self._copy(v, scope)
        for a in v:
            out[a] = self._vector(v[a], v.val_locs[a], f"{key}.{a}", scope, "direction")
        return out

    def _axes(self, scope: Scope, loc) -> YMap:
        """The component frame's axes in R0, as a body's ``frame``."""
        out = _ymap(scope.loc(loc))
        for j, a in enumerate("xyz"):
            out[a] = self._text_vector(scope.R[:, j], scope.loc(loc))
            out.key_locs[a] = out.val_locs[a] = scope.loc(loc)
        return out


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
