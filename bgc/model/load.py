"""Stage **load**: model text (YAML) -> Model.

YAML is read with node positions kept, so every error names ``file:line:col`` and the key
path (``elements.spring.C``). Values are checked here: names, kinds, keys, numbers,
expressions (parsed by ``bgc.model.expr``, never eval'd) and physically impossible parameters.
Graph-level checks (arity, power direction) belong to ``expand``.
"""

from __future__ import annotations

import contextlib
import dataclasses
import keyword
import re
import sys
from pathlib import Path

import sympy as sp

from bgc.codegen.module_file import module_name_problem, suggest_module_name
from bgc.errors import Loc, ModelError
from bgc.mechanics import exact
from bgc.mechanics.joints import JOINT_KINDS, NEEDS_AXIS2
from bgc.model import expr as bexpr
from bgc.model import limits, symbols
from bgc.model import signals as bsignals
from bgc.model.document import (  # noqa: F401
    MAX_DEPTH,
    MAX_FILE_BYTES,
    MAX_NODES,
    YList,
    YMap,
    _plain,
    _read_yaml,
    digest,
    read,
    read_source,
)
from bgc.model.model import (
    FIXED_FRAME,
    KINDS,
    MAX_POINTS,
    Body,
    Bond,
    Element,
    Excitation,
    Functional,
    Joint,
    Model,
    Output,
    Parameter,
    Parasitic,
    Settings,
    Signal,
    Table,
)

_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\Z")
TOP_KEYS = ("name", "description", "parameters", "signals", "gravity", "bodies", "joints",
            "parasitic", "excitation", "elements", "bonds", "outputs", "simulation")
BODY_KEYS = ("mass", "com", "inertia", "frame", "points", "velocity", "omega", "description")
JOINT_KEYS = ("type", "between", "at", "axis", "axis2", "frame", "pitch", "spring", "actuator",
              "directions", "parasitic", "description")
PARASITIC_KEYS = ("stiffness", "damping", "rot_stiffness", "rot_damping")


