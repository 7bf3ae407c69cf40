"""Stage **expand**: Model -> BondGraph.

Bodies become the Tiernego-Bos rigid-body multibond graph (paper 11.2.3, Figs 11.1 and
11.4), with bonds of dimension 3: a translational part in R0 (1-junction ``B__v`` with the
velocity of G, the mass, gravity) and a rotational part in the principal body frame
(1-junction ``B__w`` with omega, the inertia tensor and the Eulerian junction structure).
Where a joint needs them, a body gets its angular velocity in R0 (``B__W``, through an MTF
modulated by its rotation matrix) and the velocity of the joint point (a cross-product TF
``omega x r`` in the body frame, the rotation MTF, and a 0-junction adding ``v_G``).
A body of negligible mass gets an ``M0`` port instead of its inertias: its twist is an
algebraic unknown fixed by the balance of the forces of its joints.

Joints (``bgc.mechanics.joints``) compare the two bodies' points in the joint frame: each direction
is a scalar 0-junction fed by projection MTFs (rows of the constraint Jacobian) from the
point and angular-velocity junctions. Blocked directions get the constraint element L (the
parasitic stiff spring on the geometric deflection || damper); free directions get the
joint's functional spring, damper and actuator.

Then the graph's structure is checked: every element has the number of bonds its kind
takes, two-ports have one bond in and one out, bonds meeting at a junction share one
dimension (rule C1), nothing is left unbonded.
"""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import sympy as sp

from bgc import methods
from bgc.errors import ModelError
from bgc.graph.bondgraph import BondGraph
from bgc.mechanics import exact
from bgc.mechanics import joints as jmodels
from bgc.methods.base import ConstraintMethod
from bgc.model import symbols
from bgc.model.model import KINDS, TWO_PORTS, Body, Bond, Element, Joint, Model, Port

AXES = symbols.AXES


def body_junction(body: str, part: str) -> str:
    """Name of a body's 1-junction: 'v' velocity of G (R0), 'w' omega (body frame),
    'W' omega (R0)."""
    return f"{body}__{part}"


def rotation_matrix(body: str) -> sp.Matrix:
    """The body's rotation matrix (body frame -> R0) as the symbols ``equations`` defines."""
    return sp.Matrix([[symbols.rotation(body, i, j) for j in range(3)] for i in range(3)])


def position(body: str) -> sp.Matrix:
    return sp.Matrix([symbols.state(body, a) for a in AXES])


def body_mass(body: Body) -> sp.Expr:
    """The mass the equations read: its expression of parameters, or the exact number."""
    return body.mass_expr if body.mass_expr is not None else exact.rational(body.mass)


def body_moments(body: Body) -> sp.Matrix:
    """The principal moments the equations read (expressions of parameters, or exact)."""
    return sp.Matrix(body.inertia_expr) if body.inertia_expr is not None \
        else exact.vector(body.inertia)


def joint_offset(body: Body, at) -> sp.Matrix:
    """Body-frame offset from G of the body-fixed point that is at ``at`` (R0) initially:
    computed exactly and put in canonical form (``exact``), so no rounding noise of the
    machine reaches the equations."""
    return _offset(tuple(map(tuple, body.frame)), tuple(body.com), tuple(at)).copy()


@functools.lru_cache(maxsize=1024)
def _offset(frame, com, at) -> sp.Matrix:
    """``joint_offset``, memoized (asked for each joint direction, each side)."""
    return exact.canonical(exact.matrix(frame).T * (exact.vector(at) - exact.vector(com)))


def joint_param(joint: str, role: str) -> str:
    """Name of the parameter a joint's value lives in (changeable without recompiling)."""
    return f"{joint}__{role}"


