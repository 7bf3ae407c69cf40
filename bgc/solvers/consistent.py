"""Consistent initial conditions and constraint diagnostics (methods lagrange and zcp;
for parasitic, the static joint loads of a model that starts at rest).

A generated module's ``constraints(t, x, p)`` gives every blocked direction's deflection
g (position level) and rate dg/dt (velocity level). Before a run the user's approximate
initial state is projected onto both (Gauss-Newton with the minimum-norm step, which also
serves redundant constraints), the rank of the constraints is found and the redundant
ones are named; during a run ``RankMonitor`` watches for a singular configuration, and
a failed run is checked for one; after a run the drift is measured.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bgc.errors import SimulationError

RANK_TOL = 1e-9          # singular values below this fraction of the largest are zero
# the generated module's parameter holding the rank its constraint block keeps
RANK_PARAM = "lagrange__rank"
# a failed run whose kept constraint conditioning fell this many times below its value at
# the start (or below RANK_TOL) is diagnosed as a singular configuration; where the
# monitored minor crossed zero (located to round-off) it must have fallen LOST_RANK_EVENT
# times: a smaller drop there is a minor that became singular on its own
LOST_RANK = 10.0
LOST_RANK_EVENT = 1e6
# a constrained run fails where its position drift exceeds this many tolerance units
DRIFT_UNITS = 100.0


@dataclass
class Projection:
    position_correction: float      # max |dx| over the pose states
    velocity_correction: float      # max |dx| over the other states
    iterations: int
    rank: int
    n_constraints: int
    # a minimal redundant set: n_constraints - rank names whose removal leaves the others
    # independent at the start
    redundant: list[str] = field(default_factory=list)
    # smallest kept over largest singular value of the measured constraint rows at the
    # start: a run that fails where this has dropped LOST_RANK-fold met a singular pose
    conditioning: float = 1.0

    def to_dict(self) -> dict:
        return dict(self.__dict__)

    def describe(self) -> str:
        out = (f"initial state projected onto {self.n_constraints} constraints: position "
               f"correction {self.position_correction:.3g}, velocity correction "
               f"{self.velocity_correction:.3g} ({self.iterations} Newton iterations)")
        if self.rank < self.n_constraints:
            out += (f"; rank {self.rank}: {self.n_constraints - self.rank} redundant "
                    f"constraint(s) ({', '.join(self.redundant)}; consistent, load shared "
                    "by least squares)")
        return out


def static_loads(module, x, p) -> np.ndarray:
    """Method parasitic, a model whose initial state is a static equilibrium
    (``STATIC_LOADS``): ``p`` with each blocked direction's load parameter
    (``<joint>__<dir>_load``) set to what its parasitic spring carries there, with no
    excitation. The rhs is affine in the loads (exact differences); least squares, the
    minimum-norm share where joints are hyperstatic. Without them the springs start
    slack and the rig drops by load/stiffness at t = 0."""
    names = list(module.PARAM_NAMES)
    loads = [i for i, n in enumerate(names) if "__" in n and n.endswith("_load")]
    q = np.array(p, dtype=np.float64)
    q[loads] = 0.0
    q[[i for i, n in enumerate(names) if n.startswith("excitation__")]] = 0.0
    # the model's rates: not the quadratures of an energy variant (powers, not affine
    # in the loads, and zero at rest once the loads are found)
    rows = np.setdiff1d(np.arange(len(x)), getattr(module, "QUADRATURE", ()))
    f0 = module.rhs(0.0, x, q)[rows]
    M = np.empty((len(f0), len(loads)))
    for k, i in enumerate(loads):
        qq = q.copy()
        qq[i] = 1.0
        M[:, k] = module.rhs(0.0, x, qq)[rows] - f0
    q[loads] = np.linalg.lstsq(M, -f0, rcond=RANK_TOL)[0]
    left = module.rhs(0.0, x, q)[rows]
    k = int(np.argmax(np.abs(left)))
    worst = int(rows[k])
    if abs(left[k]) > 1e-6 * max(1.0, float(np.abs(f0).max())):
        raise SimulationError(
            f"the initial state (t = 0) is not a static equilibrium: with the parasitic "
            f"springs' best static loads d{module.STATE_NAMES[worst]}/dt is still "
            f"{left[k]:.3g}", hint="check the functional preloads and the initial "
                                   "velocities, or drop 'parasitic: {loads: static}'")
    out = np.array(p, dtype=np.float64)
    out[loads] = q[loads]
    return out


def _split(module, x, p):
    c = module.constraints(0.0, x, p)
    m = len(module.CONSTRAINT_NAMES)
    return c[:m], c[m:]


def _jacobian(fun, x, cols) -> np.ndarray:
    """Central differences of ``fun`` w.r.t. ``x[cols]``."""
    f0 = fun(x)
    J = np.zeros((len(f0), len(cols)))
    for k, j in enumerate(cols):
        h = 1e-7 * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        J[:, k] = (fun(xp) - fun(xm)) / (2 * h)
    return J


def equilibration(J: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Row and column scales that bring ``J``'s columns, then its rows, to unit length
    (zero ones kept): the rank of the constraint rows on the momenta, J M^-1, must not
    depend on the units of the rows (m/s, rad/s) nor on the spread of the inverse masses
    and inertias, which at a millimetre scale spans ten decades and hid real constraints
    below RANK_TOL. Scaling rows does not move the left null space's support, so the
    redundant rows stay named. ``RankMonitor`` keeps the scales of the start fixed, so a
    row that vanishes at a singular pose is not scaled back up."""
    c = np.linalg.norm(J, axis=0)
    c = 1.0 / np.where(c > 0, c, 1.0)
    r = np.linalg.norm(J * c, axis=1)
    return 1.0 / np.where(r > 0, r, 1.0), c


