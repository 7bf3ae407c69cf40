"""Stage **simulate**: a generated module + run settings -> Result (time, states, outputs,
solver statistics).

``simulate`` refuses what cannot run, makes the start consistent (``prepare``), checks it
(``check_start``) and integrates segment by segment with one of ``SOLVERS``: the methods
in ``bgc/solvers``, one class per method behind one small interface (``base.Solver``:
one object per run, ``integrate`` over one smooth segment). The run is split at the
model's breakpoints (step times, table knots) so no step straddles a jump. Statistics are
counted by the solvers, where the work happens (``Counts``: what an integrator does not
report is ``None``, not 0); ``Stats`` adds the facts of the run around them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from bgc.errors import SimulationError
from bgc.model.model import SOLVERS as SOLVER_NAMES
from bgc.solvers import consistent, native
from bgc.solvers.base import (
    GUARD_TOLERANCE,
    Problem,
    Segment,
    Solver,
    Stats,
    names_where,
)
from bgc.solvers.native_solver import NativeRadau, NativeRk4, NativeSolver
from bgc.solvers.scipy_ivp import Bdf, Lsoda, Radau, Rk45
from bgc.solvers.sundials import Cvode, Ida


class Interrupted(SimulationError):
    """Ctrl-C stopped the integration; ``result`` holds the states up to there."""


@dataclass
class Result:
    t: np.ndarray
    x: np.ndarray                 # (len(t), n_states)
    y: np.ndarray                 # (len(t), n_outputs)
    state_names: tuple
    output_names: tuple
    solver: str
    stats: Stats = field(default_factory=Stats)
    success: bool = True
    message: str = ""
    projection: object = None     # a constrained model: consistent.Projection of the start
    params: np.ndarray | None = None  # the parameter values integrated (loads, rank set)

    def column(self, name: str) -> np.ndarray:
        if name in self.output_names:
            return self.y[:, self.output_names.index(name)]
        return self.x[:, self.state_names.index(name)]


# the step budget of a run (``--max-steps``) unless told: a million accepted steps. The
# shipped models need at most ~1e5 (the SARIB over a 60 s chirp, its step limited by the
# excitation), native Radau takes ~1e5 steps a second on small models, so a run that
# needs more is one whose step has collapsed or whose input outruns it; the run stops
# there, keeping what it computed. rk4's fixed steps are planned: its budget is its plan.
MAX_STEPS = 10 ** 6


def precompile_loop(solver: str | None):
    """Start compiling the step loop of a native solver in a separate process
    (``native.precompile``), for the caller to go on with the model meanwhile."""
    method = SOLVERS.get(solver)
    if method is not None and issubclass(method, NativeSolver):
        native.precompile(method.loop)


# the methods by name: a run makes one object of its method's class (``Solver(problem)``)
SOLVERS: dict[str, type[Solver]] = {s.name: s for s in (
    NativeRadau, NativeRk4, Bdf, Radau, Lsoda, Rk45, Cvode, Ida)}
assert tuple(SOLVERS) == SOLVER_NAMES, "bgc.model.model.SOLVERS lists the solvers here"


_GUARD_HINT = ("XYZ Cardan angles cannot pass b = +-90 deg; choose the body's frame so that "
               "its large rotations are not about its y axis")


_FAIL_HINT = ("tighten --rtol/--atol, try another --solver, or check the model for a "
              "singularity at that time")


_UNSTABLE_HINT = ("the model's own solution grows that fast: check the signs of its laws "
                  "(dampers' c > 0) and, under --method parasitic, a joint actuator whose "
                  "law reads body velocities: it measures the joints' stiff directions too "
                  "but acts along their free ones only, which can feed energy into them "
                  "(an ideal-joint method, zcp, lagrange or augmented, has no such "
                  "directions)")

# a failed run is said to start unstable where its linearisation at the start grows by
# more than this many e-folds over the time the run reached
UNSTABLE_EFOLDS = 10.0
# ... for a model of at most so many states (a dense eigenvalue problem, on failure only)
UNSTABLE_MAX_STATES = 2000


_SINGULAR_HINT = ("the mechanism reached a dead point (its constraints became dependent); "
                  "use --method augmented, whose ideal joints pass singular configurations "
                  "(redundant constraints too), or --method parasitic (compliant joints), or "
                  "change its geometry or initial state")


def _singular(monitor, seg: Segment, drop: float) -> str | None:
    """The message for a segment that ended at a singular configuration, else None."""
    return _singular_message(seg.t_reached, monitor.lost(seg.x_end, drop))


def _singular_message(t: float, lost: list[str] | None) -> str | None:
    """The message of a singular configuration at t where the joint directions ``lost``
    became dependent (at most 12 named: a mechanism of N repeated loops loses N ranks at
    once, A02 3N directions)."""
    return lost and (f"singular configuration at t = {t:.6g}: the constraints lost rank, "
                     f"joint directions {names_where(lost, [True] * len(lost), most=12)} "
                     "became dependent")


# how far past the last state of a native loop that failed its rhs is looked at for the
# state where the model refused (``_refused_ahead``): Radau's step collapses onto that
# edge (to ~1e-15 s), rk4 fails within its fixed step
REFUSED_REACH = 1e-6


def _stopped_singular(problem: Problem, monitor, run: _Run, t_all, x_all) -> str | None:
    """The message for a failed constrained run that stopped at a singular configuration,
    else None. At its last finite state the constraints' conditioning has fallen
    ``LOST_RANK``-fold from the start, or the generated constraint block refused there or
    just after (its rhs not finite: ``Problem.non_finite``, or ``_refused_ahead``) and
    solves that state keeping a lower rank: the block, J M^-1 J^T, squares the
    constraints' conditioning and spreads it by the masses and inertias, so it refuses
    before their own conditioning has fallen much (A02 N = 40: 2.4-fold; its links' axial
    moments are 1e-6 of the others)."""
    t, x = _last_finite(run, t_all, x_all)
    if x is None:
        return None
    lost = monitor.lost(x, consistent.LOST_RANK)
    module = problem.module
    if lost is None and consistent.RANK_PARAM in module.PARAM_NAMES:
        at = problem.non_finite
        if at is None or not at[0] >= t:       # none, or a trial before the last state
            at = _refused_ahead(problem, t, x)
        if at is not None and _block_rank(module, at[1], problem.p, at[0]) > 0:
            lost = monitor.dependent(at[1])
    return _singular_message(t, lost)


def _unstable(module, p, t0: float, x0, t: float) -> str | None:
    """Why a run that failed at ``t`` could not go on, where its model is unstable at the
    start (t0, x0): the eigenvalue of the Jacobian with the largest real part, where it
    grows by more than ``UNSTABLE_EFOLDS`` e-folds by ``t``, and the states it moves most;
    else None. (A05 under parasitic: +4.3e4 1/s, its spring-dampers' law reads body
    velocities across the parasitic joints: it spent a million steps by t = 1 ms.)"""
    if len(x0) > UNSTABLE_MAX_STATES or not t > t0:
        return None
    J = np.asarray(module.jac(t0, x0, p))
    if not np.all(np.isfinite(J)):
        return None
    w, V = np.linalg.eig(J)
    k = int(np.argmax(w.real))
    if not w[k].real * (t - t0) > UNSTABLE_EFOLDS:
        return None
    top = np.argsort(-np.abs(V[:, k]))[:3]
    lam = f"{w[k].real:.3g}" + (f" +- {abs(w[k].imag):.3g}j" if w[k].imag else "")
    return (f"the model is unstable at t = {t0:g}: its linearisation there grows e-fold "
            f"every {1 / w[k].real:.2g} s (eigenvalue {lam} 1/s, mostly in "
            f"{', '.join(module.STATE_NAMES[i] for i in top)})")


def _last_finite(run: _Run, t_all, x_all):
    """The last state of a run that is finite, and its time ((None, None): none)."""
    seg = run.last
    if seg is not None and np.all(np.isfinite(seg.x_end)):
        return seg.t_reached, np.asarray(seg.x_end, dtype=np.float64)
    rows = np.flatnonzero(np.all(np.isfinite(x_all), axis=1))
    return (float(t_all[rows[-1]]), x_all[rows[-1]]) if len(rows) else (None, None)


def _refused_ahead(problem: Problem, t: float, x):
    """The first state at (t, x) or ahead along its rate (steps growing tenfold up to
    rk4's step, or ``REFUSED_REACH`` of t) where the rhs is not finite, as (t, x); None
    if there is none."""
    module, p = problem.module, problem.p
    f = module.rhs(t, x, p)
    if not np.all(np.isfinite(f)):
        return t, x
    reach = problem.step or REFUSED_REACH * max(1.0, abs(t))
    for h in reach * np.logspace(-12, 0, 13):
        y = x + h * f
        if not np.all(np.isfinite(module.rhs(t + h, y, p))):
            return t + h, y
    return None


def _drifted(module, p, t, g, limit) -> tuple[str, str]:
    """Message and hint for a constrained run whose position drift passed its limit."""
    alpha = f"{module.METHOD}__alpha"
    value = p[list(module.PARAM_NAMES).index(alpha)] if alpha in module.PARAM_NAMES else None
    why = (f" ({alpha} = 0: no Baumgarte stabilisation)" if value == 0 else
           f" ({alpha} = {value:g})" if value is not None else "")
    return (f"constraint drift {g:.3g} at t = {t:.6g} exceeds {limit:.3g} "
            f"({consistent.DRIFT_UNITS:g} tolerance units at the mechanism's size): the "
            f"joints no longer hold{why}",
            f"stabilise (-p {alpha}=10 or more: it must outrun the drift's own growth) or "
            "tighten --rtol/--atol")


def _guard_events(module, p):
    """One terminal event per guard; the integrator asks each at the same (t, x), so the
    margins are computed once per point and shared."""
    names = getattr(module, "GUARD_NAMES", ())
    last: list = [None, None, None]          # t, x, margins

    def margins(t, x):
        if last[0] != t or not np.array_equal(last[1], x):
            last[:] = [t, np.array(x), module.guards(t, x, p)]
        return last[2]

    events = []
    for k in range(len(names)):
        def event(t, x, k=k):
            return margins(t, x)[k] - GUARD_TOLERANCE
        event.terminal, event.direction, event.guard = True, -1, True
        events.append(event)
    return events


def _check_index2(module, x, p, algebraic, t):
    """An index-2 DAE x' = f(x, z), 0 = g(x) needs g_x f_z regular (else the Newton
    matrices of every step are singular): refuse one whose algebraic equations are
    dependent, naming them (a planar loop modelled in 3D repeats its constraints)."""
    J = module.jac(t, x, p)
    diff = [i for i in range(len(x)) if i not in set(algebraic)]
    B = J[np.ix_(algebraic, diff)] @ J[np.ix_(diff, algebraic)]
    s = np.linalg.svd(B, compute_uv=False)
    rank = int(np.sum(s > consistent.RANK_TOL * max(s[0], 1e-300)))
    if rank < len(algebraic):
        import scipy.linalg
        _, _, piv = scipy.linalg.qr(B, pivoting=True)
        dep = [module.STATE_NAMES[algebraic[i]] for i in sorted(piv[rank:])]
        raise SimulationError(
            f"the kinematic loops kept closed give {len(algebraic)} algebraic equations of "
            f"rank {rank} at t = {t:g}: {', '.join(dep)} depend on the others (redundant "
            "constraints), so the index-2 DAE is singular; nothing was run",
            hint="let zcp open the loops (drop --keep-loops: the break variables then share "
                 "the load by least squares) or remove the redundant joint directions")


def _one_blas_thread():
    """Run with one BLAS thread, the set-up included: the LU factorizations of a model's
    Newton matrices (n ~ 150) are too small to gain from a second thread, and lose to its
    overhead (SARIB: 0.73 ms per factorization pair with two OpenBLAS threads, 0.44 ms
    with one); the set-up's least squares (the SARIB's static loads, 152 x 74) took
    75 ms instead of 1.5 ms on a busy machine, waking OpenBLAS's second thread."""
    return threadpool_limits(limits=1, user_api="blas")


