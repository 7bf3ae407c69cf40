"""Stage **equations**, its surface: the ``Builder`` the causal equations are written into
(by the element rules of ``elements``, the control blocks' of ``blocks``, the kinematics
of the bodies, and a constraint method's hooks), with the states it collects
(``State``), the placeholder of a dependent storage's derivative (``Dt``) and the
matrix product the rules share (``matmul``)."""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from bgc.errors import EquationError
from bgc.graph.causality import CausalGraph
from bgc.graph.expand import (
    AXES,
    body_junction,
    body_mass,
    body_moments,
    joint_offset,
    position,
    rotation_matrix,
)
from bgc.mechanics import cardan, exact
from bgc.model import symbols
from bgc.model.model import Block


@dataclass
class State:
    """A state of the system: what an element in integral causality integrates."""
    name: str            # display name, e.g. "spring.q"
    sym: sp.Symbol
    dsym: sp.Symbol
    initial: sp.Expr     # in terms of parameters
    element: str


def matmul(A: sp.MatrixBase, B: sp.MatrixBase) -> sp.Matrix:
    """``A * B``, the same entries as sympy forms them (each the sum of the products of
    the non-zero entries, in order), without sympy's conversions to and from its
    DomainMatrix, which cost more than the products on the small matrices here."""
    m, k, o = A.rows, A.cols, B.cols
    if B.rows != k:
        raise ValueError(f"matmul: {A.shape} x {B.shape}")
    a, b = A.flat(), B.flat()
    out = []
    for i in range(m):
        row = a[i * k:(i + 1) * k]
        for j in range(o):
            out.append(sp.Add(*[x * y for x, y in zip(row, b[j::o]) if x != 0 and y != 0]))
    return sp.Matrix(m, o, out)


class Dt(sp.Function):
    """Placeholder for the time derivative of a dependent storage variable."""
    nargs = 1


