"""The bond-graph sections: ``elements:`` (each element's kind and constitutive law,
checked to be physical where it is constant), ``bonds:`` and the ``outputs:`` read from
them. Elements are read in two passes, headers then laws, since a law may name a bond."""

from __future__ import annotations

import sys

import sympy as sp

from bgc.model import symbols
from bgc.model.document import YList, YMap
from bgc.model.model import KINDS, Bond, Element, Output, Port
from bgc.model.sections.bodies import R0_DIRECTIONS
from bgc.model.sections.context import Context
from bgc.model.values import check_keys, fail, kind_of, text, unit


def element_headers(cx: Context, sec: YMap) -> dict[str, tuple[str, YMap]]:
    """Each element's name and kind: name -> (kind, its mapping), for the bonds and for
    ``element_fields``."""
    return cx.typed(sec, "elements", "element", [k for k in KINDS if KINDS[k].user],
                    "a mapping with 'type'")


def bonds(cx: Context, sec: YList, elements) -> list[Bond]:
    """Each bond, ``[from, to]`` or ``{name, from, to, dim}``, between two declared
    ``elements`` or ports of the mechanism (``port``); unnamed ones are b1, b2, ... by
    position."""
    out, seen_pairs = [], {}
    for i, v in enumerate(sec):
        loc, key = sec.item_locs[i], f"bonds[{i}]"
        name, dim = f"b{i + 1}", 1
        if isinstance(v, YList):
            if len(v) != 2:
                fail(f"a bond is [from, to], got {len(v)} items", loc, key)
            src, dst = v
        elif isinstance(v, YMap):
            check_keys(v, ("name", "from", "to", "dim"), key)
            for k in ("from", "to"):
                if k not in v:
                    fail(f"missing '{k}'", v.loc, key, "write {from: a, to: b}")
            src, dst = v["from"], v["to"]
            if "name" in v:
                name = v["name"]
                cx.declare(name, f"bond '{name}'", v.val_locs["name"], f"{key}.name")
            if "dim" in v:
                dim = v["dim"]
                if dim not in (1, 3) or isinstance(dim, bool):
                    fail(f"bond dimension {dim!r} is not supported", v.val_locs["dim"],
                         f"{key}.dim", "dim: 1 (scalar bond) or dim: 3 (multibond)")
        else:
            fail(f"expected [from, to] or {{from:, to:}}, got {kind_of(v)}", loc, key)
        if "name" not in (v if isinstance(v, YMap) else {}):
            if name in cx.names:
                fail(f"default bond name '{name}' is already used by "
                     f"{cx.names[name][0]}", loc, key, "give this bond a name:")
            cx.names[name] = (f"bond '{name}'", loc)
        for end in (src, dst):
            if isinstance(end, str) and "." in end and end not in elements:
                port(cx, end, loc, key)
                if dim != 1:
                    fail(f"bond to port '{end}' has dim {dim}", loc, key,
                         "a port of the mechanism is scalar: dim 1")
            elif not isinstance(end, str) or end not in elements:
                fail(f"bond connects unknown element {end!r}", loc, key,
                     "declared elements: " + ", ".join(elements) + (
                         "; or a port: joint.direction, body.point.direction"
                         if cx.bodies else ""))
        if src == dst:
            fail(f"bond connects '{src}' to itself", loc, key)
        pair = frozenset((src, dst))
        if pair in seen_pairs:
            fail(f"duplicate bond between '{src}' and '{dst}'", loc, key,
                 f"the same pair is already bonded at line {seen_pairs[pair].line}")
        seen_pairs[pair] = loc
        out.append(Bond(name, src, dst, loc, dim))
    return out