class Expander:
    """A Model being expanded into a BondGraph: the elements and bonds so far, the
    constraints a method's constraint elements add (``methods.base.Expander``: what a
    method may use), and a joint's directions per shape."""

    def __init__(self, model: Model, method: ConstraintMethod):
        self.m, self.method = model, method
        self.constraints: list = []         # bondgraph.Constraint, added by the method
        self.elements: dict[str, Element] = dict(model.elements)
        self.bonds: list[Bond] = list(model.bonds)
        self.ported = {(p.joint, p.direction) for p in model.ports.values() if p.joint}
        self.port_junction: dict[str, str] = {}     # port name -> its 1-junction
        self.shapes: dict = {}                      # a joint's shape -> its directions

    def add(self, name, kind, loc, initial=None, orthogonal=False, **fields) -> str:
        self.elements[name] = Element(name, kind, loc, fields=fields, initial=initial,
                                      orthogonal=orthogonal)
        return name

    def bond(self, src, dst, loc, dim=3):
        self.bonds.append(Bond(f"b__{src}__{dst}", src, dst, loc, dim))

    # --- bodies -------------------------------------------------------------------------
    def body(self, body: Body):
        n, loc = body.name, body.loc
        v = self.add(body_junction(n, "v"), "1", loc)
        w = self.add(body_junction(n, "w"), "1", loc)
        if body.mass == 0:      # negligible mass: the forces on it balance
            self.bond(v, self.add(f"{n}__M0v", "M0", loc), loc)
            self.bond(w, self.add(f"{n}__M0w", "M0", loc), loc)
            return
        frame = exact.matrix(body.frame)
        omega_body = frame.T * (sp.Matrix(body.omega_expr) if body.omega_expr is not None
                                else exact.vector(body.omega))
        velocity = sp.Matrix(body.velocity_expr) if body.velocity_expr is not None \
            else exact.vector(body.velocity)
        J = body_moments(body)
        mass = body_mass(body)
        self.bond(v, self.add(f"{n}__m", "I", loc, I=mass,
                              initial=velocity * mass), loc)
        Jw = sp.Matrix([J[k] * omega_body[k] for k in range(3)])
        # numbers: canonical; an expression of parameters stays as it is (exact parts)
        self.bond(w, self.add(f"{n}__J", "I", loc, I=sp.diag(*J),
                              initial=Jw if Jw.free_symbols else exact.canonical(Jw)), loc)
        self.bond(w, self.add(f"{n}__EJS", "EJS", loc, J=J), loc)
        g, gx = self.m.gravity, self.m.gravity_expr
        if any(g) or gx is not None:
            weight = (sp.Matrix(gx) if gx is not None else exact.vector(g)) * mass
            self.bond(self.add(f"{n}__g", "Se", loc, effort=weight), v, loc)

    def omega_r0(self, n: str, loc) -> str:
        W = body_junction(n, "W")
        if W not in self.elements:
            self.add(W, "1", loc)
            R = self.add(f"{n}__Rw", "MTF", loc, orthogonal=True, ratio=rotation_matrix(n))
            self.bond(body_junction(n, "w"), R, loc)
            self.bond(R, W, loc)
        return W

    def point(self, n: str, tag: str, r_body, loc) -> str:
        """1-junction of the velocity (R0) of the point of body n at body-frame offset r."""
        P = f"{n}__{tag}"
        if P not in self.elements:
            x = self.add(f"{P}__x", "XTF", loc, r=sp.Matrix(r_body))
            R = self.add(f"{P}__R", "MTF", loc, orthogonal=True, ratio=rotation_matrix(n))
            zero = self.add(f"{P}__0", "0", loc)
            self.add(P, "1", loc)
            self.bond(body_junction(n, "w"), x, loc)
            self.bond(x, R, loc)
            self.bond(R, zero, loc)
            self.bond(body_junction(n, "v"), zero, loc)
            self.bond(zero, P, loc)
        return P

    # --- joints ---------------------------------------------------------------------------
    def geometry(self, j: Joint, names=None, at=None) -> jmodels.Geometry:
        """The joint's geometry on its bodies' symbols, or on those of the bodies
        ``names`` (placeholders) with the fixed frame's point ``at``."""
        rot, pos = {}, {}
        names = names or (j.body1, j.body2)
        for side, n, sym in ((1, j.body1, names[0]), (2, j.body2, names[1])):
            if n is None:
                rot[side], pos[side] = None, exact.vector(j.at) if at is None else at
                continue
            b = self.m.bodies[n]
            r = joint_offset(b, j.at)
            rot[side] = (rotation_matrix(sym), exact.matrix(b.frame))
            pos[side] = position(sym) + rotation_matrix(sym) * r
        return jmodels.Geometry(rot[1], rot[2], pos[1], pos[2])

    def directions(self, j: Joint) -> list[jmodels.Direction]:
        """The joint's directions (``mechanics.joints.directions`` on its geometry),
        worked out once per shape: joints that differ only in their bodies and in the
        fixed frame's point (the windows of a chain, the instances of an array of
        components) share one computation, put on their own bodies' symbols by renaming
        (issue 40: compile cost follows the parts, not their copies). The first joint of
        a shape gets its directions as computed; a joint between two bodies gets the
        first's renamed in their form (``symbols.renamed``); one on the fixed frame, whose
        point enters them, the shape's worked out on placeholders, substituted."""
        sides = []
        for n in (j.body1, j.body2):
            if n is None:
                sides.append(None)
            else:
                b = self.m.bodies[n]
                sides.append((b.frame, tuple(joint_offset(b, j.at))))
        key = (j.kind, j.frame, j.pitch, tuple(sides))
        shape = self.shapes.get(key)
        if shape is None:
            dirs = jmodels.directions(j.kind, self.geometry(j), j.frame, j.pitch)
            self.shapes[key] = (dirs, (j.body1, j.body2), None)
            return dirs
        dirs, names, at = shape
        if None in names and at is None:        # on the fixed frame: on placeholders
            names = [None if n is None else f"$body{k}" for k, n in enumerate(names, 1)]
            at = sp.Matrix(sp.symbols("$at0:3", real=True))
            dirs = jmodels.directions(j.kind, self.geometry(j, names, at), j.frame, j.pitch)
            self.shapes[key] = (dirs, names, at)
        rename = {} if at is None else dict(zip(at, exact.vector(j.at)))
        for ph, n in zip(names, (j.body1, j.body2)):
            if n is not None:
                rename.update((symbols.rotation(ph, i, k), symbols.rotation(n, i, k))
                              for i in range(3) for k in range(3))
                rename.update((symbols.state(ph, a), symbols.state(n, a)) for a in AXES)
        memo: dict = {}

        def put(e):         # symbols for symbols: the form stays; a point: substituted
            return symbols.renamed(e, rename, memo) if at is None else e.xreplace(rename)

        def row(v):         # a row: a column of expressions
            return sp.Matrix(v.rows, v.cols, [put(x) for x in v])
        return [jmodels.Direction(d.label, d.blocked, d.rotational,
                                  {k: row(v) for k, v in d.rows.items()},
                                  None if d.g is None else put(d.g))
                for d in dirs]

    def joint(self, j: Joint) -> list[jmodels.Direction]:
        dirs = self.directions(j)
        for d in dirs:
            fun = j.functional.get(d.label)
            ported = (j.name, d.label) in self.ported
            if not d.blocked and (fun is None or fun.empty) and not ported:
                continue
            zero = self.add(f"{j.name}__{d.label}", "0", j.loc)
            for key, row in d.rows.items():
                side = int(key[1])
                n = j.body1 if side == 1 else j.body2
                if n is None:
                    continue
                if key[0] == "v":
                    src = self.point(n, j.name, joint_offset(self.m.bodies[n], j.at), j.loc)
                else:
                    src = self.omega_r0(n, j.loc)
                mtf = self.add(f"{j.name}__{d.label}__{key}", "MTF", j.loc, ratio=row.T)
                self.bond(src, mtf, j.loc)
                self.bond(mtf, zero, j.loc, dim=1)
            if d.blocked:       # the constraint element L: what the method makes of it
                parts = self.method.constraint_element(self, j, d, zero)
            elif fun is None:   # a port only
                parts = []
            else:
                parts = []
                def p(role, d=d, fun=fun):     # a number: its joint parameter
                    v = getattr(fun, role)
                    return v if isinstance(v, sp.Expr) else \
                        symbols.param(joint_param(j.name, f"{d.label}_{role}"))
                if fun.k != 0:
                    q = symbols.LOCAL["q"]
                    parts.append(self.add(f"{zero}__spring", "C", j.loc,
                                          effort=p("k") * q - p("preload"),
                                          initial=j.initial.get(d.label, sp.S.Zero)))
                elif fun.preload != 0:
                    parts.append(self.add(f"{zero}__preload", "Se", j.loc,
                                          effort=-p("preload")))
                if fun.c != 0:
                    parts.append(self.add(f"{zero}__damper", "R", j.loc, R=p("c")))
                if fun.actuator is not None:
                    parts.append(self.add(f"{zero}__actuator", "MSe", j.loc,
                                          effort=-fun.actuator))
            if len(parts) == 1 and not ported:
                self.bond(zero, parts[0], j.loc, dim=1)
            else:       # the 1-junction of the relative velocity: where ports bond
                one = self.add(f"{zero}__1", "1", j.loc)
                self.bond(zero, one, j.loc, dim=1)
                for e in parts:
                    self.bond(one, e, j.loc, dim=1)
                if ported:
                    self.port_junction[f"{j.name}.{d.label}"] = one
        return dirs

    def point_port(self, port: Port):
        """A port at a body's point along a direction: the point's velocity junction (R0)
        projected by a row ``u^T`` onto a scalar 1-junction, ``u`` an R0 axis or a
        direction fixed on the body (turned by its rotation matrix: a modulated row)."""
        n, body = port.body, self.m.bodies[port.body]
        r = exact.vector(body.points[port.point])     # body frame, from G (as body_refs)
        # two segments after the point (a direction's name is one): no port's name can
        # fall on the velocity junction's
        P = self.point(n, f"{port.point}__point__v", r, port.loc)
        if port.direction in "xyz":
            u = sp.Matrix([int(port.direction == a) for a in AXES])
        else:
            u = rotation_matrix(n) * exact.canonical(
                exact.matrix(body.frame).T * body.directions[port.direction])
        one = self.add(f"{n}__{port.point}__{port.direction}", "1", port.loc)
        mtf = self.add(f"{one}__u", "MTF", port.loc, ratio=u.T)
        self.bond(P, mtf, port.loc)
        self.bond(mtf, one, port.loc, dim=1)
        self.port_junction[port.name] = one

    def connect_ports(self):
        """The bonds the model drew to ports now end on the ports' junctions."""
        for port in self.m.ports.values():
            if port.body is not None:
                self.point_port(port)
        pj = self.port_junction
        self.bonds = [dataclasses.replace(b, src=pj.get(b.src, b.src), dst=pj.get(b.dst, b.dst))
                      if b.src in pj or b.dst in pj else b for b in self.bonds]


