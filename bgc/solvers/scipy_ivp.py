"""scipy's ``solve_ivp`` methods as bgc solvers (BDF, Radau, LSODA, RK45), with the
generated analytic Jacobian, and ``StopEvent``: the terminal event by which a
Python-driven integrator (scipy, SUNDIALS) stops for Ctrl-C, the step budget or a
collapsed step size. scipy.integrate (0.3 s to import) is imported only when a run
takes one of these solvers.

Statistics: solve_ivp reports rhs and Jacobian evaluations and LU factorizations; its
accepted steps are its time points (no ``t_eval`` is passed to it); rejected steps it
does not report (``None``)."""

from __future__ import annotations

import numpy as np

from bgc.solvers.base import (
    Segment,
    Solver,
    budget_message,
    collapse_message,
    fastest,
)


class ScipySolver(Solver):
    """scipy.integrate.solve_ivp's ``method`` with the generated analytic Jacobian (an
    ``implicit`` method takes it, and factors Newton matrices). Rejected steps solve_ivp
    does not report."""
    method = ""
    implicit = True
    reports = ("steps", "rhs_calls", "jac_calls", "lu_decompositions")

    def warm_up(self, x0):
        """Import scipy.integrate (0.3 s, which only these solvers need: imported here, not
        with bgc), so wall time is the run's."""
        import scipy.integrate  # noqa: F401

    def integrate(self, t0, t1, x0, t_eval, events=()):
        problem = self.problem
        stop = StopEvent(problem, self.counts, span=t1 - t0)
        try:
            sol = self._solve_ivp(t0, t1, x0, [*events, stop])
        except (ValueError, np.linalg.LinAlgError) as exc:
            # scipy's LU refuses a Newton matrix with NaN in it ("array must not contain
            # infs or NaNs"): the state left the model's domain after the last step
            t_ok, x_ok = stop.last if stop.last[0] is not None else (t0, x0)
            return Segment(self._replay(t0, t_ok, x0, t_eval), np.array(x_ok), t_ok, False,
                           f"{self.name} stopped after t = {t_ok:.6g} ({exc})"
                           + fastest(problem, t_ok, x_ok))
        self.counts.add(steps=max(len(sol.t) - 1, 0), rhs_calls=sol.nfev,
                        jac_calls=sol.njev, lu_decompositions=sol.nlu)
        t_ok = float(sol.t[-1]) if len(sol.t) else t0
        x_end = sol.y[:, -1] if sol.y.size else np.asarray(x0)
        if sol.status < 0 or sol.sol is None:
            reached = t_eval[t_eval <= t_ok] if sol.sol is not None else t_eval[:0]
            why = sol.message
            if "step size is less than spacing" in why:
                why = collapse_message(problem, t_ok, x_end, np.spacing(t_ok))
            return Segment(_dense(sol, reached, len(x0)), x_end, t_ok, False, why)
        if sol.status == 1:       # a guard fired: keep what lies before it
            k = next(i for i, te in enumerate(sol.t_events) if len(te))
            x_eval = _dense(sol, t_eval[t_eval <= t_ok], len(x0))
            if k == len(events):  # the stop event: Ctrl-C or the step budget
                return Segment(x_eval, x_end, t_ok, False, stop.why(t_ok, x_end),
                               interrupted=stop.interrupted)
            return Segment(x_eval, x_end, t_ok, False, "", event=k)
        return Segment(_dense(sol, t_eval, len(x0)), x_end, t_ok, True)

    def _solve_ivp(self, t0, t1, x0, events):
        from scipy.integrate import solve_ivp
        problem = self.problem
        kw = {"jac": problem.jac} if self.implicit else {}
        return solve_ivp(problem.rhs, (t0, t1), x0, method=self.method, rtol=problem.rtol,
                         atol=problem.atol, dense_output=True, events=events,
                         max_step=problem.max_step, **kw)

    def _replay(self, t0, t_ok, x0, t_eval) -> np.ndarray:
        """The outputs up to ``t_ok`` of a segment whose solve_ivp raised after it (its
        dense output went with the exception): the same integration again, ending there,
        takes the same steps; its work is counted as the run's up to there."""
        if not t_ok > t0:
            return np.empty((0, len(x0)))
        refused = self.problem.non_finite        # where the run itself failed
        try:
            sol = self._solve_ivp(t0, t_ok, x0, [])
        except (ValueError, np.linalg.LinAlgError):
            return np.empty((0, len(x0)))
        finally:
            self.problem.non_finite = refused
        self.counts.add(steps=max(len(sol.t) - 1, 0), rhs_calls=sol.nfev,
                        jac_calls=sol.njev, lu_decompositions=sol.nlu)
        return _dense(sol, t_eval[t_eval <= t_ok], len(x0)) if sol.sol is not None \
            else np.empty((0, len(x0)))


