"""Method **augmented**: ideal joints that pass singular configurations and take redundant
constraints, an index-1 augmented Lagrangian formulation with mass-orthogonal projections
(Bayo, Garcia de Jalon & Serna 1988; Bayo & Ledesma 1996; the formulation family with
which Cuadrado, Dopico and Gonzalez set the IFToMM benchmarks' references).

Each blocked direction's constraint element L is an effort source whose effort is the
multiplier, defined as lagrange's by the constraint at the acceleration level with
Baumgarte stabilisation (``multipliers.acceleration_constraints``). The multipliers' block
``J M^-1 J^T lambda = c`` (formed at run time from its sparse factors K and B) is solved
regularized, in each row's own scale::

    (J M^-1 J^T + eps diag(J M^-1 J^T)) lambda = c

the augmented Lagrangian's penalty 1/eps in the dual. That matrix is regular whatever the
constraints' rank, and symmetric definite, so it is factored as L D L^T of its lower
triangle on its structure (no SVD, no rank, no pivoting: ``codegen.linalg.ldl_ir``):
redundant constraints share their load by the minimum norm (the multipliers' part in the
null space of J^T moves no body), and at a singular configuration (the N-four-bar's
cranks passing horizontal, where the mobility jumps) the directions that lose rank are
released for the instant the mechanism takes to pass, instead of being held by
multipliers that grow without bound. Elsewhere the multipliers are within eps of
lagrange's; the error this leaves on a mechanism that passes singular poses grows with
eps (measured on IFToMM A02: bench part ``iftomm``).

After every step of the native integrators the state is projected back onto the
constraints, positions and velocities, mass-orthogonally and with the same regularized
matrix (``regularize_and_project``, the module's ``project``): velocities by the impulse
``dp = B mu`` with ``(J M^-1 J^T + eps diag) mu = dg/dt``; positions by the pose change
that impulse would make in unit time, ``mu`` from ``g``. The drift stays at round-off,
and near a singular pose the released directions are not forced onto a neighbouring
branch of the constraint manifold (an exact projection there follows the branch that
round-off picks: the run switches branches).

The rank monitor that stops lagrange and zcp at a singular configuration does not watch
this method (``PASSES_SINGULAR`` in the module). Parameters: ``augmented__alpha``
(Baumgarte rate, 1/s) and ``augmented__eps`` (the relative regularization).
"""

from __future__ import annotations

from dataclasses import replace

import sympy as sp

from bgc.errors import EquationError
from bgc.methods.lagrange import Lagrange
from bgc.methods.multipliers import MultiplierState, acceleration_constraints, default_alpha
from bgc.model import symbols
from bgc.symbolic.forward_mode import times
from bgc.symbolic.linear import LinearBlock, Regularized

EPS = "augmented__eps"
DEFAULT_EPS = 1e-8