def initial_pose(model: Model) -> dict:
    """Body positions and rotation-matrix entries at the initial pose."""
    subs = {}
    for n, b in model.bodies.items():
        for i in range(3):
            subs[symbols.state(n, AXES[i])] = b.com[i]
            for k in range(3):
                subs[symbols.rotation(n, i, k)] = b.frame[i][k]
    return subs


def twist_row(model: Model, j, d, col: dict, subs: dict, width: int) -> np.ndarray:
    """Direction ``d`` of joint ``j`` as a row acting on the twists (v_G in R0, omega in
    the body frame) of the bodies in ``col`` (body -> first column), at the initial pose."""
    row = np.zeros(width)
    for side, n in ((1, j.body1), (2, j.body2)):
        if n not in col:
            continue
        b = model.bodies[n]
        R = np.array(b.frame)
        r = np.array(joint_offset(b, j.at), dtype=float).ravel()
        rv = np.array(d.rows.get(f"v{side}", sp.zeros(3, 1)).xreplace(subs),
                      dtype=float).ravel()
        rw = np.array(d.rows.get(f"w{side}", sp.zeros(3, 1)).xreplace(subs),
                      dtype=float).ravel()
        row[col[n]:col[n] + 3] += rv
        row[col[n] + 3:col[n] + 6] += np.cross(r, R.T @ rv) + R.T @ rw
    return row


