"""Stage **simulate**: a generated module + run settings -> Result (time, states, outputs,
solver statistics).

Solvers share one small interface (``Solver.integrate`` over one smooth segment); the run
is split at the model's breakpoints (step times, table knots) so no step straddles a jump.
Statistics are kept honestly: what an integrator does not report is ``None``, not 0.
"""

from __future__ import annotations

import abc
import time
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

from . import consistent
from .errors import SimulationError


@dataclass
class Stats:
    steps: int = 0
    rhs_calls: int = 0
    jac_calls: int = 0
    lu_decompositions: int | None = 0
    rejected_steps: int | None = None     # scipy's solve_ivp does not report them
    wall_time: float = 0.0                # integration only
    max_step: float | None = None         # the step limit the input signals set
    compile_time: float = 0.0             # numba JIT / cache load of the module's functions
    # method lagrange: largest |g| and |dg/dt| of the blocked directions over the outputs
    drift_position: float | None = None
    drift_velocity: float | None = None

    def to_dict(self) -> dict:
        return dict(self.__dict__)


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
    projection: object = None     # method lagrange: consistent.Projection of the start

    def column(self, name: str) -> np.ndarray:
        if name in self.output_names:
            return self.y[:, self.output_names.index(name)]
        return self.x[:, self.state_names.index(name)]


@dataclass
class Segment:
    """What a solver returns for one smooth segment [t0, t1]."""
    x_eval: np.ndarray            # states at the requested times reached
    x_end: np.ndarray             # state at the last time reached
    t_reached: float
    ok: bool
    message: str = ""
    event: int | None = None      # index of the guard that stopped the segment


@dataclass
class Problem:
    """What a solver integrates: a generated module at parameter values ``p``."""
    module: object
    p: np.ndarray
    step: float | None = None         # fixed-step methods: the step

    def rhs(self, t, x):
        return self.module.rhs(t, x, self.p)

    def jac(self, t, x):
        return self.module.jac(t, x, self.p)


class Solver(abc.ABC):
    """One integration method. ``integrate`` covers a segment with no discontinuity."""
    name = ""
    description = ""

    @abc.abstractmethod
    def integrate(self, problem: Problem, t0, t1, x0, t_eval, rtol, atol, stats: Stats,
                  events=(), max_step=np.inf) -> Segment:
        """Integrate from t0 to t1, recording the states at ``t_eval``; stop early where
        one of ``events`` (functions of (t, x)) falls through zero; no step longer than
        ``max_step``."""


class ScipySolver(Solver):
    """scipy.integrate.solve_ivp with the generated analytic Jacobian."""

    def __init__(self, name: str, method: str, description: str):
        self.name, self.method, self.description = name, method, description

    def integrate(self, problem, t0, t1, x0, t_eval, rtol, atol, stats, events=(),
                  max_step=np.inf):
        kw = {"jac": problem.jac} if self.method in ("BDF", "Radau", "LSODA") else {}
        sol = solve_ivp(problem.rhs, (t0, t1), x0, method=self.method, rtol=rtol, atol=atol,
                        dense_output=True, events=list(events) or None,
                        max_step=max_step, **kw)
        stats.steps += max(len(sol.t) - 1, 0)
        stats.rhs_calls += int(sol.nfev)
        stats.jac_calls += int(sol.njev)
        if stats.lu_decompositions is not None:
            stats.lu_decompositions += int(sol.nlu)
        t_ok = float(sol.t[-1]) if len(sol.t) else t0
        x_end = sol.y[:, -1] if sol.y.size else np.asarray(x0)
        if sol.status < 0 or sol.sol is None:
            reached = t_eval[t_eval <= t_ok]
            xs = sol.sol(reached).T if sol.sol is not None else np.empty((0, len(x0)))
            return Segment(xs, x_end, t_ok, False, sol.message)
        if sol.status == 1:       # a guard fired: keep what lies before it
            k = next(i for i, te in enumerate(sol.t_events) if len(te))
            reached = t_eval[t_eval <= t_ok]
            return Segment(sol.sol(reached).T.reshape(len(reached), len(x0)), x_end, t_ok,
                           False, "", event=k)
        return Segment(sol.sol(t_eval).T.reshape(len(t_eval), len(x0)), x_end, t_ok, True)


