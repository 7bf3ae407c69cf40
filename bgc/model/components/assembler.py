"""Components: the assembler that writes a model and its instances out flat: the
model's sections, its names, constants and instances (their ports, placement,
parameters and connections); the contents of each scope (``contents.Contents``) and its
expressions and geometry (``expressions.Expressions``) are its other parts."""

from __future__ import annotations

import ast
import re

import sympy as sp

from bgc.errors import Loc, ModelError
from bgc.mechanics import exact
from bgc.model import expr as bexpr
from bgc.model.components.contents import Contents
from bgc.model.components.expressions import Expressions
from bgc.model.components.scope import (
    COMPONENT_KEYS,
    INSTANCE_KEYS,
    MAX_INSTANCES,
    NAMED,
    PORT_KINDS,
    Instance,
    InstanceLoc,
    Port,
    QName,
    Scope,
    _exact,
    _literal,
    _names,
    _rotation,
    _xyz,
    _ylist,
    _ymap,
)
from bgc.model.document import YList, YMap
from bgc.model.library import ASSEMBLY_KEYS, Definition, Sources
from bgc.model.values import IDENT, check_keys, fail, kind_of


class Assembler(Contents, Expressions):
    """A model document and its instances written out flat (``flatten``)."""

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
