"""The ``gravity:`` and ``bodies:`` sections, and the geometry joints are given in: frames,
axes and points (R0). Geometry is kept exact (``bgc.mechanics.exact``) from the decimals
written, so no floating-point noise reaches the equations; every 3-vector is read by
``vector`` here."""

from __future__ import annotations

import sys

import sympy as sp

from bgc.mechanics import exact
from bgc.model import symbols
from bgc.model.document import YList, YMap
from bgc.model.model import Body
from bgc.model.sections.context import Context
from bgc.model.values import IDENT, check_keys, fail, kind_of, mapping, number, vector

BODY_KEYS = ("mass", "com", "inertia", "frame", "points", "directions", "velocity", "omega",
             "description")
# a point port's directions fixed in R0 (``body.point.z``); a body's ``directions`` turn
# with it
R0_DIRECTIONS = ("x", "y", "z")


def gravity(cx: Context, doc: YMap, params=()) -> tuple:
    """``gravity:``: a vector [x, y, z], or g >= 0 pointing down z; none by default. Its
    values, and its exact components where parameters give any (``gravity: g_acc``),
    else None."""
    if "gravity" not in doc:
        return (0.0, 0.0, 0.0), None
    v, loc = doc["gravity"], doc.val_locs["gravity"]
    pnames = {n: symbols.param(n) for n in params}
    if isinstance(v, YList):
        return _parametric_vector(cx, doc, "gravity", "model", pnames)
    g = _expression(cx, v, loc, "gravity", pnames)
    if g is None:
        return (0.0, 0.0, -number(v, loc, "gravity", nonneg=True)), None
    value = float(g.xreplace(cx.pvals))
    if not value >= 0 or value == float("inf"):
        fail(f"gravity = {v} is {value:g} at the parameters' values", loc, "gravity",
             "g >= 0 points down z; give a vector [x, y, z] for another direction")
    return (0.0, 0.0, -value), (sp.S.Zero, sp.S.Zero, -g)


def bodies(cx: Context, sec: YMap, params=()) -> dict[str, Body]:
    """Each body: mass, centre of mass, inertia (principal moments and axes), points and
    initial velocities; the bodies and their points are known to ``cx`` from here on.
    Mass and principal moments may be expressions of the parameters ``params``."""
    pnames = {n: symbols.param(n) for n in params}
    out = {}
    for name, v in sec.items():
        key = f"bodies.{name}"
        cx.declare(name, f"body '{name}'", sec.key_locs[name], key)
        v = mapping(v, sec.val_locs[name], key, "a mapping with mass, com, inertia")
        check_keys(v, BODY_KEYS, key)
        for k in ("mass", "com"):
            if k not in v:
                fail(f"missing '{k}'", v.loc, key, "a body needs mass, com and inertia")

        def at(k, v=v, key=key):
            return v.val_locs[k], f"{key}.{k}"
        mass_expr = _expression(cx, v["mass"], *at("mass"), pnames)
        mass = number(v["mass"], *at("mass"), nonneg=True, divisor=True) \
            if mass_expr is None else float(mass_expr.xreplace(cx.pvals))
        if mass_expr is not None and not mass > sys.float_info.min:
            fail(f"mass = {v['mass']} is {mass:g} at the parameters' values", *at("mass"),
                 "a mass given by parameters must be > 0 (write 0 for a body of "
                 "negligible mass)")
        inertia_expr = None
        if isinstance(v.get("inertia"), YList) and any(isinstance(x, str)
                                                       for x in v["inertia"]):
            inertia_expr = tuple(
                _or_number(_expression(cx, x, v["inertia"].item_locs[i],
                                       f"{key}.inertia[{i}]", pnames),
                           x, v["inertia"].item_locs[i], f"{key}.inertia[{i}]")
                for i, x in enumerate(v["inertia"]))
            if len(inertia_expr) != 3:
                fail(f"expected 3 principal moments, got {len(inertia_expr)}",
                     *at("inertia"))
        com = exact_vector(cx, v["com"], *at("com"))
        if "inertia" not in v and mass > 0:
            fail("missing 'inertia'", v.loc, key,
                 "a body needs mass, com and inertia (mass: 0 for a body of "
                 "negligible mass)")
        frame_ = frame(v["frame"], *at("frame"), cx) if "frame" in v else sp.eye(3)
        moments, frame_ = _inertia(v, key, mass, frame_, inertia_expr, cx.pvals)
        points = {}
        if "points" in v:
            pts = mapping(v["points"], *at("points"))
            for pn, pv in pts.items():
                if not isinstance(pn, str) or not IDENT.match(pn) or "__" in pn:
                    fail(f"'{pn}' is not a valid point name", pts.key_locs[pn],
                         f"{key}.points", "letters, digits and single '_' ('__' is kept "
                         "for the names bgc generates)")
                pos = exact_vector(cx, pv, pts.val_locs[pn], f"{key}.points.{pn}")
                points[pn] = exact.floats(frame_.T * (pos - com))
                cx.point_r0[(name, pn)] = pos
        dirs = (_directions(v["directions"], *at("directions"), cx) if "directions" in v
                else {})
        vel, vel_expr = _parametric_vector(cx, v, "velocity", key, pnames)
        omg, omg_expr = _parametric_vector(cx, v, "omega", key, pnames)
        out[name] = Body(name, v.loc, mass, tuple(float(m) for m in moments),
                         exact.floats(frame_), exact.floats(com), points,
                         tuple(float(x) for x in vel), tuple(float(x) for x in omg),
                         mass_expr, inertia_expr, vel_expr, omg_expr, dirs)
    cx.bodies = out
    return out