def _segments(t_start: float, t_end: float, breakpoints) -> list[tuple[float, float]]:
    cuts = [t_start] + [float(b) for b in breakpoints if t_start < b < t_end] + [t_end]
    return list(zip(cuts[:-1], cuts[1:]))


def _refuse_non_finite(module, x, p, t):
    """Refuse an initial state or parameter values that are not finite, naming them."""
    for what, names, v in (("parameter", module.PARAM_NAMES, p),
                           ("initial state", module.STATE_NAMES, x)):
        bad = ~np.isfinite(v)
        if bad.any():
            raise SimulationError(f"{what}(s) {names_where(names, bad)} not finite at t = {t:g} "
                                  f"({', '.join(map(str, v[bad][:3]))}); nothing was run",
                                  hint=f"give every {what} a finite value")


def _block_rank(module, x, p, t) -> int:
    """The largest rank below the one set in ``p`` that the generated constraint block
    solve keeps at (t, x) with a finite rhs (0: none). The block refuses (NaN) where the
    last singular value it keeps falls below its cut, so a lower rank stays finite where
    a higher one is: bisection, a few rhs calls whatever the rank (A02 N = 40: 485)."""
    i = list(module.PARAM_NAMES).index(consistent.RANK_PARAM)
    q = np.array(p, dtype=np.float64)

    def finite(k: int) -> bool:
        q[i] = k
        return bool(np.all(np.isfinite(module.rhs(t, x, q))))

    lo, hi = 1, int(p[i]) - 1          # finite at lo (once checked), not above hi
    if hi < 1 or finite(hi):
        return max(hi, 0)
    if not finite(lo):
        return 0
    while hi - lo > 1:
        mid = (lo + hi) // 2
        lo, hi = (mid, hi) if finite(mid) else (lo, mid)
    return lo


