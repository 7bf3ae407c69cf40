"""The ``joints:`` section and the model's ``parasitic:`` defaults: each joint's kind,
bodies, point and frame, its compliance (parasitic springs), and the springs, dampers and
actuators in its free directions."""

from __future__ import annotations

import dataclasses
import math

import sympy as sp

from bgc.mechanics import exact
from bgc.mechanics.joints import JOINT_KINDS, NEEDS_AXIS2
from bgc.model import symbols
from bgc.model.document import YList, YMap
from bgc.model.model import FIXED_FRAME, Body, Functional, Joint, Parameter, Parasitic
from bgc.model.sections.bodies import frame, joint_point, unit_vector
from bgc.model.sections.context import Context
from bgc.model.values import check_keys, fail, mapping, number

JOINT_KEYS = ("type", "between", "at", "axis", "axis2", "frame", "pitch", "spring", "actuator",
              "directions", "parasitic", "initial", "description")
PARASITIC_KEYS = ("stiffness", "damping", "rot_stiffness", "rot_damping")


def parasitic(v, loc, key, base: Parasitic) -> Parasitic:
    """A ``parasitic:`` mapping (the model's, ``key`` 'parasitic', which may also say
    ``loads``; or a joint's) over ``base``."""
    m = mapping(v, loc, key, "a mapping {stiffness, damping, rot_stiffness, "
                "rot_damping}")
    check_keys(m, PARASITIC_KEYS + (("loads",) if key == "parasitic" else ()), key)
    if m.get("loads", "none") not in ("none", "static"):
        fail(f"unknown parasitic loads {m['loads']!r}", m.val_locs["loads"],
             f"{key}.loads", "'static': the initial state is a static equilibrium "
                             "and the parasitic springs start loaded; 'none'")
    kw = {k: number(m[k], m.val_locs[k], f"{key}.{k}", nonneg=True)
          for k in PARASITIC_KEYS if k in m}
    return Parasitic(**{**base.__dict__, **kw})


def joints(cx: Context, sec: YMap, params, signals, base: Parasitic) -> dict[str, Joint]:
    """Each joint (``base``: the model's parasitic defaults); their stiffnesses,
    dampings and preloads become parameters in ``params`` (``joint_params``). The joints
    are known to ``cx`` from here on."""
    names = cx.expr_names(params, signals)
    out = {}
    for name, v in sec.items():
        key = f"joints.{name}"
        cx.declare(name, f"joint '{name}'", sec.key_locs[name], key)
        v = mapping(v, sec.val_locs[name], key, "a mapping with type, between, at")
        check_keys(v, JOINT_KEYS, key)
        for k in ("type", "between", "at"):
            if k not in v:
                fail(f"missing '{k}'", v.loc, key,
                     "a joint needs type, between: [body1, body2] and at")
        j = _joint(cx, name, v, key, names, base)
        joint_params(j, params)
        out[name] = j
    cx.joints = out
    for j in out.values():
        if j.initial:
            _start_displaced(cx, j, sec[j.name])
    return out


def _initial(cx: Context, v: YMap, kind, key, names) -> dict:
    """``initial: {tx: x0}``: how far body 2 starts along free translations of the joint
    (numbers or expressions of parameters, so ``-p`` moves the start)."""
    spec = JOINT_KINDS[kind]
    m = mapping(v["initial"], v.val_locs["initial"], f"{key}.initial",
                "a mapping {direction: displacement}")
    pnames = {n: s for n, s in names.items() if symbols.kind(s) == "parameter"}
    out = {}
    for lab, x in m.items():
        kk = f"{key}.initial.{lab}"
        free = [d for d in spec.free if d.startswith("t")]
        if lab not in free:
            fail(f"'{lab}' is not a free translation of a {kind} joint", m.key_locs[lab], kk,
                 "an initial displacement is along one of: " + (", ".join(free) or "none"))
        e = cx.parse(x, loc=m.val_locs[lab], key=kk, names=pnames)
        if not math.isfinite(float(e.xreplace(cx.pvals))):
            fail(f"initial displacement {x} is not finite at the parameters' values",
                 m.val_locs[lab], kk)
        out[lab] = e
    return out