# ---------------------------------------------------------------- the loader
class _Loader:
    def __init__(self, file: str):
        self.file = file
        self.names: dict[str, tuple[str, Loc]] = {}   # global namespace: name -> (what, loc)
        self.bodies: dict[str, Body] = {}
        self.point_r0: dict[tuple[str, str], sp.Matrix] = {}   # (body, point) -> exact R0
        self.joints: dict[str, Joint] = {}
        self.multibond: set[str] = set()    # bonds and elements on bonds of dimension > 1
        self.pvals: dict = {}               # parameter symbol -> value, once parsed
        self.overridden: set = set()        # parameters given by -p (``loads`` overrides)
        self.t_end = Settings.t_end         # the model's, once its settings are read

    # helpers -------------------------------------------------------------
    def parse(self, text, **kw) -> sp.Expr:
        """``bexpr.parse`` with the parameters' values known, so a part that is constant
        given them (``1/Z`` with ``Z: 0``, ``log(Z)``) is judged at its line."""
        return bexpr.parse(text, values=self.pvals, **kw)

    def err(self, msg, loc, key, hint=None):
        raise ModelError(msg, loc=loc, key=key, hint=hint)

    def mapping(self, v, loc, key, what="a mapping") -> YMap:
        if not isinstance(v, YMap):
            self.err(f"expected {what}, got {_kind_of(v)}", loc, key,
                     "write a mapping such as {name: value}" if what == "a mapping"
                     else f"write {what}")
        return v

    def string(self, v, loc, key, what="a name") -> str:
        """A plain string (a name, a path), not a number, list or mapping."""
        if not isinstance(v, str):
            self.err(f"expected {what}, got {_kind_of(v)}{_short(v)}", loc, key,
                     f"write {what} as plain text")
        return v

    def strings(self, v, loc, key, what="names") -> list[str]:
        """A list of plain strings."""
        if not isinstance(v, YList):
            self.err(f"expected a list of {what}, got {_kind_of(v)}{_short(v)}", loc, key,
                     "write [a, b, ...]")
        return [self.string(x, v.item_locs[i], f"{key}[{i}]", "a " + what.rstrip("s"))
                for i, x in enumerate(v)]

    def check_keys(self, m: YMap, allowed, key):
        """Every key of ``m`` is one of ``allowed``; a description or unit is text."""
        for k in m:
            if k not in allowed:
                self.err(f"unknown key '{k}'", m.key_locs[k], f"{key}.{k}",
                         "valid keys: " + ", ".join(allowed))
            if k in ("description", "unit") and m[k] is not None:
                self.string(m[k], m.val_locs[k], f"{key}.{k}", f"a {k} text")

    def declare(self, name, what, loc, key):
        if not isinstance(name, str) or not _IDENT.match(name) or keyword.iskeyword(name):
            self.err(f"{name!r} is not a valid name", loc, key,
                     "use letters, digits and '_', not starting with a digit")
        if "__" in name:
            self.err(f"'{name}' contains '__', which bgc keeps for the names it generates",
                     loc, key, "use a single '_'")
        if name in bexpr.RESERVED:
            self.err(f"'{name}' is a reserved name", loc, key,
                     "reserved: " + ", ".join(sorted(bexpr.RESERVED)))
        if name in self.names:
            other, oloc = self.names[name]
            self.err(f"duplicate name '{name}'", loc, key,
                     f"already used by {other} at line {oloc.line}")
        self.names[name] = (what, loc)

    def number(self, v, loc, key, *, positive=False, nonneg=False, divisor=False) -> float:
        """A finite plain number; ``positive``/``nonneg`` bound it; ``divisor``: it divides
        in the equations, so it must be a normal float (a subnormal one such as 5e-324 has
        a reciprocal beyond the float range)."""
        if isinstance(v, str):      # YAML 1.1 reads 1e-3 and 4.0e6 as strings
            with contextlib.suppress(ValueError):
                v = float(v)
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            self.err(f"expected a number, got {_kind_of(v)} {v!r}", loc, key,
                     "write a plain number such as 1.5 or 2e-3")
        try:
            bexpr.number(v)
        except ValueError as exc:
            self.err(f"expected a finite number: {exc}", loc, key,
                     "write a finite number such as 1.5 or 2e-3")
        v = float(v)
        if positive and v <= 0:
            self.err(f"must be > 0, got {v}", loc, key, "write a positive number")
        if nonneg and v < 0:
            self.err(f"must be >= 0, got {v}", loc, key, "write a number >= 0")
        if divisor and 0 < abs(v) < sys.float_info.min:
            self.err(f"{v:g} is a subnormal float: its reciprocal is beyond the float range",
                     loc, key, f"a divisor is at least {sys.float_info.min:.4g} in size; "
                               "rescale the units if the value is really this small")
        return v

    def points(self, v, loc, key) -> int:
        """A number of output times: an integer from 2 to ``MAX_POINTS``."""
        n = self.number(v, loc, key)
        if n != int(n) or not 2 <= n <= MAX_POINTS:
            self.err(f"expected a whole number of output times from 2 to {MAX_POINTS}, got "
                     f"{n:g}", loc, key, "e.g. 1001; each point is a row of the result")
        return int(n)

    # sections ------------------------------------------------------------
    def parameters(self, sec: YMap) -> dict[str, Parameter]:
        out = {}
        for name, v in sec.items():
            key, loc = f"parameters.{name}", sec.val_locs[name]
            self.declare(name, f"parameter '{name}'", sec.key_locs[name], key)
            unit = None
            if isinstance(v, YMap):
                self.check_keys(v, ("value", "unit", "description"), key)
                if "value" not in v:
                    self.err("missing 'value'", v.loc, key, "write {value: 1.0, unit: kg}")
                unit = v.get("unit")
                loc = v.val_locs["value"]
                v = v["value"]
            value = self.number(v, loc, key)
            if unit == "deg":
                value = value * 3.141592653589793 / 180.0
            out[name] = Parameter(name, value, loc, unit)
            self.pvals[symbols.param(name)] = value
        return out

    def expr_names(self, params, signals=()) -> dict[str, sp.Expr]:
        """What a bare name in an expression may be: a parameter, a signal or ``t``."""
        names = {n: symbols.param(n) for n in params}
        names.update({n: symbols.signal(n) for n in signals})
        names["t"] = symbols.t
        return names

    def signals(self, sec: YMap, params, tables: list[Table]) -> dict[str, Signal]:
        out = {}
        names = {n: symbols.param(n) for n in params}
        for name, v in sec.items():
            key = f"signals.{name}"
            self.declare(name, f"signal '{name}'", sec.key_locs[name], key)
            out[name] = self.signal(name, v, sec.val_locs[name], key, names, tables)[0]
        return out

    def signal(self, name, v, loc, key, names, tables: list[Table]) -> tuple[Signal, dict]:
        """One signal and its parsed fields."""
        v = self.mapping(v, loc, key, "a mapping with 'type'")
        kind = v.get("type")
        if not isinstance(kind, str) or kind not in bsignals.SIGNAL_TYPES:
            self.err(f"unknown signal type {kind!r}", v.val_locs.get("type", v.loc),
                     f"{key}.type", "valid types: " + ", ".join(bsignals.SIGNAL_TYPES))
        required, optional = bsignals.SIGNAL_TYPES[kind]
        self.check_keys(v, ("type", "description") + required + tuple(optional), key)
        vals = {}
        for k in required:
            if k not in v:
                self.err(f"missing '{k}' for a {kind} signal", v.loc, key,
                         "needs: " + ", ".join(required))
        for k in required + tuple(optional):
            kk, kloc = f"{key}.{k}", v.val_locs.get(k, v.loc)
            if kind == "table":
                vals[k] = self.number_list(v[k], kloc, kk)
            elif k in bsignals.NUMBER_FIELDS:
                vals[k] = self.number(v.get(k, optional.get(k)), kloc, kk)
            elif k == "expr":
                vals[k] = self.parse(v[k], loc=kloc, key=kk, names={**names, "t": symbols.t})
            else:
                vals[k] = self.parse(v.get(k, optional.get(k)), loc=kloc, key=kk,
                                      names=names)
        if kind == "table":
            tt, yy = vals["t"], vals["values"]
            if len(tt) != len(yy) or len(tt) < 2:
                self.err(f"'t' and 'values' must have the same length >= 2 "
                         f"(got {len(tt)} and {len(yy)})", v.loc, key)
            if any(b <= a for a, b in zip(tt, tt[1:])):
                self.err("'t' must be strictly increasing", v.val_locs["t"], f"{key}.t")
            tables.append(Table(len(tables), tuple(tt), tuple(yy)))
        for k in ("frequency", "f_start", "f_end"):
            f = (sp.sympify(sp.sympify(vals[k]).xreplace(self.pvals)) if k in vals
                 else None)
            if f is None or not f.is_number:
                continue
            if float(f) <= 0:
                self.err(f"must be > 0, got {float(f)}", v.val_locs.get(k, v.loc),
                         f"{key}.{k}", "a frequency in Hz, > 0")
            why = limits.too_fast(float(f), self.t_end)
            if why:
                self.err(why, v.val_locs.get(k, v.loc), f"{key}.{k}",
                         "lower the frequency or shorten simulation.t_end")
        if kind == "chirp":
            t1, t2, t3 = vals["t1"], vals["t2"], vals["t3"]
            if not 0 < t1 <= t2 < t3:
                self.err(f"chirp times must satisfy 0 < t1 <= t2 < t3, got t1 = {t1:g}, "
                         f"t2 = {t2:g}, t3 = {t3:g}", v.loc, key,
                         "t1: end of the ramp-up, t2/t3: start/end of the sweep")
        expr, bps = bsignals.build(kind, vals, len(tables) - 1)
        numbers = {k: float(x) for k, x in vals.items() if k in bsignals.NUMBER_FIELDS}
        return Signal(name, kind, sp.sympify(expr), v.loc, bps, numbers,
                      bsignals.frequency(kind, vals)), vals

    def number_list(self, v, loc, key) -> list[float]:
        if not isinstance(v, YList):
            self.err(f"expected a list of numbers, got {_kind_of(v)}", loc, key)
        return [self.number(x, v.item_locs[i], f"{key}[{i}]") for i, x in enumerate(v)]

    def element_headers(self, sec: YMap) -> dict[str, tuple[str, YMap]]:
        out = {}
        for name, v in sec.items():
            key = f"elements.{name}"
            self.declare(name, f"element '{name}'", sec.key_locs[name], key)
            v = self.mapping(v, sec.val_locs[name], key, "a mapping with 'type'")
            kind = v.get("type")
            kind = str(kind) if isinstance(kind, int) and not isinstance(kind, bool) else kind
            if not isinstance(kind, str) or kind not in KINDS or not KINDS[kind].user:
                self.err(f"unknown element type {v.get('type')!r}",
                         v.val_locs.get("type", v.loc), f"{key}.type",
                         "valid types: " + ", ".join(k for k in KINDS if KINDS[k].user))
            out[name] = (kind, v)
        return out

    def bonds(self, sec: YList, elements) -> list[Bond]:
        out, seen_pairs = [], {}
        for i, v in enumerate(sec):
            loc, key = sec.item_locs[i], f"bonds[{i}]"
            name, dim = f"b{i + 1}", 1
            if isinstance(v, YList):
                if len(v) != 2:
                    self.err(f"a bond is [from, to], got {len(v)} items", loc, key)
                src, dst = v
            elif isinstance(v, YMap):
                self.check_keys(v, ("name", "from", "to", "dim"), key)
                for k in ("from", "to"):
                    if k not in v:
                        self.err(f"missing '{k}'", v.loc, key, "write {from: a, to: b}")
                src, dst = v["from"], v["to"]
                if "name" in v:
                    name = v["name"]
                    self.declare(name, f"bond '{name}'", v.val_locs["name"], f"{key}.name")
                if "dim" in v:
                    dim = v["dim"]
                    if dim not in (1, 3) or isinstance(dim, bool):
                        self.err(f"bond dimension {dim!r} is not supported", v.val_locs["dim"],
                                 f"{key}.dim", "dim: 1 (scalar bond) or dim: 3 (multibond)")
            else:
                self.err(f"expected [from, to] or {{from:, to:}}, got {_kind_of(v)}", loc, key)
            if "name" not in (v if isinstance(v, YMap) else {}):
                if name in self.names:
                    self.err(f"default bond name '{name}' is already used by "
                             f"{self.names[name][0]}", loc, key, "give this bond a name:")
                self.names[name] = (f"bond '{name}'", loc)
            for end in (src, dst):
                if not isinstance(end, str) or end not in elements:
                    self.err(f"bond connects unknown element {end!r}", loc, key,
                             "declared elements: " + ", ".join(elements))
            if src == dst:
                self.err(f"bond connects '{src}' to itself", loc, key)
            pair = frozenset((src, dst))
            if pair in seen_pairs:
                self.err(f"duplicate bond between '{src}' and '{dst}'", loc, key,
                         f"the same pair is already bonded at line {seen_pairs[pair].line}")
            seen_pairs[pair] = loc
            out.append(Bond(name, src, dst, loc, dim))
        return out

    def element_fields(self, headers, params, signals, bonds) -> dict[str, Element]:
        kinds = {n: k for n, (k, _) in headers.items()}
        self.multibond = {b.name for b in bonds if b.dim > 1} | {
            end for b in bonds if b.dim > 1 for end in (b.src, b.dst)}
        bond_names = {b.name for b in bonds}
        base = self.expr_names(params, signals)
        pvals = {symbols.param(p.name): p.value for p in params.values()}

        def resolver(key, loc):
            def resolve(target, attr):
                return self.resolve_ref(target, attr, kinds, bond_names, key, loc)
            return resolve

        out = {}
        for name, (kind, v) in headers.items():
            spec, key = KINDS[kind], f"elements.{name}"
            allowed = ("type", "description") + spec.laws + ((spec.initial,) if spec.initial
                                                             else ())
            self.check_keys(v, allowed, key)
            given = [k for k in spec.laws if k in v]
            if spec.laws and len(given) != 1:
                self.err(f"{kind} needs exactly one of: " + ", ".join(spec.laws)
                         + (f" (got {', '.join(given)})" if given else ""), v.loc, key,
                         KINDS[kind].doc)
            el = Element(name, kind, v.loc, description=v.get("description"))
            for k in given:
                kloc, kk = v.val_locs[k], f"{key}.{k}"
                names = dict(base)
                law_is_local = k in ("effort", "flow") and kind in ("C", "I", "R")
                if law_is_local:
                    names.update({n: symbols.LOCAL[n] for n in spec.local})
                    if kind == "R":
                        names = {n: s for n, s in names.items()
                                 if n != ("f" if k == "flow" else "e")}
                if kind in ("TF", "GY"):    # constant ratio: parameters only
                    names = {n: s for n, s in names.items() if n in params}
                if isinstance(v[k], YList):     # a vector or matrix (multibond elements)
                    el.fields[k] = self.matrix(v[k], kloc, kk, names,
                                               resolver(kk, kloc) if spec.modulated else None)
                    el.field_locs[k] = kloc
                    self.check_matrix(el, k, el.fields[k], pvals, kloc, kk)
                    continue
                e = self.parse(v[k], loc=kloc, key=kk, names=names,
                                resolve_ref=resolver(kk, kloc) if spec.modulated else None)
                if law_is_local:
                    own = {symbols.LOCAL[n] for n in spec.local if not (
                        kind == "R" and n == ("f" if k == "flow" else "e"))}
                    if not (e.free_symbols & own):
                        hint = {"C": "write it in q, e.g. k*q + k3*q**3",
                                "I": "write it in p, e.g. p/m",
                                "R": "write effort in f (e.g. R*f) or flow in e"}[kind]
                        self.err("the law does not use the element's variable", kloc, kk, hint)
                el.fields[k] = e
                el.field_locs[k] = kloc
                self.check_physical(el, k, e, pvals, params, kloc, kk)
            if spec.initial:
                k = spec.initial
                if k in v:
                    kloc = v.val_locs[k]
                    pnames = {n: symbols.param(n) for n in params}
                    if isinstance(v[k], YList):
                        el.initial = self.matrix(v[k], kloc, f"{key}.{k}", pnames, None)
                    else:
                        el.initial = self.parse(v[k], loc=kloc, key=f"{key}.{k}",
                                                 names=pnames)
                else:
                    el.initial = sp.S.Zero
            out[name] = el
        return out

    def matrix(self, v: YList, loc, key, names, resolve) -> sp.Matrix:
        """[a, b, c] -> a column vector; [[..], [..], [..]] -> a matrix (rows)."""
        def parse(x, xloc, xkey):
            return self.parse(x, loc=xloc, key=xkey, names=names, resolve_ref=resolve)
        if v and all(isinstance(r, YList) for r in v):
            if len({len(r) for r in v}) != 1:
                self.err("the rows of a matrix differ in length", loc, key)
            return sp.Matrix([[parse(x, r.item_locs[j], f"{key}[{i}][{j}]")
                               for j, x in enumerate(r)] for i, r in enumerate(v)])
        if not v or any(isinstance(x, (YList, YMap)) for x in v):
            self.err("expected a vector [a, b, c] or a matrix [[..], [..], [..]]", loc, key)
        return sp.Matrix([parse(x, v.item_locs[i], f"{key}[{i}]") for i, x in enumerate(v)])

    def check_matrix(self, el, key, M, pvals, loc, kk):
        """Matrix laws of multiport storage and resistors: symmetric, and positive
        definite (C, I) or semi-definite (R) where the entries are constant."""
        import numpy as np
        if el.kind not in ("C", "I", "R") or key not in ("C", "k", "I", "R"):
            return
        if M.shape[0] != M.shape[1]:
            self.err(f"'{key}' of {el.kind} '{el.name}' must be a square matrix", loc, kk)
        if not all(e.free_symbols <= set(pvals) for e in M):
            return
        A = np.array(M.xreplace(pvals), dtype=float)
        if np.abs(A - A.T).max() > 1e-9 * max(np.abs(A).max(), 1e-300):
            self.err(f"'{key}' of {el.kind} '{el.name}' is not symmetric", loc, kk,
                     "a multiport C, I or R law is a symmetric matrix")
        low = np.linalg.eigvalsh(A).min()
        if low < 0 or (low == 0 and el.kind != "R" and key != "k"):
            self.err(f"'{key}' of {el.kind} '{el.name}' is not positive definite "
                     f"(smallest eigenvalue {low:g})", loc, kk,
                     "a stored energy must be positive in every direction")

    def check_physical(self, el, key, e, pvals, params, loc, kk):
        """Reject values that cannot be physical where they are constant."""
        rule = {("C", "C"): "positive", ("C", "k"): "nonneg", ("I", "I"): "positive",
                ("R", "R"): "nonneg", ("TF", "ratio"): "nonzero",
                ("GY", "r"): "nonzero"}.get((el.kind, key))
        if rule is None or not e.free_symbols <= set(pvals):
            return
        val = float(e.xreplace(pvals))
        bad = {"positive": val <= 0, "nonneg": val < 0, "nonzero": val == 0}[rule]
        if rule != "nonneg" and 0 < abs(val) < sys.float_info.min:
            self.err(f"{key} of {el.kind} '{el.name}' is {val:g}, a subnormal float: its "
                     "reciprocal is beyond the float range", loc, kk,
                     f"it divides in the equations: at least {sys.float_info.min:.4g} "
                     "in size; rescale the units if it is really this small")
        if bad:
            what = {"positive": "must be > 0", "nonneg": "must be >= 0",
                    "nonzero": "must not be 0"}[rule]
            src = [p for p in params if symbols.param(p) in e.free_symbols]
            origin = "".join(f"; parameter '{p}' is set " + (
                "by -p" if p in self.overridden else f"at line {params[p].loc.line}")
                for p in src)
            hint = {"positive": "it divides in the law; use a small positive value",
                    "nonneg": "a negative value generates energy; write a law if intended",
                    "nonzero": "a zero ratio divides in the other causality"}[rule]
            label = {"C": "capacitance C", "k": "stiffness k", "I": "inertance I",
                     "R": "resistance R", "ratio": "ratio", "r": "ratio r"}[key]
            self.err(f"{label} of {el.kind} '{el.name}' {what}, got {val:g}{origin}", loc, kk,
                     hint)

    def resolve_ref(self, target, attr, kinds, bond_names, key, loc):
        if "." in target:                      # body.point.attr
            body, pt = target.split(".", 1)
            if body not in self.bodies or pt not in self.bodies[body].points:
                self.err(f"'{target}' names no point of a body", loc, key,
                         "write body.point.attr with a point from the body's 'points:'")
            valid = Body.POINT_ATTRS if self.bodies[body].mass > 0 else Body.POINT_ATTRS[:6]
            if attr not in valid:
                self.err(f"point '{target}' has no '.{attr}'", loc, key,
                         "valid: " + ", ".join(f"{target}.{a}" for a in valid))
            return symbols.ref(f"{body}__{pt}", attr)
        if target in self.joints:
            if attr not in Joint.ATTRS:
                self.err(f"joint '{target}' has no '.{attr}'", loc, key,
                         "valid: " + ", ".join(f"{target}.{a}" for a in Joint.ATTRS))
            return symbols.ref(target, attr)
        if target in self.bodies:
            valid = Body.ATTRS if self.bodies[target].mass > 0 else Body.ATTRS[:12]
            if attr not in valid:
                self.err(f"body '{target}' has no '.{attr}'", loc, key,
                         "valid: " + ", ".join(f"{target}.{a}" for a in valid))
            return symbols.ref(target, attr)
        vector = target in self.multibond
        if target in bond_names:
            valid = ("ex", "ey", "ez", "fx", "fy", "fz") if vector else ("e", "f")
            if attr not in valid:
                self.err(f"bond '{target}' has {', '.join('.' + a for a in valid)}, not "
                         f".{attr}", loc, key)
            return symbols.ref(target, attr)
        if target not in kinds:
            self.err(f"'{target}.{attr}' names no element or bond", loc, key,
                     "write element.e, element.f, C.q, I.p or bond.e, bond.f")
        kind = kinds[target]
        valid = {"C": ("e", "f", "q"), "I": ("e", "f", "p"), "0": ("e",), "1": ("f",)}.get(
            kind, ("e", "f") if KINDS[kind].ports == 1 else ())
        if vector:          # components of a multibond element: e -> ex, ey, ez
            valid = tuple(a + x for a in valid for x in "xyz")
        if attr not in valid:
            if kind in ("0", "1"):
                self.err(f"a {kind}-junction shares one {'effort' if kind == '0' else 'flow'}"
                         f"; '{target}.{attr}' differs per bond", loc, key,
                         f"write {target}.{valid[0]}, or name a bond and use bond.{attr}")
            if not valid:
                self.err(f"{kind} '{target}' has several bonds; '.{attr}' is ambiguous", loc,
                         key, "name one of its bonds and refer to bond.e or bond.f")
            self.err(f"{kind} '{target}' has no '.{attr}'", loc, key,
                     "valid: " + ", ".join(f"{target}.{a}" for a in valid))
        return symbols.ref(target, attr)

    def outputs(self, sec: YMap, params, signals, elements, bonds) -> list[Output]:
        kinds = {n: e.kind for n, e in elements.items()}
        bond_names = {b.name for b in bonds}
        names = self.expr_names(params, signals)
        out = []
        for name, v in sec.items():
            key, loc = f"outputs.{name}", sec.val_locs[name]
            self.declare(name, f"output '{name}'", sec.key_locs[name], key)
            e = self.parse(v, loc=loc, key=key, names=names, resolve_ref=lambda tg, at, key=key,
                            loc=loc: self.resolve_ref(tg, at, kinds, bond_names, key, loc))
            out.append(Output(name, e, loc))
        return out

    def vector(self, v, loc, key) -> tuple[float, float, float]:
        vals = self.number_list(v, loc, key)
        if len(vals) != 3:
            self.err(f"expected 3 numbers [x, y, z], got {len(vals)}", loc, key)
        return tuple(vals)

    def gravity(self, doc) -> tuple[float, float, float]:
        if "gravity" not in doc:
            return (0.0, 0.0, 0.0)
        v, loc = doc["gravity"], doc.val_locs["gravity"]
        if isinstance(v, YList):
            return self.vector(v, loc, "gravity")
        return (0.0, 0.0, -self.number(v, loc, "gravity", nonneg=True))

    def bodies_section(self, sec: YMap) -> dict[str, Body]:
        import numpy as np
        out = {}
        for name, v in sec.items():
            key = f"bodies.{name}"
            self.declare(name, f"body '{name}'", sec.key_locs[name], key)
            v = self.mapping(v, sec.val_locs[name], key, "a mapping with mass, com, inertia")
            self.check_keys(v, BODY_KEYS, key)
            for k in ("mass", "com"):
                if k not in v:
                    self.err(f"missing '{k}'", v.loc, key, "a body needs mass, com and inertia")

            def at(k, v=v, key=key):
                return v.val_locs[k], f"{key}.{k}"
            mass = self.number(v["mass"], *at("mass"), nonneg=True, divisor=True)
            com = exact.vector(self.vector(v["com"], *at("com")))
            if "inertia" not in v and mass > 0:
                self.err("missing 'inertia'", v.loc, key,
                         "a body needs mass, com and inertia (mass: 0 for a body of "
                         "negligible mass)")
            inertia = v.get("inertia", [0, 0, 0])     # negligible mass: no inertia either
            loc, kk = at("inertia") if "inertia" in v else at("mass")
            frame = self.frame(v["frame"], *at("frame")) if "frame" in v else sp.eye(3)
            if "inertia" not in v:
                moments = sp.zeros(3, 1)
            elif isinstance(inertia, YList) and inertia and isinstance(inertia[0], YList):
                if len(inertia) != 3:
                    self.err("an inertia matrix has 3 rows", loc, kk)
                M = exact.matrix([self.vector(r, inertia.item_locs[i], f"{kk}[{i}]")
                                  for i, r in enumerate(inertia)])
                Mf = np.array(exact.floats(M))
                if np.abs(Mf - Mf.T).max() > 1e-9 * max(np.abs(Mf).max(), 1e-30):
                    self.err("the inertia matrix is not symmetric", loc, kk)
                moments, frame = exact.principal_axes(
                    frame * M * frame.T if "frame" in v else M)
            else:
                moments = exact.vector(self.vector(inertia, loc, kk))
            moments = np.array(exact.floats(moments))
            if mass == 0:
                if np.abs(moments).max() > 0:
                    self.err("a body of negligible mass (mass: 0) has no inertia either",
                             loc, kk, "leave 'inertia' out or give the body its mass")
            elif moments.min() < sys.float_info.min:     # zero, negative or subnormal
                self.err(f"the inertia tensor must be positive definite (principal moments "
                         f"{', '.join(f'{m:g}' for m in moments)})", loc, kk,
                         "principal moments > 0 (and not subnormal: they divide in the "
                         "equations)")
            a, b, c = sorted(moments)
            if mass > 0 and a + b < c * (1 - 1e-9):
                self.err(f"principal moments {a:g}, {b:g}, {c:g} break the triangle "
                         "inequality (no rigid mass distribution has them)", loc, kk)
            points = {}
            if "points" in v:
                pts = self.mapping(v["points"], *at("points"))
                for pn, pv in pts.items():
                    if not isinstance(pn, str) or not _IDENT.match(pn):
                        self.err(f"'{pn}' is not a valid point name", pts.key_locs[pn],
                                 f"{key}.points")
                    pos = exact.vector(self.vector(pv, pts.val_locs[pn],
                                                   f"{key}.points.{pn}"))
                    points[pn] = exact.floats(frame.T * (pos - com))
                    self.point_r0[(name, pn)] = pos
            vel = self.vector(v["velocity"], *at("velocity")) if "velocity" in v else (0, 0, 0)
            omg = self.vector(v["omega"], *at("omega")) if "omega" in v else (0, 0, 0)
            out[name] = Body(name, v.loc, mass, tuple(float(m) for m in moments),
                             exact.floats(frame), exact.floats(com), points,
                             tuple(float(x) for x in vel), tuple(float(x) for x in omg))
        self.bodies = out
        return out

    def parasitic(self, v, loc, key, base: Parasitic) -> Parasitic:
        m = self.mapping(v, loc, key, "a mapping {stiffness, damping, rot_stiffness, "
                         "rot_damping}")
        self.check_keys(m, PARASITIC_KEYS + (("loads",) if key == "parasitic" else ()), key)
        if m.get("loads", "none") not in ("none", "static"):
            self.err(f"unknown parasitic loads {m['loads']!r}", m.val_locs["loads"],
                     f"{key}.loads", "'static': the initial state is a static equilibrium "
                                     "and the parasitic springs start loaded; 'none'")
        kw = {k: self.number(m[k], m.val_locs[k], f"{key}.{k}", nonneg=True)
              for k in PARASITIC_KEYS if k in m}
        return Parasitic(**{**base.__dict__, **kw})

    def frame(self, v, loc, key) -> sp.Matrix:
        """``{x: [..], y: [..], z: [..]}`` (R0) -> exact 3x3 matrix whose columns are the
        unit axes (``exact``: no floating-point noise reaches the equations); they must be
        orthogonal and right-handed."""
        import numpy as np
        fr = self.mapping(v, loc, key, "a mapping {x: [..], y: [..], z: [..]}")
        self.check_keys(fr, ("x", "y", "z"), key)
        if set(fr) != {"x", "y", "z"}:
            self.err("a frame needs its three axes x, y, z", fr.loc, key)
        F = sp.Matrix.hstack(*[exact.unit(exact.vector(
            self.vector(fr[a], fr.val_locs[a], f"{key}.{a}"))) for a in "xyz"])
        Ff = np.array(exact.floats(F))
        if np.abs(Ff.T @ Ff - np.eye(3)).max() > 1e-6 or np.linalg.det(Ff) < 0:
            self.err("the frame axes must be orthogonal and right-handed (x cross y = z)",
                     fr.loc, key, "give unit axes such as x: [1, 0, 0] ...")
        return F

    def unit_vector(self, v, loc, key) -> sp.Matrix:
        """An axis, scaled to unit length exactly."""
        u = exact.vector(self.vector(v, loc, key))
        if exact.to_float(exact.norm(u)) < 1e-12:
            self.err("an axis of zero length", loc, key, "give a direction such as [0, 0, 1]")
        return exact.unit(u)

    def joint_point(self, v, loc, key) -> sp.Matrix:
        """``at``: [x, y, z] in R0, a point name of one body, or body.point (exact: the
        point as the body's ``points`` wrote it)."""
        if isinstance(v, YList):
            return exact.vector(self.vector(v, loc, key))
        if not isinstance(v, str):
            self.err(f"expected [x, y, z] or a point name, got {_kind_of(v)}", loc, key)
        body, _, pt = v.rpartition(".")
        owners = [b for b in self.bodies.values() if pt in b.points and body in ("", b.name)]
        if len(owners) != 1:
            known = sorted(f"{b.name}.{p}" for b in self.bodies.values() for p in b.points)
            why = "names no point" if not owners else "is a point of several bodies"
            self.err(f"'{v}' {why}", loc, key, ("write body.point; " if owners else "")
                     + "known points: " + (", ".join(known) or "none (add 'points:' to a body)"))
        return self.point_r0[(owners[0].name, pt)]

    def functional(self, v, loc, key, names) -> Functional:
        m = self.mapping(v, loc, key, "a mapping {k, c, preload, actuator}")
        self.check_keys(m, ("k", "c", "preload", "actuator"), key)
        kw = {}
        for k in ("k", "c"):
            if k in m:
                kw[k] = self.number(m[k], m.val_locs[k], f"{key}.{k}", nonneg=True)
        if "preload" in m:
            kw["preload"] = self.number(m["preload"], m.val_locs["preload"], f"{key}.preload")
        if "actuator" in m:
            kw["actuator"] = self.actuator(m["actuator"], m.val_locs["actuator"],
                                           f"{key}.actuator", names)
        return Functional(loc=loc, **kw)

    def actuator(self, v, loc, key, names) -> sp.Expr:
        """A joint actuator's force or torque: parameters, signals, t, and the bodies'
        positions, angles and velocities (a spring or controller law; not accelerations,
        which would close an algebraic loop through the actuator)."""
        def ref(target, attr):
            body = target.split(".")[0]
            if body not in self.bodies:
                self.err(f"'{target}.{attr}' names no body; a joint actuator may read "
                         "bodies only", loc, key, "write body.x, body.az, body.point.vx, ...")
            if "." in target:
                valid = Body.POINT_ATTRS[:6]
            else:
                valid = Body.ATTRS[:15]
            if attr not in valid:
                self.err(f"a joint actuator cannot read '{target}.{attr}'", loc, key,
                         "valid: " + ", ".join(f"{target}.{a}" for a in valid))
            return self.resolve_ref(target, attr, {}, set(), key, loc)
        return self.parse(v, loc=loc, key=key, names=names, resolve_ref=ref)

    def joints_section(self, sec: YMap, params, signals, base: Parasitic) -> dict[str, Joint]:
        names = self.expr_names(params, signals)
        out = {}
        for name, v in sec.items():
            key = f"joints.{name}"
            self.declare(name, f"joint '{name}'", sec.key_locs[name], key)
            v = self.mapping(v, sec.val_locs[name], key, "a mapping with type, between, at")
            self.check_keys(v, JOINT_KEYS, key)
            for k in ("type", "between", "at"):
                if k not in v:
                    self.err(f"missing '{k}'", v.loc, key,
                             "a joint needs type, between: [body1, body2] and at")

            def at(k, v=v, key=key):
                return v.val_locs[k], f"{key}.{k}"
            kind = v["type"]
            if not isinstance(kind, str) or kind not in JOINT_KINDS:
                self.err(f"unknown joint type {kind!r}", *at("type"),
                         "valid types: " + ", ".join(JOINT_KINDS))
            spec = JOINT_KINDS[kind]
            pair = v["between"]
            if not isinstance(pair, YList) or len(pair) != 2:
                self.err("'between' is a list of two bodies", *at("between"),
                         f"write [body1, body2]; '{FIXED_FRAME}' is the fixed frame")
            bodies = []
            for i, b in enumerate(pair):
                if b != FIXED_FRAME and (not isinstance(b, str) or b not in self.bodies):
                    self.err(f"unknown body {b!r}", pair.item_locs[i], f"{key}.between[{i}]",
                             "declared bodies: " + ", ".join(list(self.bodies) + [FIXED_FRAME]))
                bodies.append(None if b == FIXED_FRAME else b)
            if bodies[0] == bodies[1]:
                self.err(f"a joint joins two different bodies, got {pair[0]!r} twice",
                         *at("between"))
            point = self.joint_point(v["at"], *at("at"))
            x = (self.unit_vector(v["axis"], *at("axis")) if "axis" in v
                 else sp.Matrix([1, 0, 0]))
            if "axis2" in v:
                y = self.unit_vector(v["axis2"], *at("axis2"))
                if abs(exact.to_float(x.dot(y))) > 1e-6:
                    self.err("axis2 must be perpendicular to axis", *at("axis2"))
            elif kind in NEEDS_AXIS2:
                self.err(f"a {kind} joint needs 'axis2'", v.loc, key,
                         "the second axis (body 2's), perpendicular to 'axis'")
            else:       # the R0 axis most nearly perpendicular to x, made perpendicular
                xf = [abs(c) for c in exact.floats(x)]
                e = sp.Matrix([int(i == xf.index(min(xf))) for i in range(3)])
                y = exact.unit(e - e.dot(x) * x)
            frame = sp.Matrix.hstack(x, y, x.cross(y))
            out_frame = None
            if "frame" in v:
                out_frame = exact.floats(self.frame(v["frame"], *at("frame")))
            pitch = 0.0
            if kind == "screw":
                if "pitch" not in v:
                    self.err("a screw joint needs 'pitch' (translation per turn, m)", v.loc, key)
                pitch = self.number(v["pitch"], *at("pitch"))
            elif "pitch" in v:
                self.err("'pitch' belongs to screw joints", *at("pitch"))
            functional = {}
            if "spring" in v or "actuator" in v:
                if not spec.free:
                    self.err(f"a {kind} joint has no free direction for a spring or actuator",
                             *at("spring" if "spring" in v else "actuator"))
                fun = (self.functional(v["spring"], *at("spring"), names) if "spring" in v
                       else Functional(loc=v.loc))
                if "actuator" in v:
                    fun = Functional(fun.k, fun.c, fun.preload,
                                     self.actuator(v["actuator"], at("actuator")[0],
                                                   f"{key}.actuator", names), fun.loc)
                functional[spec.free[0]] = fun
            if "directions" in v:
                dm = self.mapping(v["directions"], *at("directions"))
                for lab, dv in dm.items():
                    if lab not in spec.free:
                        self.err(f"'{lab}' is not a free direction of a {kind} joint",
                                 dm.key_locs[lab], f"{key}.directions",
                                 "free directions: " + (", ".join(spec.free) or "none"))
                    if lab in functional:
                        self.err(f"direction '{lab}' already has the joint's spring/actuator",
                                 dm.key_locs[lab], f"{key}.directions")
                    functional[lab] = self.functional(dv, dm.val_locs[lab],
                                                      f"{key}.directions.{lab}", names)
            para = (self.parasitic(v["parasitic"], *at("parasitic"), base)
                    if "parasitic" in v else base)
            j = Joint(name, v.loc, kind, bodies[0], bodies[1],
                      exact.floats(point), exact.floats(frame), para,
                      functional, pitch, out_frame)
            joint_params(j, params)
            out[name] = j
        self.joints = out
        return out

    def excitation(self, sec: YMap, params, signals, tables) -> Excitation | None:
        """The ``excitation:`` section, lowered to parameters (each direction's amplitude,
        each kind's weight, the sine's frequency), the signal ``excitation`` (the weighted
        sum of the kinds' g(t)) and an actuator term on each direction's joint."""
        if not sec:
            return None
        self.check_keys(sec, ("directions", "kinds", "description"), "excitation")
        for k in ("directions", "kinds"):
            if k not in sec:
                self.err(f"missing 'excitation.{k}'", sec.loc, "excitation",
                         "directions: {name: {joint, amplitude}}, kinds: {name: signal}")
        names = {n: symbols.param(n) for n in params}
        ks = self.mapping(sec["kinds"], sec.val_locs["kinds"], "excitation.kinds",
                          "a mapping kind -> signal (constant, sine, chirp, ...)")
        kinds, freq, g, bps, freqs = {}, None, sp.S.Zero, set(), []
        for kind, v in ks.items():
            key = f"excitation.kinds.{kind}"
            if not isinstance(kind, str) or not _IDENT.match(kind) or "__" in kind:
                self.err(f"'{kind}' is not a valid kind name", ks.key_locs[kind], key)
            sig, vals = self.signal(kind, v, ks.val_locs[kind], key, names, tables)
            if sig.kind == "sine":
                if freq is not None or not vals["frequency"].is_number:
                    self.err("one sine kind, with a numeric frequency (--frequency changes "
                             "it at run time)", ks.val_locs[kind], key)
                freq = float(vals["frequency"])
                params[Excitation.FREQUENCY] = Parameter(Excitation.FREQUENCY, freq, sig.loc,
                                                         "Hz")
                expr = bsignals.build("sine", {**vals, "frequency":
                                               symbols.param(Excitation.FREQUENCY)}, -1)[0]
                sig = Signal(kind, "sine", sp.sympify(expr), sig.loc,
                             frequency=symbols.param(Excitation.FREQUENCY))
            w = Excitation.param(kind)
            params[w] = Parameter(w, 0.0, sig.loc)
            g += symbols.param(w) * sig.expr
            if sig.frequency is not None:      # only the selected kind limits the step
                freqs.append(sp.Piecewise((sig.frequency, sp.Ne(symbols.param(w), 0)),
                                          (0, True)))
            bps.update(sig.breakpoints)
            kinds[kind] = sig
        self.declare(Excitation.SIGNAL, "the excitation signal", sec.loc, "excitation")
        signals[Excitation.SIGNAL] = Signal(Excitation.SIGNAL, "excitation", g, sec.loc,
                                            tuple(sorted(bps)),
                                            frequency=sp.Max(*freqs) if freqs else None)
        ds = self.mapping(sec["directions"], sec.val_locs["directions"],
                          "excitation.directions", "a mapping name -> {joint, amplitude}")
        directions = {}
        for d, v in ds.items():
            key = f"excitation.directions.{d}"
            if not isinstance(d, str) or not _IDENT.match(d) or "__" in d or d in kinds:
                self.err(f"'{d}' is not a valid direction name (or it names a kind)",
                         ds.key_locs[d], key)
            m = self.mapping(v, ds.val_locs[d], key, "a mapping {joint, amplitude}")
            self.check_keys(m, ("joint", "amplitude", "direction", "description"), key)
            for k in ("joint", "amplitude"):
                if k not in m:
                    self.err(f"missing '{k}'", m.loc, key,
                             "joint: the joint it acts in, amplitude: force [N] or torque [N m]")
            j = self.joints.get(m["joint"]) if isinstance(m["joint"], str) else None
            if j is None:
                self.err(f"unknown joint {m['joint']!r}", m.val_locs["joint"], f"{key}.joint",
                         "declared joints: " + ", ".join(self.joints))
            free = JOINT_KINDS[j.kind].free
            if not free:
                self.err(f"a {j.kind} joint has no free direction to excite",
                         m.val_locs["joint"], f"{key}.joint")
            label = m.get("direction", free[0])
            if label not in free:
                self.err(f"'{label}' is not a free direction of a {j.kind} joint",
                         m.val_locs["direction"], f"{key}.direction",
                         "free directions: " + ", ".join(free))
            amp = self.number(m["amplitude"], m.val_locs["amplitude"], f"{key}.amplitude")
            a = Excitation.param(d)
            params[a] = Parameter(a, 0.0, m.loc)
            term = symbols.param(a) * symbols.signal(Excitation.SIGNAL)
            fun = j.functional.get(label, Functional(loc=m.loc))
            j.functional[label] = Functional(
                fun.k, fun.c, fun.preload, term if fun.actuator is None else fun.actuator + term,
                fun.loc)
            joint_params(j, params)
            directions[d] = (j.name, amp)
        return Excitation(directions, kinds, freq, sec.loc)

    def settings(self, sec: YMap) -> Settings:
        allowed = ("t_end", "rtol", "atol", "solver", "points")
        self.check_keys(sec, allowed, "simulation")
        kw = {}
        for k in allowed:
            if k in sec:
                loc, kk = sec.val_locs[k], f"simulation.{k}"
                if k == "solver":
                    kw[k] = self.string(sec[k], loc, kk, "a solver name")
                elif k == "points":
                    kw[k] = self.points(sec[k], loc, kk)
                else:
                    kw[k] = self.number(sec[k], loc, kk, positive=True)
        return Settings(**kw)