def port(cx: Context, name: str, loc, key) -> Port:
    """The port a bond end ``joint.direction`` or ``body.point.direction`` names (kept in
    ``cx.ports``): a free direction of the joint, or a point of the body along x, y, z
    (R0) or one of the body's ``directions``."""
    from bgc.mechanics.joints import JOINT_KINDS
    if name in cx.ports:
        return cx.ports[name]
    parts = _port_parts(cx, name)
    if len(parts) == 2 and parts[0] in cx.joints:
        j = cx.joints[parts[0]]
        spec = JOINT_KINDS[j.kind]
        free = ", ".join(spec.free) or "none"
        if parts[1] in spec.blocked:
            fail(f"port '{name}': a {j.kind} joint blocks {parts[1]}", loc, key,
                 f"a port is on a free direction; free directions of '{j.name}': {free}")
        if parts[1] not in spec.free:
            fail(f"port '{name}': joint '{j.name}' has no direction '{parts[1]}'", loc, key,
                 f"free directions of this {j.kind} joint: {free}")
        p = Port(name, loc, parts[1], joint=j.name)
    elif len(parts) == 3 and parts[0] in cx.bodies:
        b = cx.bodies[parts[0]]
        if parts[1] not in b.points:
            fail(f"port '{name}': body '{b.name}' has no point '{parts[1]}'", loc, key,
                 "its points: " + (", ".join(b.points) or "none (add 'points:' to it)"))
        valid = R0_DIRECTIONS + tuple(b.directions)
        if parts[2] not in valid:
            fail(f"port '{name}': no direction '{parts[2]}' at a point of '{b.name}'", loc,
                 key, "x, y, z (R0) or one of the body's 'directions:'"
                 + (f" ({', '.join(b.directions)})" if b.directions else ""))
        p = Port(name, loc, parts[2], body=b.name, point=parts[1])
    else:
        what = ("joint" if parts[0] in cx.joints else "body" if parts[0] in cx.bodies
                else None)
        form = {"joint": "joint.direction (e.g. slide.tx)",
                "body": "body.point.direction (e.g. box.P.z)"}.get(what)
        fail(f"bond connects unknown element or port {name!r}", loc, key,
             f"write {form}" if form else
             "a port is joint.direction or body.point.direction; joints: "
             + (", ".join(cx.joints) or "none") + "; bodies: " + (", ".join(cx.bodies) or "none"))
    cx.ports[name] = p
    return p


def _port_parts(cx: Context, name: str) -> list[str]:
    """A port's name split after its joint or body, whose name may hold dots (an
    instance's: ``leg_1.slide.tx``, ``leg_1.beater.B.z``): [joint, direction] or [body,
    point, direction] where one is known, else split at every dot."""
    head, _, last = name.rpartition(".")
    if head in cx.joints:
        return [head, last]
    body, _, point = head.rpartition(".")
    if body in cx.bodies:
        return [body, point, last]
    return name.split(".")


def element_fields(cx: Context, headers, params, signals, bonds) -> dict[str, Element]:
    """Each element with its law (one of its kind's ``laws``) and initial value; a law
    is an expression or, on a multibond, a vector or matrix."""
    kinds = {n: k for n, (k, _) in headers.items()}
    cx.multibond = {b.name for b in bonds if b.dim > 1} | {
        end for b in bonds if b.dim > 1 for end in (b.src, b.dst)}
    bond_names = {b.name for b in bonds}

    def resolver(key, loc):
        def resolve(target, attr):
            return cx.resolve_ref(target, attr, kinds, bond_names, key, loc)
        return resolve

    out = {}
    for name, (kind, v) in headers.items():
        spec, key = KINDS[kind], f"elements.{name}"
        allowed = ("type", "description") + spec.laws + ((spec.initial,) if spec.initial
                                                         else ())
        check_keys(v, allowed, key)
        given = [k for k in spec.laws if k in v]
        if spec.laws and len(given) != 1:
            fail(f"{kind} needs exactly one of: " + ", ".join(spec.laws)
                 + (f" (got {', '.join(given)})" if given else ""), v.loc, key,
                 KINDS[kind].doc)
        el = Element(name, kind, v.loc, description=text(
            v.get("description"), v.val_locs.get("description"), f"{key}.description"))
        for k in given:
            kloc, kk = v.val_locs[k], f"{key}.{k}"
            resolve = resolver(kk, kloc) if spec.modulated else None
            el.fields[k] = _law(cx, el, v, k, params, signals, resolve)
            el.field_locs[k] = kloc
        if spec.initial:
            el.initial = _initial(cx, v, spec.initial, key, params)
        out[name] = el
    return out


