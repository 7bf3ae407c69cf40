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

from dataclasses import dataclass, field

import sympy as sp

from sympy.solvers.solveset import NonlinearError

from . import cardan, symbols
from .causality import CausalGraph
from .expand import AXES, body_junction
from .errors import EquationError
from .graphs import is_cyclic, strongly_connected
from .model import Model, Table

# Largest loop solved symbolically (tearing variables); larger loops become numeric blocks.
MAX_SYMBOLIC_LOOP = 6


@dataclass
class State:
    name: str            # display name, e.g. "spring.q"
    sym: sp.Symbol
    dsym: sp.Symbol
    initial: sp.Expr     # in terms of parameters
    element: str


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
    entries only."""
    index: int
    unknowns: tuple[sp.Symbol, ...]
    A: tuple[tuple[int, int, sp.Expr], ...]
    b: tuple[sp.Expr, ...]

    @property
    def free_symbols(self) -> set:
        out = set()
        for _, _, e in self.A:
            out |= e.free_symbols
        for e in self.b:
            out |= e.free_symbols
        return out

    def xreplace(self, mapping) -> "LinearBlock":
        return LinearBlock(self.index, self.unknowns,
                           tuple((i, j, e.xreplace(mapping)) for i, j, e in self.A),
                           tuple(e.xreplace(mapping) for e in self.b))


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

    @property
    def tables(self) -> list[Table]:
        return self.model.tables

    @property
    def breakpoints(self) -> list[float]:
        return sorted({bp for s in self.model.signals.values() for bp in s.breakpoints})


class Dt(sp.Function):
    """Placeholder for the time derivative of a dependent storage variable."""
    nargs = 1


class _Builder:
    def __init__(self, cg: CausalGraph):
        self.cg, self.g, self.m = cg, cg.graph, cg.graph.model
        self.eqs: dict[sp.Symbol, sp.Expr] = {}
        self.origin: dict[sp.Symbol, tuple[str | None, str | None]] = {}  # (element, bond)
        self.display: dict[sp.Symbol, str] = {}
        self.states: list[State] = []
        self.dependent: dict[str, sp.Symbol] = {}
        self.refs: dict[sp.Symbol, sp.Expr] = {}
        self.guards: list[tuple[str, sp.Expr]] = []

    # --- helpers --------------------------------------------------------------------
    def define(self, var: sp.Symbol, expr, element: str, bond: int | None = None):
        if var in self.eqs:   # cannot happen after a correct causality assignment
            raise AssertionError(f"{var} defined twice")
        self.eqs[var] = sp.sympify(expr)
        self.origin[var] = (element, self.g.bonds[bond].name if bond is not None else None)

    def E(self, b: int) -> sp.Symbol:
        return symbols.effort(self.g.bonds[b].name)

    def F(self, b: int) -> sp.Symbol:
        return symbols.flow(self.g.bonds[b].name)

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
            self.display[self.E(b)] = f"{bond.name}.e"
            self.display[self.F(b)] = f"{bond.name}.f"
        for name, el in self.g.elements.items():
            getattr(self, f"_el_{ {'0': 'zero', '1': 'one'}.get(el.kind, el.kind) }")(name, el)
        self.kinematics()

    def _port(self, name):
        b = self.g.ports[name][0]
        return b, self.g.port_sign(b, name), self.E(b), self.F(b)

    def _el_Se(self, name, el):
        b, s, E, F = self._port(name)
        self.define(E, el.fields["effort"], name, b)

    _el_MSe = _el_Se

    def _el_Sf(self, name, el):
        b, s, E, F = self._port(name)
        self.define(F, s * el.fields["flow"], name, b)

    _el_MSf = _el_Sf

    def _storage(self, name, el, qname):
        """C (qname 'q') and I (qname 'p'): integral or derivative causality."""
        b, s, E, F = self._port(name)
        # For C: e = law(q), dq/dt = f.  For I: f = law(p), dp/dt = e.
        out_var, in_var = (E, s * F) if el.kind == "C" else (s * F, E)
        if self.cg.storage[name] == "integral":
            x, dx = symbols.state(name, qname), symbols.dstate(name, qname)
            if el.law == el.kind:                   # linear: e = q/C, f = p/I
                value = x / el.fields[el.kind]
            elif el.law == "k":
                value = el.fields["k"] * x
            else:
                value = self.law(el, el.law, **{qname: x})
            self.define(E if el.kind == "C" else F, value if el.kind == "C" else s * value,
                        name, b)
            self.define(dx, in_var, name, b)
            label = f"{name}.{qname}".replace("__", ".")   # box__mx -> box.mx.p
            self.states.append(State(label, x, dx, el.initial, name))
            self.display[x], self.display[dx] = label, f"d({label})/dt"
        else:
            v = symbols.algebraic(name, qname)
            if el.law == el.kind:
                value = el.fields[el.kind] * out_var
            elif el.law == "k":
                value = out_var / el.fields["k"]
            else:
                value = self.invert(el, el.law, out_var, qname)
            self.define(v, value, name, b)
            self.display[v] = f"{name}.{qname}"
            self.dependent[name] = v
            # the storage's other port variable is the time derivative of v
            self.define(F if el.kind == "C" else E, (s if el.kind == "C" else 1) * Dt(v),
                        name, b)

    def _el_C(self, name, el):
        self._storage(name, el, "q")

    def _el_I(self, name, el):
        self._storage(name, el, "p")

    def _el_R(self, name, el):
        b, s, E, F = self._port(name)
        f = s * F
        if self.cg.r_form[name] == "resistance":
            if el.law == "R":
                value = el.fields["R"] * f
            elif el.law == "effort":
                value = self.law(el, "effort", f=f)
            else:
                value = self.invert(el, "flow", f, "e")
            self.define(E, value, name, b)
        else:
            if el.law == "R":
                R = el.fields["R"]
                if R == 0:
                    raise EquationError(f"R '{name}' is 0 but its causality needs its "
                                        "conductance 1/R", loc=el.field_locs["R"],
                                        key=f"elements.{name}.R",
                                        hint="use a small positive R or remove the element")
                value = E / R
            elif el.law == "flow":
                value = self.law(el, "flow", e=E)
            else:
                value = self.invert(el, "effort", E, "f")
            self.define(F, s * value, name, b)

    def _el_zero(self, name, el):
        self._junction(name, effort_common=True)

    def _el_one(self, name, el):
        self._junction(name, effort_common=False)

    def _junction(self, name, effort_common):
        bonds = self.g.ports[name]
        sign = {b: (1 if self.g.points_into(b, name) else -1) for b in bonds}
        # 0: the strong bond brings the effort in; 1: the strong bond brings the flow in.
        strong = [b for b in bonds if self.cg.receives_effort(b, name) == effort_common][0]
        common, summed = (self.E, self.F) if effort_common else (self.F, self.E)
        for b in bonds:
            if b != strong:
                self.define(common(b), common(strong), name, b)
        total = sp.Add(*[sign[b] * summed(b) for b in bonds if b != strong])
        self.define(summed(strong), -sign[strong] * total, name, strong)

    def _el_TF(self, name, el):
        a, c = self.g.two_port(name)       # e_a = n e_c, f_c = n f_a
        n = el.fields["ratio"]
        if self.cg.receives_effort(a, name):
            self.define(self.E(c), self.E(a) / n, name, c)
            self.define(self.F(a), self.F(c) / n, name, a)
        else:
            self.define(self.E(a), n * self.E(c), name, a)
            self.define(self.F(c), n * self.F(a), name, c)

    _el_MTF = _el_TF

    def _el_GY(self, name, el):
        a, c = self.g.two_port(name)       # e_a = r f_c, e_c = r f_a
        r = el.fields["r"]
        if self.cg.receives_effort(a, name):
            self.define(self.F(c), self.E(a) / r, name, c)
            self.define(self.F(a), self.E(c) / r, name, a)
        else:
            self.define(self.E(a), r * self.F(c), name, a)
            self.define(self.E(c), r * self.F(a), name, c)

    _el_MGY = _el_GY

    def _el_EJS(self, name, el):
        """Euler's gyroscopic torque omega x (J omega), omega in the principal body frame."""
        bonds = self.g.ports[name]
        w = sp.Matrix([self.g.port_sign(b, name) * self.F(b) for b in bonds])
        h = sp.Matrix([el.fields["J"][i] * w[i] for i in range(3)])
        torque = w.cross(h)
        for i, b in enumerate(bonds):
            self.define(self.E(b), torque[i], name, b)

    def common_flow(self, junction: str) -> sp.Symbol:
        return self.F(self.g.ports[junction][0])

    def kinematics(self):
        """Position of G (R0) and XYZ Cardan angles of every body, integrated from the
        junction velocities: x' = v, [a b c]' = E(a, b, c)^-1 omega (paper Fig. 11.2)."""
        for n, body in self.g.bodies.items():
            v = [self.common_flow(body_junction(n, "v", k)) for k in range(3)]
            w = [self.common_flow(body_junction(n, "w", k)) for k in range(3)]
            pos = [symbols.state(n, a) for a in AXES]
            ang = [symbols.state(n, f"a{a}") for a in AXES]
            rates = cardan.angle_rates(*ang, w)
            init = cardan.angles(body.frame)
            self.guards.append((f"Cardan singularity (gimbal lock, cos {n}.ay -> 0) of body "
                                f"'{n}'", cardan.gimbal_margin(ang[1])))
            for k in range(3):
                for x, rate, x0, label in ((pos[k], v[k], body.com[k], AXES[k]),
                                           (ang[k], rates[k], init[k], f"a{AXES[k]}")):
                    dx = symbols.dstate(n, label)
                    self.define(dx, rate, n)
                    self.states.append(State(f"{n}.{label}", x, dx, sp.Float(x0), n))
                    self.display[x], self.display[dx] = f"{n}.{label}", f"d({n}.{label})/dt"

    # --- references, derivatives --------------------------------------------------------
    def ref_map(self) -> dict[sp.Symbol, sp.Expr]:
        out = {}
        bonds = {bd.name: i for i, bd in enumerate(self.g.bonds)}
        for name, el in self.g.elements.items():
            if el.kind in ("0", "1"):
                first = self.g.ports[name][0]
                common = self.E(first) if el.kind == "0" else self.F(first)
                out[symbols.ref(name, "e" if el.kind == "0" else "f")] = common
            elif len(self.g.ports[name]) == 1:
                b, s, E, F = self._port(name)
                out[symbols.ref(name, "e")] = E
                out[symbols.ref(name, "f")] = s * F
        for st in self.states:
            out[symbols.ref(st.element, st.name.split(".")[1])] = st.sym
        for name, v in self.dependent.items():
            out[symbols.ref(name, "q" if self.g.elements[name].kind == "C" else "p")] = v
        for n in self.g.bodies:
            for k, a in enumerate(AXES):
                out[symbols.ref(n, a)] = symbols.state(n, a)
                out[symbols.ref(n, f"a{a}")] = symbols.state(n, f"a{a}")
                out[symbols.ref(n, f"v{a}")] = self.common_flow(body_junction(n, "v", k))
                out[symbols.ref(n, f"w{a}")] = self.common_flow(body_junction(n, "w", k))
        for bname, i in bonds.items():
            out[symbols.ref(bname, "e")] = self.E(i)
            out[symbols.ref(bname, "f")] = self.F(i)
        return out

    def resolve_refs(self):
        self.refs = self.ref_map()
        for v, e in self.eqs.items():
            if any(symbols.is_ref(s) for s in e.free_symbols):
                self.eqs[v] = e.xreplace(self.refs)

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
                if s.name.startswith("DX_"):
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


