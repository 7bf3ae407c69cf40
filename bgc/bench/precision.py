"""Work-precision diagrams: wall time against error, one series per constraint method x
integrator over tolerances 1e-3 .. 1e-9 (RK4: over step sizes), and for the parasitic
method the stiffness sweep that separates numerical from modelling error.

Every error is measured against the scenario's reference (``Bench.reference``): the
ideal-constraint (``lagrange``) model at rtol = atol = 1e-10, or published values, so a
parasitic series levels off at its modelling error however tight its tolerance.
"""

from __future__ import annotations

import time

import numpy as np

from bgc.bench.cases import Bench, Scenario
from bgc.errors import SimulationError
from bgc.solvers.rk4 import stable_step

TOLERANCES = (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8, 1e-9)
INTEGRATORS = ("native", "bdf", "lsoda", "cvode", "ida", "rk4")
# rk4's series: steps as fractions of its stability limit at the start
RK4_FRACTIONS = (0.9, 0.45, 0.22, 0.11)
# parasitic stiffness sweep: factors on the model's stiffness (damping by their root,
# which keeps each parasitic mode's damping ratio)
STIFFNESS_FACTORS = (0.01, 0.1, 1.0, 10.0, 100.0)


def row(scn: Scenario, method: str, integrator: str, setting: float, error: float,
        result=None, status: str = "ok", wall: float | None = None, **extra) -> dict:
    """One CSV row: a run's settings, error and statistics."""
    st = result.stats if result is not None else None
    out = {"scenario": scn.name, "method": method, "integrator": integrator,
           "setting": setting, "error": error,
           "wall_time": st.wall_time if st else wall, "steps": st.steps if st else None,
           "rhs_calls": st.rhs_calls if st else None,
           "jac_calls": st.jac_calls if st else None,
           "lu": st.lu_decompositions if st else None, "status": status}
    out.update(extra)
    return out


def work_precision_series(bench: Bench, scn: Scenario, method: str, integrator: str,
                          settings, budget, ref, overrides=None, **extra) -> list[dict]:
    """Runs over ``settings`` (tolerances, or rk4 steps) from loose to tight; the rest
    of a series is skipped once a run takes longer than ``budget`` seconds."""
    rows = []
    over = False
    for s in settings:
        if over:
            rows.append(row(scn, method, integrator, s, np.nan, status="skipped: the "
                            f"previous run took over {budget:g} s", **extra))
            continue
        kw = {"step": s} if integrator == "rk4" else {}
        t0 = time.perf_counter()
        try:
            r = bench.run(scn, method, integrator, 1e-6 if integrator == "rk4" else s,
                          overrides=overrides, **kw)
            err = bench.error(scn, r, ref)
            rows.append(row(scn, method, integrator, s, err, r, **extra))
            wall = r.stats.wall_time
        except SimulationError as exc:
            wall = time.perf_counter() - t0
            rows.append(row(scn, method, integrator, s, np.nan, status=f"failed: {exc}",
                            wall=wall, **extra))
        bench.log(f"    {scn.name} {method:9s} {integrator:6s} {s:8.2g}: "
                  f"error {rows[-1]['error']:.3g}, {wall:.3g} s ({rows[-1]['status'][:60]})")
        over = wall > budget
    return rows


def rk4_steps(bench: Bench, scn: Scenario, method: str, fractions=RK4_FRACTIONS,
              overrides=None) -> list[float]:
    """rk4's steps: fractions of its stability limit at the scenario's start."""
    mod, x, p = bench.initial(scn, method, overrides)
    h_max = stable_step(np.linalg.eigvals(mod.jac(scn.t_start, x, p)))[0]
    return [f * h_max for f in fractions]


def work_precision(bench: Bench, scn: Scenario, methods, integrators=INTEGRATORS,
                   tolerances=TOLERANCES, budget: float = 60.0,
                   rk4_fractions=RK4_FRACTIONS) -> list[dict]:
    """Every method x integrator series of a scenario."""
    ref, _ = bench.reference(scn)
    rows = []
    for method in methods:
        for integrator in integrators:
            settings = (rk4_steps(bench, scn, method, rk4_fractions) if integrator == "rk4"
                        else tolerances)
            rows += work_precision_series(bench, scn, method, integrator, settings, budget, ref)
    return rows


def stiffness_overrides(mod, factor: float) -> dict:
    """Every joint's parasitic stiffness times ``factor``, its damping times the root."""
    out = {}
    for name, value in zip(mod.PARAM_NAMES, mod.PARAMS):
        if name.endswith(("__stiffness", "__rot_stiffness")):
            out[name] = value * factor
        elif name.endswith(("__damping", "__rot_damping")):
            out[name] = value * factor ** 0.5
    return out


def stiffness_sweep(bench: Bench, scn: Scenario, factors=STIFFNESS_FACTORS,
                    tolerances=TOLERANCES[1:], budget: float = 60.0) -> list[dict]:
    """Native Radau on the parasitic model at each stiffness: error against the
    ideal-constraint reference vs time. Each series falls with the tolerance until it
    meets its modelling error, which falls as 1/stiffness."""
    ref, _ = bench.reference(scn)
    mod = bench.module(scn, "parasitic")
    rows = []
    nominal = max(v for n, v in zip(mod.PARAM_NAMES, mod.PARAMS) if n.endswith("__stiffness"))
    for f in factors:
        rows += work_precision_series(bench, scn, "parasitic", "native", tolerances, budget, ref,
                        overrides=stiffness_overrides(mod, f), stiffness=nominal * f)
    return rows


def time_to_error(rows, method: str, level: float, integrator: str | None = None):
    """The least wall time over a method's runs (one integrator's, or any) whose error is
    at most ``level``; None if none reaches it."""
    times = [r["wall_time"] for r in rows if r["method"] == method and r["status"] == "ok"
             and (integrator is None or r["integrator"] == integrator)
             and r["error"] <= level]
    return min(times) if times else None