def _check_functional_not_blocked(model: Model, joint_dirs: dict, subs: dict):
    """Two joints between the same bodies where one's spring, damper or actuator acts on
    a motion the other blocks: the parasitic spring would absorb it, silently."""
    pairs: dict[frozenset, list] = {}
    for name, (j, dirs) in joint_dirs.items():
        pairs.setdefault(frozenset((j.body1, j.body2)), []).append((name, j, dirs))
    for pair, joints in pairs.items():
        if len(joints) < 2:
            continue
        col = {n: 6 * i for i, n in enumerate(sorted(n for n in pair if n is not None))}
        width = 6 * len(col)
        for name, j, dirs in joints:
            blocked = [(other, twist_row(model, oj, d, col, subs, width))
                       for other, oj, odirs in joints if other != name
                       for d in odirs if d.blocked]
            if not blocked:
                continue
            B = np.array([r for _, r in blocked])
            rank = np.linalg.matrix_rank(B, tol=1e-9)
            for d in dirs:
                fun = j.functional.get(d.label)
                ported = f"{name}.{d.label}" in model.ports
                if d.blocked or ((fun is None or fun.empty) and not ported):
                    continue
                f = twist_row(model, j, d, col, subs, width)
                if np.linalg.matrix_rank(np.vstack([B, f]), tol=1e-9) == rank:
                    others = sorted({o for o, _ in blocked})
                    raise ModelError(
                        f"the spring/damper/actuator/port on direction {d.label} of joint "
                        f"'{name}' acts on a motion that joint {', '.join(others)} blocks "
                        "between the same bodies; its parasitic spring would take the load",
                        loc=j.loc, key=f"joints.{name}",
                        hint="remove the blocking joint, or move the functional element "
                             "to a direction that is free in both")


