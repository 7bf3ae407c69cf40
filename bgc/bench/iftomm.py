"""Part ``iftomm``: the IFToMM basic benchmark problems (González, Dopico, Lugrís &
Cuadrado, Multibody System Dynamics 16, 2006) under every constraint method, error
against time (work-precision), each against its exact or published reference:

- A01 simple pendulum (``simple_pendulum.yaml``): the exact 1-DOF solution, P1 (m);
- A02 N-four-bar (``n_four_bar.yaml``, N its constant; N = 2, 10 and, in the full run, 40): the
  exact reduced solution, B0 (m), the benchmark's limit 1e-3 m; the peer, Exudyn 1.13.6 at
  N = 40 (generalized-alpha, planar bodies): 9.9e-4 m in 7.1 s at its largest step within
  the limit (issue 39, measured on this machine's kind);
- A03 Andrews' mechanism (``andrews.yaml``): the IVP test set's angles at 0.03 s
  (relative);
- A04 Bricard's mechanism (``bricard.yaml``): P3 over 10 s against lagrange at 1e-10 (m);
- A05 flyball governor (``flyball_governor.yaml``): s over 10 s against lagrange at 1e-9
  (m).

A run that stops (lagrange and zcp at A02's first crossings) is a row with its status
and the time it reached; the summary's table says, per problem and method, the least
time to the benchmark's limit and the best error reached, from which the README's
advice (which method for which kind of mechanism) is drawn.
"""

from __future__ import annotations

import importlib.util
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bgc.errors import SimulationError
from bgc.pipeline import ensure_module
from bgc.simulate import simulate

MODELS = Path(__file__).resolve().parents[2] / "models"
METHODS = ("augmented", "lagrange", "zcp", "parasitic")
LIMIT = 1e-3            # IFToMM's high-precision limit (A02's, on B0, in m)
PEER = {"name": "Exudyn 1.13.6 (generalized-alpha, planar bodies)", "problem": "A02 N=40",
        "error": 9.9e-4, "time": 7.1}