def _culprit_params(module, x, p, t) -> list[str]:
    """The parameters whose own value makes the rhs non-finite at (t, x): moving one alone
    (by a thousandth, or to 1e-3 from 0) makes it finite."""
    if len(p) > 2000:               # one rhs call each: keep the check cheap
        return []
    found = []
    for i, name in enumerate(module.PARAM_NAMES):
        if name == consistent.RANK_PARAM:
            continue
        q = np.array(p, dtype=np.float64)
        q[i] = q[i] * 1.001 + 1e-3
        if np.all(np.isfinite(module.rhs(t, x, q))):
            found.append(name)
    return found


def check_start(module, x, p, t, projection=None):
    """Evaluate rhs and Jacobian at the start of a run (after the projection) and refuse
    non-finite values with one line naming the states whose derivative is not finite and
    what is responsible, where it can be told: the constraint block (method lagrange: the
    rank the projection found is more than its generated solve keeps), or the parameters
    whose value alone makes it so. Integrating from there fails at once or, worse, never
    ends (a NaN step size)."""
    f = np.asarray(module.rhs(t, x, p))
    J = np.asarray(module.jac(t, x, p))
    bad = ~np.isfinite(f)
    where = "d/dt of"
    if not bad.any():
        bad = ~np.all(np.isfinite(J), axis=1)
        where = "the Jacobian row of"
        if not bad.any():
            return
    states = f"{where} {names_where(module.STATE_NAMES, bad)} not finite at the initial state " \
             f"(t = {t:g})"
    if projection is not None and consistent.RANK_PARAM in module.PARAM_NAMES:
        kept = _block_rank(module, x, p, t)
        if kept:
            n, rank = projection.n_constraints, projection.rank
            red = (f", {n - rank} redundant ({', '.join(projection.redundant)})"
                   if rank < n else "")
            raise SimulationError(
                f"{states}: the constraint block is singular there; its {n} constraints "
                f"have rank {rank}{red}, but the generated block solve keeps only {kept} "
                f"singular values of J M^-1 J^T above 1e-10 of the largest (the inverse "
                f"masses, inertias and lever arms spread over too many decades); nothing "
                f"was run", hint="state the model in units that bring masses and inertias "
                                 "closer (mm and g for a millimetre mechanism), remove the "
                                 "redundant joint directions, or use --method parasitic")
    culprits = _culprit_params(module, x, p, t)
    cause = (f": parameter(s) {', '.join(culprits[:6])} make it so (a division by zero, "
             "a log or sqrt out of its domain?)" if culprits else "")
    raise SimulationError(f"{states}{cause}; nothing was run",
                          hint="check the model's parameters, initial state and laws there")