def _law(cx: Context, el: Element, v: YMap, k, params, signals, resolve):
    """The law ``k`` of element ``el`` (``v``: its mapping): what its expression may name
    (a C's, I's or R's own variable; a TF's or GY's ratio only parameters), checked
    physical."""
    kind, spec = el.kind, KINDS[el.kind]
    value, kloc, kk = v[k], v.val_locs[k], f"elements.{el.name}.{k}"
    pvals = {symbols.param(p.name): p.value for p in params.values()}
    names = cx.expr_names(params, signals)
    law_is_local = k in ("effort", "flow") and kind in ("C", "I", "R")
    if law_is_local:
        names.update({n: symbols.LOCAL[n] for n in spec.local})
        if kind == "R":
            names = {n: s for n, s in names.items() if n != ("f" if k == "flow" else "e")}
    if kind in ("TF", "GY"):    # constant ratio: parameters only
        names = {n: s for n, s in names.items() if n in params}
    if isinstance(value, YList):     # a vector or matrix (multibond elements)
        M = matrix(cx, value, kloc, kk, names, resolve)
        check_matrix(el, k, M, pvals, kloc, kk)
        return M
    e = cx.parse(value, loc=kloc, key=kk, names=names, resolve_ref=resolve)
    if law_is_local:
        own = {symbols.LOCAL[n] for n in spec.local if not (
            kind == "R" and n == ("f" if k == "flow" else "e"))}
        if not (e.free_symbols & own):
            hint = {"C": "write it in q, e.g. k*q + k3*q**3",
                    "I": "write it in p, e.g. p/m",
                    "R": "write effort in f (e.g. R*f) or flow in e"}[kind]
            fail("the law does not use the element's variable", kloc, kk, hint)
    check_physical(cx, el, k, e, pvals, params, kloc, kk)
    return e


def _initial(cx: Context, v: YMap, k, key, params):
    """A storage element's initial value ``k`` (q or p; 0 if not given): parameters
    only."""
    if k not in v:
        return sp.S.Zero
    kloc = v.val_locs[k]
    pnames = {n: symbols.param(n) for n in params}
    if isinstance(v[k], YList):
        return matrix(cx, v[k], kloc, f"{key}.{k}", pnames, None)
    return cx.parse(v[k], loc=kloc, key=f"{key}.{k}", names=pnames)


def matrix(cx: Context, v: YList, loc, key, names, resolve) -> sp.Matrix:
    """[a, b, c] -> a column vector; [[..], [..], [..]] -> a matrix (rows)."""
    def parse(x, xloc, xkey):
        return cx.parse(x, loc=xloc, key=xkey, names=names, resolve_ref=resolve)
    if v and all(isinstance(r, YList) for r in v):
        if len({len(r) for r in v}) != 1:
            fail("the rows of a matrix differ in length", loc, key)
        return sp.Matrix([[parse(x, r.item_locs[j], f"{key}[{i}][{j}]")
                           for j, x in enumerate(r)] for i, r in enumerate(v)])
    if not v or any(isinstance(x, (YList, YMap)) for x in v):
        fail("expected a vector [a, b, c] or a matrix [[..], [..], [..]]", loc, key)
    return sp.Matrix([parse(x, v.item_locs[i], f"{key}[{i}]") for i, x in enumerate(v)])


