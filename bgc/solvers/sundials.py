"""SUNDIALS' CVODE and IDA as bgc solvers, through scikit-sundae (maintained Cython
bindings to SUNDIALS 7): the peers of the native Radau in the benchmarks, on the same
generated code and analytic Jacobian (dense direct linear solver).

- ``cvode``: variable-order (1-5) variable-step BDF for ``dx/dt = f(t, x)``, the
  integrator family of DASSL that the paper's 20-sim BDF is built on.
- ``ida``: the same BDF on the residual ``M dx/dt - f(t, x) = 0``, so it also takes a
  mass matrix (an index-1 DAE when M is singular).

Statistics: the bindings report rhs (residual) and Jacobian evaluations; steps, LU
factorizations and rejected steps they do not, so those stay ``None``.
"""

from __future__ import annotations

import numpy as np

from bgc.errors import SimulationError
from bgc.solvers.base import Segment, Solver, Stats
from bgc.solvers.scipy_ivp import StopEvent

MAX_STEPS = 10 ** 8         # per output interval: the run's own budget, not SUNDIALS' 500


def _events(events, kind):
    """scikit-sundae's events function (filled in place) from scipy-style events; its
    signature is checked: (t, y, out) for CVODE, (t, y, yp, out) for IDA."""
    if not events:
        return {}

    def fill(t, y, out):
        x = np.array(y)
        for k, e in enumerate(events):
            out[k] = e(t, x)

    if kind == "cvode":
        def fn(t, y, out):
            fill(t, y, out)
    else:
        def fn(t, y, yp, out):
            fill(t, y, out)
    fn.terminal = [bool(getattr(e, "terminal", True)) for e in events]
    fn.direction = [int(getattr(e, "direction", 0)) for e in events]
    return {"eventsfn": fn, "num_events": len(events)}


class SundialsSolver(Solver):
    """CVODE (``kind = "cvode"``) or IDA (``"ida"``) with the generated Jacobian."""

    def __init__(self, name: str, kind: str, description: str):
        self.name, self.kind, self.description = name, kind, description
        self.max_index = 1 if kind == "ida" else 0

    @staticmethod
    def _import():
        try:
            from sksundae import cvode, ida
        except ImportError as exc:       # pragma: no cover - a dependency of bgc
            raise SimulationError(f"SUNDIALS is not available: {exc}",
                                  hint="pip install scikit-sundae") from None
        return cvode, ida

    def new_stats(self):
        """Steps, LU factorizations and rejected steps the bindings do not report."""
        return Stats(steps=None, lu_decompositions=None, rejected_steps=None)

    def _solver(self, problem, events):
        cvode, ida = self._import()
        m, p = problem.module, problem.p
        # SUNDIALS hands read-only views of its vectors: numba would compile the model
        # again for read-only arrays, so the states are copied (0.2 us)
        h_max = problem.max_step
        opts = dict(rtol=problem.rtol, atol=problem.atol, linsolver="dense",
                    max_num_steps=MAX_STEPS,
                    max_step=float(h_max) if np.isfinite(h_max) else 0.0)
        if self.kind == "cvode":
            def rhsfn(t, y, yp):
                yp[:] = m.rhs(t, np.array(y), p)

            def jacfn(t, y, yp, JJ):
                JJ[:, :] = m.jac(t, np.array(y), p)
            return cvode.CVODE(rhsfn, jacfn=jacfn, method="BDF", **opts,
                               **_events(events, self.kind))
        M = problem.mass

        def resfn(t, y, yp, res):
            f = m.rhs(t, np.array(y), p)
            res[:] = (yp if M is None else M @ yp) - f

        def jacfn(t, y, yp, res, cj, JJ):
            JJ[:, :] = (cj * np.eye(len(y)) if M is None else cj * M) - m.jac(t, np.array(y), p)
        algebraic = None if M is None else np.flatnonzero(~M.any(axis=0))   # x' unused
        return ida.IDA(resfn, jacfn=jacfn, algebraic_idx=algebraic, **opts,
                       **_events(events, self.kind))

    def integrate(self, problem, t0, t1, x0, t_eval, stats, events=()):
        # Ctrl-C stops it at the end of a step (SUNDIALS calls events between steps too,
        # so they do not count its steps: the step budget is its own MAX_STEPS)
        stop = StopEvent(problem, stats, budget=False)
        watched = [*events, stop]
        solver = self._solver(problem, watched)
        # output times: the segment's start and end always, so the end state is exact
        tspan = np.unique(np.concatenate([[t0], np.asarray(t_eval, dtype=float), [t1]]))
        x0 = np.array(x0, dtype=np.float64)
        if self.kind == "cvode":
            sol = solver.solve(tspan, x0)
        else:
            # x' from M x' = f (least squares: an algebraic state's derivative enters no
            # residual); x0 itself must be consistent
            f0 = problem.rhs(t0, x0)
            stats.rhs_calls += 1
            M = problem.mass
            yp0 = f0 if M is None else np.linalg.lstsq(M, f0, rcond=None)[0]
            sol = solver.solve(tspan, x0, yp0)
        stats.rhs_calls += int(sol.nfev)
        stats.jac_calls += int(sol.njev)
        t, y = np.asarray(sol.t, dtype=float), np.asarray(sol.y, dtype=float)
        if y.ndim == 1:
            y = y.reshape(len(t), -1)
        event = None
        if sol.i_events is not None and len(sol.i_events):
            fired = np.flatnonzero(np.asarray(sol.i_events)[-1])
            if len(fired) and getattr(watched[int(fired[0])], "terminal", True):
                event = int(fired[0])
        t_ok = float(t[-1]) if len(t) else t0
        if event is not None:           # the event point is appended to the outputs
            t, y = t[:-1], y[:-1]
        keep = np.isin(t, t_eval)
        x_eval = y[keep]
        x_end = np.asarray(sol.y_events[-1] if event is not None else y[-1], dtype=float)
        if event == len(events):        # the stop event: Ctrl-C
            return Segment(x_eval, x_end.reshape(-1), float(sol.t_events[-1]), False,
                           "interrupted", interrupted=True)
        if event is not None:
            return Segment(x_eval, x_end.reshape(-1), float(sol.t_events[-1]), False,
                           event=event)
        if not sol.success or t_ok < t1:
            return Segment(x_eval, x_end, t_ok, False, str(sol.message))
        return Segment(x_eval, x_end, t_ok, True)