def equilibrate(J: np.ndarray, scales=None) -> np.ndarray:
    """``J`` scaled by ``equilibration(J)`` (or the given row and column scales)."""
    if J.size == 0:
        return J
    r, c = equilibration(J) if scales is None else scales
    return J * r[:, None] * c[None, :]


# two rows whose distances from the rows taken are within this share of each other are a
# tie, broken by model order: the choice must not hang on the last digits (the simulator
# measures the rows by differences, ``bgc check`` from the joints' exact rows)
TIE = 1e-6


def independent_rows(J: np.ndarray, rank: int, first: int = 0) -> np.ndarray:
    """The ``rank`` rows of ``J`` a rank-revealing QR with column pivoting on J^T
    (Businger & Golub) takes: one at a time, the row farthest from the span of those
    taken (ties within ``TIE``: the first in order), as indices; the ``first`` rows are
    taken first whatever their distance (method zcp's imposed directions)."""
    V = np.array(J, dtype=np.float64)
    left = np.ones(len(V), dtype=bool)
    taken = []
    for step in range(min(rank, len(V))):
        norms = np.where(left, np.einsum("ij,ij->i", V, V), -1.0)
        top = norms.max()
        if top <= 0.0:
            break
        k = step if step < first else int(np.flatnonzero(norms >= top * (1.0 - TIE))[0])
        top = max(norms[k], 1e-300)
        taken.append(k)
        left[k] = False
        q = V[k] / np.sqrt(top)
        V -= np.outer(V @ q, q)
    return np.asarray(taken, dtype=np.int64)


def _dependent(J: np.ndarray, names, rank: int, first: int = 0) -> list[str]:
    """A minimal redundant set of the rows of ``J`` (equilibrated): exactly
    ``len(names) - rank`` of them, whose removal leaves ``rank`` independent rows (those
    ``independent_rows`` takes; the ``first`` rows, held independent, are not named)."""
    if rank >= len(names):
        return []
    kept = set(independent_rows(J, rank, first).tolist())
    return [n for i, n in enumerate(names) if i not in kept and i >= first]


def _rank(J: np.ndarray) -> int:
    if J.size == 0:
        return 0
    s = np.linalg.svd(J, compute_uv=False)
    return int(np.sum(s > RANK_TOL * max(s[0], 1e-300)))


def _conditioning(J: np.ndarray, rank: int) -> float:
    """The ``rank``-th singular value of ``J`` over its largest (1 where nothing is kept)."""
    if rank < 1 or J.size == 0:
        return 1.0
    s = np.linalg.svd(J, compute_uv=False)
    return float(s[rank - 1] / s[0]) if rank <= len(s) and s[0] > 0 else 0.0


def _other_states(module, n: int) -> list[int]:
    """The states that are not body poses (momenta, functional springs)."""
    pose = set(module.POSE_STATES)
    return [j for j in range(n) if j not in pose]


def _imposed(module) -> np.ndarray:
    """Which constraint rows method zcp imposes: its flow sources hold them by
    construction (their rows on the states are zero, their rates round-off)."""
    return np.asarray(module.IMPOSED, dtype=bool)


def _measured_rows(module, K):
    """The rows of ``K`` whose rank is measured, their names, and how many rows are left
    out: method zcp's imposed flows hold by construction (zero rows on the states), each
    one rank of the constraints."""
    imposed = _imposed(module)
    names = [n for n, i in zip(module.CONSTRAINT_NAMES, imposed) if not i]
    return K[~imposed], names, int(imposed.sum())