def _start_displaced(cx: Context, j: Joint, v: YMap):
    """Body 2 of ``j`` starts at ``com + sum(x0 * axis)`` (R0). Only a body that no
    other joint holds can start displaced this way: the rest of the mechanism stays at
    its given pose, so the joint's blocked directions stay closed."""
    loc, key = v.val_locs["initial"], f"joints.{j.name}.initial"
    others = [o.name for o in cx.joints.values()
              if o.name != j.name and j.body2 in (o.body1, o.body2)]
    if j.body2 is None or others or cx.bodies[j.body2].mass == 0:
        why = ("body 2 is the fixed frame" if j.body2 is None else
               f"body '{j.body2}' is also held by joint {', '.join(others)}" if others else
               f"body '{j.body2}' has negligible mass")
        fail(f"joint '{j.name}' cannot start displaced: {why}", loc, key,
             "an initial displacement moves body 2 alone: a body with mass that only "
             "this joint holds")
    axes = exact.matrix(j.frame)
    shift = sum((axes[:, "xyz".index(lab[1])] * x for lab, x in j.initial.items()),
                sp.zeros(3, 1))
    body = cx.bodies[j.body2]
    cx.bodies[j.body2] = dataclasses.replace(body, offset_expr=tuple(shift))


def _joint(cx: Context, name, v: YMap, key, names, base: Parasitic) -> Joint:
    def at(k):
        return v.val_locs[k], f"{key}.{k}"
    kind = v["type"]
    if not isinstance(kind, str) or kind not in JOINT_KINDS:
        fail(f"unknown joint type {kind!r}", *at("type"),
             "valid types: " + ", ".join(JOINT_KINDS))
    pair = v["between"]
    if not isinstance(pair, YList) or len(pair) != 2:
        fail("'between' is a list of two bodies", *at("between"),
             f"write [body1, body2]; '{FIXED_FRAME}' is the fixed frame")
    bodies = []
    for i, b in enumerate(pair):
        if b != FIXED_FRAME and (not isinstance(b, str) or b not in cx.bodies):
            fail(f"unknown body {b!r}", pair.item_locs[i], f"{key}.between[{i}]",
                 "declared bodies: " + ", ".join(list(cx.bodies) + [FIXED_FRAME]))
        bodies.append(None if b == FIXED_FRAME else b)
    if bodies[0] == bodies[1]:
        fail(f"a joint joins two different bodies, got {pair[0]!r} twice", *at("between"))
    point, axes = _placement(cx, v, kind, key, at)
    out_frame = exact.floats(frame(v["frame"], *at("frame"), cx)) if "frame" in v else None
    pitch = 0.0
    if kind == "screw":
        if "pitch" not in v:
            fail("a screw joint needs 'pitch' (translation per turn, m)", v.loc, key)
        pitch = number(v["pitch"], *at("pitch"))
    elif "pitch" in v:
        fail("'pitch' belongs to screw joints", *at("pitch"))
    functional = _functionals(cx, v, kind, key, at, names)
    initial = _initial(cx, v, kind, key, names) if "initial" in v else {}
    para = parasitic(v["parasitic"], *at("parasitic"), base) if "parasitic" in v else base
    return Joint(name, v.loc, kind, bodies[0], bodies[1], exact.floats(point),
                 exact.floats(axes), para, functional, pitch, out_frame, initial)


def _placement(cx: Context, v: YMap, kind, key, at) -> tuple[sp.Matrix, sp.Matrix]:
    """A joint's point (R0) and its frame: axis x (``axis``, default [1, 0, 0]), y
    (``axis2``, else the R0 axis most nearly perpendicular to x, made perpendicular),
    z = x cross y; exact."""
    point = joint_point(cx, v["at"], *at("at"))
    x = unit_vector(v["axis"], *at("axis"), cx) if "axis" in v else sp.Matrix([1, 0, 0])
    if "axis2" in v:
        y = unit_vector(v["axis2"], *at("axis2"), cx)
        if abs(exact.to_float(x.dot(y))) > 1e-6:
            fail("axis2 must be perpendicular to axis", *at("axis2"))
    elif kind in NEEDS_AXIS2:
        fail(f"a {kind} joint needs 'axis2'", v.loc, key,
             "the second axis (body 2's), perpendicular to 'axis'")
    else:       # the R0 axis most nearly perpendicular to x, made perpendicular
        xf = [abs(c) for c in exact.floats(x)]
        e = sp.Matrix([int(i == xf.index(min(xf))) for i in range(3)])
        y = exact.unit(e - e.dot(x) * x)
    return point, sp.Matrix.hstack(x, y, x.cross(y))