class Builder:
    """The causal equations of a CausalGraph, built element by element (``equations.build``), before
    they are sorted and solved. A constraint method extends them through this surface
    only (``ConstraintMethod.embed`` and ``constraint_equations``): ``define``, ``port``,
    ``add_state``, ``algebraic_state``, the tables ``eqs``, ``origin``, ``display``,
    ``states``, ``projection``, and one slot for the method's own state
    (``method_state``: ``ConstraintMethod.new_state``), which the builder never reads
    (``methods.base.Equations``)."""

    def __init__(self, cg: CausalGraph):
        self.cg, self.g, self.m = cg, cg.graph, cg.graph.model
        self.eqs: dict[sp.Symbol, sp.Expr] = {}
        self.origin: dict[sp.Symbol, tuple[str | None, str | None]] = {}  # (element, bond)
        self.display: dict[sp.Symbol, str] = {}
        self.states: list[State] = []
        self.dependent: dict[str, sp.Symbol] = {}
        self.refs: dict[sp.Symbol, sp.Expr] = {}
        self.guards: list[tuple[str, sp.Expr]] = []
        self.method_state: object = None     # the constraint method's (``new_state``)
        self.algebraic: list = []       # states of a DAE whose row of M is zero
        self.projection: dict = {}      # state -> its correction after a step
        self._columns: dict = {}        # (bond, effort | flow) -> its column of symbols
        # (junction, bond, component or None): the terms a junction's sum leaves out
        # (a scene's junction-activity pass, ``scene.reduce.junctions``)
        self.cut: frozenset = frozenset()

    # --- helpers --------------------------------------------------------------------
    def define(self, var, expr, element: str, bond: int | None = None):
        """``var = expr``; both may be matrices (the components of a multibond)."""
        if isinstance(var, sp.MatrixBase):
            for v, e in zip(var, sp.Matrix(expr)):
                self.define(v, e, element, bond)
            return
        if isinstance(expr, sp.MatrixBase):     # a 1x1 product (projection onto a row)
            (expr,) = expr
        if var in self.eqs:   # cannot happen after a correct causality assignment
            raise AssertionError(f"{var} defined twice")
        self.eqs[var] = sp.sympify(expr)
        self.origin[var] = (element, self.g.bonds[bond].name if bond is not None else None)

    def _var(self, b: int, make):
        bond = self.g.bonds[b]
        if bond.dim == 1:
            return make(bond.name)
        key = (b, make)
        col = self._columns.get(key)
        if col is None:     # built once: a Matrix costs ~10x its copy
            col = self._columns[key] = sp.Matrix([make(bond.name, k) for k in range(bond.dim)])
        return col.copy()

    def E(self, b: int):
        """Effort of bond b: a symbol, or a column of symbols on a multibond."""
        return self._var(b, symbols.effort)

    def F(self, b: int):
        return self._var(b, symbols.flow)

    def law(self, el, key, **local) -> sp.Expr:
        return el.fields[key].xreplace({symbols.LOCAL[k]: v for k, v in local.items()})

    def invert(self, el, key, value, want: str) -> sp.Expr:
        """Solve ``value = law(want)`` for ``want`` (a law used in the other causality)."""
        w = sp.Dummy(want, real=True)
        law = self.law(el, key, **{want: w})
        sols = sp.solve(sp.Eq(law, value), w, dict=False)
        if len(sols) != 1:
            raise EquationError(
                f"{el.kind} '{el.name}' is used in the causality its law '{key}' is not "
                f"written for, and the law cannot be inverted uniquely "
                f"({len(sols)} solutions for {want})", loc=el.field_locs[key],
                key=f"elements.{el.name}.{key}",
                hint=f"write the law the other way ({'flow' if key == 'effort' else 'effort'}"
                     " as a function) or change the model so causality matches")
        return sols[0]

    # --- element equations -------------------------------------------------------------
    def port(self, name):
        """A one-port element's bond, the sign of its power, its effort and flow."""
        b = self.g.ports[name][0]
        return b, self.g.port_sign(b, name), self.E(b), self.F(b)

    def add_state(self, label: str, sym, dsym, initial, element: str):
        """A state ``sym`` with its rate's symbol ``dsym`` (defined elsewhere), its initial
        value in the parameters, shown as ``label``."""
        self.states.append(State(label, sym, dsym, initial, element))
        self.display[sym], self.display[dsym] = label, f"d({label})/dt"

    def algebraic_state(self, label: str, sym, dsym, residual, element: str):
        """A state with no derivative in the equations (a zero row of the mass matrix):
        the right-hand side's row ``dsym`` is the residual ``0 = residual``."""
        self.define(dsym, residual, element)
        self.states.append(State(label, sym, dsym, sp.S.Zero, element))
        self.algebraic.append(sym)
        self.display[sym], self.display[dsym] = label, f"0 = {label} residual"

    def common_flow(self, junction: str):
        return self.F(self.g.ports[junction][0])

    def kinematics(self):
        """Position of G (R0), XYZ Cardan angles and rotation matrix of every body,
        integrated from the junction velocities: x' = v, [a b c]' = E(a, b, c)^-1 omega
        (paper Fig. 11.2). The angles are measured from the body's initial frame F0
        (R = F0 Rx(a) Ry(b) Rz(c)), so every body starts at zero angles, far from the
        gimbal lock, whatever its initial orientation. The rotation matrix entries are
        shared assignments that the MTFs and joints read."""
        for n, body in self.g.bodies.items():
            v = self.common_flow(body_junction(n, "v"))
            w = self.common_flow(body_junction(n, "w"))
            pos = position(n)
            ang = [symbols.state(n, f"a{a}") for a in AXES]
            rates = cardan.angle_rates(*ang, w)
            self.guards.append((f"Cardan singularity (gimbal lock, cos {n}.ay -> 0) of body "
                                f"'{n}'", cardan.gimbal_margin(ang[1])))
            F0 = exact.matrix(body.frame)
            C = cardan.rotation(*ang)
            self.define(rotation_matrix(n), C if F0 == sp.eye(3) else matmul(F0, C), n)
            shift = body.offset_expr or (0, 0, 0)    # a joint's initial displacement
            for k in range(3):
                for x, rate, x0, label in ((pos[k], v[k], body.com[k], AXES[k]),
                                           (ang[k], rates[k], 0.0, f"a{AXES[k]}")):
                    dx = symbols.dstate(n, label)
                    self.define(dx, rate, n)
                    x0 = exact.rational(x0) + (shift[k] if label in AXES else 0)
                    self.states.append(State(f"{n}.{label}", x, dx, x0, n))
                    self.display[x], self.display[dx] = f"{n}.{label}", f"d({n}.{label})/dt"

    # --- references, derivatives --------------------------------------------------------
    def point_velocity(self, n: str, r) -> sp.Matrix:
        """Velocity (R0) of the point of body ``n`` at body-frame offset ``r`` from G:
        v_G + R (omega x r)."""
        w = self.common_flow(body_junction(n, "w"))
        return self.common_flow(body_junction(n, "v")) + rotation_matrix(n) * w.cross(r)

    def body_refs(self, n: str, body) -> dict:
        """body.x ... body.accz, and body.point.x ... body.point.accz (R0)."""
        out = {}
        R = rotation_matrix(n)
        x = position(n)
        v = self.common_flow(body_junction(n, "v"))
        w = self.common_flow(body_junction(n, "w"))
        massive = body.mass > 0
        if massive:
            acc = (sp.Matrix([symbols.dstate(f"{n}__m", f"p{a}") for a in AXES])
                   / body_mass(body))
            J = body_moments(body)
            wdot = sp.Matrix([symbols.dstate(f"{n}__J", f"p{a}") / J[k]
                              for k, a in enumerate(AXES)])
        for k, a in enumerate(AXES):
            out[symbols.ref(n, a)] = x[k]
            out[symbols.ref(n, f"a{a}")] = symbols.state(n, f"a{a}")
            out[symbols.ref(n, f"v{a}")] = v[k]
            out[symbols.ref(n, f"w{a}")] = w[k]         # body frame
            out[symbols.ref(n, f"w{a}_R0")] = (R * w)[k]
            if massive:
                out[symbols.ref(n, f"acc{a}")] = acc[k]
        for pt, r in body.points.items():
            r = exact.vector(r)
            target = f"{n}__{pt}"
            xp, vp = x + R * r, self.point_velocity(n, r)
            if massive:
                ap = acc + R * (wdot.cross(r) + w.cross(w.cross(r)))
            for k, a in enumerate(AXES):
                out[symbols.ref(target, a)] = xp[k]
                out[symbols.ref(target, f"v{a}")] = vp[k]
                if massive:
                    out[symbols.ref(target, f"acc{a}")] = ap[k]
        return out

    def joint_refs(self, name: str, dirs) -> dict:
        """Force and moment on body 2 from body 1 at the joint point, in the joint frame
        (turning with body 1) and in R0: minus the sum over directions of effort * row."""
        j = self.m.joints[name]
        F, M = sp.zeros(3, 1), sp.zeros(3, 1)
        gap = [d.g for d in dirs if d.blocked and d.g is not None and not d.rotational]
        tilt = [d.g for d in dirs if d.blocked and d.g is not None and d.rotational]
        out = {symbols.ref(name, "gap"): sp.sqrt(sum(g ** 2 for g in gap)),
               symbols.ref(name, "tilt"): sp.sqrt(sum(g ** 2 for g in tilt))}
        for d in dirs:
            zero = f"{name}__{d.label}"
            if zero not in self.g.ports:
                continue
            lam = self.E(self.g.ports[zero][0])
            if j.body2 is not None:
                F -= lam * d.rows.get("v2", sp.zeros(3, 1))
                M -= lam * d.rows.get("w2", sp.zeros(3, 1))
            else:       # reaction of the force on body 1 (the points coincide)
                F += lam * d.rows.get("v1", sp.zeros(3, 1))
                M += lam * d.rows.get("w1", sp.zeros(3, 1))
        frame = exact.matrix(j.output_frame or j.frame)
        if j.body1 is not None:
            b = self.m.bodies[j.body1]
            frame = rotation_matrix(j.body1) * exact.canonical(exact.matrix(b.frame).T * frame)
        Fj, Mj = frame.T * F, frame.T * M
        for k, a in enumerate(AXES):
            out[symbols.ref(name, f"F{a}")] = Fj[k]
            out[symbols.ref(name, f"M{a}")] = Mj[k]
            out[symbols.ref(name, f"F{a}_R0")] = F[k]
            out[symbols.ref(name, f"M{a}_R0")] = M[k]
        return out

    def direction_refs(self, name: str, d) -> dict:
        """joint.direction.v: the rate of a free direction, its rows applied to the two
        bodies' joint-point velocities and angular velocities (R0); joint.direction.q: its
        displacement, geometric for a translation, else its rate integrated (a state)."""
        j = self.m.joints[name]
        rate = sp.S.Zero
        for side, n in ((1, j.body1), (2, j.body2)):
            if n is None:
                continue
            r = joint_offset(self.m.bodies[n], j.at)
            w = rotation_matrix(n) * self.common_flow(body_junction(n, "w"))
            for key, vec in ((f"v{side}", self.point_velocity(n, r)), (f"w{side}", w)):
                if key in d.rows:
                    rate += (d.rows[key].T * vec)[0]
        target = f"{name}__{d.label}"
        q = d.g
        if q is None:
            q, dq = symbols.state(target, "q"), symbols.dstate(target, "q")
            if dq not in self.eqs:
                self.define(dq, rate, name)
                self.states.append(State(f"{name}.{d.label}", q, dq, sp.S.Zero, target))
                self.display[q], self.display[dq] = f"{name}.{d.label}.q", \
                    f"d({name}.{d.label}.q)/dt"
        return {symbols.ref(target, "q"): q, symbols.ref(target, "v"): rate}

    def ref_map(self, wanted: set[str] | None = None) -> dict[sp.Symbol, sp.Expr]:
        """Every reference ``target.attr`` -> its expression; with ``wanted``, only those
        of the targets named (building every body's and joint's references costs more
        than all the rest of the equations of a large model)."""
        def want(target):
            return wanted is None or target in wanted
        out = {}
        bonds = {bd.name: i for i, bd in enumerate(self.g.bonds)}
        for name, el in self.g.elements.items():
            if not want(name):
                continue
            if el.kind in ("0", "1"):
                first = self.g.ports[name][0]
                tag = "e" if el.kind == "0" else "f"
                out.update(self._refs(name, tag, self.E(first) if tag == "e" else self.F(first)))
            elif len(self.g.ports[name]) == 1:
                b, s, E, F = self.port(name)
                out.update(self._refs(name, "e", E))
                out.update(self._refs(name, "f", s * F))
        out.update({symbols.ref(n, a): symbols.block(n, a)    # block.y, block.u, ...
                    for n in self.m.blocks if want(n) for a in Block.ATTRS})
        for st in self.states:
            if want(st.element):
                out[symbols.ref(st.element, st.name.rsplit(".", 1)[1])] = st.sym
        for name, v in self.dependent.items():
            if want(name):
                out[symbols.ref(name, "q" if self.g.elements[name].kind == "C" else "p")] = v
        for n, body in self.g.bodies.items():
            if want(n) or any(want(f"{n}__{pt}") for pt in body.points):
                out.update(self.body_refs(n, body))
        for name, dirs in self.g.joints.items():
            if want(name):
                out.update(self.joint_refs(name, dirs))
            for d in dirs:
                if not d.blocked and want(f"{name}__{d.label}"):
                    out.update(self.direction_refs(name, d))
        for bname, i in bonds.items():
            if not want(bname):
                continue
            out.update(self._refs(bname, "e", self.E(i)))
            out.update(self._refs(bname, "f", self.F(i)))
        return out

    @staticmethod
    def _refs(target: str, tag: str, value) -> dict:
        """target.e -> value; on a multibond target.ex, .ey, .ez -> its components."""
        if isinstance(value, sp.MatrixBase):
            return {symbols.ref(target, f"{tag}{AXES[k]}"): v for k, v in enumerate(value)}
        return {symbols.ref(target, tag): value}

    def resolve_refs(self):
        """Replace the references in the equations; ``refs`` keeps those of the equations
        and the outputs (the only readers)."""
        reading = {}
        for v, e in self.eqs.items():
            refs = {s for s in e.free_symbols if symbols.is_ref(s)}
            if refs:
                reading[v] = refs
        used = set().union(*reading.values(), *(
            {s for s in o.expr.free_symbols if symbols.is_ref(s)} for o in self.m.outputs))
        self.refs = self.ref_map({symbols.split_ref(s)[0] for s in used})
        for v in reading:
            self.eqs[v] = self.eqs[v].xreplace(self.refs)

    def explicit(self, var: sp.Symbol, memo: dict, path: tuple) -> sp.Expr:
        """``var`` as a function of states, parameters and t only (for d/dt)."""
        if var in memo:
            return memo[var]
        if var in path:
            raise self._dt_error(path, "lies on an algebraic loop")
        expr = self.eqs[var]
        if expr.has(Dt) and path:
            raise self._dt_error(path, "depends on another derivative-causal storage")
        subs = {}
        for s in expr.free_symbols:
            if s in self.eqs:
                if symbols.kind(s) == "rate":
                    raise self._dt_error(path + (var,), "depends on a state derivative")
                subs[s] = self.explicit(s, memo, path + (var,))
        memo[var] = expr.xreplace(subs)
        return memo[var]

    def _dt_error(self, path, why) -> EquationError:
        el = self.origin[path[0]][0]
        names = ", ".join(self.display.get(v, v.name) for v in path)
        e = self.g.elements[el]
        return EquationError(f"the derivative causality of {e.kind} '{el}' cannot be resolved: "
                             f"its dependent state {why} ({names})", loc=e.loc,
                             key=f"elements.{el}",
                             hint="give the storage integral causality (e.g. a stiff C or "
                                  "small I between the coupled storages)")

    def resolve_derivatives(self):
        memo: dict = {}
        dx = {st.sym: st.dsym for st in self.states}
        for var, expr in list(self.eqs.items()):
            for d in expr.atoms(Dt):
                g = self.explicit(d.args[0], memo, ())
                total = sp.diff(g, symbols.t)
                for x, dxs in dx.items():
                    if g.has(x):
                        total += sp.diff(g, x) * dxs
                expr = expr.xreplace({d: total})
            self.eqs[var] = expr