# RK4's stability region reaches 2.785 on the negative real axis and 2.83 on the imaginary
RK4_LIMIT = 2.78


class NativeSolver(Solver):
    """A step loop compiled into the generated module (``templates/radau5.py.j2``): it
    calls the rhs and Jacobian without returning to Python per step. Guards are checked
    in the loop; other events (the rank monitor, Python functions) are checked between
    chunks of the segment and located by bisection, re-integrating from the chunk's
    start."""
    CHUNKS = 100            # per segment, where Python events must be watched

    def __init__(self, name: str, loop: str, description: str):
        self.name, self.loop, self.description = name, loop, description

    def check(self, problem, t0, x0):
        """rk4: a step beyond the method's stability limit at the start is refused (the
        run would blow up, or worse, just ring): h |lambda_max| <= RK4_LIMIT, lambda_max
        the Jacobian's largest eigenvalue magnitude there."""
        if self.loop != "rk4":
            return
        if not problem.step or problem.step <= 0:
            raise SimulationError("solver rk4 takes a fixed step: give --step H (s)",
                                  hint=f"its stability limit is h |lambda_max| <= {RK4_LIMIT}")
        lam = float(np.abs(np.linalg.eigvals(problem.jac(t0, x0))).max(initial=0.0))
        if problem.step * lam > RK4_LIMIT:
            raise SimulationError(
                f"rk4 step {problem.step:.3g} s is beyond its stability limit at t = {t0:g}: "
                f"h |lambda_max| = {problem.step * lam:.3g} > {RK4_LIMIT} (|lambda_max| = "
                f"{lam:.4g} 1/s from the Jacobian)",
                hint=f"take --step {RK4_LIMIT / lam:.3g} or less, or a stiff solver "
                     "(native, bdf, radau)")

    def _run(self, problem, t0, t1, x0, t_eval, rtol, atol, max_step, stats):
        m = problem.module
        counts = np.zeros(5, dtype=np.int64)
        if self.loop == "rk4":
            res = m.rk4(t0, t1, x0, t_eval, problem.p, float(problem.step), GUARD_TOLERANCE,
                        counts)
        else:
            res = m.radau5(t0, t1, x0, t_eval, problem.p, rtol, atol, max_step,
                           GUARD_TOLERANCE, counts)
        stats.steps += int(counts[0])
        stats.rhs_calls += int(counts[1])
        stats.jac_calls += int(counts[2])
        stats.lu_decompositions += int(counts[3])
        stats.rejected_steps = (stats.rejected_steps or 0) + int(counts[4])
        return res

    def integrate(self, problem, t0, t1, x0, t_eval, rtol, atol, stats, events=(),
                  max_step=np.inf):
        if not hasattr(problem.module, "radau5"):
            raise SimulationError(f"solver {self.name} needs a module generated by this "
                                  "bgc", hint="recompile the model (bgc compile)")
        watched = [(k, e) for k, e in enumerate(events) if not getattr(e, "guard", False)]
        t_eval = np.ascontiguousarray(t_eval, dtype=np.float64)
        cuts = np.linspace(t0, t1, self.CHUNKS + 1) if watched else np.array([t0, t1])
        x = np.array(x0, dtype=np.float64)
        xs = []
        before = [e(t0, x) for _, e in watched]
        for a, b in zip(cuts[:-1], cuts[1:]):
            sel = t_eval[(t_eval >= a) & ((t_eval < b) | (b == t1))]
            out, k, t_r, x_r, status, guard = self._run(problem, a, b, x, sel, rtol, atol,
                                                        max_step, stats)
            xs.append(out[:k])
            if status == 0:
                after = [e(b, x_r) for _, e in watched]
                hit = [j for j in range(len(watched))
                       if np.sign(after[j]) != np.sign(before[j]) and before[j] != 0]
                if hit:
                    xs.pop()
                    return self._locate(problem, a, b, x, sel, rtol, atol, max_step, stats,
                                        watched[hit[0]], before[hit[0]], xs)
                x, before = np.array(x_r), after
                continue
            x_eval = np.vstack(xs) if xs else np.empty((0, len(x0)))
            if status == 2:
                return Segment(x_eval, np.array(x_r), float(t_r), False, "", event=int(guard))
            why = ("the state became non-finite (beyond the method's stability limit)"
                   if status == 3 else "step size too small")
            return Segment(x_eval, np.array(x_r), float(t_r), False, why)
        return Segment(np.vstack(xs) if xs else np.empty((0, len(x0))), x, float(t1), True)

    def _locate(self, problem, a, b, x, sel, rtol, atol, max_step, stats, event, before, xs):
        """An event changed sign on [a, b] (from ``x`` at a): bisect by re-integrating."""
        k, fun = event
        lo, hi = a, b
        empty = np.empty(0)
        while hi - lo > 1e-12 * max(1.0, abs(hi)):
            mid = 0.5 * (lo + hi)
            x_mid = self._run(problem, a, mid, x, empty, rtol, atol, max_step, stats)[3]
            if np.sign(fun(mid, x_mid)) == np.sign(before):
                lo = mid
            else:
                hi = mid
        out, n, t_r, x_r, _, _ = self._run(problem, a, hi, x, sel[sel <= hi], rtol, atol,
                                           max_step, stats)
        xs.append(out[:n])
        return Segment(np.vstack(xs), np.array(x_r), float(hi), False, "", event=k)