def _directions(v, loc, key, cx: Context | None = None) -> dict:
    """``directions: {name: [x, y, z]}``: body-fixed unit vectors (R0 at the initial pose)
    that a port at one of the body's points may act along."""
    dirs = mapping(v, loc, key, "a mapping {name: [x, y, z]}")
    out = {}
    for dn, dv in dirs.items():
        if not isinstance(dn, str) or not IDENT.match(dn) or dn in R0_DIRECTIONS \
                or "__" in dn:
            fail(f"{dn!r} is not a valid direction name", dirs.key_locs[dn], key,
                 "an identifier without '__', other than x, y, z (which are R0's axes)")
        out[dn] = unit_vector(dv, dirs.val_locs[dn], f"{key}.{dn}", cx)     # exact
    return out


def _parametric_vector(cx: Context, v: YMap, k, key, pnames) -> tuple:
    """A vector [x, y, z] (a body's initial ``velocity`` or ``omega``, R0; the model's
    ``gravity``): its values and, where a component is an expression of parameters, the
    exact components (else None)."""
    if k not in v:
        return (0.0, 0.0, 0.0), None
    vec, loc = v[k], v.val_locs[k]
    where = f"{key}.{k}" if key != "model" else k
    parsed = [_expression(cx, x, vec.item_locs[i], f"{where}[{i}]", pnames)
              for i, x in enumerate(vec)] if isinstance(vec, YList) else []
    if not any(e is not None for e in parsed):
        return vector(vec, loc, where), None
    if len(vec) != 3:
        fail(f"expected 3 components [x, y, z], got {len(vec)}", loc, where)
    exprs = tuple(e if e is not None else
                  exact.rational(number(x, vec.item_locs[i], f"{where}[{i}]"))
                  for i, (x, e) in enumerate(zip(vec, parsed)))
    return tuple(float(e.xreplace(cx.pvals)) for e in exprs), exprs


def _expression(cx: Context, x, loc, key, pnames) -> sp.Expr | None:
    """``x`` as an expression if it is one (a string that is not a plain number: of
    parameters, or a constant such as a component's placement writes, exact), else None
    (a number: read by ``number``)."""
    if not isinstance(x, str):
        return None
    try:
        float(x)
        return None
    except ValueError:
        pass
    e = cx.parse(x, loc=loc, key=key, names=pnames)
    return e if e.free_symbols else _exact_constant(e)


def _or_number(e, x, loc, key) -> sp.Expr:
    """An expression ``_expression`` gave, else the exact number ``x``."""
    return e if e is not None else exact.rational(number(x, loc, key))


def _exact_constant(e: sp.Expr) -> sp.Expr:
    """A constant expression with its decimals read as written (``exact``)."""
    return sp.sympify(e).xreplace({f: exact.rational(f) for f in e.atoms(sp.Float)})


def exact_vector(cx: Context | None, v, loc, key) -> sp.Matrix:
    """A position or axis [x, y, z], exact: numbers read as the decimals written, or
    constant expressions (``3*sqrt(2)/20``: a component's placement writes its R0
    geometry so)."""
    if not (isinstance(v, YList) and any(isinstance(x, str) for x in v)):
        return exact.vector(vector(v, loc, key))
    if len(v) != 3:
        fail(f"expected 3 numbers [x, y, z], got {len(v)}", loc, key)
    out = []
    for i, x in enumerate(v):
        xl, k = v.item_locs[i], f"{key}[{i}]"
        e = _expression(cx, x, xl, k, {}) if cx is not None and isinstance(x, str) else None
        out.append(exact.rational(number(x, xl, k)) if e is None else e)
    return sp.Matrix(out)