def check_matrix(el, key, M, pvals, loc, kk):
    """Matrix laws of multiport storage and resistors: symmetric, and positive
    definite (C, I) or semi-definite (R) where the entries are constant."""
    import numpy as np
    if el.kind not in ("C", "I", "R") or key not in ("C", "k", "I", "R"):
        return
    if M.shape[0] != M.shape[1]:
        fail(f"'{key}' of {el.kind} '{el.name}' must be a square matrix", loc, kk)
    if not all(e.free_symbols <= set(pvals) for e in M):
        return
    A = np.array(M.xreplace(pvals), dtype=float)
    if np.abs(A - A.T).max() > 1e-9 * max(np.abs(A).max(), 1e-300):
        fail(f"'{key}' of {el.kind} '{el.name}' is not symmetric", loc, kk,
             "a multiport C, I or R law is a symmetric matrix")
    low = np.linalg.eigvalsh(A).min()
    if low < 0 or (low == 0 and el.kind != "R" and key != "k"):
        fail(f"'{key}' of {el.kind} '{el.name}' is not positive definite "
             f"(smallest eigenvalue {low:g})", loc, kk,
             "a stored energy must be positive in every direction")


def check_physical(cx: Context, el, key, e, pvals, params, loc, kk):
    """Reject values that cannot be physical where they are constant."""
    rule = {("C", "C"): "positive", ("C", "k"): "nonneg", ("I", "I"): "positive",
            ("R", "R"): "nonneg", ("TF", "ratio"): "nonzero",
            ("GY", "r"): "nonzero"}.get((el.kind, key))
    if rule is None or not e.free_symbols <= set(pvals):
        return
    val = float(e.xreplace(pvals))
    bad = {"positive": val <= 0, "nonneg": val < 0, "nonzero": val == 0}[rule]
    if rule != "nonneg" and 0 < abs(val) < sys.float_info.min:
        fail(f"{key} of {el.kind} '{el.name}' is {val:g}, a subnormal float: its "
             "reciprocal is beyond the float range", loc, kk,
             f"it divides in the equations: at least {sys.float_info.min:.4g} "
             "in size; rescale the units if it is really this small")
    if bad:
        what = {"positive": "must be > 0", "nonneg": "must be >= 0",
                "nonzero": "must not be 0"}[rule]
        src = [p for p in params if symbols.param(p) in e.free_symbols]
        origin = "".join(f"; parameter '{p}' is set " + (
            "by -p" if p in cx.overridden else f"at line {params[p].loc.line}")
            for p in src)
        hint = {"positive": "it divides in the law; use a small positive value",
                "nonneg": "a negative value generates energy; write a law if intended",
                "nonzero": "a zero ratio divides in the other causality"}[rule]
        label = {"C": "capacitance C", "k": "stiffness k", "I": "inertance I",
                 "R": "resistance R", "ratio": "ratio", "r": "ratio r"}[key]
        fail(f"{label} of {el.kind} '{el.name}' {what}, got {val:g}{origin}", loc, kk,
             hint)


def outputs(cx: Context, sec: YMap, params, signals, elements, bonds) -> list[Output]:
    """Each output: an expression in parameters, signals, t and references to the
    model's variables (``element.e``, ``body.x``, ``joint.q``, ...), written as is or as
    ``{expr: ..., unit: ...}`` (the unit labels plots; ``values.unit``)."""
    kinds = {n: e.kind for n, e in elements.items()}
    bond_names = {b.name for b in bonds}
    names = cx.expr_names(params, signals)
    out = []
    for name, v in sec.items():
        key, loc = f"outputs.{name}", sec.val_locs[name]
        cx.declare(name, f"output '{name}'", sec.key_locs[name], key)
        unit_text = None
        if isinstance(v, YMap):
            check_keys(v, ("expr", "unit"), key)
            if "expr" not in v:
                fail("missing 'expr'", v.loc, key, "write {expr: body.x, unit: m}")
            if "unit" in v:
                unit_text = unit(v["unit"], v.val_locs["unit"], f"{key}.unit")
            key, loc, v = f"{key}.expr", v.val_locs["expr"], v["expr"]
        e = cx.parse(v, loc=loc, key=key, names=names, resolve_ref=lambda tg, at, key=key,
                     loc=loc: cx.resolve_ref(tg, at, kinds, bond_names, key, loc))
        out.append(Output(name, e, loc, unit_text))
    return out
