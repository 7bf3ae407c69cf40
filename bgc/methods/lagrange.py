"""Method pass **lagrange** (paper 11.2.5.3): each blocked joint direction's constraint
element L is an effort source whose effort, the Lagrange multiplier, keeps the direction
closed.

Keeping ``dg/dt = 0`` exactly makes an index-2 DAE. It is reduced to index 1 at the
acceleration level with Baumgarte stabilisation, one equation per blocked direction::

    d2g/dt2 + 2 alpha dg/dt + alpha^2 g = 0

where ``dg/dt`` is the flow of L (the rate the joint's rows give) and ``d2g/dt2`` is its
total time derivative, carried through the sorted kinematic assignments by forward mode
with the pose states' rates as seeds (never a substituted expression), plus the rates'
rows on the momenta, K = J M^-1, times the momenta's rates. The equations are linear in
the multipliers, which form one numeric block: the KKT matrix ``J M^-1 J^T`` is never
written down symbolically; the generated code forms it as K B (B: the multipliers' rows
on the momenta's rates, ``equations._kkt_block``) and solves it by SVD, keeping the rank
found at the initial state, so redundant constraints (hyperstatic mechanisms) share their
load by least squares. A body of negligible mass has no momentum: its twist is a state
and its rate an unknown of the same block, defined by the balance of the forces on it
(``equations.Builder._massless_lagrange``), which makes the block the saddle point
``[J M^-1 J^T, J_U; J_U^T, 0]`` (rank: the constraints' plus 6 per such body).

Method zcp with its kinematic loops kept closed (``zcp.Plan.closed``): the break
variables of the loop-closing joints are not solved at the acceleration level but are
algebraic states with the velocity-level equations ``0 = dg/dt + alpha g``: an index-2
DAE for an integrator that takes one.

Why Baumgarte rather than projection or GGL: the result is one explicit ODE, so every
integrator (scipy's BDF/Radau/LSODA, the native one) runs it unchanged with the analytic
Jacobian; the initial state is projected onto the constraints (``bgc.methods.consistent``), so the
stabilisation only has to damp integration error, and the drift it leaves is measured and
reported after every run. ``alpha`` is the parameter ``lagrange__alpha`` (1/s).
"""

from __future__ import annotations

import sympy as sp

from bgc import methods
from bgc.symbolic.forward_mode import directional, propagate
from bgc.errors import EquationError
from bgc.symbolic.algorithms import is_cyclic, strongly_connected
from bgc.graph.bondgraph import Constraint
from bgc.methods.base import ConstraintMethod
from bgc.methods.consistent import RANK_PARAM
from bgc.model import symbols

ALPHA = "lagrange__alpha"
RANK = RANK_PARAM            # set by the simulator from the rank at the start


def default_alpha(t_end: float | None) -> float:
    """Baumgarte rate: 10 time constants over the run (at least 10/s)."""
    return max(10.0, 10.0 / t_end) if t_end else 10.0


def acceleration_constraints(b, pose_rows: bool = False
                             ) -> list[tuple[str, sp.Expr | None, sp.Expr]]:
    """Define every multiplier by its Baumgarte equation in ``b`` (an equations builder);
    return ``(name, g, dg/dt)`` of every constraint, for the generated ``constraints``.

    Method zcp: the flow sources' rates are already ``-alpha g`` (the dependent momenta,
    ``zcp.embed``, are leaves here with their rates from the forces), so their efforts
    keep ``d2g/dt2 + alpha dg/dt = 0``; the break variables are multipliers as above.

    Each multiplier's (g, dg/dt) is kept in ``b.kkt_constraint``; with ``pose_rows``
    (method augmented's projection) the pose states' rates' rows on the dynamic states
    too, in ``b.pose_rows``."""
    cons = b.g.constraints
    if not cons:
        return []
    method = methods.get(b.g.method)
    alpha = symbols.param(method.stabilisation)
    leaves = {s for s, _, _ in b.zcp_dependent}
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
    pose = {st.sym: {0: st.dsym} for st in b.states if st.element in b.g.bodies}
    for v, e in propagate(chain, pose, lambda v, k: f"D_{v.name}"):
        b.define(v, e, None)
        b.display[v] = f"d({b.display.get(v, v.name)})/dt at fixed momenta"
    dynamic = [(st.sym, st.dsym) for st in b.states if st.element not in b.g.bodies]
    dynamic += [(s, ds) for s, ds, _ in b.zcp_dependent]
    ksens = {x: {j: sp.S.One} for j, (x, _) in enumerate(dynamic)}
    for v, e in propagate(chain, ksens, lambda v, j: f"K_{v.name}__{j}"):
        b.define(v, e, None)
    if pose_rows:       # dq/dt of the poses = P p: P's rows, for the position projection
        for st in b.states:
            if st.element in b.g.bodies:
                b.pose_rows[st.sym] = {dynamic[j][0]: d for j, d in
                                       directional(b.eqs[st.dsym], ksens).items()}
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
        b.kkt_rows[lam] = rows
        rdot = directional(r, pose).get(0, sp.S.Zero) + sum(
            (d * dx for x, dx in dynamic if (d := rows.get(x)) is not None), sp.S.Zero)
        g = c.g if c.g is not None else sp.S.Zero
        residual = (rdot + alpha * r if c.imposed
                    else rdot + 2 * alpha * r + alpha ** 2 * g)
        b.kkt_constraint[lam] = (g, r)
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


class Lagrange(ConstraintMethod):
    """L is an effort source whose effort is the multiplier (paper 11.2.5.3): each blocked
    direction a constraint ``g = 0`` held at the acceleration level with Baumgarte
    stabilisation (``acceleration_constraints``); the multipliers are unknowns of the
    constraint block, solved with the accelerations."""

    name = "lagrange"
    ideal = True

    def constraint_element(self, ex, joint, d, zero):
        L = ex.add(f"{zero}__L", "MSe", joint.loc, effort=symbols.multiplier(joint.name, d.label))
        ex.constraints.append(Constraint(joint.name, d.label, L, d.g, d.rotational))
        return [L]

    def constraint_equations(self, b) -> list:
        return acceleration_constraints(b)

    def parameters(self, model, constraints) -> list[tuple[str, float]]:
        """The stabilisation rate and the constraint block's rank (set again by the
        simulator from the rank at the start)."""
        return [(self.stabilisation, default_alpha(model.settings.t_end)),
                (RANK, float(len(constraints)))]

    def report(self, compiled):
        s = compiled.system
        if not s.constraints:
            return {}, []
        return {}, [f"constraints (method {self.name}): {len(s.constraints)} multipliers, "
                    "solved at the acceleration level with Baumgarte stabilisation"]