def joint_params(j: Joint, params: dict):
    """A joint's stiffness, damping and preload values become parameters (in ``params``),
    so they can be changed (and swept) without recompiling."""
    vals = dict(j.parasitic.__dict__)
    vals.update({f"{lab}_load": 0.0 for lab in JOINT_KINDS[j.kind].blocked})
    for lab, f in j.functional.items():
        vals.update({f"{lab}_k": f.k, f"{lab}_c": f.c, f"{lab}_preload": f.preload})
    for role, val in vals.items():
        pname = f"{j.name}__{role}"
        params[pname] = Parameter(pname, float(val), j.loc)


def _short(v) -> str:
    """A value shown after its kind in a message: ' ' and its repr, cut to 40
    characters ('' for nothing)."""
    if v is None:
        return ""
    text = " " + repr(_plain(v))
    return text if len(text) <= 40 else text[:37] + "..."


def _kind_of(v) -> str:
    if isinstance(v, dict):
        return "a mapping"
    if isinstance(v, list):
        return "a list"
    if v is None:
        return "nothing"
    return type(v).__name__


def loads(text: str, file: str = "<string>", overrides: dict | None = None) -> Model:
    """Parse model text; ``file`` is used in error locations and for the default name.
    ``overrides``: parameter values that replace the file's (``-p NAME=VALUE``) before
    anything uses them, so that every check of the model (a positive capacitance, a
    finite constant) holds for them too."""
    return from_document(_read_yaml(text, file), file, overrides)