def _check_massless(model: Model, joint_dirs: dict, subs: dict, method: ConstraintMethod):
    """A body of negligible mass must have its twist fixed by its joints (blocked or damped
    directions), or the balance of forces on it cannot be solved. Under lagrange (and zcp)
    its twist is a state whose rate the constraint block solves: only blocked
    directions fix it."""
    massless = [n for n, b in model.bodies.items() if b.mass == 0]
    if not massless:
        return
    col = {n: 6 * i for i, n in enumerate(massless)}
    rows, touching = [], {n: [] for n in massless}
    for name, (j, dirs) in joint_dirs.items():
        for d in dirs:
            fun = j.functional.get(d.label)
            damped = fun is not None and fun.c != 0 and not method.ideal
            if not (d.blocked or damped):
                continue
            for n in (j.body1, j.body2):
                if n in col and name not in touching[n]:
                    touching[n].append(name)
            rows.append(twist_row(model, j, d, col, subs, 6 * len(massless)))
    A = np.array(rows) if rows else np.zeros((0, 6 * len(massless)))
    for n in massless:
        sub = A[:, col[n]:col[n] + 6]
        rank = np.linalg.matrix_rank(sub, tol=1e-9) if len(sub) else 0
        if rank < 6:
            b = model.bodies[n]
            via = (f"its joints ({', '.join(touching[n])})" if touching[n]
                   else "it has no joint (no path to the fixed frame)")
            raise ModelError(f"body '{n}' has negligible mass and {via} leave its motion "
                             f"undetermined in {6 - rank} direction(s)", loc=b.loc,
                             key=f"bodies.{n}.mass",
                             hint="give it a mass, join it, or put a damper on the free "
                                  "direction of one of its joints" + (
                                      f" with --method {methods.DEFAULT} (under {method.name} "
                                      "only blocked directions fix it)"
                                      if method.ideal else ""))
    if np.linalg.matrix_rank(A, tol=1e-9) < A.shape[1]:
        names = ", ".join(massless)
        raise ModelError(f"the bodies of negligible mass ({names}) can move together without "
                         "any joint resisting", loc=model.bodies[massless[0]].loc,
                         key=f"bodies.{massless[0]}.mass",
                         hint="give one of them a mass or block the chain's free direction")


def expand(model: Model, method: str = methods.DEFAULT) -> BondGraph:
    """``method`` (a name in ``bgc.methods``) decides what the constraint element L of a
    blocked joint direction is (``ConstraintMethod.constraint_element``): under
    ``parasitic`` a stiff spring || damper, under ``lagrange`` an effort source (the
    multiplier); ``zcp`` starts from the latter and its ``restructure`` pass turns the
    tree joints' L into flow sources."""
    ex = Expander(model, methods.get(method))
    for body in model.bodies.values():
        ex.body(body)
    joint_dirs = {name: (j, ex.joint(j)) for name, j in model.joints.items()}
    ex.connect_ports()
    pose = initial_pose(model)
    _check_functional_not_blocked(model, joint_dirs, pose)
    _check_massless(model, joint_dirs, pose, ex.method)
    elements, bonds = ex.elements, ex.bonds
    ports: dict[str, list[int]] = {name: [] for name in elements}
    for i, b in enumerate(bonds):
        ports[b.src].append(i)
        ports[b.dst].append(i)
    graph = BondGraph(model, elements, bonds, ports, dict(model.bodies), method=method,
                      constraints=ex.constraints)
    graph.joints = {name: dirs for name, (j, dirs) in joint_dirs.items()}
    graph.port_junctions = {jn: port for port, jn in ex.port_junction.items()}
    for name, el in elements.items():
        _check_element(graph, name, el)
    return graph