def _inertia(v: YMap, key, mass, frame_, inertia_expr=None, pvals=None) -> tuple:
    """A body's principal moments and its principal frame: ``inertia`` as principal
    moments [Ixx, Iyy, Izz] in ``frame`` (numbers or expressions of parameters:
    ``inertia_expr``) or as a symmetric matrix of numbers (in ``frame`` if given); none
    for a body of negligible mass (mass: 0)."""
    import numpy as np
    inertia = v.get("inertia", [0, 0, 0])     # negligible mass: no inertia either
    loc, kk = ((v.val_locs["inertia"], f"{key}.inertia") if "inertia" in v
               else (v.val_locs["mass"], f"{key}.mass"))
    if "inertia" not in v:
        moments = sp.zeros(3, 1)
    elif inertia_expr is not None:
        moments = sp.Matrix([float(e.xreplace(pvals)) for e in inertia_expr])
    elif isinstance(inertia, YList) and inertia and isinstance(inertia[0], YList):
        if len(inertia) != 3:
            fail("an inertia matrix has 3 rows", loc, kk)
        M = exact.matrix([vector(r, inertia.item_locs[i], f"{kk}[{i}]")
                          for i, r in enumerate(inertia)])
        Mf = np.array(exact.floats(M))
        if np.abs(Mf - Mf.T).max() > 1e-9 * max(np.abs(Mf).max(), 1e-30):
            fail("the inertia matrix is not symmetric", loc, kk)
        moments, frame_ = exact.principal_axes(
            frame_ * M * frame_.T if "frame" in v else M)
    else:
        moments = exact.vector(vector(inertia, loc, kk))
    moments = np.array(exact.floats(moments))
    if mass == 0:
        if np.abs(moments).max() > 0:
            fail("a body of negligible mass (mass: 0) has no inertia either",
                 loc, kk, "leave 'inertia' out or give the body its mass")
    elif moments.min() < sys.float_info.min:     # zero, negative or subnormal
        fail(f"the inertia tensor must be positive definite (principal moments "
             f"{', '.join(f'{m:g}' for m in moments)})", loc, kk,
             "principal moments > 0 (and not subnormal: they divide in the "
             "equations)")
    a, b, c = sorted(moments)
    if mass > 0 and a + b < c * (1 - 1e-9):
        fail(f"principal moments {a:g}, {b:g}, {c:g} break the triangle "
             "inequality (no rigid mass distribution has them)", loc, kk)
    return moments, frame_


def frame(v, loc, key, cx: Context | None = None) -> sp.Matrix:
    """``{x: [..], y: [..], z: [..]}`` (R0) -> exact 3x3 matrix whose columns are the
    unit axes (``exact``: no floating-point noise reaches the equations); they must be
    orthogonal and right-handed."""
    import numpy as np
    fr = mapping(v, loc, key, "a mapping {x: [..], y: [..], z: [..]}")
    check_keys(fr, ("x", "y", "z"), key)
    if set(fr) != {"x", "y", "z"}:
        fail("a frame needs its three axes x, y, z", fr.loc, key)
    F = sp.Matrix.hstack(*[exact.unit(exact_vector(cx, fr[a], fr.val_locs[a], f"{key}.{a}"))
                           for a in "xyz"])
    Ff = np.array(exact.floats(F))
    if np.abs(Ff.T @ Ff - np.eye(3)).max() > 1e-6 or np.linalg.det(Ff) < 0:
        fail("the frame axes must be orthogonal and right-handed (x cross y = z)",
             fr.loc, key, "give unit axes such as x: [1, 0, 0] ...")
    return F


def unit_vector(v, loc, key, cx: Context | None = None) -> sp.Matrix:
    """An axis, scaled to unit length exactly."""
    u = exact_vector(cx, v, loc, key)
    if exact.to_float(exact.norm(u)) < 1e-12:
        fail("an axis of zero length", loc, key, "give a direction such as [0, 0, 1]")
    return exact.unit(u)


def joint_point(cx: Context, v, loc, key) -> sp.Matrix:
    """``at``: [x, y, z] in R0, a point name of one body, or body.point (exact: the
    point as the body's ``points`` wrote it)."""
    if isinstance(v, YList):
        return exact_vector(cx, v, loc, key)
    if not isinstance(v, str):
        fail(f"expected [x, y, z] or a point name, got {kind_of(v)}", loc, key)
    body, _, pt = v.rpartition(".")
    owners = [b for b in cx.bodies.values() if pt in b.points and body in ("", b.name)]
    if len(owners) != 1:
        known = sorted(f"{b.name}.{p}" for b in cx.bodies.values() for p in b.points)
        why = "names no point" if not owners else "is a point of several bodies"
        fail(f"'{v}' {why}", loc, key, ("write body.point; " if owners else "")
             + "known points: " + (", ".join(known) or "none (add 'points:' to a body)"))
    return cx.point_r0[(owners[0].name, pt)]
