"""Stage **equations**: CausalGraph -> EquationSystem.

Every bond variable, storage rate and signal gets exactly one defining equation, read off
the causal strokes. The equations are sorted into causal order (block lower triangular,
Tarjan's SCCs) and kept as a list of assignments; they are never substituted into one
expression. Two things need more than sorting:

- **derivative causality**: a C or I whose causality is derivative has a dependent state
  g(x, t); its output is the total derivative sum(dg/dx_i * dx_i/dt) + dg/dt, which ties
  it to the integral states' rates in a *linear* loop;
- **algebraic loops** (R-R networks, derivative causality): each strongly connected block
  is torn (a small set of tearing variables is kept, the rest substituted), checked to be
  linear in the tearing variables and solved; a nonlinear loop is refused with the
  elements and bonds it runs through.
"""

from __future__ import annotations

import gc
from contextlib import contextmanager
from dataclasses import dataclass, field

import sympy as sp
from sympy.solvers.solveset import NonlinearError

from bgc import methods
from bgc.codegen import blocks, elements
from bgc.codegen.elements import Dt, State, matmul
from bgc.codegen.forward_mode import directional, propagate, trivial
from bgc.errors import EquationError
from bgc.graph.algorithms import is_cyclic, strongly_connected
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
from bgc.methods.consistent import RANK_PARAM
from bgc.model import symbols
from bgc.model.model import Model, Table

# Largest loop solved symbolically (tearing variables); larger loops become numeric blocks.
MAX_SYMBOLIC_LOOP = 6


@dataclass
class Loop:
    """An algebraic loop (a strongly connected block of equations) and how it was solved."""
    kind: str            # "algebraic" | "derivative" (through a derivative-causal storage)
    variables: list[str]
    bonds: list[str]
    elements: list[str]
    tearing: list[str]

    def describe(self) -> str:
        return (f"{self.kind} loop through {', '.join(self.elements)} (bonds "
                f"{', '.join(self.bonds)}), {len(self.variables)} equations, solved for "
                f"{', '.join(self.tearing)}")


@dataclass(frozen=True)
class LinearBlock:
    """A linear loop solved numerically at run time: ``A(w) u = b(w)`` by LU, for loops
    too large to solve symbolically without expression swell. ``A`` holds the non-zero
    entries only; ``b`` is None where it is evaluated numerically, as ``tear_eqs`` with
    ``u = 0`` and the chain run once at that point (no substituted expression); ``pre``
    are assignments that ``A`` reads (the loop's sensitivities to ``u``). For the Jacobian: ``u = tear_eqs(u, chain)``, where ``chain`` are the loop's
    other variables in causal order (computed after the block), both unsubstituted."""
    index: int
    unknowns: tuple[sp.Symbol, ...]
    A: tuple[tuple[int, int, sp.Expr], ...]
    b: tuple[sp.Expr, ...] | None
    tear_eqs: tuple[sp.Expr, ...]
    chain: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    pre: tuple[tuple[sp.Symbol, sp.Expr], ...] = ()
    # None: LU. An expression: the constraint block of method lagrange, solved by SVD
    # keeping that many singular values (the rank of the constraints at the initial state,
    # plus the twist rates of bodies of negligible mass)
    rank: sp.Expr | None = None
    # constraint blocks: A = -K B with K (n x d) and B (d x n) sparse, d dynamic states
    factors: tuple | None = None
    # a block solved with the diagonal of A raised by eps times itself on these rows
    # (``Regularized``: method augmented's projections), regular whatever the rank
    regularize: "Regularized | None" = None
    # right-hand sides solved at once (``b`` holds n x columns, row-major; the unknowns
    # likewise): method augmented's projection solves its velocities and positions so
    columns: int = 1

    @property
    def free_symbols(self) -> set:
        out = set(self.rank.free_symbols) if self.rank is not None else set()
        if self.regularize is not None:
            out |= self.regularize.free_symbols
        exprs = [e for _, _, e in self.A] + [e for _, e in self.pre]
        if self.factors is not None:
            exprs += [e for _, _, e in self.factors[1] + self.factors[2]]
        if self.b is None:      # b = tear_eqs at u = 0, the chain evaluated in the block
            exprs += list(self.tear_eqs) + [e for _, e in self.chain]
        else:
            exprs += list(self.b)
        for e in exprs:
            out |= e.free_symbols
        inner = set(self.unknowns) | {v for v, _ in self.chain} if self.b is None else set()
        return out - {v for v, _ in self.pre} - inner

    def xreplace(self, mapping) -> "LinearBlock":
        """Apply ``mapping`` (aliases: symbol -> symbol or number) everywhere; chain
        variables that are aliases themselves are dropped from the chain."""
        def pairs(items):
            return tuple((v, e.xreplace(mapping)) for v, e in items if v not in mapping)
        return LinearBlock(self.index, self.unknowns,
                           tuple((i, j, e.xreplace(mapping)) for i, j, e in self.A),
                           None if self.b is None else
                           tuple(e.xreplace(mapping) for e in self.b),
                           tuple(e.xreplace(mapping) for e in self.tear_eqs),
                           pairs(self.chain), pairs(self.pre), self.rank,
                           None if self.factors is None else
                           (self.factors[0],
                            tuple((i, j, e.xreplace(mapping)) for i, j, e in self.factors[1]),
                            tuple((i, j, e.xreplace(mapping)) for i, j, e in self.factors[2])),
                           None if self.regularize is None else
                           self.regularize.xreplace(mapping), self.columns)