def velocity_jacobian(module, x, p) -> tuple[np.ndarray, list[int]]:
    """d(dg/dt)/d(other states) (the constraint rows acting on the momenta), and those
    states' indices."""
    other = _other_states(module, len(x))
    return _jacobian(lambda y: _split(module, y, p)[1], x, other), other


def project(module, x, p, tol: float = 1e-12, max_iter: int = 50):
    """The consistent state nearest ``x`` (minimum-norm corrections) and a Projection.

    Positions first (g = 0 over the pose states, Gauss-Newton), then velocities (dg/dt is
    linear in the momenta: one least-squares step, repeated once for round-off) over the
    rows that zcp does not impose (an imposed row's dg/dt is round-off whatever the
    momenta: a step on it would divide round-off by round-off)."""
    x = np.array(x, dtype=np.float64)
    x_user = x.copy()
    names = list(module.CONSTRAINT_NAMES)
    pos = [i for i in range(len(names)) if module.HAS_POSITION[i]]
    pose = list(module.POSE_STATES)
    it = 0
    scale = max(1.0, float(np.abs(x[pose]).max())) if pose else 1.0
    stalled = False
    for it in range(1, max_iter + 1):
        g = _split(module, x, p)[0][pos]
        if not len(g) or np.abs(g).max() <= tol * scale:
            it -= 1
            break
        G = _jacobian(lambda y: _split(module, y, p)[0][pos], x, pose)
        dx = np.linalg.lstsq(G, -g, rcond=RANK_TOL)[0]
        x[pose] += dx
        if np.abs(dx).max() <= 1e-14 * scale:      # no step left: round-off or stuck
            stalled = np.abs(g).max() > 1e-9 * scale
            break
    else:
        stalled = True
    if stalled:
        g = _split(module, x, p)[0][pos]
        worst = pos[int(np.argmax(np.abs(g)))]
        raise SimulationError(
            f"the initial positions (t = 0) cannot be made consistent with the joints: after "
            f"{it} Newton iterations joint direction {names[worst]} is still open by "
            f"{abs(g).max():.3g}", hint="the bodies' initial poses are too far from an "
                                        "assembly of the joints (a blocked rotation turned "
                                        "a quarter turn stalls the Newton steps): check the "
                                        "joint points and the bodies' com/frame or x0")
    K, other = velocity_jacobian(module, x, p)
    Kb, free, n_imposed = _measured_rows(module, K)
    measured = ~_imposed(module)
    if measured.any():
        for _ in range(2):
            r = _split(module, x, p)[1]
            x[other] += np.linalg.lstsq(Kb, -r[measured], rcond=RANK_TOL)[0]
    r = _split(module, x, p)[1]
    Ke = equilibrate(Kb)
    rank = n_imposed + _rank(Ke)
    if np.abs(r).max(initial=0.0) > 1e-8 * max(1.0, np.abs(x[other]).max(initial=0.0)):
        worst = int(np.argmax(np.abs(r)))
        raise SimulationError(
            f"the initial velocities (t = 0) cannot be made consistent: joint direction "
            f"{names[worst]} still moves at {abs(r[worst]):.3g} after projection",
            hint="the constraints are singular at the initial pose; move the mechanism "
                 "away from the dead point")
    dx = x - x_user
    proj = Projection(float(np.abs(dx[pose]).max(initial=0.0)),
                      float(np.abs(dx[other]).max(initial=0.0)), it, rank, len(names),
                      _dependent(Ke, free, rank - n_imposed)
                      if rank < len(names) else [],
                      _conditioning(Ke, rank - n_imposed))
    return x, proj


def drift_history(module, xs, p) -> tuple[np.ndarray, np.ndarray]:
    """Largest |g| (position level, where a direction has one) and |dg/dt| of the blocked
    directions at each of the states ``xs`` (rows)."""
    has_position = np.asarray(module.HAS_POSITION, dtype=bool)
    g_t, v_t = np.zeros(len(xs)), np.zeros(len(xs))
    for k, x in enumerate(xs):
        g, r = _split(module, x, p)
        g_t[k] = np.abs(g[has_position]).max(initial=0.0)
        v_t[k] = np.abs(r).max(initial=0.0)
    return g_t, v_t


def drift(module, xs, p) -> tuple[float, float]:
    """Largest |g| and |dg/dt| over the states ``xs`` (rows)."""
    g_t, v_t = drift_history(module, xs, p)
    return float(np.nanmax(g_t, initial=0.0)), float(np.nanmax(v_t, initial=0.0))


