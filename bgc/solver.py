"""The integrator interface every solver implements (scipy's ``_ivp/base.py`` in spirit):
a ``Problem`` (a generated module at parameter values, with an optional mass matrix), one
``integrate`` call per smooth segment returning a ``Segment``, and ``Stats`` kept honestly:
what an integrator does not report is ``None``, never a made-up 0.
"""

from __future__ import annotations

import abc
import functools
from dataclasses import dataclass

import numpy as np

# A run stops where a guard margin (e.g. |cos b| of a body's Cardan angles) falls below this.
GUARD_TOLERANCE = 1e-3


@dataclass
class Stats:
    steps: int | None = 0
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
class Segment:
    """What a solver returns for one smooth segment [t0, t1]."""
    x_eval: np.ndarray            # states at the requested times reached
    x_end: np.ndarray             # state at the last time reached
    t_reached: float
    ok: bool
    message: str = ""
    event: int | None = None      # index of the event that stopped the segment


@dataclass
class Problem:
    """What a solver integrates: a generated module at parameter values ``p``,
    ``mass @ dx/dt = rhs(t, x, p)`` (no mass matrix: the identity)."""
    module: object
    p: np.ndarray
    step: float | None = None         # fixed-step methods: the step
    mass: np.ndarray | None = None
    check_stability: bool = True      # rk4: refuse a step beyond its stability limit
    # a DAE: 1.0 where a state is algebraic of index 2 (its error scaled by the step)
    index2: np.ndarray | None = None

    def rhs(self, t, x):
        return self.module.rhs(t, x, self.p)

    @functools.cached_property
    def lu_plan(self):
        """The sparse elimination plan of its Newton matrices (``sparse_lu.analyse``)."""
        from .sparse_lu import analyse
        return analyse(len(self.module.STATE_NAMES), self.module.JAC_I, self.module.JAC_J,
                       self.mass)

    def jac(self, t, x):
        return self.module.jac(t, x, self.p)


class Solver(abc.ABC):
    """One integration method. ``integrate`` covers a segment with no discontinuity."""
    name = ""
    description = ""
    # the highest DAE index it integrates, M dx/dt = f with a singular M (0: ODEs only)
    max_index = 0

    @property
    def takes_mass(self) -> bool:
        return self.max_index > 0

    def check(self, problem: Problem, t0: float, x0: np.ndarray):
        """Refuse, before the run, what this method cannot integrate (SimulationError)."""

    def warm_up(self, problem: Problem, x0: np.ndarray):
        """Compile (or load from a cache) what the method runs, so wall time is the run's."""

    @abc.abstractmethod
    def integrate(self, problem: Problem, t0, t1, x0, t_eval, rtol, atol, stats: Stats,
                  events=(), max_step=np.inf) -> Segment:
        """Integrate from t0 to t1, recording the states at ``t_eval``; stop early where
        one of ``events`` (functions of (t, x), ``terminal`` and ``direction`` as in
        scipy) falls through zero; no step longer than ``max_step``."""
