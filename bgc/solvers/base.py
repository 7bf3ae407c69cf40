"""The integrator interface every solver implements (scipy's ``_ivp/base.py`` in spirit):
a ``Problem`` (a generated module at parameter values, with an optional mass matrix), one
``Solver`` object per run, one ``integrate`` call per smooth segment returning a
``Segment``, and ``Counts`` kept honestly: what an integrator does not report is ``None``,
never a made-up 0 (printed "n/a"). ``Stats``: a run's counts and the facts set around it.
"""

from __future__ import annotations

import abc
import functools
import mmap
import os
import signal
import tempfile
import threading
import weakref
from dataclasses import dataclass, field

import numpy as np

# the elimination plans made (``Problem.lu_plan``), per module (kept while it lives)
_PLANS: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()

# A run stops where a guard margin (e.g. |cos b| of a body's Cardan angles) falls below this.
GUARD_TOLERANCE = 1e-3


# the solver's counts, in the order a summary names them
COUNTS = ("steps", "rhs_calls", "jac_calls", "lu_decompositions", "rejected_steps")


@dataclass
class Counts:
    """The work a solver did, counted by the solver where it happens (its own loop, or
    what its library reports). ``None``: this solver does not report the count; a count
    it reports starts at 0 (``Counts.of``)."""
    steps: int | None = None              # accepted steps
    rhs_calls: int | None = None          # evaluations of rhs (ida: of its residual)
    jac_calls: int | None = None          # evaluations of the Jacobian
    # LU factorizations of Newton matrices (native Radau: its real and complex ones apart)
    lu_decompositions: int | None = None
    rejected_steps: int | None = None     # steps tried and rejected (error test, Newton)

    @classmethod
    def of(cls, reported=COUNTS) -> "Counts":
        """The counts before a run's first step: 0 for those ``reported``, else None."""
        return cls(**{k: 0 if k in reported else None for k in COUNTS})

    def add(self, **counts: int) -> None:
        """Add to the counts this solver reports (one it does not report stays None)."""
        for k, v in counts.items():
            if getattr(self, k) is not None:
                setattr(self, k, getattr(self, k) + int(v))

    def text(self, name: str) -> str:
        """One count as a summary prints it: "n/a" where it is not reported."""
        v = getattr(self, name)
        return "n/a" if v is None else str(v)


@dataclass
class Stats(Counts):
    """A run's statistics: the solver's ``Counts`` (above), then the facts ``simulate``
    sets around the run."""
    # seconds integrating: the segments, their events and the Python between them
    wall_time: float = 0.0
    # seconds before the first step: the start's checks and projection, the step loop's
    # JIT or cache load, scipy.integrate's import
    compile_time: float = 0.0
    max_step: float | None = None         # the step limit the input signals set (None: none)
    # a constrained run: the largest |g| (position) and |dg/dt| (velocity) of its blocked
    # directions over the output times (None: the model has no constraints)
    drift_position: float | None = None
    drift_velocity: float | None = None

    @classmethod
    def of_run(cls, counts: Counts, **facts) -> "Stats":
        """A run's statistics from its solver's ``counts`` and the ``facts`` set."""
        return cls(**{k: getattr(counts, k) for k in COUNTS}, **facts)

    def to_dict(self) -> dict:
        return dict(self.__dict__)


@dataclass
class Segment:
    """What a solver returns for one smooth segment [t0, t1]."""
    x_eval: np.ndarray            # states at the requested times reached
    x_end: np.ndarray             # state at the last time reached
    t_reached: float
    ok: bool
    message: str = ""
    event: int | None = None      # index of the event that stopped the segment
    interrupted: bool = False     # stopped by Ctrl-C (``Interrupt``)
    # native Radau: each state's share of the error of the last rejected step (inf where
    # its derivative was not finite), what names the culprits of a failure; else None
    error_share: np.ndarray | None = None