def drift_limit(module, x, rtol: float, atol: float) -> float:
    """The position drift beyond which a run has not kept its constraints to the accuracy
    it asked for: DRIFT_UNITS tolerance units at the mechanism's size (the largest body
    position or angle, at least 1 mm). With Baumgarte stabilisation the drift stays near
    one unit; without it (``lagrange__alpha`` = 0) it grows with time, fast where the
    constraint manifold repels (a slider-crank: 1 m in 10 s)."""
    size = max(1e-3, float(np.abs(np.asarray(x)[list(module.POSE_STATES)]).max(initial=0.0)))
    return DRIFT_UNITS * (atol + rtol * size)


class RankMonitor:
    """A terminal event for a constrained run: the determinant of an r x r minor of the
    measured constraint rows (r = their rank at the start; rows and columns chosen by
    pivoted QR), normalised to 1 where it was chosen. It falls through zero where the
    constraints lose rank, a singular configuration (``lost`` names it), or where only
    this minor does; then ``repick`` chooses another and the run goes on."""

    def __init__(self, module, x, p, projection: Projection):
        self.module, self.p, self.projection = module, p, projection
        self.rank = projection.rank - int(np.sum(module.IMPOSED))
        self.terminal, self.direction = True, 0
        # the rank is judged on the rows scaled as at the start (kept fixed, so a row that
        # vanishes at a dead point still shows); the event's minor is picked on the rows
        # as they are, where its determinant has a simple zero at the dead point
        K = self._rows(x)[0]
        self.scales = equilibration(K)
        U = np.linalg.svd(equilibrate(K, self.scales))[0]
        self.start_null = U[:, self.rank:]          # the consistent redundancy
        self.repick(x)

    def _rows(self, x):
        return _measured_rows(self.module, velocity_jacobian(self.module, x, self.p)[0])

    def _scaled(self, x):
        K, names, n_imposed = self._rows(x)
        return (equilibrate(K, self.scales) if K.size else K), names, n_imposed

    def minor(self, x) -> tuple[float, float]:
        """The minor's determinant as (sign, log|det|): a determinant of hundreds of rows
        over- or underflows doubles where its logarithm does not."""
        K = self._rows(x)[0]
        with np.errstate(invalid="ignore"):     # NaN at a state gone non-finite (lsoda)
            sign, logdet = np.linalg.slogdet(K[np.ix_(self.rows, self.cols)])
        return float(sign), float(logdet)

    def repick(self, x) -> None:
        import scipy.linalg  # its import (0.25 s) paid only by the runs that use it
        K = self._rows(x)[0]
        self.rows = np.sort(scipy.linalg.qr(K.T, pivoting=True)[2][:self.rank])
        self.cols = np.sort(scipy.linalg.qr(K[self.rows], pivoting=True)[2][:self.rank])
        self.scale = self.minor(x)

    def __call__(self, t, x) -> float:
        """The minor's determinant over its value where it was picked (1 there)."""
        sign, logdet = self.minor(x)
        if sign == 0:
            return 0.0
        return sign * self.scale[0] * float(np.exp(min(logdet - self.scale[1], 700.0)))

    def settle(self, t, x) -> bool:
        """The monitored minor changed sign by (t, x): if the constraints there are as
        well conditioned as at the start (within ``LOST_RANK``), only the minor went
        singular, so re-pick one and go on without locating the crossing (True);
        otherwise the crossing may be a singular configuration, to be located (False).
        A rotating mechanism's minors cross zero every turn: locating each crossing and
        restarting the integrator there cost Andrews' squeezer five times its steps."""
        if self.lost(x, LOST_RANK) is not None:
            return False
        self.repick(x)
        return True

    def lost(self, x, drop: float = LOST_RANK) -> list[str] | None:
        """If the constraints at ``x`` have lost (or nearly lost: conditioning ``drop``
        times worse than at the start) the rank they had, the joint directions of the new
        dependency (left out: the redundancy there was at the start)."""
        K = self._scaled(x)[0]
        if _conditioning(K, self.rank) > max(RANK_TOL, self.projection.conditioning / drop):
            return None
        return self.dependent(x)

    def dependent(self, x) -> list[str]:
        """The joint directions of the dependency the constraints at ``x`` come nearest
        (their smallest kept singular value's and beyond), the start's redundancy left
        out: those of a singular configuration at or near ``x``."""
        K, names, _ = self._scaled(x)
        near = np.linalg.svd(K)[0][:, self.rank - 1:]
        # the combination of the near-null rows farthest from the start's redundancy
        off = near - self.start_null @ (self.start_null.T @ near)
        u = np.abs(near @ np.linalg.svd(off)[2][0])
        return [n for n, w in zip(names, u) if w > 0.05 * u.max()]