def prepare(module, x, p, t_start: float = 0.0, redundancy: bool = True):
    """The start of a run as ``simulate`` makes it: joint loads of a model that starts at
    rest (at t = 0), the state projected onto the constraints and the rank of the
    constraint block set. Returns (x, p, Projection or None)."""
    p = np.array(p, dtype=np.float64)
    x = np.array(x, dtype=np.float64)
    if getattr(module, "STATIC_LOADS", False) and t_start == 0:
        p = consistent.static_loads(module, x, p)
    projection = None
    if len(getattr(module, "CONSTRAINT_NAMES", ())):
        x, projection = consistent.project(module, x, p)
        if not redundancy and projection.rank < projection.n_constraints:
            raise SimulationError(
                f"{projection.n_constraints - projection.rank} redundant constraint(s) "
                f"({', '.join(projection.redundant)}): without redundancy handling "
                f"the constraint block is singular (rank {projection.rank} of "
                f"{projection.n_constraints}) and the joint forces are undetermined; "
                f"nothing was run (t = {t_start:g})",
                hint="keep redundancy handling (the default: redundant constraints share "
                     "the load by least squares) or remove the redundant joint directions")
        if consistent.RANK_PARAM in module.PARAM_NAMES:
            p[list(module.PARAM_NAMES).index(consistent.RANK_PARAM)] = projection.rank
    return x, p, projection