def _functionals(cx: Context, v: YMap, kind, key, at, names) -> dict[str, Functional]:
    """The springs, dampers and actuators in a joint's free directions: ``spring`` and
    ``actuator`` act in the first, ``directions`` names each."""
    spec = JOINT_KINDS[kind]
    out = {}
    if "spring" in v or "actuator" in v:
        if not spec.free:
            fail(f"a {kind} joint has no free direction for a spring or actuator",
                 *at("spring" if "spring" in v else "actuator"))
        fun = (functional(cx, v["spring"], *at("spring"), names) if "spring" in v
               else Functional(loc=v.loc))
        if "actuator" in v:
            fun = Functional(fun.k, fun.c, fun.preload,
                             actuator(cx, v["actuator"], at("actuator")[0],
                                      f"{key}.actuator", names), fun.loc)
        out[spec.free[0]] = fun
    if "directions" in v:
        dm = mapping(v["directions"], *at("directions"))
        for lab, dv in dm.items():
            if lab not in spec.free:
                fail(f"'{lab}' is not a free direction of a {kind} joint",
                     dm.key_locs[lab], f"{key}.directions",
                     "free directions: " + (", ".join(spec.free) or "none"))
            if lab in out:
                fail(f"direction '{lab}' already has the joint's spring/actuator",
                     dm.key_locs[lab], f"{key}.directions")
            out[lab] = functional(cx, dv, dm.val_locs[lab], f"{key}.directions.{lab}",
                                  names)
    return out


def spring_value(cx: Context, v, loc, key, names, nonneg: bool):
    """A spring's ``k``, a damper's ``c`` or a ``preload``: a number, or an expression of
    the model's parameters (``k: 2 * k_leg``), which the generated code reads as it is, so
    that ``-p k_leg=...`` changes it without recompiling. Its value at the parameters'
    values must be finite (and not negative for ``k`` and ``c``)."""
    if not isinstance(v, str):
        return number(v, loc, key, nonneg=nonneg)
    pnames = {n: s for n, s in names.items() if symbols.kind(s) == "parameter"}
    e = cx.parse(v, loc=loc, key=key, names=pnames)
    value = float(e.xreplace(cx.pvals)) if e.free_symbols else float(e)
    if not math.isfinite(value) or (nonneg and value < 0):
        fail(f"{key.rsplit('.', 1)[-1]} = {v} is {value:g} at the parameters' values", loc,
             key, "a spring constant or damping must be finite and >= 0" if nonneg else
             "a preload must be finite")
    return e if e.free_symbols else value


def functional(cx: Context, v, loc, key, names) -> Functional:
    """``{k, c, preload, actuator}`` of one free direction."""
    m = mapping(v, loc, key, "a mapping {k, c, preload, actuator}")
    check_keys(m, ("k", "c", "preload", "actuator"), key)
    kw = {}
    for k in ("k", "c", "preload"):
        if k in m:
            kw[k] = spring_value(cx, m[k], m.val_locs[k], f"{key}.{k}", names,
                                 nonneg=k != "preload")
    if "actuator" in m:
        kw["actuator"] = actuator(cx, m["actuator"], m.val_locs["actuator"],
                                  f"{key}.actuator", names)
    return Functional(loc=loc, **kw)


def actuator(cx: Context, v, loc, key, names) -> sp.Expr:
    """A joint actuator's force or torque: parameters, signals, t, and the bodies'
    positions, angles and velocities (a spring or controller law; not accelerations,
    which would close an algebraic loop through the actuator)."""
    def ref(target, attr):
        body = target if target in cx.bodies else target.rpartition(".")[0]
        if body not in cx.bodies:
            fail(f"'{target}.{attr}' names no body; a joint actuator may read "
                 "bodies only", loc, key, "write body.x, body.az, body.point.vx, ...")
        valid = Body.POINT_ATTRS[:6] if target != body else Body.ATTRS[:15]
        if attr not in valid:
            fail(f"a joint actuator cannot read '{target}.{attr}'", loc, key,
                 "valid: " + ", ".join(f"{target}.{a}" for a in valid))
        return cx.resolve_ref(target, attr, {}, set(), key, loc)
    return cx.parse(v, loc=loc, key=key, names=names, resolve_ref=ref)


def joint_params(j: Joint, params: dict):
    """A joint's stiffness, damping and preload values become parameters (in ``params``),
    so they can be changed (and swept) without recompiling."""
    vals = dict(j.parasitic.__dict__)
    vals.update({f"{lab}_load": 0.0 for lab in JOINT_KINDS[j.kind].blocked})
    for lab, f in j.functional.items():      # an expression of parameters is read as such
        vals.update({f"{lab}_{role}": getattr(f, role) for role in ("k", "c", "preload")
                     if not isinstance(getattr(f, role), sp.Expr)})
    for role, val in vals.items():
        pname = f"{j.name}__{role}"
        params[pname] = Parameter(pname, float(val), j.loc)