SOLVERS: dict[str, Solver] = {s.name: s for s in (
    NativeSolver("native", "radau5", "Radau IIA order 5 compiled into the module "
                                     "(numba step loop), stiff"),
    NativeSolver("rk4", "rk4", "classical Runge-Kutta 4, fixed step (--step), explicit, "
                               "compiled into the module"),
    ScipySolver("bdf", "BDF", "scipy BDF (variable order 1-5), stiff"),
    ScipySolver("radau", "Radau", "scipy Radau IIA order 5, stiff"),
    ScipySolver("lsoda", "LSODA", "scipy LSODA (ODEPACK), switches stiff/non-stiff"),
    ScipySolver("rk45", "RK45", "scipy Dormand-Prince 5(4), non-stiff"),
)}


# A run stops where a guard margin (e.g. |cos b| of a body's Cardan angles) falls below this.
GUARD_TOLERANCE = 1e-3


_GUARD_HINT = ("XYZ Cardan angles cannot pass b = +-90 deg; choose the body's frame so that "
               "its large rotations are not about its y axis")


_SINGULAR_HINT = ("the mechanism reached a dead point (its constraints became dependent); "
                  "change its geometry or initial state, or use --method parasitic to pass "
                  "through it")


def _singular(monitor, seg: Segment, drop: float) -> str | None:
    """The message for a segment that ended at a singular configuration, else None."""
    lost = monitor.lost(seg.x_end, drop)
    return lost and (f"singular configuration at t = {seg.t_reached:.6g}: the constraints "
                     f"lost rank, joint directions {lost} became dependent")


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


def _segments(t_end: float, breakpoints) -> list[tuple[float, float]]:
    cuts = [0.0] + [float(b) for b in breakpoints if 0.0 < b < t_end] + [t_end]
    return list(zip(cuts[:-1], cuts[1:]))