# (16 parameters, all but the module keyword-only with defaults: the run's settings as the
# CLI, the benchmarks, the tests and docs/generated-modules.md pass them, by name; a
# settings object would only move the same names into every caller)
def simulate(module, *, t_end: float, rtol: float = 1e-6, atol: float = 1e-8,
             solver: str = "native", points: int = 1001, params=None, x0=None,
             step: float | None = None, mass=None, check_stability: bool = True,
             t_start: float = 0.0, check_drift: bool = True,
             redundancy: bool = True, check_index: bool = True,
             max_steps: int | None = None) -> Result:
    """Integrate a generated module from ``t_start`` to ``t_end``; outputs on a uniform
    grid. A model that starts at rest (``STATIC_LOADS``) has its joint loads set from its
    state at t = 0; a run that continues another from ``t_start`` > 0 takes that run's
    ``x`` and ``params`` (``Result.params``: the loads and rank it used) as they are.
    ``mass``: a constant matrix M for ``M dx/dt = rhs`` (singular: an index-1 DAE, whose
    ``x0`` must be consistent), for the solvers that take one (native, ida). A module
    that is an index-2 DAE (``ALGEBRAIC``: zcp with its loops kept closed) brings its own
    M, and only a solver that takes index 2 runs it (``check_index=False`` integrates it
    as if it were of index 1: lets a solver that does not take index 2 try, and native
    Radau without its index-2 error scaling, to map how they fail).
    ``check_stability=False`` lets rk4 run past its stability limit, ``check_drift=False``
    a constrained run past its drift limit (``consistent.drift_limit``), to map where
    they fail. ``redundancy=False`` solves the constraint block as if its rows were
    independent, as a tool without redundancy handling does: a model with redundant
    constraints is then refused (its block is singular, its joint forces undetermined).

    ``max_steps``: the run's step budget (None: ``MAX_STEPS`` for the adaptive solvers;
    rk4's plan of fixed steps), a run that needs more stops there.

    The start (after the projection) is checked: a rhs or Jacobian that is not finite
    there is refused (``check_start``). A failing run raises SimulationError whose
    ``result`` holds everything computed up to the failure; Ctrl-C during the integration
    stops it within a step and raises ``Interrupted`` (a SimulationError) likewise.
    """
    method = _method(solver, t_start, t_end)
    check_result_size(int(points), len(module.STATE_NAMES) + len(module.OUTPUT_NAMES))
    mass, index2 = _mass_matrix(module, method, mass, check_index)
    budget = _budget(method, step, max_steps, t_start, t_end)
    p = np.array(module.PARAMS if params is None else params, dtype=np.float64)
    x = np.array(module.initial_state(p) if x0 is None else x0, dtype=np.float64)

    with _one_blas_thread():
        t0 = time.perf_counter()
        _refuse_non_finite(module, x, p, t_start)
        x, p, projection = prepare(module, x, p, t_start, redundancy)
        check_start(module, x, p, t_start, projection)
        if index2 is not None:
            _check_index2(module, x, p, list(module.ALGEBRAIC), t_start)
        max_step = float(module.max_step(p)) if hasattr(module, "max_step") else np.inf
        problem = Problem(module, p, step, mass, check_stability,
                          index2 if check_index else None, max_steps=budget, rtol=rtol,
                          atol=atol, max_step=max_step)
        run_solver = method(problem)
        run_solver.check(t_start, x)
        run_solver.warm_up(x)
        module.outputs(t_start, x, p)
        events, monitor = _events(module, x, p, t_start, projection)
        problem.monitor = monitor
        compile_time = time.perf_counter() - t0

        grid = np.linspace(t_start, t_end, int(points))
        wall = time.perf_counter()
        run = _integrate(run_solver, x, grid, _segments(t_start, t_end, module.BREAKPOINTS),
                         events, monitor)
        stats = Stats.of_run(run_solver.counts, wall_time=time.perf_counter() - wall,
                             compile_time=compile_time,
                             max_step=max_step if np.isfinite(max_step) else None)
        return _result(module, run_solver, run, stats, projection, monitor, check_drift)