def from_document(doc, file: str, overrides: dict | None = None) -> Model:
    """The Model of a document ``document.read`` gave (``loads``, past the YAML)."""
    ld = _Loader(file)
    if not isinstance(doc, YMap):
        raise ModelError(f"a model file is a mapping of sections, got {_kind_of(doc)}",
                         loc=Loc(file, 1), hint="sections: " + ", ".join(TOP_KEYS))
    ld.check_keys(doc, TOP_KEYS, "model")

    def section(key, kind=YMap):
        if key not in doc or doc[key] is None:
            return kind() if kind is YMap else YList()
        v = doc[key]
        if not isinstance(v, kind):
            ld.err(f"expected {'a mapping' if kind is YMap else 'a list'}, got {_kind_of(v)}",
                   doc.val_locs[key], key)
        return v

    if not doc.get("bodies"):
        for required in ("elements", "bonds"):
            if not doc.get(required):
                ld.err(f"missing section '{required}'", doc.loc, required,
                       "a model needs elements and the bonds between them (or bodies)")
    elif doc.get("elements") and not doc.get("bonds"):
        ld.err("missing section 'bonds'", doc.loc, "bonds",
               "elements need the bonds between them")
    name = doc.get("name", Path(file).stem)
    problem = module_name_problem(name)
    if problem:     # without a name: key, the file's stem names the module
        ld.err(f"model name {problem}", doc.val_locs.get("name", doc.loc), "name",
               f"write name: {suggest_module_name(name)} (it names the generated module "
               "<name>.py)")
    settings = ld.settings(section("simulation"))
    ld.t_end = settings.t_end
    params = ld.parameters(section("parameters"))
    ld.overridden = set(overrides or ())
    for name, value in (overrides or {}).items():
        if name in params:
            params[name] = dataclasses.replace(params[name], value=float(value))
            ld.pvals[symbols.param(name)] = float(value)
    tables: list[Table] = []
    sigs = ld.signals(section("signals"), params, tables)
    gravity = ld.gravity(doc)
    bodies = ld.bodies_section(section("bodies"))
    base = (ld.parasitic(doc["parasitic"], doc.val_locs["parasitic"], "parasitic", Parasitic())
            if "parasitic" in doc else Parasitic())
    joints = ld.joints_section(section("joints"), params, sigs, base)
    excitation = ld.excitation(section("excitation"), params, sigs, tables)
    headers = ld.element_headers(section("elements"))
    bonds = ld.bonds(section("bonds", YList), headers)
    elements = ld.element_fields(headers, params, sigs, bonds)
    outputs = ld.outputs(section("outputs"), params, sigs, elements, bonds)
    return Model(name=name, file=file, digest=digest(doc), parameters=params, signals=sigs,
                 tables=tables, elements=elements, bonds=bonds, outputs=outputs,
                 settings=settings, description=doc.get("description"), bodies=bodies,
                 gravity=gravity, joints=joints, excitation=excitation,
                 static_loads=doc.get("parasitic", {}).get("loads") == "static")


def load(path: str | Path, overrides: dict | None = None) -> Model:
    """Read and parse a model file (``overrides``: as in ``loads``)."""
    return from_document(read(path), str(path), overrides)