@dataclass
class Problem:
    """What a solver integrates, and how finely: a generated module at parameter values
    ``p``, ``mass @ dx/dt = rhs(t, x, p)`` (no mass matrix: the identity), to the
    tolerances ``rtol``, ``atol`` with no step longer than ``max_step``."""
    module: object
    p: np.ndarray
    step: float | None = None         # fixed-step methods: the step
    mass: np.ndarray | None = None
    check_stability: bool = True      # rk4: refuse a step beyond its stability limit
    # a DAE: 1.0 where a state is algebraic of index 2 (its error scaled by the step)
    index2: np.ndarray | None = None
    max_steps: int = 0                # the run's step budget over all segments (0: none)
    rtol: float = 1e-6
    atol: float = 1e-8
    max_step: float = np.inf          # the step limit the input signals set
    interrupt: Interrupt = field(default_factory=lambda: Interrupt())
    # a constrained run's rank monitor (``consistent.RankMonitor``), among its events too:
    # native Radau checks it in its loop (``bgc.solvers.rank``), the others as an event
    monitor: object = None
    # the last (t, x) with x finite where ``rhs`` or ``jac`` was not (the integrators
    # driven from Python call them; native loops do not): where a failed run's model
    # refused, e.g. a constraint block that lost rank (``simulate``)
    non_finite: tuple | None = None

    def budget(self, counts: Counts) -> int | None:
        """Steps left of the run's budget after ``counts`` (None: no budget)."""
        return max(self.max_steps - (counts.steps or 0), 0) if self.max_steps else None

    def rhs(self, t, x):
        return self._seen(t, x, self.module.rhs(t, x, self.p))

    def _seen(self, t, x, value):
        """``value`` (of rhs or jac at (t, x)); where it is not finite at a finite x, (t, x)
        kept as ``non_finite``."""
        if not np.isfinite(value).all() and np.isfinite(x).all():
            self.non_finite = (float(t), np.array(x, dtype=np.float64))
        return value

    @functools.cached_property
    def lu_plan(self):
        """The sparse elimination plan of its Newton matrices (``sparse_lu.analyse``),
        made once per module and mass matrix (its symbolic analysis in Python: 5-10 ms of
        a 100 ms SARIB run)."""
        try:
            plans = _PLANS.setdefault(self.module, {})
        except TypeError:                   # not weakly referenceable (a stand-in module)
            plans = {}
        key = None if self.mass is None else self.mass.tobytes()
        if key not in plans:
            from bgc.solvers.sparse_lu import analyse
            aug = self.aug_mass
            plans[key] = analyse(self.jac_size, self.module.JAC_I, self.module.JAC_J,
                                 aug if aug.size else self.mass)
        return plans[key]

    @property
    def jac_size(self) -> int:
        """The size of the module's Jacobian as the native integrator factors it
        (``JAC_SIZE``: more than the states where a constraint block is kept open)."""
        return int(getattr(self.module, "JAC_SIZE", len(self.module.STATE_NAMES)))

    @functools.cached_property
    def aug_mass(self) -> np.ndarray:
        """The mass matrix of the open Jacobian: the run's (or I) on the states, zero on
        the open block's rows; empty where the Jacobian is the states' own."""
        n, na = len(self.module.STATE_NAMES), self.jac_size
        if na == n:
            return np.empty((0, 0))
        out = np.zeros((na, na))
        out[:n, :n] = np.eye(n) if self.mass is None else self.mass
        return out

    def jac(self, t, x):
        return self._seen(t, x, self.module.jac(t, x, self.p))


class Solver(abc.ABC):
    """One integration method, one object per run (scipy's ``OdeSolver`` in spirit):
    ``Solver(problem)`` is made by ``simulate`` for one run and holds that run's state
    only, its ``counts`` among it. ``integrate`` covers a segment with no discontinuity;
    what it learns comes back in its ``Segment``."""
    name = ""
    description = ""
    # the highest DAE index it integrates, M dx/dt = f with a singular M (0: ODEs only)
    max_index = 0
    # the counts it reports (``Counts``; the others stay None)
    reports: tuple = COUNTS

    def __init__(self, problem: Problem):
        self.problem = problem
        self.counts = Counts.of(self.reports)

    @classmethod
    def takes_mass(cls) -> bool:
        return cls.max_index > 0

    @classmethod
    def planned_steps(cls, step, t0: float, t1: float) -> int | None:
        """The steps a fixed-step method plans from t0 to t1 (None: adaptive)."""
        return None

    def check(self, t0: float, x0: np.ndarray):
        """Refuse, before the run, what this method cannot integrate (SimulationError)."""

    def warm_up(self, x0: np.ndarray):
        """Compile (or load from a cache) what the method runs, so wall time is the run's."""

    @abc.abstractmethod
    def integrate(self, t0, t1, x0, t_eval, events=()) -> Segment:
        """Integrate from t0 to t1, recording the states at ``t_eval`` and adding the
        work done to ``self.counts``; stop early where one of ``events`` (functions of
        (t, x), ``terminal`` and ``direction`` as in scipy) falls through zero."""