# A run keeps every state and output at every output time: at most this many values (a
# gigabyte), refused before anything is allocated (--points over a large model, a --t-end
# that keeps the model's spacing over 1e308 s).
MAX_RESULT_VALUES = 125_000_000


def check_result_size(points: int, columns: int) -> None:
    """Refuse a result of ``points`` output times x ``columns`` values over
    ``MAX_RESULT_VALUES``, before any allocation."""
    if points * max(columns, 1) > MAX_RESULT_VALUES:
        raise SimulationError(
            f"{points} output times x {columns} states and outputs is "
            f"{points * columns:.3g} values, more than bgc's limit of "
            f"{MAX_RESULT_VALUES:.3g} (1 GB); nothing was run",
            hint="fewer output times (--points), a shorter --t-end, or --no-states "
                 "with a scene that keeps only the outputs asked for")


def _method(solver: str, t_start: float, t_end: float) -> type[Solver]:
    """The class of the solver named ``solver``, for a run from t_start to t_end."""
    if solver not in SOLVERS:
        raise SimulationError(f"unknown solver '{solver}'",
                              hint="valid solvers: " + ", ".join(SOLVERS))
    if not t_end > t_start >= 0:
        raise SimulationError(f"need 0 <= t_start < t_end, got t_start = {t_start} and "
                              f"t_end = {t_end}")
    return SOLVERS[solver]


def _mass_matrix(module, method: type[Solver], mass, check_index: bool):
    """The mass matrix of the run (a module that is an index-2 DAE brings its own unless
    given one) and ``index2`` (1.0 where a state is algebraic of index 2; None for an
    ODE or index-1 DAE); refused where ``method`` cannot take it."""
    algebraic = list(getattr(module, "ALGEBRAIC", ()))
    index2 = None
    if algebraic:
        index2 = np.zeros(len(module.STATE_NAMES))
        index2[algebraic] = 1.0
        mass = np.diag(1.0 - index2) if mass is None else mass
        if method.max_index < 2 and (check_index or not method.takes_mass()):
            loops = sorted({module.STATE_NAMES[i].split(".")[0] for i in algebraic})
            raise SimulationError(
                f"{module.MODEL_NAME} ({module.METHOD}, kinematic loops kept closed by joint "
                f"{', '.join(map(repr, loops))}) is an index-2 DAE: solver {method.name} "
                + ("takes ODEs only" if not method.max_index else
                   f"takes index {method.max_index} at most") + "; nothing was run",
                hint="use --solver native (Radau IIA, index-2 error scaling) or let zcp "
                     "open the loops with break variables (drop --keep-loops)")
    if mass is not None:
        mass = np.ascontiguousarray(mass, dtype=np.float64)
        n = len(module.STATE_NAMES)
        if mass.shape != (n, n):
            raise SimulationError(f"the mass matrix must be {n} x {n}, got "
                                  f"{' x '.join(map(str, mass.shape))}")
        if not method.takes_mass():
            raise SimulationError(f"solver {method.name} cannot integrate a system with a "
                                  "mass matrix", hint="solvers that can: " + ", ".join(
                                      s.name for s in SOLVERS.values() if s.takes_mass()))
    return mass, index2


