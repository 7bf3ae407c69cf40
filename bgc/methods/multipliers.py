"""What the methods with multipliers share (lagrange, zcp, augmented): the constraint
element L an effort source whose effort is a multiplier, the multipliers defined at the
acceleration level with Baumgarte stabilisation (``acceleration_constraints``), their
constraint block ``A = -K B`` (``kkt_block``: K the rates' rows on the dynamic states, B
the multipliers' rows on those states' rates), a body of negligible mass's twist rates as
unknowns of that block (``massless_body``), and how the equations stage solves the loops
such a method makes (``loop_block``). What a method learns on the way lives in its own
state on the builder (``MultiplierState``: ``Equations.method_state``), not in the
builder's tables: the equations stage knows none of it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp

from bgc import methods
from bgc.errors import EquationError
from bgc.graph.bondgraph import Constraint
from bgc.graph.expand import AXES
from bgc.methods.base import ConstraintMethod, Equations, LoopSolution, TornLoop
from bgc.solvers.consistent import RANK_PARAM
from bgc.model import symbols
from bgc.symbolic.algorithms import is_cyclic, strongly_connected
from bgc.symbolic.forward_mode import directional, propagate, times
from bgc.symbolic.linear import LinearBlock

RANK = RANK_PARAM            # set by the simulator from the rank at the start


def default_alpha(t_end: float | None) -> float:
    """Baumgarte rate: 10 time constants over the run (at least 10/s)."""
    return max(10.0, 10.0 / t_end) if t_end else 10.0


@dataclass
class MultiplierState:
    """What a method with multipliers keeps while the equations are built
    (``Equations.method_state``): each block unknown's rows on the dynamic states
    (``rows``: multiplier or twist rate -> {state: d rate / d x}), the rates that stand for
    a virtual momentum's (``rates``: a massless body's net force -> its column), each
    multiplier's (g, dg/dt) (``constraint``), the pose states' rows (``pose_rows``,
    augmented's projection) and the momenta that are not states but solved from imposed
    flows (``dependent``: (momentum, its rate, name); zcp's ``embed``)."""
    rows: dict = field(default_factory=dict)
    rates: dict = field(default_factory=dict)
    constraint: dict = field(default_factory=dict)
    pose_rows: dict = field(default_factory=dict)
    dependent: list = field(default_factory=list)


def acceleration_constraints(b: Equations, pose_rows: bool = False
                             ) -> list[tuple[str, sp.Expr | None, sp.Expr]]:
    """Define every multiplier by its Baumgarte equation in ``b`` (an equations builder);
    return ``(name, g, dg/dt)`` of every constraint, for the generated ``constraints``.

    Imposed flows (method zcp): the flow sources' rates are already ``-alpha g`` (the
    dependent momenta, ``st.dependent``, are leaves here with their rates from the
    forces), so their efforts keep ``d2g/dt2 + alpha dg/dt = 0``; the break variables are
    multipliers as above.

    The method's state ``st`` (``b.method_state``, a ``MultiplierState``) keeps each
    multiplier's rows and (g, dg/dt); with ``pose_rows`` (method augmented's projection)
    the pose states' rates' rows on the dynamic states too."""
    cons = b.g.constraints
    if not cons:
        return []
    method = methods.get(b.g.method)
    st: MultiplierState = b.method_state
    alpha = symbols.param(method.stabilisation)
    leaves = {s for s, _, _ in st.dependent}
    rates = {}
    for c in cons:
        bond, s, E, F = b.port(c.element)
        rates[c] = -s * F          # the flow into the 0-junction's direction: dg/dt
    cone = _cone(b, list(rates.values()) + [c.g for c in cons if c.g is not None], leaves)
    bad = [v for v in cone if symbols.kind(v) in ("rate", "multiplier", "unknown")]
    if bad:
        c = cons[0]
        j = b.m.joints[c.joint]
        raise EquationError(
            "method lagrange needs every joint velocity to follow from the states; here "
            f"it depends on {b.display.get(bad[0], bad[0].name)} (a body of negligible mass "
            "or an algebraic loop in the kinematics)", loc=j.loc, key=f"joints.{c.joint}",
            hint="give the bodies of negligible mass a small mass, or use --method "
                 "parasitic")
    deps = {v: [s for s in b.eqs[v].free_symbols if s in cone] for v in cone}
    comps = strongly_connected(sorted(cone, key=lambda v: v.name), deps)
    assert not any(is_cyclic(c, deps) for c in comps), "kinematics are acyclic"
    chain = [(c[0], b.eqs[c[0]]) for c in comps]
    # d2g/dt2 = (dJ/dt) v + J M^-1 dp/dt: the rates differentiated along the pose states'
    # rates (no multiplier there: computed once, outside the constraint block) plus their
    # rows on the dynamic states (momenta) times those states' rates, which carry the
    # multipliers. K holds the rows: d(dg/dt)/dp = J M^-1 in momentum coordinates.
    pose = {x.sym: {0: x.dsym} for x in b.states if x.element in b.g.bodies}
    for v, e in propagate(chain, pose, lambda v, k: f"D_{v.name}"):
        b.define(v, e, None)
        b.display[v] = f"d({b.display.get(v, v.name)})/dt at fixed momenta"
    dynamic = [(x.sym, x.dsym) for x in b.states if x.element not in b.g.bodies]
    dynamic += [(s, ds) for s, ds, _ in st.dependent]
    ksens = {x: {j: sp.S.One} for j, (x, _) in enumerate(dynamic)}
    for v, e in propagate(chain, ksens, lambda v, j: f"K_{v.name}__{j}"):
        b.define(v, e, None)
    if pose_rows:       # dq/dt of the poses = P p: P's rows, for the position projection
        for x in b.states:
            if x.element in b.g.bodies:
                st.pose_rows[x.sym] = {dynamic[j][0]: d for j, d in
                                       directional(b.eqs[x.dsym], ksens).items()}
    out = []
    for c in cons:
        r = rates[c]
        lam = symbols.multiplier(c.joint, c.label)
        if c.closed:        # a kinematic loop kept closed: lam is an index-2 state
            b.algebraic_state(f"{c.name}.lambda", lam, symbols.dstate(f"LAM_{c.joint}",
                                                                      c.label),
                              r + alpha * (c.g if c.g is not None else sp.S.Zero),
                              c.element)
            out.append((c.name, c.g, r))
            continue
        rows = {dynamic[j][0]: d for j, d in directional(r, ksens).items()}
        st.rows[lam] = rows
        rdot = sp.Add(directional(r, pose).get(0, sp.S.Zero),
                      *[times(d, dx) for x, dx in dynamic if (d := rows.get(x)) is not None])
        g = c.g if c.g is not None else sp.S.Zero
        residual = (rdot + alpha * r if c.imposed
                    else rdot + 2 * alpha * r + alpha ** 2 * g)
        st.constraint[lam] = (g, r)
        b.eqs[lam] = lam + residual
        b.origin[lam] = (c.element, None)
        b.display[lam] = f"{c.name}.{method.role(c)}"
        out.append((c.name, c.g, r))
    return out


def _cone(b, exprs, leaves=frozenset()) -> set:
    """The assigned variables ``exprs`` depend on (not looking past ``leaves``)."""
    seen, stack = set(), [s for e in exprs for s in e.free_symbols]
    while stack:
        v = stack.pop()
        if v in seen or v not in b.eqs or v in leaves:
            continue
        seen.add(v)
        stack.extend(b.eqs[v].free_symbols)
    return seen


def kkt_block(b: Equations, tears: list, order: list, index: int) -> LinearBlock:
    """The constraint block: the acceleration-level equations are linear in the
    multipliers u, ``resid = K (dp/dt) + ...`` with ``dp/dt = dp/dt|u=0 + B u``; K (the
    rates' rows on the dynamic states, ``MultiplierState.rows``) and B (the multipliers'
    rows on the dynamic states' rates, forward mode along the loop, which is the force
    path) are sparse; their product ``J M^-1 J^T`` is formed numerically at run time."""
    st: MultiplierState = b.method_state
    chain = tuple((v, b.eqs[v]) for v in order)
    dynamic = sorted({x for rows in st.rows.values() for x in rows},
                     key=lambda x: x.name)
    col = {x: j for j, x in enumerate(dynamic)}
    dstate = {x.dsym: x.sym for x in b.states}
    dstate.update({ds: x for x, ds, _ in st.dependent})
    dstate.update(st.rates)
    sens = {t: {k: sp.S.One} for k, t in enumerate(tears)}
    pre = propagate(chain, sens, lambda v, k: f"S{index}_{v.name}__{k}")
    B = tuple((col[dstate[dx]], k, d) for dx in sorted(sens, key=lambda s: s.name)
              if dx in dstate and dstate[dx] in col for k, d in sens[dx].items())
    K = tuple((i, col[x], d) for i, t in enumerate(tears)
              for x, d in sorted(st.rows[t].items(), key=lambda kv: kv[0].name))
    # a body of negligible mass adds its twist's rates, each one rank of the saddle point
    rank = symbols.param(RANK_PARAM) + sum(symbols.kind(t) == "acceleration" for t in tears)
    return LinearBlock(index, tuple(tears), (), None, tuple(b.eqs[t] for t in tears), chain,
                       tuple(pre), rank, (len(dynamic), K, B))


class Multipliers(ConstraintMethod):
    """A method whose constraint elements are effort sources with a multiplier each,
    held at the acceleration level (module docstring); a subclass names itself and may
    change the graph (zcp) or the block (augmented)."""

    ideal = True

    def constraint_element(self, ex, joint, d, zero):
        L = ex.add(f"{zero}__L", "MSe", joint.loc, effort=symbols.multiplier(joint.name, d.label))
        ex.constraints.append(Constraint(joint.name, d.label, L, d.g, d.rotational))
        return [L]

    def new_state(self, builder) -> MultiplierState:
        return MultiplierState()

    def constraint_equations(self, b) -> list:
        return acceleration_constraints(b)

    def parameters(self, model, constraints) -> list[tuple[str, float]]:
        """The stabilisation rate and the constraint block's rank (set again by the
        simulator from the rank at the start)."""
        return [(self.stabilisation, default_alpha(model.settings.t_end)),
                (RANK, float(len(constraints)))]

    def massless_body(self, b, name, bond, sign, E, F) -> bool:
        """The twist U of a body of negligible mass: the constraints fix U only at the
        velocity level, so U is a state and its rate A an unknown of the constraint block
        next to the multipliers, defined by the balance ``A = A + e``: the block becomes
        the saddle point ``[J M^-1 J^T, J_U; J_U^T, 0]``, regular where the blocked
        directions fix U."""
        st: MultiplierState = b.method_state
        for k in range(len(E)):
            u, du = symbols.state(name, f"u{AXES[k]}"), symbols.dstate(name, f"u{AXES[k]}")
            acc = symbols.acceleration(name, k)
            b.define(F[k], sign * u, name, bond)
            b.define(du, acc, name, bond)
            b.define(acc, acc + sign * E[k], name, bond)
            label = f"{name.replace('__', '.')}.{AXES[k]}"
            b.add_state(label, u, du, sp.S.Zero, name)
            b.display[acc] = f"{label}.balance"
            # the block's row of A: e, the net force on the body, as the rate of a virtual
            # momentum (column ``net``) that must stay zero
            net = symbols.state(name, f"net{AXES[k]}")
            st.rows[acc] = {net: sp.Integer(sign)}
            st.rates[E[k]] = net
        return True

    def tear_first(self, b, comp: list) -> list:
        """A loop's multipliers (and twist rates), then its dependent momenta."""
        st: MultiplierState = b.method_state
        dependent = {x for x, _, _ in st.dependent}
        return ([v for v in comp if symbols.kind(v) in ("multiplier", "acceleration")]
                + [v for v in comp if v in dependent])

    def loop_block(self, b, loop: TornLoop) -> LoopSolution | None:
        """The constraint block (every tear a multiplier: ``kkt_block``, as the method
        solves it: ``constraint_block``); a loop of multipliers and other tears (a storage
        in derivative causality on the mechanism's ports), reduced to its tears and
        solved keeping the constraints' rank; the dependent momenta's loop (imposed
        flows), reduced to its tears."""
        st: MultiplierState = b.method_state
        tears = loop.tears
        multipliers = [v for v in loop.comp if symbols.kind(v) in ("multiplier",
                                                                   "acceleration")]
        dependent = {x for x, _, _ in st.dependent}
        if multipliers and set(tears) == set(multipliers):
            loop.kind = "constraint"
            n_acc = sum(symbols.kind(v) == "acceleration" for v in tears)
            tearing = [f"numeric SVD of the {len(tears) - n_acc} Lagrange multipliers"
                       + (f" and {n_acc} twist rates of bodies of negligible mass"
                          if n_acc else "")]
            block = kkt_block(b, tears, loop.order, loop.index)
            before, block, after = self.constraint_block(b, block)
            return LoopSolution(tearing, before + [block] + loop.chain() + after)
        if multipliers:
            loop.kind = "constraint"
            # the constraints' rank at run time, plus the other tears (a storage in
            # derivative causality on the mechanism's ports), which are never redundant
            regular = sum(symbols.kind(v) != "multiplier" for v in tears)
            block = loop.reduced_block(rank=symbols.param(RANK_PARAM) + regular)
            return LoopSolution([f"numeric SVD of {len(tears)} unknowns "
                                 f"({len(multipliers)} Lagrange multipliers)"],
                                [block] + loop.chain())
        if any(v in dependent for v in loop.comp):
            loop.kind = "imposed-flow"
            n = sum(v in dependent for v in loop.comp)
            block = loop.reduced_block(numeric_rhs=True)
            return LoopSolution([
                f"numeric LU of the {n} dependent momenta (class-1 ZCP: velocities imposed "
                "by the flow sources)"], [block] + loop.chain())
        return None