def names_where(names, mask, most: int = 6) -> str:
    """The names where ``mask`` holds, at most ``most`` of them and how many more."""
    picked = [n for n, m in zip(names, mask) if m]
    more = len(picked) - most
    return ", ".join(picked[:most]) + (f" and {more} more" if more > 0 else "")


def fastest(problem: Problem, t, x, most: int = 3) -> str:
    """The states changing fastest at (t, x) (|dx/dt| over |x| + 1), as a clause."""
    f = np.asarray(problem.rhs(t, np.asarray(x, dtype=np.float64)))
    names = problem.module.STATE_NAMES
    if not np.all(np.isfinite(f)):
        return f"; d/dt of {names_where(names, ~np.isfinite(f))} not finite"
    rate = np.abs(f) / (np.abs(x) + 1.0)
    top = [names[i] for i in np.argsort(-rate)[:most] if rate[i] > 0]
    return f"; fastest states there: {', '.join(top)}" if top else ""


def budget_message(problem: Problem, t, x) -> str:
    """Why a run stopped at its step budget, with the states moving fastest there."""
    return (f"the step budget ({problem.max_steps} steps) is spent at t = {t:.6g}"
            + fastest(problem, t, x))


def collapse_message(problem: Problem, t, x, h, diag=None, most: int = 3) -> str:
    """Why a step size collapsed at (t, x): the states with the largest share of the last
    rejected step's error (``diag``, native Radau), else the fastest ones."""
    text = f"the step size collapsed to {h:.3g} s at t = {t:.6g}"
    if diag is not None and np.any(diag != 0):
        names = problem.module.STATE_NAMES
        if not np.all(np.isfinite(diag)):
            bad = names_where(names, ~np.isfinite(diag))
            return text + f"; d/dt of {bad} not finite there"
        top = [names[i] for i in np.argsort(-diag)[:most] if diag[i] > 0]
        return text + f"; largest error in {', '.join(top)}"
    return text + fastest(problem, t, x)


class Interrupt:
    """Ctrl-C (SIGINT) during a run, as a request to stop rather than an exception, so the
    states computed so far are kept. Within ``with Interrupt() as stop:`` a SIGINT sets
    ``stop.requested``; the native loops see it within a step: Python's C signal handler
    writes the signal's number to the wakeup fd (``signal.set_wakeup_fd``), here a
    one-page file mapped into ``stop.flag``, which the compiled loops read (an atomic
    load, ``native.stopped``) without returning to Python. Outside the main thread (no
    signal handlers there) it does nothing. A second Ctrl-C stops at once
    (KeyboardInterrupt)."""

    def __init__(self):
        self.flag = np.zeros(0, dtype=np.uint8)   # empty: never set
        self._hit = False
        self._mm = self._file = None
        self._saved = None

    @property
    def requested(self) -> bool:
        return self._hit or bool(self.flag.size and self.flag[0])

    def _handler(self, signum, frame):
        if self._hit:
            raise KeyboardInterrupt
        self._hit = True

    def __enter__(self):
        if threading.current_thread() is not threading.main_thread():
            return self
        if hasattr(os, "memfd_create"):
            fd = os.memfd_create("bgc-interrupt")
        else:                                          # pragma: no cover - not Linux
            self._file = tempfile.TemporaryFile()
            fd = os.dup(self._file.fileno())
        try:
            os.ftruncate(fd, mmap.PAGESIZE)
            os.set_blocking(fd, False)
            self._mm = mmap.mmap(fd, mmap.PAGESIZE)
            self.flag = np.frombuffer(self._mm, dtype=np.uint8)
            old_fd = signal.set_wakeup_fd(fd, warn_on_full_buffer=False)
            self._saved = (fd, old_fd, signal.signal(signal.SIGINT, self._handler))
        except (OSError, ValueError):                  # pragma: no cover - no mmap/memfd
            self.flag = np.zeros(0, dtype=np.uint8)
            os.close(fd)
        return self

    def __exit__(self, *exc):
        if self._saved is not None:
            fd, old_fd, old_handler = self._saved
            signal.signal(signal.SIGINT, old_handler)
            signal.set_wakeup_fd(old_fd)
            self._hit = self.requested
            self.flag = np.zeros(0, dtype=np.uint8)
            self._mm.close()
            os.close(fd)
            if self._file is not None:
                self._file.close()
            self._saved = self._mm = self._file = None
        return False