def _budget(method: type[Solver], step, max_steps, t_start: float, t_end: float) -> int:
    """The run's step budget: ``max_steps`` if given (refused below rk4's plan of fixed
    steps), else rk4's plan, else ``MAX_STEPS``."""
    if max_steps is not None and not (isinstance(max_steps, (int, np.integer))
                                      and max_steps >= 1):
        raise SimulationError(f"the step budget must be a whole number >= 1, got "
                              f"{max_steps!r}", key="--max-steps")
    planned = method.planned_steps(step, t_start, t_end)
    if planned is not None and max_steps is not None and planned > max_steps:
        raise SimulationError(f"{method.name} with --step {step:g} takes {planned} steps from t = "
                              f"{t_start:g} to {t_end:g}, more than the step budget "
                              f"{max_steps}; nothing was run", key="--max-steps",
                              hint=f"take --max-steps {planned} or a larger --step")
    return max_steps or (planned + 1 if planned is not None else MAX_STEPS)


def _events(module, x, p, t_start: float, projection):
    """The run's events: one per guard (refused if one is already reached at the start)
    and, for a constrained model whose rank is above its imposed rows, the rank monitor
    (last; also returned, None without one)."""
    events = _guard_events(module, p)
    if events:
        margins = module.guards(t_start, x, p)
        if margins.min() <= GUARD_TOLERANCE:
            k = int(np.argmin(margins))
            raise SimulationError(f"{module.GUARD_NAMES[k]} at the initial state (margin "
                                  f"{margins[k]:.3g})", hint=_GUARD_HINT)
    monitor = None
    if projection is not None and projection.rank > int(np.sum(module.IMPOSED)) \
            and not getattr(module, "PASSES_SINGULAR", False):
        monitor = consistent.RankMonitor(module, x, p, projection)
        events.append(monitor)
    return events, monitor


@dataclass
class _Run:
    """What the segment loop reached: the output times and states, and how it ended
    (``hint``: what to do about a failure; ``last``: the last segment integrated)."""
    t: np.ndarray
    x: np.ndarray
    ok: bool = True
    message: str = ""
    hint: str | None = _FAIL_HINT
    interrupted: bool = False
    last: Segment | None = None