def regularize_and_project(b, block: LinearBlock) -> tuple[list, LinearBlock, list]:
    """The constraint block regularized (``Regularized`` on the multipliers' rows, its
    tear equations with the same term for the Jacobian), its factors' sensitivities
    assigned before it (the projection reads them without solving the block), and after
    it the projection: one regularized block on the same factors with two right-hand
    sides (velocities: ``dg/dt``; positions: ``g``), the pose motions of the position
    impulse, and each state's correction (``b.projection``)."""
    st: MultiplierState = b.method_state
    tears = block.unknowns
    rows = tuple(i for i, u in enumerate(tears) if symbols.kind(u) == "multiplier")
    if len(rows) != len(tears):         # (bodies of negligible mass: refused before)
        raise AssertionError("augmented: a constraint block with other unknowns")
    d, K, B = block.factors
    eps = symbols.param(EPS)
    # each row's scale: its diagonal (K B)_ii, the sum of its terms K_ij B_ji (one per
    # coordinate of the bodies it joins: 1/m, l^2/I, ...; they share a sign). (A body
    # whose inertia is decades below m l^2, a point mass, makes that sum, and the
    # softening, large against the translation the row constrains: IFToMM A01's point
    # mass is given the inertia of a 3 cm ball: README, which method)
    k_of = {(i, j): e for i, j, e in K}
    terms: dict = {}
    for j, k, e in B:
        if (k, j) in k_of:
            terms.setdefault(k, []).append(times(k_of[(k, j)], e))
    before, weights = [], []
    for i in rows:
        if not terms.get(i):
            raise EquationError(f"method augmented: the constraint "
                                f"{b.display.get(tears[i], tears[i])} acts on no body's "
                                "momentum", hint="use --method lagrange")
        w = sp.Symbol(f"REG_{tears[i].name}", real=True)
        # A = -K B: w = eps A_ii raises |A_ii|
        before.append((w, -eps * sp.Add(*terms[i])))
        weights.append(w)
    # the tear equations carry -w_i u_i, so that the Jacobian's solve is the regularized
    # one (u = 0 in b: the right-hand side as it was)
    tear = tuple(e - weights[i] * tears[i] for i, e in enumerate(block.tear_eqs))
    reg = Regularized(tuple(weights), rows)
    loop = set(tears) | {v for v, _ in block.chain}
    if not any(e.free_symbols & loop for _, e in block.pre):     # (linear: never)
        before, block = list(block.pre) + before, replace(block, pre=())
    else:
        raise AssertionError("augmented: the constraint block's sensitivities read its "
                             "unknowns (a nonlinear loop)")
    block = replace(block, rank=None, regularize=reg, tear_eqs=tear)
    dynamic = sorted({x for t in tears for x in st.rows[t]}, key=lambda x: x.name)
    names = [t.name[len("LAM_"):] for t in tears]
    mu = {tag: [sp.Symbol(f"MU{tag}_{n}", real=True) for n in names] for tag in "VG"}
    unknowns = tuple(u for pair in zip(mu["V"], mu["G"]) for u in pair)
    rhs = tuple(e for t in tears for e in (st.constraint[t][1], st.constraint[t][0]))
    after = [LinearBlock(block.index + 1, unknowns, (), rhs,
                         tuple(sp.S.Zero for _ in unknowns), factors=(d, K, B),
                         regularize=reg, columns=2)]
    # the impulses B mu on the dynamic states (velocities: the momenta's correction;
    # positions: the momenta whose pose rates move the poses onto the constraints)
    impulse = {"V": {}, "G": {}}
    for j, k, e in B:
        for tag in impulse:         # (each sum's terms added at once, not one by one)
            impulse[tag].setdefault(dynamic[j], []).append(times(e, mu[tag][k]))
    push = {}
    for x, terms in sorted(impulse["G"].items(), key=lambda kv: kv[0].name):
        v = sp.Symbol(f"PG_{x.name}", real=True)
        after.append((v, sp.Add(*terms)))
        push[x] = v
    for x, terms in impulse["V"].items():
        b.projection[x] = sp.Add(*terms)
    for q, prow in st.pose_rows.items():
        e = sp.Add(*[times(c, push[x]) for x, c in prow.items() if x in push])
        if e != 0:
            b.projection[q] = e
    return before, block, after


class Augmented(Lagrange):
    """L is an effort source whose effort, the multiplier, is an algebraic state defined
    by the regularized acceleration-level constraint; the state is projected onto the
    constraints after every step (module docstring)."""

    name = "augmented"
    ideal = True
    passes_singular = True

    def constraint_equations(self, b) -> list:
        if any(symbols.kind(v) == "acceleration" for v in b.eqs):
            name = next(v for v in b.eqs if symbols.kind(v) == "acceleration")
            raise EquationError(
                f"method augmented does not take bodies of negligible mass ({name.name})",
                hint="give the body a small mass, or use --method lagrange")
        return acceleration_constraints(b, pose_rows=True)

    def constraint_block(self, builder, block):
        return regularize_and_project(builder, block)

    def parameters(self, model, constraints) -> list[tuple[str, float]]:
        """The stabilisation rate and the relative regularization."""
        return [(self.stabilisation, default_alpha(model.settings.t_end)),
                (EPS, DEFAULT_EPS)]

    def report(self, compiled):
        s = compiled.system
        if not s.constraints:
            return {}, []
        return {}, [f"constraints (method {self.name}): {len(s.constraints)} multipliers, "
                    "solved at the acceleration level with Baumgarte stabilisation, "
                    "regularized by augmented__eps (sparse L D L^T, any rank); positions and "
                    "velocities projected after every step"]
