"""What the readers of a model's sections share while one model loads: the global
namespace (every declared name and where), the parameters' values (so a constant part of
an expression is judged at its line), and the bodies, points and joints read so far (which
``element.attr`` references and joint points resolve against)."""

from __future__ import annotations

import keyword

import sympy as sp

from bgc.errors import Loc
from bgc.model import expr as bexpr
from bgc.model import symbols
from bgc.model.model import KINDS, Block, Body, Joint, Settings
from bgc.model.values import IDENT, fail, mapping


class Context:
    """The state of one model's load, filled section by section."""

    def __init__(self, file: str):
        self.file = file
        self.names: dict[str, tuple[str, Loc]] = {}   # global namespace: name -> (what, loc)
        self.bodies: dict[str, Body] = {}
        self.point_r0: dict[tuple[str, str], sp.Matrix] = {}   # (body, point) -> exact R0
        self.joints: dict[str, Joint] = {}
        self.ports: dict = {}               # ports the bonds reach: name -> model.Port
        self.blocks: dict[str, str] = {}    # control blocks' kinds, once their names are read
        self.multibond: set[str] = set()    # bonds and elements on bonds of dimension > 1
        self.pvals: dict = {}               # parameter symbol -> value, once parsed
        self.overridden: set = set()        # parameters given by -p (``loads`` overrides)
        self.t_end = Settings.t_end         # the model's, once its settings are read

    def parse(self, text, **kw) -> sp.Expr:
        """``bexpr.parse`` with the parameters' values known, so a part that is constant
        given them (``1/Z`` with ``Z: 0``, ``log(Z)``) is judged at its line."""
        return bexpr.parse(text, values=self.pvals, **kw)

    def declare(self, name, what, loc, key):
        """Enter ``name`` (``what`` it names, e.g. "body 'b'") in the global namespace: a
        valid identifier, not reserved, not already declared."""
        from bgc.model.components import QName
        parts = name.split(".") if isinstance(name, QName) else [name]
        if not all(isinstance(p, str) and IDENT.match(p) and not keyword.iskeyword(p)
                   for p in parts):
            fail(f"{name!r} is not a valid name", loc, key,
                 "use letters, digits and '_', not starting with a digit")
        if "__" in name:
            fail(f"'{name}' contains '__', which bgc keeps for the names it generates",
                 loc, key, "use a single '_'")
        if parts[-1] in bexpr.RESERVED:
            fail(f"'{name}' is a reserved name", loc, key,
                 "reserved: " + ", ".join(sorted(bexpr.RESERVED)))
        if name in self.names:
            other, oloc = self.names[name]
            fail(f"duplicate name '{name}'", loc, key,
                 f"already used by {other} at line {oloc.line}")
        self.names[name] = (what, loc)

    @staticmethod
    def expr_names(params, signals=()) -> dict[str, sp.Expr]:
        """What a bare name in an expression may be: a parameter, a signal or ``t``."""
        names = {n: symbols.param(n) for n in params}
        names.update({n: symbols.signal(n) for n in signals})
        names["t"] = symbols.t
        return names

    def resolve_ref(self, target, attr, kinds, bond_names, key, loc):
        """The symbol of a reference ``target.attr`` in an expression: a body's or a
        point's coordinate, a joint's or a joint direction's, a bond's or an element's
        variable, a control block's output or input (``kinds``: the elements' kinds by
        name; ``bond_names``: the bonds')."""
        owner = target.rpartition(".")[0]
        known = (target in self.blocks or target in self.joints or target in self.bodies
                 or target in bond_names or target in kinds)
        if not known and owner in self.joints:          # joint.direction.attr
            return self._direction_ref(target, attr, key, loc)
        if not known and owner:                         # body.point.attr
            return self._point_ref(target, attr, key, loc)
        if target in self.blocks:
            if attr not in Block.ATTRS:
                fail(f"block '{target}' has no '.{attr}'", loc, key,
                     f"valid: {target}.y (its output), {target}.u (its input)")
            return symbols.ref(target, attr)
        if target in self.joints:
            if attr not in Joint.ATTRS:
                fail(f"joint '{target}' has no '.{attr}'", loc, key,
                     "valid: " + ", ".join(f"{target}.{a}" for a in Joint.ATTRS))
            return symbols.ref(target, attr)
        if target in self.bodies:
            valid = Body.ATTRS if self.bodies[target].mass > 0 else Body.ATTRS[:12]
            if attr not in valid:
                fail(f"body '{target}' has no '.{attr}'", loc, key,
                     "valid: " + ", ".join(f"{target}.{a}" for a in valid))
            return symbols.ref(target, attr)
        vector = target in self.multibond
        if target in bond_names:
            valid = ("ex", "ey", "ez", "fx", "fy", "fz") if vector else ("e", "f")
            if attr not in valid:
                fail(f"bond '{target}' has {', '.join('.' + a for a in valid)}, not "
                     f".{attr}", loc, key)
            return symbols.ref(target, attr)
        if target not in kinds:
            fail(f"'{target}.{attr}' names no element or bond", loc, key,
                 "write element.e, element.f, C.q, I.p, bond.e, bond.f or block.y")
        return self._element_ref(target, attr, kinds[target], vector, key, loc)

    def typed(self, sec, section: str, what: str, valid, expect: str) -> dict:
        """The entries of a section of ``name: {type: KIND, ...}`` (elements, blocks):
        each name declared (``what`` it is), its mapping and its kind, one of ``valid``
        (a YAML integer such as the junction ``0`` read as its name): name -> (kind,
        mapping)."""
        out = {}
        for name, v in sec.items():
            key = f"{section}.{name}"
            self.declare(name, f"{what} '{name}'", sec.key_locs[name], key)
            v = mapping(v, sec.val_locs[name], key, expect)
            kind = v.get("type")
            kind = str(kind) if isinstance(kind, int) and not isinstance(kind, bool) else kind
            if not isinstance(kind, str) or kind not in valid:
                fail(f"unknown {what} type {v.get('type')!r}", v.val_locs.get("type", v.loc),
                     f"{key}.type", "valid types: " + ", ".join(valid))
            out[name] = (kind, v)
        return out

    def _direction_ref(self, target, attr, key, loc):
        """``joint.direction.q`` (displacement from the initial pose: m or rad) and
        ``.v`` (rate) of a joint's free direction: its sensors."""
        from bgc.mechanics.joints import JOINT_KINDS
        joint, label = target.rsplit(".", 1)
        free = JOINT_KINDS[self.joints[joint].kind].free
        if label not in free:
            fail(f"'{target}' is not a free direction of joint '{joint}'", loc, key,
                 "free directions: " + (", ".join(f"{joint}.{d}" for d in free) or "none"))
        if attr not in Joint.DIRECTION_ATTRS:
            fail(f"joint direction '{target}' has no '.{attr}'", loc, key,
                 "valid: " + ", ".join(f"{target}.{a}" for a in Joint.DIRECTION_ATTRS))
        return symbols.ref(f"{joint}__{label}", attr)

    def _point_ref(self, target, attr, key, loc):
        body, pt = target.rsplit(".", 1)
        if body not in self.bodies or pt not in self.bodies[body].points:
            fail(f"'{target}' names no point of a body nor a joint's direction", loc, key,
                 "write body.point.attr (a point from the body's 'points:') or "
                 "joint.direction.q / .v")
        valid = Body.POINT_ATTRS if self.bodies[body].mass > 0 else Body.POINT_ATTRS[:6]
        if attr not in valid:
            fail(f"point '{target}' has no '.{attr}'", loc, key,
                 "valid: " + ", ".join(f"{target}.{a}" for a in valid))
        return symbols.ref(f"{body}__{pt}", attr)

    @staticmethod
    def _element_ref(target, attr, kind, vector, key, loc):
        valid = {"C": ("e", "f", "q"), "I": ("e", "f", "p"), "0": ("e",), "1": ("f",)}.get(
            kind, ("e", "f") if KINDS[kind].ports == 1 else ())
        if vector:          # components of a multibond element: e -> ex, ey, ez
            valid = tuple(a + x for a in valid for x in "xyz")
        if attr not in valid:
            if kind in ("0", "1"):
                fail(f"a {kind}-junction shares one {'effort' if kind == '0' else 'flow'}"
                     f"; '{target}.{attr}' differs per bond", loc, key,
                     f"write {target}.{valid[0]}, or name a bond and use bond.{attr}")
            if not valid:
                fail(f"{kind} '{target}' has several bonds; '.{attr}' is ambiguous", loc,
                     key, "name one of its bonds and refer to bond.e or bond.f")
            fail(f"{kind} '{target}' has no '.{attr}'", loc, key,
                 "valid: " + ", ".join(f"{target}.{a}" for a in valid))
        return symbols.ref(target, attr)