def _integrate(solver: Solver, x, grid, segs, events, monitor) -> _Run:
    """Integrate segment by segment (``segs``: no jump inside one), the outputs at the
    ``grid`` times; stop at a guard, a singular configuration the rank ``monitor`` sees
    (where only its minor went singular it re-picks one and goes on), Ctrl-C or a
    failure."""
    problem = solver.problem
    module = problem.module
    ts, xs = [], []
    run = _Run(grid[:0], np.empty((0, len(x))))
    done = -np.inf                # last output time recorded
    with problem.interrupt:
        while segs:
            a, b = segs.pop(0)
            last = not segs
            sel = grid[(grid >= a) & (grid > done) & ((grid < b) | (last & (grid <= b)))]
            if x.size == 0:
                ts.append(sel)
                xs.append(np.zeros((len(sel), 0)))
                continue
            seg = run.last = solver.integrate(a, b, x, sel, events)
            ts.append(sel[:len(seg.x_eval)])
            xs.append(seg.x_eval)
            done = ts[-1][-1] if len(ts[-1]) else done
            if monitor is not None and seg.event == len(events) - 1:
                singular = _singular(monitor, seg, consistent.LOST_RANK_EVENT)
                if singular:
                    run.ok, run.message, run.hint = False, singular, _SINGULAR_HINT
                    break
                monitor.repick(seg.x_end)        # only the monitored minor was singular
                x = np.array(seg.x_end, dtype=np.float64)
                segs.insert(0, (seg.t_reached, b))
                continue
            if seg.event is not None:
                run.ok, run.hint = False, _GUARD_HINT
                run.message = (f"{module.GUARD_NAMES[seg.event]} reached at "
                               f"t = {seg.t_reached:.6g}")
                break
            if seg.interrupted:
                run.ok, run.interrupted, run.hint = False, True, None
                run.message = f"Ctrl-C at t = {seg.t_reached:.6g}: the run stopped there"
                break
            if not seg.ok:
                run.ok = False
                run.message = (f"{solver.name} failed at t = {seg.t_reached:.6g}: "
                               f"{seg.message}")
                break
            x = np.array(seg.x_end, dtype=np.float64)
    if ts:
        run.t, run.x = np.concatenate(ts), np.vstack(xs)
    return run


def _result(module, solver: Solver, run: _Run, stats: Stats, projection, monitor,
            check_drift: bool) -> Result:
    """The run's Result, its outputs computed and, for a constrained model, its drift
    measured and checked (a run whose joints came apart ends where they did); raised with
    its failure (``Interrupted`` for Ctrl-C) if it has one."""
    problem = solver.problem
    p = problem.p
    t_all, x_all = run.t, run.x
    y_all = module.outputs_at(t_all, x_all, p)
    ok, message, hint = run.ok, run.message, run.hint
    if projection is not None and len(x_all):
        g_t, v_t = consistent.drift_history(module, x_all, p)
        # a state gone non-finite has no drift: NaN there, the run's message says why
        stats.drift_position = float(np.nanmax(g_t, initial=0.0))
        stats.drift_velocity = float(np.nanmax(v_t, initial=0.0))
        limit = consistent.drift_limit(module, x_all[0], problem.rtol, problem.atol)
        if ok and check_drift and stats.drift_position > limit:   # joints apart: keep the run
            k = int(np.argmax(g_t > limit))
            ok, message, hint = False, *_drifted(module, p, t_all[k], g_t[k], limit)
            t_all, x_all, y_all = t_all[:k + 1], x_all[:k + 1], y_all[:k + 1]
    failed = not run.ok
    if ok and not np.all(np.isfinite(x_all)):    # an integrator went on through NaN (lsoda)
        k = int(np.argmax(~np.all(np.isfinite(x_all), axis=1)))
        ok, failed, hint = False, True, "check the model's parameters and laws"
        message = f"the solution became non-finite at t = {t_all[k]:.6g}"
        t_all, x_all, y_all = t_all[:k], x_all[:k], y_all[:k]       # the results so far
    if failed and monitor is not None and not run.interrupted and hint != _SINGULAR_HINT:
        singular = _stopped_singular(problem, monitor, run, t_all, x_all)
        if singular:       # the integrator gave up short of the singular pose: say why
            message, hint = f"{singular} ({message})", _SINGULAR_HINT
    # (a DAE's, M dx/dt = f with M singular, is not the spectrum of df/dx: not judged)
    if failed and not run.interrupted and hint == _FAIL_HINT and len(x_all) \
            and problem.mass is None:
        t, _ = _last_finite(run, t_all, x_all)
        unstable = t is not None and _unstable(module, p, float(t_all[0]), x_all[0], t)
        if unstable:
            message, hint = f"{message}; {unstable}", _UNSTABLE_HINT
    result = Result(t_all, x_all, y_all, tuple(module.STATE_NAMES),
                    tuple(module.OUTPUT_NAMES), solver.name, stats, ok, message, projection,
                    p)
    if run.interrupted:
        raise Interrupted(message, result=result, hint=hint)
    if not ok:
        raise SimulationError(message, result=result, hint=hint)
    return result