@dataclass(frozen=True)
class Regularized:
    """A linear block solved as ``(A + diag(w)) u = b``, ``w[k]`` added on row
    ``rows[k]`` (Tikhonov, each row in its own scale: method augmented), regular where A
    is not (redundant constraints, a singular configuration), within the weights of A's
    solution on its well-conditioned part."""
    weights: tuple[sp.Expr, ...]
    rows: tuple[int, ...]

    @property
    def free_symbols(self) -> set:
        return set().union(*(w.free_symbols for w in self.weights))

    def xreplace(self, mapping) -> "Regularized":
        return Regularized(tuple(w.xreplace(mapping) for w in self.weights), self.rows)


@dataclass
class EquationSystem:
    model: Model
    method: str
    states: list[State]
    params: list[tuple[sp.Symbol, str, float]]   # (symbol, name, default)
    assignments: list  # causal order: (symbol, expr) pairs and LinearBlocks
    outputs: list[tuple[str, sp.Expr]]
    loops: list[Loop] = field(default_factory=list)
    dependent: dict[str, str] = field(default_factory=dict)  # storage -> dependent state
    display: dict[sp.Symbol, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    # (what, margin expression): the run stops where a margin reaches GUARD_TOLERANCE
    guards: list[tuple[str, sp.Expr]] = field(default_factory=list)
    # lagrange: (joint.direction, deflection g or None, rate dg/dt) per multiplier
    constraints: list[tuple[str, sp.Expr | None, sp.Expr]] = field(default_factory=list)
    # zcp: the constraints whose flow is imposed (tree joints), not break variables
    imposed: set[str] = field(default_factory=set)
    # a DAE M dx/dt = rhs: the states whose row of M is zero (index 2: zcp, loops kept
    # closed); empty for an ODE
    algebraic: list[int] = field(default_factory=list)
    # method augmented: the projection onto the constraints after a step, as (state
    # index, its correction) (``methods.augmented``)
    projection: list[tuple[int, sp.Expr]] = field(default_factory=list)
    loops_closed: bool = False      # zcp: kinematic loops kept closed (--keep-loops)
    scene: str = ""                 # reduced for a scene (bgc/scene.py): its name
    # the energy variant (``codegen.energy``): (name, kind, column, body, joint) per
    # element whose energy and activity are quadrature states; None: the ordinary module
    energy: list | None = None
    # the states no equation reads (the energy variant's quadratures): left out where the
    # run-time side solves for the rates (static loads)
    quadrature: list[int] = field(default_factory=list)
    # the variables inlined as copies of others or numbers (``_drop_aliases``): a pass
    # that reads a bond's variable by name finds where it went
    aliases: dict = field(default_factory=dict)
    # parameters folded into constants (a scene's ``fold_parameters``): symbol -> value,
    # for what reads the model's parameters outside the equations (a signal's frequency)
    folded: dict = field(default_factory=dict)

    @property
    def variant(self) -> str:
        """What the generated module is named and hashed by: the method, for zcp whether
        its loops were kept closed (``zcp_closed``), and the scene it was reduced for."""
        v = methods.variant(self.method, not self.loops_closed)
        v = f"{v}_{self.scene}" if self.scene else v
        return f"{v}_energy" if self.energy is not None else v

    @property
    def tables(self) -> list[Table]:
        return self.model.tables

    @property
    def breakpoints(self) -> list[float]:
        return sorted({bp for s in self.model.signals.values() for bp in s.breakpoints})


class Builder:
    """The causal equations of a CausalGraph, built element by element (``build``), before
    they are sorted and solved. A constraint method extends them through this surface
    only (``ConstraintMethod.embed`` and ``constraint_equations``): ``define``, ``port``,
    ``algebraic_state``, and the tables ``eqs``, ``origin``, ``display``, ``states``,
    ``kkt_rows`` (lagrange's rows of the constraint block) and ``zcp_dependent`` (zcp's
    momenta no longer integrated)."""

    def __init__(self, cg: CausalGraph):
        self.cg, self.g, self.m = cg, cg.graph, cg.graph.model
        self.eqs: dict[sp.Symbol, sp.Expr] = {}
        self.origin: dict[sp.Symbol, tuple[str | None, str | None]] = {}  # (element, bond)
        self.display: dict[sp.Symbol, str] = {}
        self.states: list[State] = []
        self.dependent: dict[str, sp.Symbol] = {}
        self.refs: dict[sp.Symbol, sp.Expr] = {}
        self.guards: list[tuple[str, sp.Expr]] = []
        self.kkt_rows: dict = {}     # lagrange: multiplier -> {dynamic state: d rate/d x}
        self.kkt_rates: dict = {}    # lagrange: net force on a massless body -> its column
        self.kkt_constraint: dict = {}  # lagrange: multiplier -> (g, dg/dt)
        self.pose_rows: dict = {}       # augmented: pose state -> {dynamic state: d rate/d x}
        self.zcp_dependent: list = []   # zcp: (momentum, its rate, name) not integrated
        self.algebraic: list = []       # states of a DAE whose row of M is zero
        self.projection: dict = {}      # state -> its correction after a step
        self._columns: dict = {}        # (bond, effort | flow) -> its column of symbols

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
    def build(self):
        for name, sig in self.m.signals.items():
            var = symbols.signal(name)
            self.define(var, sig.expr, name)
            self.display[var] = name
        for b, bond in enumerate(self.g.bonds):
            for var, tag in ((self.E(b), "e"), (self.F(b), "f")):
                if bond.dim == 1:
                    self.display[var] = f"{bond.name}.{tag}"
                else:
                    for k, v in enumerate(var):
                        self.display[v] = f"{bond.name}.{tag}{AXES[k]}"
        for name, el in self.g.elements.items():
            elements.RULES[el.kind](self, name, el)
        self.kinematics()
        blocks.build(self)

    def port(self, name):
        """A one-port element's bond, the sign of its power, its effort and flow."""
        b = self.g.ports[name][0]
        return b, self.g.port_sign(b, name), self.E(b), self.F(b)

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
        out.update(blocks.refs(self.m, want))
        for st in self.states:
            if want(st.element):
                out[symbols.ref(st.element, st.name.split(".")[1])] = st.sym
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


def _deps(eqs: dict) -> dict:
    return {v: sorted((s for s in e.free_symbols if s in eqs), key=lambda s: s.name)
            for v, e in eqs.items()}


def _tear(comp: list, deps: dict, first=()) -> list:
    """Greedy tearing: drop the variable with most loop in*out edges until acyclic
    (after the variables ``first``, torn by choice)."""
    first = set(first)
    tears = [v for v in comp if v in first]
    rest = [v for v in comp if v not in first]
    while True:
        live = set(rest)
        sub = {v: [d for d in deps[v] if d in live] for v in rest}
        cyclic = [c for c in strongly_connected(rest, sub) if is_cyclic(c, sub)]
        if not cyclic:
            return tears
        block = cyclic[0]
        indeg = {v: 0 for v in block}
        for v in block:
            for d in sub[v]:
                if d in indeg:
                    indeg[d] += 1
        best = max(block, key=lambda v: indeg[v] * sum(d in indeg for d in sub[v]))
        tears.append(best)
        rest.remove(best)


def _numeric_block(b: Builder, comp: list, index: int, refuse) -> LinearBlock:
    """The whole loop as one linear system in all its variables (simple coefficients,
    nothing substituted), to be factorized numerically in the generated code."""
    residuals = [v - b.eqs[v] for v in comp]
    try:
        A, rhs = sp.linear_eq_to_matrix(residuals, comp)
    except NonlinearError:
        raise refuse("nonlinear algebraic loop",
                     "break the loop with a small parasitic C or I") from None
    if any(e.has(*comp) for e in list(A) + list(rhs)):
        raise refuse("nonlinear algebraic loop", "break the loop with a small parasitic C or I")
    entries = tuple((i, j, A[i, j]) for i in range(A.rows) for j in range(A.cols)
                    if A[i, j] != 0)
    return LinearBlock(index, tuple(comp), entries, tuple(rhs),
                       tuple(b.eqs[v] for v in comp))


def _substituted(b: Builder, order: list) -> dict:
    """The loop variables ``order`` (causal order) as expressions of the tearing variables
    and what lies outside the loop (only where a substituted residual is wanted: they
    swell along long loops)."""
    subs: dict = {}
    for v in order:
        subs[v] = b.eqs[v].xreplace(subs)
    return subs


def _reduced_block(b: Builder, tears: list, order: list, index: int,
                   refuse, rank=None, numeric_rhs=False) -> LinearBlock:
    """A linear loop solved numerically in its tearing variables only. ``A = I - d
    tear_eqs/du`` comes from forward-mode sensitivities to the tears carried through the
    loop's assignments (small, hoisted; never the substituted residual, which swells with
    every modulated transformer along the loop); ``b`` is the substituted residual at
    ``u = 0``. The other loop variables are computed afterwards in causal order."""
    chain = tuple((v, b.eqs[v]) for v in order)
    loop_vars = set(tears) | set(order)
    sens = {t: {k: sp.S.One} for k, t in enumerate(tears)}
    pre = propagate(chain, sens, lambda v, k: f"S{index}_{v.name}__{k}")
    entries = []
    for i, t in enumerate(tears):
        row = directional(b.eqs[t], sens)
        for k in range(len(tears)):
            a = (sp.S.One if i == k else sp.S.Zero) - row.get(k, sp.S.Zero)
            if a != 0:
                entries.append((i, k, a))
    if any(e.has(*loop_vars) for e in [e for _, e in pre] + [a for _, _, a in entries]):
        raise refuse("nonlinear algebraic loop", "break the loop with a small parasitic C or I")
    zero = {t: 0 for t in tears}
    rhs = None
    if rank is None and not numeric_rhs:
        subs = _substituted(b, order)
        rhs = tuple(b.eqs[t].xreplace(subs).xreplace(zero) for t in tears)
    return LinearBlock(index, tuple(tears), tuple(entries), rhs,
                       tuple(b.eqs[t] for t in tears), chain, tuple(pre), rank)


def _kkt_block(b: Builder, tears: list, order: list, index: int) -> LinearBlock:
    """The constraint block of method lagrange: the acceleration-level equations are
    linear in the multipliers u, ``resid = K (dp/dt) + ...`` with ``dp/dt = dp/dt|u=0 +
    B u``; K (the rates' rows on the dynamic states, from ``lagrange``) and B (the
    multipliers' rows on the dynamic states' rates, forward mode along the loop, which
    is the force path) are sparse; their product ``J M^-1 J^T`` is formed numerically at
    run time."""
    chain = tuple((v, b.eqs[v]) for v in order)
    dynamic = sorted({x for rows in b.kkt_rows.values() for x in rows},
                     key=lambda x: x.name)
    col = {x: j for j, x in enumerate(dynamic)}
    dstate = {st.dsym: st.sym for st in b.states}
    dstate.update({ds: x for x, ds, _ in b.zcp_dependent})
    dstate.update(b.kkt_rates)
    sens = {t: {k: sp.S.One} for k, t in enumerate(tears)}
    pre = propagate(chain, sens, lambda v, k: f"S{index}_{v.name}__{k}")
    B = tuple((col[dstate[dx]], k, d) for dx in sorted(sens, key=lambda s: s.name)
              if dx in dstate and dstate[dx] in col for k, d in sens[dx].items())
    K = tuple((i, col[x], d) for i, t in enumerate(tears)
              for x, d in sorted(b.kkt_rows[t].items(), key=lambda kv: kv[0].name))
    # a body of negligible mass adds its twist's rates, each one rank of the saddle point
    rank = symbols.param(RANK_PARAM) + sum(symbols.kind(t) == "acceleration" for t in tears)
    return LinearBlock(index, tuple(tears), (), None, tuple(b.eqs[t] for t in tears), chain,
                       tuple(pre), rank, (len(dynamic), K, B))


def _solve_loop(b: Builder, comp: list, deps: dict, max_symbolic: int = MAX_SYMBOLIC_LOOP,
                block_index: int = 0) -> tuple[list, Loop]:
    eqs = b.eqs
    multipliers = [v for v in comp if symbols.kind(v) in ("multiplier", "acceleration")]
    zcp_dependent = {x for x, _, _ in b.zcp_dependent}
    dependent = [v for v in comp if v in zcp_dependent]
    tears = _tear(comp, deps, multipliers + dependent)
    torn = set(tears)
    rest = [v for v in comp if v not in torn]
    live = set(rest)
    sub_deps = {v: [d for d in deps[v] if d in live] for v in rest}
    order = [c[0] for c in strongly_connected(rest, sub_deps)]
    elements = sorted({b.origin[v][0] for v in comp if b.origin[v][0]})
    bonds = sorted({b.origin[v][1] for v in comp if b.origin[v][1]})
    kind = "derivative" if any(symbols.kind(v) == "rate" for v in comp) else "algebraic"
    loop = Loop(kind, [b.display.get(v, v.name) for v in comp], bonds, elements,
                [b.display.get(v, v.name) for v in tears])
    placed = [e for e in elements if e in b.g.elements]     # not a control block
    where = b.g.elements[placed[0]] if placed else None

    def refuse(why, hint):
        return EquationError(f"{why}: {loop.kind} loop through elements "
                             f"{', '.join(elements)} and bonds {', '.join(bonds)}",
                             loc=where.loc if where else None,
                             key=f"elements.{placed[0]}" if placed else None, hint=hint)

    if multipliers and set(tears) == set(multipliers):
        loop.kind = "constraint"
        n_acc = sum(symbols.kind(v) == "acceleration" for v in tears)
        loop.tearing = [f"numeric SVD of the {len(tears) - n_acc} Lagrange multipliers"
                        + (f" and {n_acc} twist rates of bodies of negligible mass"
                           if n_acc else "")]
        block = _kkt_block(b, tears, order, block_index)
        before, block, after = methods.get(b.g.method).constraint_block(b, block)
        return before + [block] + [(v, eqs[v]) for v in order] + after, loop
    if multipliers:
        loop.kind = "constraint"
        loop.tearing = [f"numeric SVD of {len(tears)} unknowns "
                        f"({len(multipliers)} Lagrange multipliers)"]
        # the constraints' rank at run time, plus the other tears (a storage in
        # derivative causality on the mechanism's ports), which are never redundant
        regular = sum(symbols.kind(v) != "multiplier" for v in tears)
        block = _reduced_block(b, tears, order, block_index, refuse,
                               rank=symbols.param(RANK_PARAM) + regular)
        return [block] + [(v, eqs[v]) for v in order], loop
    if dependent:
        loop.kind = "imposed-flow"
        loop.tearing = [f"numeric LU of the {len(dependent)} dependent momenta (class-1 "
                        "ZCP: velocities imposed by the flow sources)"]
        block = _reduced_block(b, tears, order, block_index, refuse, numeric_rhs=True)
        return [block] + [(v, eqs[v]) for v in order], loop
    if kind == "derivative" and any(b.g.elements[e].kind == "XTF" or b.g.elements[e].orthogonal
                                    for e in placed):
        # a storage geared rigidly to the mechanism through a port: its loop runs through
        # the bodies' rotations (orthogonal MTFs, cross-product TFs), whose substituted
        # residual would swell (and expanding it take most of a compile); solved
        # numerically in its tears
        loop.tearing = [f"numeric LU of {len(tears)} tearing variables"]
        block = _reduced_block(b, tears, order, block_index, refuse)
        return [block] + [(v, eqs[v]) for v in order], loop
    if any(symbols.kind(v) == "unknown" for v in comp):
        loop.kind = "negligible-mass"
        loop.tearing = [f"numeric LU of {len(tears)} tearing variables"]
        block = _reduced_block(b, tears, order, block_index, refuse)
        return [block] + [(v, eqs[v]) for v in order], loop
    if len(tears) > max_symbolic:
        loop.tearing = ["numeric LU of all " + str(len(comp)) + " loop variables"]
        return [_numeric_block(b, comp, block_index, refuse)], loop
    subs = _substituted(b, order)
    residuals = [sp.expand(t - eqs[t].xreplace(subs)) for t in tears]
    try:
        A, rhs = sp.linear_eq_to_matrix(residuals, tears)
    except NonlinearError:
        raise refuse("nonlinear algebraic loop",
                     "make a loop element linear, or break the loop with a small parasitic "
                     "C or I (its value sets how stiff the result is)") from None
    if any(e.has(*tears) for e in list(A) + list(rhs)):
        raise refuse("nonlinear algebraic loop", "break the loop with a small parasitic C or I")
    if A.det() == 0:
        raise refuse("singular algebraic loop (the loop equations are dependent)",
                     "check for redundant sources or a junction structure without elements")
    sol = [sp.cancel(e) for e in A.LUsolve(rhs)] if len(tears) > 1 else [rhs[0] / A[0, 0]]
    out = list(zip(tears, sol)) + [(v, eqs[v]) for v in order]
    return out, loop


def derive(cg: CausalGraph, max_symbolic_loop: int = MAX_SYMBOLIC_LOOP,
           energy: bool = False) -> EquationSystem:
    """Build, sort and solve the causal equations of a causal graph. Loops with more
    than ``max_symbolic_loop`` tearing variables are solved numerically at run time.
    The method (what L became) was chosen by ``expand``; ``lagrange`` adds the
    multipliers' acceleration-level equations. ``energy``: the energy variant, every
    element's work and activity as quadrature states (``codegen.energy``)."""
    with gc_paused():
        return _derive(cg, max_symbolic_loop, energy)


@contextmanager
def gc_paused():
    """Python's cyclic garbage collector off for a while: building expressions allocates
    millions of acyclic sympy objects, and each full collection walks all that are alive,
    so the collections cost more than linearly with the model's size (about a fifth of
    the equations of a 40-link chain)."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.enable()


def _derive(cg: CausalGraph, max_symbolic_loop: int, energy: bool = False) -> EquationSystem:
    b = Builder(cg)
    method = methods.get(cg.graph.method)
    b.build()
    b.resolve_refs()
    b.resolve_derivatives()
    method.embed(b)
    constraints = method.constraint_equations(b)
    deps = _deps(b.eqs)
    assignments, loops, blocks = [], [], 0
    for comp in strongly_connected(list(b.eqs), deps):
        if is_cyclic(comp, deps):
            solved, loop = _solve_loop(b, comp, deps, max_symbolic_loop, blocks)
            blocks += sum(isinstance(a, LinearBlock) for a in solved)
            assignments += solved
            loops.append(loop)
        else:
            assignments.append((comp[0], b.eqs[comp[0]]))
    assignments, aliases = _drop_aliases(assignments)
    outputs = [(o.name, o.expr.xreplace(b.refs).xreplace(aliases)) for o in b.m.outputs]
    params = [(symbols.param(p.name), p.name, p.value) for p in b.m.parameters.values()]
    if constraints:
        params += [(symbols.param(n), n, v) for n, v in method.parameters(b.m, constraints)]
        constraints = [(n, g if g is None else g.xreplace(aliases), r.xreplace(aliases))
                       for n, g, r in constraints]
    system = EquationSystem(b.m, method.name, b.states, params, assignments, outputs, loops,
                            {n: b.display[v] for n, v in b.dependent.items()}, b.display,
                            guards=b.guards, constraints=constraints,
                            imposed={c.name for c in cg.graph.constraints if c.imposed},
                            algebraic=[i for i, st in enumerate(b.states)
                                       if st.sym in set(b.algebraic)],
                            projection=[(i, b.projection[st.sym].xreplace(aliases))
                                        for i, st in enumerate(b.states)
                                        if st.sym in b.projection],
                            loops_closed=bool(cg.graph.zcp is not None
                                              and cg.graph.zcp.closed), aliases=aliases)
    if energy:
        from bgc.codegen import energy as accounting
        accounting.account(b, system, aliases)
    for name in b.dependent:
        el = b.g.elements[name]
        if el.initial != 0:
            system.notes.append(f"{el.kind} '{name}' has derivative causality: its initial "
                                f"value {el.initial} is ignored (its state follows the "
                                "others)")
    return system


def _drop_aliases(assignments):
    """Inline assignments that only copy a variable (``e2 = e1``, ``f3 = -f1``) or a number;
    state derivatives stay, since the right-hand side returns them. Blocks get the final
    alias map (their chains name loop variables assigned after them)."""
    aliases: dict = {}
    kept = []
    for item in assignments:
        if isinstance(item, LinearBlock):
            kept.append(item)
            continue
        v, e = item
        e = e.xreplace(aliases)
        if trivial(e) and symbols.kind(v) != "rate":
            aliases[v] = e
        else:
            kept.append((v, e))
    kept = [it.xreplace(aliases) if isinstance(it, LinearBlock) else it for it in kept]
    return kept, aliases