def simulate(module, *, t_end: float, rtol: float = 1e-6, atol: float = 1e-8,
             solver: str = "bdf", points: int = 1001, params=None, x0=None,
             step: float | None = None) -> Result:
    """Integrate a generated module from t = 0 to ``t_end``; outputs on a uniform grid.

    A failing run raises SimulationError whose ``result`` holds everything computed up to
    the failure.
    """
    if solver not in SOLVERS:
        raise SimulationError(f"unknown solver '{solver}'",
                              hint="valid solvers: " + ", ".join(SOLVERS))
    if not t_end > 0:
        raise SimulationError(f"t_end must be > 0, got {t_end}")
    method = SOLVERS[solver]
    p = np.array(module.PARAMS if params is None else params, dtype=np.float64)
    x = np.array(module.initial_state(p) if x0 is None else x0, dtype=np.float64)
    stats = Stats(lu_decompositions=0 if solver != "rk45" else None)

    t0 = time.perf_counter()
    if getattr(module, "STATIC_LOADS", False):
        p = consistent.static_loads(module, x, p)
    projection = None
    if len(getattr(module, "CONSTRAINT_NAMES", ())):
        x, projection = consistent.project(module, x, p)
        p[list(module.PARAM_NAMES).index(consistent.RANK_PARAM)] = projection.rank
    module.rhs(0.0, x, p)
    module.jac(0.0, x, p)
    if isinstance(method, NativeSolver) and hasattr(module, "radau5"):   # JIT the loop
        getattr(module, method.loop)(0.0, 0.0, x, np.empty(0), p, *(
            (1.0, 0.0) if method.loop == "rk4" else (rtol, atol, np.inf, 0.0)),
            np.zeros(5, dtype=np.int64))
    module.outputs(0.0, x, p)
    events = _guard_events(module, p)
    if events:
        margins = module.guards(0.0, x, p)
        if margins.min() <= GUARD_TOLERANCE:
            k = int(np.argmin(margins))
            raise SimulationError(f"{module.GUARD_NAMES[k]} at the initial state (margin "
                                  f"{margins[k]:.3g})", hint=_GUARD_HINT)
    monitor = None
    if projection is not None and projection.rank > int(np.sum(module.IMPOSED)):
        monitor = consistent.RankMonitor(module, x, p, projection)
        events.append(monitor)
    stats.compile_time = time.perf_counter() - t0

    problem = Problem(module, p, step)
    if isinstance(method, NativeSolver):
        method.check(problem, 0.0, x)

    max_step = float(module.max_step(p)) if hasattr(module, "max_step") else np.inf
    stats.max_step = max_step if np.isfinite(max_step) else None
    grid = np.linspace(0.0, t_end, int(points))
    ts, xs = [], []
    ok, message = True, ""
    hint = ("tighten --rtol/--atol, try another --solver, or check the model for a "
            "singularity at that time")
    t_start = time.perf_counter()
    segs = _segments(t_end, module.BREAKPOINTS)
    done = -np.inf                # last output time recorded
    while segs:
        a, b = segs.pop(0)
        last = not segs
        sel = grid[(grid >= a) & (grid > done) & ((grid < b) | (last & (grid <= b)))]
        if x.size == 0:
            ts.append(sel)
            xs.append(np.zeros((len(sel), 0)))
            continue
        seg = method.integrate(problem, a, b, x, sel, rtol, atol, stats, events, max_step)
        ts.append(sel[:len(seg.x_eval)])
        xs.append(seg.x_eval)
        done = ts[-1][-1] if len(ts[-1]) else done
        if monitor is not None and seg.event == len(events) - 1:
            singular = _singular(monitor, seg, consistent.LOST_RANK_EVENT)
            if singular:
                ok, message, hint = False, singular, _SINGULAR_HINT
                break
            monitor.repick(seg.x_end)        # only the monitored minor was singular
            x = np.array(seg.x_end, dtype=np.float64)
            segs.insert(0, (seg.t_reached, b))
            continue
        if seg.event is not None:
            ok, message = False, (f"{module.GUARD_NAMES[seg.event]} reached at "
                                  f"t = {seg.t_reached:.6g}")
            hint = _GUARD_HINT
            break
        if not seg.ok:
            ok, message = False, f"{method.name} failed at t = {seg.t_reached:.6g}: {seg.message}"
            break
        x = np.array(seg.x_end, dtype=np.float64)
    stats.wall_time = time.perf_counter() - t_start
    t_all = np.concatenate(ts) if ts else np.empty(0)
    x_all = np.vstack(xs) if xs else np.empty((0, len(module.STATE_NAMES)))
    y_all = np.array([module.outputs(t, xi, p) for t, xi in zip(t_all, x_all)]).reshape(
        len(t_all), len(module.OUTPUT_NAMES))
    if projection is not None and len(x_all):
        stats.drift_position, stats.drift_velocity = consistent.drift(module, x_all, p)
        singular = None if ok or hint == _SINGULAR_HINT or monitor is None else _singular(
            monitor, seg, consistent.LOST_RANK)
        if singular:       # the integrator gave up short of the singular pose: say why
            message, hint = f"{singular} ({message})", _SINGULAR_HINT
    result = Result(t_all, x_all, y_all, tuple(module.STATE_NAMES),
                    tuple(module.OUTPUT_NAMES), solver, stats, ok, message, projection)
    if not ok:
        raise SimulationError(message, result=result, hint=hint)
    if not np.all(np.isfinite(x_all)):
        bad = t_all[np.argmax(~np.all(np.isfinite(x_all), axis=1))]
        raise SimulationError(f"the solution became non-finite at t = {bad:.6g}",
                              result=result, hint="check the model's parameters and laws")
    return result