def _tear(comp: list, deps: dict) -> list:
    """Greedy tearing: drop the variable with most loop in*out edges until acyclic."""
    rest, tears = list(comp), []
    while True:
        sub = {v: [d for d in deps[v] if d in rest] for v in rest}
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


def _numeric_block(b: _Builder, comp: list, index: int, refuse) -> LinearBlock:
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
    return LinearBlock(index, tuple(comp), entries, tuple(rhs))


def _solve_loop(b: _Builder, comp: list, deps: dict, max_symbolic: int = MAX_SYMBOLIC_LOOP,
                block_index: int = 0) -> tuple[list, Loop]:
    eqs = b.eqs
    tears = _tear(comp, deps)
    rest = [v for v in comp if v not in tears]
    sub_deps = {v: [d for d in deps[v] if d in rest] for v in rest}
    order = [c[0] for c in strongly_connected(rest, sub_deps)]
    subs: dict = {}
    for v in order:
        subs[v] = eqs[v].xreplace(subs)
    residuals = [sp.expand(t - eqs[t].xreplace(subs)) for t in tears]
    elements = sorted({b.origin[v][0] for v in comp if b.origin[v][0]})
    bonds = sorted({b.origin[v][1] for v in comp if b.origin[v][1]})
    kind = "derivative" if any(v.name.startswith("DX_") for v in comp) else "algebraic"
    loop = Loop(kind, [b.display.get(v, v.name) for v in comp], bonds, elements,
                [b.display.get(v, v.name) for v in tears])
    where = b.g.elements[elements[0]] if elements else None

    def refuse(why, hint):
        return EquationError(f"{why}: {loop.kind} loop through elements "
                             f"{', '.join(elements)} and bonds {', '.join(bonds)}",
                             loc=where.loc if where else None,
                             key=f"elements.{elements[0]}" if elements else None, hint=hint)

    if len(tears) > max_symbolic:
        loop.tearing = ["numeric LU of all " + str(len(comp)) + " loop variables"]
        return [_numeric_block(b, comp, block_index, refuse)], loop
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