def _check_element(graph: BondGraph, name: str, el: Element):
    bonds, ports, model = graph.bonds, graph.ports, graph.model
    n, spec = len(ports[name]), KINDS[el.kind]
    key = f"elements.{name}"
    user = name in model.elements
    if n == 0:
        raise ModelError(f"{el.kind} '{name}' is not connected by any bond", loc=el.loc,
                         key=key, hint="add a bond to it or remove it")
    if spec.ports is None and n < 2 and user:   # a body's own junction may carry one bond
        raise ModelError(f"{el.kind}-junction '{name}' has {n} bond; a junction needs "
                         "at least 2", loc=el.loc, key=key,
                         hint="bond the element directly, or add the missing bond")
    if spec.ports is not None and n != spec.ports:
        listed = ", ".join(f"{bonds[i].name} (line {bonds[i].loc.line})" for i in ports[name])
        raise ModelError(f"{el.kind} '{name}' has {n} bonds, it takes exactly "
                         f"{spec.ports}: {listed}", loc=el.loc, key=key,
                         hint="put a 0- or 1-junction in front of it to connect more")
    if el.kind in TWO_PORTS:
        n_in = sum(graph.points_into(i, name) for i in ports[name])
        if n_in != 1:
            raise ModelError(f"{el.kind} '{name}' has {n_in} bonds pointing in; a "
                             "two-port takes one bond in and one out", loc=el.loc,
                             key=key, hint="reverse one bond: power goes through it")
    dims = [bonds[i].dim for i in ports[name]]
    if el.kind in ("0", "1") and len(set(dims)) > 1:
        listed = ", ".join(f"{bonds[i].name} (dim {bonds[i].dim}, line {bonds[i].loc.line})"
                           for i in ports[name])
        raise ModelError(f"rule C1: the bonds of {el.kind}-junction '{name}' differ in "
                         f"dimension: {listed}", loc=el.loc, key=key,
                         hint="a junction joins bonds of one dimension; use a TF with a "
                              "matrix ratio to change dimension")
    _check_shape(graph, name, el, dims)


def _check_shape(graph: BondGraph, name: str, el: Element, dims: list[int]):
    """The element's matrix-valued fields must fit the dimensions of its bonds."""
    key = f"elements.{name}"

    def bad(field, want, got):
        raise ModelError(f"{el.kind} '{name}': '{field}' must be {want} for its bond(s) of "
                         f"dimension {', '.join(map(str, dims))}, got {got}",
                         loc=el.field_locs.get(field, el.loc), key=f"{key}.{field}",
                         hint="a scalar applies to every component; otherwise give a "
                              "vector or matrix of the bond's dimension")

    def shape(v):
        return f"{v.rows}x{v.cols}" if isinstance(v, sp.MatrixBase) else "a scalar"

    if el.kind in TWO_PORTS:
        a, c = graph.two_port(name)
        din, dout = graph.bonds[a].dim, graph.bonds[c].dim
        field = "r" if el.kind == "XTF" else ("ratio" if "ratio" in el.fields else "r")
        v = el.fields.get(field)
        if el.kind == "XTF":
            if din != 3 or dout != 3 or not (isinstance(v, sp.MatrixBase) and v.shape == (3, 1)):
                bad(field, "a 3-vector on bonds of dimension 3", shape(v))
        elif isinstance(v, sp.MatrixBase):
            if v.shape != (dout, din):
                bad(field, f"a {dout}x{din} matrix (out x in)", shape(v))
        elif din != dout:
            bad(field, f"a {dout}x{din} matrix (out x in)", shape(v))
        if el.kind in ("GY", "MGY") and din != 1:
            bad(field, "scalar on scalar bonds (a vector gyrator is not supported)", shape(v))
        return
    if el.kind in ("0", "1", "M0"):
        return
    d = dims[0]
    if d > 1 and el.kind in ("C", "I", "R") and el.law not in ("C", "k", "I", "R"):
        raise ModelError(f"{el.kind} '{name}' is on a multibond of dimension {d}: its law must "
                         f"be a matrix (or a scalar for every component), not '{el.law}'",
                         loc=el.field_locs.get(el.law, el.loc), key=f"{key}.{el.law}",
                         hint="write e.g. k: [[k1, 0, 0], [0, k2, 0], [0, 0, k3]]")
    for field, v in el.fields.items():
        if not isinstance(v, sp.MatrixBase):
            continue
        if field in ("effort", "flow") and el.kind in ("Se", "Sf", "MSe", "MSf"):
            if v.shape != (d, 1):
                bad(field, f"a vector of {d}", shape(v))
        elif field == "J":
            if v.shape != (3, 1) or d != 3:
                bad(field, "3 principal moments on a bond of dimension 3", shape(v))
        elif v.shape != (d, d):
            bad(field, f"a {d}x{d} matrix", shape(v))
