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

import abc

import numpy as np

from bgc.errors import SimulationError
from bgc.solvers.base import Segment, Solver
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


def _import():
    try:
        from sksundae import cvode, ida
    except ImportError as exc:       # pragma: no cover - a dependency of bgc
        raise SimulationError(f"SUNDIALS is not available: {exc}",
                              hint="pip install scikit-sundae") from None
    return cvode, ida


def _options(problem) -> dict:
    """SUNDIALS' options of a run: tolerances, dense direct linear solver, step limits."""
    h_max = problem.max_step
    return dict(rtol=problem.rtol, atol=problem.atol, linsolver="dense",
                max_num_steps=MAX_STEPS, max_step=float(h_max) if np.isfinite(h_max) else 0.0)


class SundialsSolver(Solver):
    """A SUNDIALS integrator with the generated Jacobian: ``_solver`` makes it, ``_solve``
    runs it over the output times. Steps, LU factorizations and rejected steps the
    bindings do not report."""
    reports = ("rhs_calls", "jac_calls")

    @abc.abstractmethod
    def _solver(self, events):
        """The scikit-sundae solver object of this run, watching ``events``."""

    def _solve(self, solver, tspan, x0):
        return solver.solve(tspan, x0)

    def integrate(self, t0, t1, x0, t_eval, events=()):
        # Ctrl-C or a collapsed step size stops it at the end of a step (SUNDIALS calls
        # events between steps too, so they do not count its steps: the step budget is
        # its own MAX_STEPS; a thousand calls in a row each a tiny step apart are a
        # collapse all the same: a NaN rhs had CVODE and IDA take steps of 1e-18 s, with
        # t + h = t, for ever)
        stop = StopEvent(self.problem, self.counts, budget=False, span=t1 - t0)
        watched = [*events, stop]
        solver = self._solver(watched)
        # output times: the segment's start and end always, so the end state is exact
        tspan = np.unique(np.concatenate([[t0], np.asarray(t_eval, dtype=float), [t1]]))
        sol = self._solve(solver, tspan, np.array(x0, dtype=np.float64))
        self.counts.add(rhs_calls=sol.nfev, jac_calls=sol.njev)
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
        if event == len(events):        # the stop event: Ctrl-C or a collapse
            t_stop, x_stop = float(sol.t_events[-1]), x_end.reshape(-1)
            return Segment(x_eval, x_stop, t_stop, False, stop.why(t_stop, x_stop),
                           interrupted=stop.interrupted)
        if event is not None:
            return Segment(x_eval, x_end.reshape(-1), float(sol.t_events[-1]), False,
                           event=event)
        if not sol.success or t_ok < t1:
            return Segment(x_eval, x_end, t_ok, False, str(sol.message))
        return Segment(x_eval, x_end, t_ok, True)


class Cvode(SundialsSolver):
    """CVODE: variable-order BDF on dx/dt = f(t, x)."""
    name = "cvode"
    description = "SUNDIALS CVODE (scikit-sundae): variable-order BDF 1-5, stiff"

    def _solver(self, events):
        cvode, _ = _import()
        problem = self.problem
        # SUNDIALS hands read-only views of its vectors: numba would compile the model
        # again for read-only arrays, so the states are copied (0.2 us)

        def rhsfn(t, y, yp):
            yp[:] = problem.rhs(t, np.array(y))

        def jacfn(t, y, yp, JJ):
            JJ[:, :] = problem.jac(t, np.array(y))
        return cvode.CVODE(rhsfn, jacfn=jacfn, method="BDF", **_options(self.problem),
                           **_events(events, "cvode"))


class Ida(SundialsSolver):
    """IDA: BDF on the residual M dx/dt - f(t, x) = 0 (an index-1 DAE where M is
    singular)."""
    name = "ida"
    description = ("SUNDIALS IDA (scikit-sundae): BDF on the residual, mass matrices "
                   "(index-1 DAEs)")
    max_index = 1

    def _solver(self, events):
        _, ida = _import()
        problem, M = self.problem, self.problem.mass

        def resfn(t, y, yp, res):       # the states copied: see Cvode
            f = problem.rhs(t, np.array(y))
            res[:] = (yp if M is None else M @ yp) - f

        def jacfn(t, y, yp, res, cj, JJ):
            JJ[:, :] = (cj * np.eye(len(y)) if M is None else cj * M) - problem.jac(
                t, np.array(y))
        algebraic = None if M is None else np.flatnonzero(~M.any(axis=0))   # x' unused
        return ida.IDA(resfn, jacfn=jacfn, algebraic_idx=algebraic, **_options(self.problem),
                       **_events(events, "ida"))

    def _solve(self, solver, tspan, x0):
        """x' from M x' = f (least squares: an algebraic state's derivative enters no
        residual); x0 itself must be consistent."""
        f0 = self.problem.rhs(tspan[0], x0)
        self.counts.add(rhs_calls=1)
        M = self.problem.mass
        yp0 = f0 if M is None else np.linalg.lstsq(M, f0, rcond=None)[0]
        return solver.solve(tspan, x0, yp0)