def derive(cg: CausalGraph, method: str = "scalar",
           max_symbolic_loop: int = MAX_SYMBOLIC_LOOP) -> EquationSystem:
    """Build, sort and solve the causal equations of a causal graph. Loops with more
    than ``max_symbolic_loop`` tearing variables are solved numerically at run time."""
    b = _Builder(cg)
    b.build()
    b.resolve_refs()
    b.resolve_derivatives()
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
    system = EquationSystem(b.m, method, b.states, params, assignments, outputs, loops,
                            {n: b.display[v] for n, v in b.dependent.items()}, b.display,
                            guards=b.guards)
    for name in b.dependent:
        el = b.g.elements[name]
        if el.initial != 0:
            system.notes.append(f"{el.kind} '{name}' has derivative causality: its initial "
                                f"value {el.initial} is ignored (its state follows the "
                                "others)")
    return system


def _drop_aliases(assignments):
    """Inline assignments that only copy a variable (``e2 = e1``, ``f3 = -f1``) or a number;
    state derivatives stay, since the right-hand side returns them."""
    aliases: dict = {}
    kept = []
    for item in assignments:
        if isinstance(item, LinearBlock):
            kept.append(item.xreplace(aliases))
            continue
        v, e = item
        e = e.xreplace(aliases)
        trivial = e.is_Symbol or e.is_Number or (e.could_extract_minus_sign()
                                                  and (-e).is_Symbol)
        if trivial and not v.name.startswith("DX_"):
            aliases[v] = e
        else:
            kept.append((v, e))
    return kept, aliases
