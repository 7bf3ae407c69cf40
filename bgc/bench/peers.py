"""Peers in the same run: every integrator on the same generated module (its rhs and
analytic Jacobian), the same parameters and tolerance; median wall time of several
repeats, and the ratio to native Radau measured in this run (the machines are noisy, so
only ratios are compared across runs)."""

from __future__ import annotations

import numpy as np

from bgc.bench.cases import Bench, Scenario
from bgc.errors import SimulationError

PEERS = ("native", "bdf", "radau", "lsoda", "cvode", "ida")


def _row(bench: Bench, scn: Scenario, method: str, integrator: str, rtol: float,
         repeats: int, ref) -> dict:
    """Median and spread of the wall time over ``repeats`` runs, statistics of the last,
    error against ``ref``."""
    walls, result, status = [], None, "ok"
    for _ in range(repeats):
        try:
            result = bench.run(scn, method, integrator, rtol)
        except SimulationError as exc:
            status = f"failed: {exc}"
            break
        walls.append(result.stats.wall_time)
    st = result.stats if result is not None else None
    row = {"scenario": scn.name, "method": method, "integrator": integrator,
           "rtol": rtol, "atol": rtol, "repeats": len(walls),
           "wall_median": float(np.median(walls)) if walls else np.nan,
           "wall_min": min(walls, default=np.nan), "wall_max": max(walls, default=np.nan),
           "error": bench.error(scn, result, ref) if status == "ok" else np.nan,
           "steps": st.steps if st else None,
           "rhs_calls": st.rhs_calls if st else None,
           "jac_calls": st.jac_calls if st else None,
           "lu": st.lu_decompositions if st else None,
           "rejected": st.rejected_steps if st else None, "status": status}
    bench.log(f"    {scn.name} {method} {integrator:6s} rtol {rtol:g}: median "
              f"{row['wall_median']:.3g} s over {len(walls)}, error {row['error']:.3g} "
              f"({status[:60]})")
    return row


def peers(bench: Bench, scn: Scenario, method: str, rtol: float, repeats: int = 3,
          integrators=PEERS) -> list[dict]:
    """One row per integrator: median and spread of the wall time, statistics of the
    last repeat, error against the same model at rtol = atol = 1e-10 (numerical error
    only), and time relative to native."""
    ref, _ = bench.reference(scn, method)
    rows = [_row(bench, scn, method, i, rtol, repeats, ref) for i in integrators]
    native = next((r["wall_median"] for r in rows if r["integrator"] == "native"), np.nan)
    for r in rows:
        r["time_vs_native"] = r["wall_median"] / native
    return rows


def at_equal_error(bench: Bench, scn: Scenario, method: str, error: float, rtols,
                   repeats: int = 3, integrator: str = "native") -> dict | None:
    """The run of ``integrator`` at the loosest of ``rtols`` (atol = rtol) whose error is
    no larger than ``error`` (another integrator's at its tolerance): speed compared at
    equal accuracy, not at equal tolerance. None if none of them reaches it."""
    ref, _ = bench.reference(scn, method)
    for rtol in sorted(rtols, reverse=True):
        row = _row(bench, scn, method, integrator, rtol, repeats, ref)
        if row["status"] == "ok" and row["error"] <= error:
            return row
    return None
