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
on the momenta's rates, ``multipliers.kkt_block``) and solves it by SVD, keeping the rank
found at the initial state, so redundant constraints (hyperstatic mechanisms) share their
load by least squares. A body of negligible mass has no momentum: its twist is a state
and its rate an unknown of the same block, defined by the balance of the forces on it
(``multipliers.Multipliers.massless_body``), which makes the block the saddle point
``[J M^-1 J^T, J_U; J_U^T, 0]`` (rank: the constraints' plus 6 per such body).

Method zcp with its kinematic loops kept closed (``zcp.Plan.closed``): the break
variables of the loop-closing joints are not solved at the acceleration level but are
algebraic states with the velocity-level equations ``0 = dg/dt + alpha g``: an index-2
DAE for an integrator that takes one.

Why Baumgarte rather than projection or GGL: the result is one explicit ODE, so every
integrator (scipy's BDF/Radau/LSODA, the native one) runs it unchanged with the analytic
Jacobian; the initial state is projected onto the constraints (``bgc.solvers.consistent``), so the
stabilisation only has to damp integration error, and the drift it leaves is measured and
reported after every run. ``alpha`` is the parameter ``lagrange__alpha`` (1/s).
"""

from __future__ import annotations

from bgc.methods.multipliers import Multipliers

ALPHA = "lagrange__alpha"


class Lagrange(Multipliers):
    """L is an effort source whose effort is the multiplier (paper 11.2.5.3): each blocked
    direction a constraint ``g = 0`` held at the acceleration level with Baumgarte
    stabilisation (``acceleration_constraints``); the multipliers are unknowns of the
    constraint block, solved with the accelerations."""

    name = "lagrange"

    def report(self, compiled):
        s = compiled.system
        if not s.constraints:
            return {}, []
        return {}, [f"constraints (method {self.name}): {len(s.constraints)} multipliers, "
                    "solved at the acceleration level with Baumgarte stabilisation"]