def _a02():
    spec = importlib.util.spec_from_file_location("n_four_bar", MODELS / "n_four_bar.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@dataclass
class Problem:
    """One benchmark problem: its model file, run length, output points, and its
    reference as a function of a run (the error of that run, in ``unit``)."""
    name: str
    title: str
    model: Path
    t_end: float
    points: int
    unit: str
    constants: dict | None = None       # the model's compile-time constants (A02: N)


def _pendulum_error(r) -> float:
    from scipy.integrate import solve_ivp
    inertia = 4e-4                      # the model's ball (simple_pendulum.yaml)
    s = solve_ivp(lambda _, z: [z[1], -9.81 * np.sin(z[0]) / (1.0 + inertia)],
                  (0.0, float(r.t[-1])), [np.pi / 2, 0.0], method="DOP853", t_eval=r.t,
                  rtol=1e-13, atol=1e-13)
    return float(np.hypot(r.column("P1_x") + np.sin(s.y[0]),
                          r.column("P1_y") + np.cos(s.y[0])).max())


class IFToMM:
    """The part's runs: modules built once per problem and method (in ``build``),
    references made once."""

    def __init__(self, build: Path, log, quick: bool, budget: float):
        self.build, self.log, self.quick, self.budget = Path(build), log, quick, budget
        self.a02 = _a02()
        self._refs: dict = {}

    def problems(self) -> list[tuple[Problem, tuple, tuple]]:
        """(problem, methods, tolerances) of this run."""
        ns = (2,) if self.quick else (2, 10, 40)
        out = []
        for n in ns:
            tols = (1e-4, 1e-5, 1e-6) if n > 2 or self.quick else (1e-4, 1e-5, 1e-6, 1e-7)
            out.append((Problem(f"A02_N{n}", f"A02 N-four-bar, N = {n}, 20 s",
                                MODELS / "n_four_bar.yaml", 20.0, 801, "m", {"N": n}),
                        METHODS, tols))
        a01 = Problem("A01", "A01 simple pendulum, 10 s", MODELS / "simple_pendulum.yaml",
                      10.0, 501, "m")
        out.insert(0, (a01, METHODS, (1e-4, 1e-6) if self.quick else
                       (1e-4, 1e-5, 1e-6, 1e-7, 1e-8)))
        if not self.quick:
            out += [(Problem("A03", "A03 Andrews' mechanism, 0.03 s (IVP test set)",
                             MODELS / "andrews.yaml", 0.03, 31, "rel."), METHODS,
                     (1e-4, 1e-5, 1e-6, 1e-7, 1e-8)),
                    (Problem("A04", "A04 Bricard's mechanism, 10 s", MODELS / "bricard.yaml",
                             10.0, 501, "m"), METHODS, (1e-4, 1e-5, 1e-6, 1e-7)),
                    (Problem("A05", "A05 flyball governor, 10 s",
                             MODELS / "flyball_governor.yaml", 10.0, 501, "m"), METHODS,
                     (1e-4, 1e-5, 1e-6, 1e-7))]
        return out

    def module(self, prob: Problem, method: str):
        out = self.build / "modules" / prob.name      # one module per N (its constants)
        return ensure_module(prob.model, out, method, constants=prob.constants)[0]

    def error(self, prob: Problem, r) -> float:
        """The run's error against the problem's reference (over the run's times)."""
        if prob.name.startswith("A02"):
            n = int(prob.name.split("N")[1])
            x, y = self.a02.reference(n, r.t)
            return float(np.hypot(r.column("B0_x") - x, r.column("B0_y") - y).max())
        if prob.name == "A01":
            return _pendulum_error(r)
        if prob.name == "A03":
            from bgc.bench.cases import ANDREWS_REF
            return max(abs(r.column(k)[-1] - v) / abs(v) for k, v in ANDREWS_REF.items())
        ref = self.reference(prob)
        cols = ("P3_x", "P3_y", "P3_z") if prob.name == "A04" else ("s",)
        n = min(len(r.t), len(ref.t))
        return float(max(np.abs(r.column(c)[:n] - ref.column(c)[:n]).max() for c in cols))

    def reference(self, prob: Problem):
        """A04, A05: lagrange at 1e-10 (A05: 1e-9), native Radau."""
        if prob.name not in self._refs:
            tol = 1e-10 if prob.name == "A04" else 1e-9
            self.log(f"  [{prob.name}] reference: lagrange, rtol = {tol:g}")
            self._refs[prob.name] = simulate(self.module(prob, "lagrange"), t_end=prob.t_end,
                                             rtol=tol, atol=tol * 1e-2, points=prob.points)
        return self._refs[prob.name]

    def run(self, prob: Problem, method: str, rtol: float) -> dict:
        """One run: its error, wall time (integration), statistics, how it ended."""
        mod = self.module(prob, method)
        t0 = time.perf_counter()
        status, r = "ok", None
        try:
            r = simulate(mod, t_end=prob.t_end, rtol=rtol, atol=rtol * 1e-2,
                         points=prob.points)
        except SimulationError as exc:
            status, r = f"failed: {str(exc).splitlines()[0][:160]}", exc.result
        wall = r.stats.wall_time if r is not None and r.stats.wall_time else \
            time.perf_counter() - t0
        err = self.error(prob, r) if r is not None and len(r.t) > 1 else float("nan")
        return {"problem": prob.name, "method": method, "integrator": "native",
                "rtol": rtol, "setting": rtol, "error": err, "wall_time": wall,
                "t_reached": float(r.t[-1]) if r is not None and len(r.t) else 0.0,
                "steps": r.stats.steps if r is not None else None,
                "rhs_calls": r.stats.rhs_calls if r is not None else None,
                "status": status}

    def series(self, prob: Problem, methods, tols) -> list[dict]:
        rows = []
        for method in methods:
            why = None          # why the series stopped: a run that failed, or too long
            for tol in tols:
                if why is not None:
                    rows.append({"problem": prob.name, "method": method, "rtol": tol,
                                 "setting": tol, "integrator": "native", "error": np.nan,
                                 "status": f"skipped: {why}"})
                    continue
                row = self.run(prob, method, tol)
                rows.append(row)
                self.log(f"    {prob.name} {method:9s} rtol {tol:8.2g}: error "
                         f"{row['error']:.3g} {prob.unit}, {row['wall_time']:.3g} s "
                         f"({row['status'][:60]})")
                if row["status"] != "ok":
                    why = "the previous run failed"
                elif row["wall_time"] > self.budget:
                    why = f"the previous run took over {self.budget:g} s"
        return rows


def best(rows, method: str, limit: float):
    """(least time to an error within ``limit``, the best error reached) of a method's
    runs that reached the end (None where none)."""
    ok = [r for r in rows if r["method"] == method and r["status"] == "ok"
          and np.isfinite(r["error"])]
    within = [r["wall_time"] for r in ok if r["error"] <= limit]
    return (min(within) if within else None,
            min((r["error"] for r in ok), default=None))


def report(run) -> None:
    """The part: runs, CSV, a chart per problem, the summary's table."""
    from bgc.bench import charts
    from bgc.bench.rows import write_rows
    bench = IFToMM(run.bench.build / "iftomm", run.log, run.quick, run.budget)
    run.summary.append("## IFToMM benchmark problems: every method against the "
                       "references\n")
    run.summary.append(
        "Native Radau IIA, rtol from 1e-4 down (atol = rtol / 100); error against each "
        "problem's exact or published reference (A01, A02: exact; A03: the IVP test set; "
        "A04, A05: lagrange at 1e-10 / 1e-9); wall time of the integration (modules "
        "compiled and warm). A series stops at a failed run or one over "
        f"{run.budget:g} s. The benchmark's limit: {LIMIT:g} m on A02's B0. Peer: "
        f"{PEER['name']}, {PEER['problem']}: {PEER['error']:g} m in {PEER['time']:g} s "
        "(issue 39).\n")
    all_rows = []
    table = []
    for prob, methods, tols in bench.problems():
        run.log(f"iftomm: {prob.title}")
        rows = bench.series(prob, methods, tols)
        all_rows += rows
        limit = LIMIT if prob.unit == "m" else 1e-6
        charts.work_precision(rows, run.out / f"iftomm_{prob.name}.png",
                              f"work-precision: {prob.title}",
                              "native Radau; a method without a point stopped or missed "
                              "by more than the axis", xlabel=f"error against the "
                              f"reference [{prob.unit}]", limit=limit)
        for m in methods:
            t_lim, e_best = best(rows, m, limit)
            failed = [r for r in rows if r["method"] == m and r["status"].startswith("fail")]
            table.append({
                "problem": prob.name, "method": m, "limit": f"{limit:g} {prob.unit}",
                "time to the limit": f"{t_lim:.3g} s" if t_lim is not None else "-",
                "best error": f"{e_best:.2g}" if e_best is not None else "-",
                "stopped": (f"t = {failed[0]['t_reached']:.3g} s: "
                            f"{failed[0]['status'][8:70]}") if failed else ""})
    write_rows(run.out / "iftomm.csv", all_rows)
    run.table(table, ["problem", "method", "limit", "time to the limit", "best error",
                      "stopped"])
    run.data["iftomm"] = all_rows
    a02 = [r for r in all_rows if r["problem"] == "A02_N40" and r["method"] == "augmented"]
    if a02:
        t_lim, e_best = best(a02, "augmented", LIMIT)
        par = [r for r in all_rows if r["problem"] == "A02_N40" and r["method"] == "parasitic"
               and r["status"] == "ok"]
        same = {r["rtol"]: r["wall_time"] for r in par}
        aug = {r["rtol"]: r["wall_time"] for r in a02 if r["status"] == "ok"}
        common = sorted(set(same) & set(aug))
        ratio = ", ".join(f"rtol {t:g}: {aug[t]:.3g} s against {same[t]:.3g} s"
                          for t in common)
        run.targets.append(
            f"A02 N = 40 under augmented: within {LIMIT:g} m in "
            + (f"{t_lim:.3g} s (peer: {PEER['time']:g} s): "
               + ("met" if t_lim <= PEER["time"] else "NOT met") if t_lim is not None
               else "no run: NOT met")
            + f"; against parasitic at the same rtol: {ratio or 'no common run'}")
