"""Components: the contents of a model or of an instance's component written into the
flat document (signals, bodies, joints, elements, blocks, outputs, bonds, excitation,
each entry renamed and rewritten) and the names its connections reach: the
``Contents`` part of the assembler."""

from __future__ import annotations

import sympy as sp

from bgc.errors import ModelError
from bgc.mechanics import exact
from bgc.model.components.scope import (
    FIXED_FRAME,
    LITERAL,
    NAMED,
    Port,
    QName,
    Scope,
    _ylist,
    _ymap,
)
from bgc.model.document import YList, YMap
from bgc.model.values import fail, kind_of


class Contents:
    """A scope's sections and connections in the flat document (a part of
    ``assembler.Assembler``)."""

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