class Bdf(ScipySolver):
    name, method = "bdf", "BDF"
    description = "scipy BDF (variable order 1-5), stiff"


class Radau(ScipySolver):
    name, method = "radau", "Radau"
    description = "scipy Radau IIA order 5, stiff"


class Lsoda(ScipySolver):
    name, method = "lsoda", "LSODA"
    description = "scipy LSODA (ODEPACK), switches stiff/non-stiff"


class Rk45(ScipySolver):
    """Explicit: no Jacobian, no LU factorizations (not reported)."""
    name, method, implicit = "rk45", "RK45", False
    description = "scipy Dormand-Prince 5(4), non-stiff"
    reports = ("steps", "rhs_calls", "jac_calls")


class StopEvent:
    """A terminal event that stops a Python-driven integrator (scipy, SUNDIALS) at the end
    of the step where Ctrl-C was pressed (``Problem.interrupt``), the run's step budget
    ran out, or the step size collapsed: ``COLLAPSE_STEPS`` accepted steps in a row each
    shorter than ``TINY_STEP`` of the segment (``span``; scipy's own test, a step below
    the spacing of t, never fires near t = 0, where BDF crawled through a million steps
    of 1e-145 s on a millimetre mechanism, nor for LSODA chattering in steps of 1e-13 s). +1 until then, t - t_stop after (a root exactly at the step's end
    t_stop). solve_ivp calls it once at the start and once per accepted step; it also
    keeps the last accepted point (``last``)."""

    terminal, direction = True, 0

    def __init__(self, problem, counts, budget: bool = True, span: float = 0.0):
        self.problem, self.t_stop, self.calls = problem, None, 0
        self.left = problem.budget(counts) if budget else None
        self.interrupted = False
        self.tiny, self.h, self.floor = 0, None, TINY_STEP * span
        self.last = (None, None)

    def __call__(self, t, x):
        if self.t_stop is None:
            self.calls += 1
            if self.last[0] is not None:
                self.h = abs(t - self.last[0])
                self.tiny = self.tiny + 1 if self.h < self.floor else 0
            self.last = (float(t), np.array(x))
            self.interrupted = self.problem.interrupt.requested
            if (self.interrupted or self.tiny >= COLLAPSE_STEPS
                    or (self.left is not None and self.calls - 1 >= self.left)):
                self.t_stop = t
            else:
                return 1.0
        return t - self.t_stop

    def why(self, t, x) -> str:
        if self.interrupted:
            return "interrupted"
        if self.tiny >= COLLAPSE_STEPS:
            return collapse_message(self.problem, t, x, self.h)
        return budget_message(self.problem, t, x)


# a collapsed step size: so many accepted steps in a row, each below this part of the
# segment's length. A run that advanced less than 1e-7 of its segment in a thousand steps
# would need more than 1e10 steps at that pace (a chattering switch, a state pressed
# against a singularity); no healthy start or event takes a thousand such steps in a row.
TINY_STEP, COLLAPSE_STEPS = 1e-10, 1000


def _dense(sol, ts, n: int) -> np.ndarray:
    """solve_ivp's dense output at the times ``ts`` (rows); none: an empty (0, n) array
    (scipy's OdeSolution fails on an empty array: a segment between two of a run's
    breakpoints may hold no output point)."""
    if not len(ts):
        return np.empty((0, n))
    return sol.sol(ts).T.reshape(len(ts), n)
