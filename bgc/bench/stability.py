"""Stability maps: where each way of handling the constraints fails, measured, and what
bgc says there. Each map runs the failing case with bgc's own check switched off (to see
what a tool without it would produce) and again with it on (to record bgc's message).

- ``rk4_map``: explicit RK4 on the parasitic model against the parasitic stiffness and
  the step, against the limit predicted from the linearization (every h lambda inside
  |R(z)| <= 1, and the cruder h |lambda_max| <= 2.78);
- ``drift_map``: method lagrange without (or with weak) Baumgarte stabilisation: the
  constraint drift against time, and the drift at the end over (alpha, tolerance);
- ``redundancy_map``: redundant constraints with and without redundancy handling;
- ``zcp_map``: method zcp with a kinematic loop kept closed (an index-2 DAE) under
  integrators that do and do not take index 2.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from bgc.bench.cases import Bench, Scenario
from bgc.bench.precision import stiffness_overrides
from bgc.errors import SimulationError
from bgc.solvers import consistent
from bgc.solvers.rk4 import stable_step

RK4_STEP_FRACTIONS = (0.5, 0.8, 0.95, 1.05, 1.25, 2.0)
ALPHAS = (0.0, 0.3, 1.0, 3.0, 10.0, 100.0)
DRIFT_TOLERANCES = (1e-4, 1e-6, 1e-8)


def _verdict(fn) -> tuple[str, object]:
    """('ran', result) or ('refused'/'failed', message) of a bgc run."""
    try:
        return "ran", fn()
    except SimulationError as exc:
        return ("failed" if exc.result is not None and len(exc.result.t) > 1
                else "refused"), str(exc)


def rk4_map(bench: Bench, scn: Scenario, factors, fractions=RK4_STEP_FRACTIONS,
            window: float = 0.1) -> list[dict]:
    """For each stiffness factor: the Jacobian's spectrum at the start, the predicted
    limits, and RK4 runs at fractions of the predicted limit over ``window`` seconds,
    each classified stable (its outputs within 100 % of native Radau's at rtol 1e-8) or
    not, with bgc's check off; and bgc's verdict with it on. Every state starts 1e-12
    (relative) off the start, the same for all runs: a mode that is exactly zero (an
    out-of-plane rotation of a planar motion) would otherwise never show its
    instability, which any real start seeds."""
    scn = replace(scn, t_end=scn.t_start + window, points=101)
    mod = bench.module(scn, "parasitic")
    rows = []
    for f in factors:
        over = stiffness_overrides(mod, f)
        _, x0, p = bench.initial(scn, "parasitic", over)
        x0 = x0 + 1e-12 * (1.0 + np.abs(x0)) * np.random.default_rng(0).standard_normal(
            len(x0))
        eig = np.linalg.eigvals(mod.jac(scn.t_start, x0, p))
        h_pred, lam = stable_step(eig)
        lam_max = float(np.abs(eig).max())
        ref = bench.run(scn, "parasitic", "native", 1e-8, overrides=over, x0=x0)
        stiffness = max(v for k, v in over.items() if k.endswith("__stiffness"))
        for frac in fractions:
            h = frac * h_pred
            status, res = _verdict(lambda: bench.run(scn, "parasitic", "rk4", 1e-6,
                                                     overrides=over, x0=x0, step=h,
                                                     check_stability=False))
            err = bench.error(scn, res, ref.y) if status == "ran" else np.inf
            stable = bool(np.isfinite(err) and err < 1.0)
            bgc, msg = _verdict(lambda: bench.run(scn, "parasitic", "rk4", 1e-6,
                                                  overrides=over, x0=x0, step=h))
            rows.append({"stiffness": stiffness, "step": h, "fraction": frac,
                         "h_predicted": h_pred, "h_278": 2.78 / lam_max,
                         "lambda_max": lam_max, "lambda_limiting": str(lam),
                         "stable": stable, "error": err, "unchecked": status,
                         "bgc": bgc, "bgc_message": msg if isinstance(msg, str) else ""})
            bench.log(f"    rk4 k = {stiffness:.3g}, h = {frac:.2f} x {h_pred:.3g} s: "
                      f"{'stable' if stable else 'UNSTABLE'} (error {err:.3g}); bgc {bgc}")
    return rows


def drift_history(bench: Bench, scn: Scenario, method: str, alphas=ALPHAS,
                  rtol: float = 1e-6) -> list[dict]:
    """The position drift |g| against time for each Baumgarte rate, bgc's drift check
    off; the time bgc's check stops the run."""
    mod = bench.module(scn, method)
    alpha = f"{method}__alpha"
    rows = []
    for a in alphas:
        r = bench.run(scn, method, "native", rtol, atol=rtol * 1e-2,
                      overrides={alpha: a}, check_drift=False)
        g_t, _ = consistent.drift_history(mod, r.x, r.params)
        limit = consistent.drift_limit(mod, r.x[0], rtol, rtol * 1e-2)
        bgc, msg = _verdict(lambda: bench.run(scn, method, "native", rtol, atol=rtol * 1e-2,
                                              overrides={alpha: a}))
        stop = (float(msg.split("at t = ")[1].split()[0])
                if bgc == "failed" and "drift" in msg else np.nan)
        rows += [{"alpha": a, "rtol": rtol, "t": t, "drift": g, "limit": limit,
                  "bgc_stop": stop} for t, g in zip(r.t, g_t)]
        bench.log(f"    drift alpha = {a:g}: |g| at the end {g_t[-1]:.3g} (limit "
                  f"{limit:.3g}); bgc {bgc}" + (f" at t = {stop:g}" if stop == stop else ""))
    return rows


def drift_map(bench: Bench, scn: Scenario, method: str, alphas=ALPHAS,
              tolerances=DRIFT_TOLERANCES) -> list[dict]:
    """Largest drift over the run against (alpha, rtol), bgc's check off, and bgc's
    verdict with it on."""
    mod = bench.module(scn, method)
    alpha = f"{method}__alpha"
    rows = []
    for a in alphas:
        for tol in tolerances:
            r = bench.run(scn, method, "native", tol, atol=tol * 1e-2,
                          overrides={alpha: a}, check_drift=False)
            g = float(consistent.drift_history(mod, r.x, r.params)[0].max())
            limit = consistent.drift_limit(mod, r.x[0], tol, tol * 1e-2)
            bgc, _ = _verdict(lambda: bench.run(scn, method, "native", tol, atol=tol * 1e-2,
                                                overrides={alpha: a}))
            rows.append({"alpha": a, "rtol": tol, "drift": g, "limit": limit,
                         "steps": r.stats.steps, "wall_time": r.stats.wall_time,
                         "bgc": bgc})
            bench.log(f"    drift map alpha = {a:g}, rtol = {tol:g}: max |g| {g:.3g} "
                      f"(limit {limit:.3g}); bgc {bgc}")
    return rows


def redundancy_map(bench: Bench, scn: Scenario, tolerances=DRIFT_TOLERANCES) -> list[dict]:
    """A mechanism with redundant constraints under lagrange: with redundancy handling
    (the rank found at the start, least squares) and without (the block solved as if
    regular, as a tool without the handling does): its error against the parasitic
    model, and bgc's verdict. Without the handling the block's LU meets a zero pivot:
    the right-hand side is NaN from t = 0."""
    ref = bench.run(scn, "parasitic", "native", 1e-9)
    mod = bench.module(scn, "lagrange")
    rows = []
    for tol in tolerances:
        for handled in (True, False):
            status, res = _verdict(lambda: bench.run(scn, "lagrange", "native", tol,
                                                     atol=tol * 1e-2, redundancy=handled))
            err = bench.error(scn, res, ref.y) if status == "ran" else np.nan
            row = {"rtol": tol, "redundancy_handling": handled, "bgc": status,
                   "error_vs_parasitic": err,
                   "message": res if isinstance(res, str) else ""}
            if not handled:
                # what the run would meet: the right-hand side at the consistent start
                _, x, p = bench.initial(scn, "lagrange")
                proj = consistent.project(mod, x, p)[1]
                p[list(mod.PARAM_NAMES).index(consistent.RANK_PARAM)] = proj.n_constraints
                row["rhs_finite_unchecked"] = bool(np.isfinite(mod.rhs(0.0, x, p)).all())
                row["rank"], row["constraints"] = proj.rank, proj.n_constraints
            rows.append(row)
            bench.log(f"    redundancy {'on ' if handled else 'off'} rtol = {tol:g}: "
                      f"{status}, error vs parasitic {err:.3g}")
    return rows


def zcp_map(bench: Bench, scn: Scenario, tolerances=(1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8)
            ) -> list[dict]:
    """Method zcp with the kinematic loops kept closed (an index-2 DAE) under native
    Radau with its index-2 error scaling, native Radau without it and IDA (BDF, built for
    index 1), bgc's index check off; error against zcp with the loops opened (rtol
    1e-10); how far each run got; and bgc's verdict with the check on."""
    ref = bench.run(scn, "zcp", "native", 1e-10, atol=1e-12)
    rows = []
    for tol in tolerances:
        for integrator, scaled in (("native", True), ("native", False), ("ida", False)):
            status, res = _verdict(lambda: bench.run(scn, "zcp_closed", integrator, tol,
                                                     atol=tol * 1e-2, check_index=scaled))
            reached = (scn.t_end if status == "ran" else
                       float(res.split("at t = ")[1].split(":")[0])
                       if status == "failed" and "at t = " in res else scn.t_start)
            label = f"{integrator}" + (", index-2 scaling" if scaled else
                                       ", as index 1" if integrator == "native" else "")
            bgc = "ran" if scaled else _verdict(lambda: bench.run(
                scn, "zcp_closed", integrator, tol, atol=tol * 1e-2))[0]
            rows.append({"rtol": tol, "integrator": label, "status": status,
                         "reached": reached, "fraction": (reached - scn.t_start)
                         / (scn.t_end - scn.t_start),
                         "error": bench.error(scn, res, ref.y) if status == "ran" else np.nan,
                         "steps": res.stats.steps if status == "ran" else None,
                         "rejected": res.stats.rejected_steps if status == "ran" else None,
                         "bgc": bgc, "message": res if isinstance(res, str) else ""})
            bench.log(f"    zcp closed, {label}, rtol = {tol:g}: {status} to t = "
                      f"{reached:g}, error {rows[-1]['error']:.3g}; bgc {bgc}")
    return rows


def report(run) -> None:
    """The stability part of ``bgc bench`` (``run``: its ``bench.Run``): the maps, their CSV
    and charts, and their section of the summary."""
    from bgc.bench import charts, precision
    from bgc.bench.cases import BRICARD, FOUR_BAR, SLIDER, sarib
    from bgc.bench.rows import write_rows
    run.summary.append("## Stability maps: where each method fails\n")
    # RK4 on the parasitic model
    if run.quick:
        scn, factors, fracs = SLIDER, (0.1, 1.0, 10.0), (0.8, 1.25, 2.0)
    else:
        scn, factors, fracs = (sarib("sarib_sine"), precision.STIFFNESS_FACTORS,
                               RK4_STEP_FRACTIONS)
    run.log(f"stability: rk4 on {scn.title}")
    rk = rk4_map(run.bench, scn, factors, fracs)
    write_rows(run.out / "stability_rk4.csv", rk)
    charts.rk4_map(rk, run.out / "stability_rk4.png", f"RK4 on the parasitic "
                                                       f"model: {scn.title}")
    wrong = [r for r in rk if r["stable"] != (r["fraction"] <= 1.0)]
    silent = [r for r in rk if not r["stable"] and r["bgc"] == "ran"]
    run.summary.append(
        f"**RK4, parasitic** (`stability_rk4.png`): {len(rk)} runs over "
        f"{len(factors)} stiffnesses; the predicted limit (every h lambda in |R| <= 1) "
        f"classified {len(rk) - len(wrong)} of {len(rk)} runs right; bgc refused "
        f"{sum(r['bgc'] == 'refused' for r in rk)} and let no unstable run through "
        f"({len(silent)} silent).\n")
    # lagrange without stabilisation
    t_drift = 5.0 if run.quick else 10.0
    dscn = replace(SLIDER, t_end=t_drift, points=201,
                   title=f"slider-crank falling from rest, {t_drift:g} s")
    run.log(f"stability: drift on {dscn.title}")
    alphas = (0.0, 1.0, 10.0) if run.quick else ALPHAS
    hist = drift_history(run.bench, dscn, "lagrange", alphas)
    grid = drift_map(run.bench, dscn, "lagrange", alphas,
                               (1e-4, 1e-7) if run.quick else DRIFT_TOLERANCES)
    write_rows(run.out / "stability_drift_history.csv", hist)
    write_rows(run.out / "stability_drift.csv", grid)
    charts.drift(hist, grid, run.out / "stability_drift.png",
                 f"lagrange without stabilisation: slider-crank, {dscn.t_end:g} s")
    run.summary.append(f"**lagrange, Baumgarte rate alpha** (`stability_drift.png`), "
                        f"slider-crank over {dscn.t_end:g} s:\n")
    run.table(grid, ["alpha", "rtol", "drift", "limit", "bgc"])
    # redundant constraints
    rscn = replace(BRICARD, t_end=0.5) if run.quick else BRICARD
    run.log(f"stability: redundancy on {rscn.title}")
    red = redundancy_map(run.bench, rscn, (1e-6,) if run.quick else
                                   DRIFT_TOLERANCES)
    write_rows(run.out / "stability_redundancy.csv", red)
    run.summary.append("**Redundant constraints** (Bricard, 1 redundant of 30):\n")
    run.table(red, ["rtol", "redundancy_handling", "bgc", "error_vs_parasitic",
                     "rhs_finite_unchecked", "message"],
               {"message": lambda v: v[:110]})
    # zcp, a kinematic loop kept closed
    zscn = replace(FOUR_BAR, t_end=0.5) if run.quick else FOUR_BAR
    run.log(f"stability: zcp with the loop kept closed, {zscn.title}")
    zc = zcp_map(run.bench, zscn, (1e-4, 1e-7) if run.quick else
                           (1e-3, 1e-4, 1e-5, 1e-6, 1e-7, 1e-8))
    write_rows(run.out / "stability_zcp.csv", zc)
    charts.zcp_map(zc, run.out / "stability_zcp.png",
                   f"zcp, loop kept closed (index-2 DAE): {zscn.title}")
    run.summary.append("**zcp with the kinematic loop kept closed** (`stability_zcp.png`,"
                        " an index-2 DAE; error against the opened loops):\n")
    run.table(zc, ["rtol", "integrator", "status", "reached", "error", "steps", "bgc",
                    "message"], {"message": lambda v: v[:90]})
    run.data["stability"] = {"rk4": rk, "drift": grid, "redundancy": red, "zcp": zc}
