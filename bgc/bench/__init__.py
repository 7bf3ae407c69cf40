"""Stage **bench**: every speed claim as a measured chart of speed against accuracy.

``bgc bench`` (``make bench``) runs the parts below on the same generated code and writes
CSV + PNG per part and ``summary.md`` to its output directory (``bench/results``):

- ``peers``: native Radau against scipy (BDF, Radau, LSODA) and SUNDIALS (CVODE, IDA),
  medians of repeats, ratios measured in one run (``peers.py``);
- ``precision``: work-precision diagrams, method x integrator (``precision.py``);
- ``stiffness``: the parasitic stiffness sweep, numerical against modelling error;
- ``stability``: where each method fails and what bgc says (``stability.py``);
- ``compile``: cold and warm time to first result (``bgc simulate`` in a fresh
  interpreter, empty caches), per stage, against model size: chains of N = 5 ... 80
  links and the SARIB, per method (``compile_cost.py``);
- ``startup``: a 2-state model's warm start to its first result, by phase (bgc's fixed
  cost: ``startup.py``);
- ``symmetry``: the one-leg SARIB against the full rig under pumping, its error next to
  its speed (``symmetry.py``);
- ``scenes``: each shipped scene's reduced module against the full model: states,
  compile and run time, output difference (``scenes.py``);
- ``components``: an assembly's cold time from its model file to the first result, the
  A02 N-four-bar at N = 10, 40, 160 (``components.py``);
- ``activity``: the scenes' activity passes (model order reduction by element activity,
  and junction inactivity) on the SARIB's pumping, roll and pitch chirps under parasitic
  and zcp, beside the exact passes: states, elements removed, junction terms cut and
  parts split off, run time, output error (``activity.py``);
- ``iftomm``: the IFToMM basic benchmark problems (A01 pendulum, A02 N-four-bar at N = 2,
  10, 40, A03 Andrews, A04 Bricard, A05 flyball governor) under every method against their
  exact or published references, work-precision per problem (``iftomm.py``).

``quick=True`` runs every part at small scale (a slider-crank, a pendulum, chains of 5
and 10 links) for the tests.
"""

from __future__ import annotations

import datetime
import json
import os
import platform
from dataclasses import replace
from pathlib import Path

import numpy as np

from bgc import methods as constraint_methods
from bgc.bench import (
    activity,
    charts,
    compile_cost,
    components,
    iftomm,
    precision,
    scenes,
    stability,
    startup,
    symmetry,
)
from bgc.bench.cases import ANDREWS, MODELS, SLIDER, Bench, Scenario, sarib
from bgc.bench.rows import write_rows
from bgc.bench.peers import at_equal_error, peers
from bgc.fileio import atomic_write

PARTS = ("peers", "precision", "stiffness", "stability", "compile", "startup", "symmetry",
         "scenes", "activity", "iftomm", "components")
SCENES = Path(__file__).resolve().parents[2] / "scenes"
METHODS = constraint_methods.NAMES

def machine() -> str:
    import numba
    import scipy
    cpu = next((ln.split(":", 1)[1].strip() for ln in open("/proc/cpuinfo")
                if ln.startswith("model name")), platform.processor()) \
        if os.path.exists("/proc/cpuinfo") else platform.processor()
    return (f"{cpu}, {os.cpu_count()} cores; Python {platform.python_version()}, numpy "
            f"{np.__version__}, scipy {scipy.__version__}, numba {numba.__version__}")


def revision() -> str:
    """The bgc commit a run measures (``-dirty``: with uncommitted changes to bgc/), or
    'unknown' outside a git checkout."""
    import subprocess
    root = Path(__file__).resolve().parents[2]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root,
                              capture_output=True, text=True, check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--", "bgc"], cwd=root,
                               capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"
    return head + ("-dirty" if dirty else "")


class Run:
    """One benchmark run: its parts write into ``out`` and add to ``summary``."""

    def __init__(self, out: Path, quick: bool, repeats: int, budget: float, log,
                 build: Path | None = None):
        self.out, self.quick, self.repeats, self.budget, self.log = (out, quick, repeats,
                                                                     budget, log)
        build = build or (out / "build" if quick else out.parent / "build")
        self.bench = Bench(Path(build), log)
        self.summary: list[str] = []
        self.data: dict = {}
        self.targets: list[str] = []
        self.revision = revision()       # what was imported: read at the start
        self.compile_timeout = compile_cost.TIMEOUT

    def table(self, rows, cols, fmt=None) -> None:
        fmt = fmt or {}
        self.summary.append("| " + " | ".join(cols) + " |")
        self.summary.append("|" + "---|" * len(cols))
        for r in rows:
            cells = []
            for c in cols:
                v = r.get(c)
                cells.append(fmt[c](v) if c in fmt and v is not None
                             else f"{v:.3g}" if isinstance(v, float) else str(v))
            self.summary.append("| " + " | ".join(cells) + " |")
        self.summary.append("")

    # --- parts -----------------------------------------------------------------------
    def peers(self):
        cases = ([(SLIDER, "lagrange", 1e-6)] if self.quick else
                 [(sarib("sarib_chirp"), "parasitic", 1e-5), (ANDREWS, "lagrange", 1e-6)])
        integrators = ("native", "bdf", "cvode") if self.quick else None
        rows = []
        self.summary.append("## Peers: the same generated code under every integrator\n")
        for scn, method, tol in cases:
            self.log(f"peers: {scn.title} ({method}, rtol = atol = {tol:g})")
            kw = {"integrators": integrators} if integrators else {}
            rs = peers(self.bench, scn, method, tol, self.repeats, **kw)
            if scn.name == "sarib_chirp":
                self._bdf_target(scn, method, tol, rs)
            rows += rs
            _, note = self.bench.reference(scn, method)
            self.summary.append(f"**{scn.title}**, method {method}, rtol = atol = {tol:g}; "
                                f"median of {self.repeats} runs; error against {note}.\n")
            self.table(rs, ["integrator", "rtol", "wall_median", "time_vs_native", "error",
                            "steps", "rhs_calls", "jac_calls", "lu", "status"],
                       {"time_vs_native": lambda v: f"{v:.3g}x",
                        "status": lambda v: v[:70]})
        write_rows(self.out / "peers.csv", rows)
        self.data["peers"] = rows

    def _bdf_target(self, scn, method, tol, rs):
        """The target: native at least 10x faster than scipy BDF at the same tolerance, at
        equal or better error; and, since native's error there is far smaller, the speed
        at equal error too (native at the loosest tolerance that still reaches BDF's)."""
        nat = next(r for r in rs if r["integrator"] == "native")
        bdf = next(r for r in rs if r["integrator"] == "bdf")
        speed = bdf["wall_median"] / nat["wall_median"]
        text = (f"SARIB 28 s pumping chirp, {method}, rtol {tol:g}: native "
                f"{nat['wall_median']:.3g} s, scipy BDF {bdf['wall_median']:.3g} s: "
                f"**{speed:.1f}x** (target >= 10x) at error {nat['error']:.2g} against "
                f"BDF's {bdf['error']:.2g} (target: equal or better): "
                + ("met" if speed >= 10 and nat["error"] <= bdf["error"] else "NOT met"))
        eq = at_equal_error(self.bench, scn, method, bdf["error"],
                            [float(f"{tol * 10 ** k:.0e}") for k in range(1, 4)],
                            self.repeats)
        if eq is not None:
            eq["integrator"] = "native (equal error)"
            eq["time_vs_native"] = eq["wall_median"] / nat["wall_median"]
            rs.append(eq)
            text += (f". At equal error native needs only rtol {eq['rtol']:g}: "
                     f"{eq['wall_median']:.3g} s at error {eq['error']:.2g}, "
                     f"**{bdf['wall_median'] / eq['wall_median']:.1f}x** faster than BDF")
        self.targets.append(text)

    def precision(self):
        fractions = precision.RK4_FRACTIONS
        if self.quick:
            cases = [(SLIDER, METHODS, ("native", "bdf", "rk4"), (1e-3, 1e-5, 1e-7))]
            fractions = fractions[:1]
        else:
            cases = [(sarib("sarib_chirp_window"), METHODS, precision.INTEGRATORS,
                      precision.TOLERANCES),
                     (sarib("sarib_sine"), METHODS, precision.INTEGRATORS,
                      precision.TOLERANCES),
                     (ANDREWS, ("lagrange", "zcp", "parasitic"), precision.INTEGRATORS,
                      precision.TOLERANCES)]
        self.summary.append("## Work-precision\n")
        self.summary.append("Wall time (integration only, numba compiled and warm) against "
                            "the largest relative error of the scenario's outputs; one run "
                            "per point; rk4 at fractions "
                            f"{', '.join(f'{f:g}' for f in fractions)} of its "
                            f"stability limit. A series stops after a run over "
                            f"{self.budget:g} s.\n")
        all_rows = []
        for scn, methods, integrators, tols in cases:
            self.log(f"precision: {scn.title}")
            rows = precision.work_precision(self.bench, scn, methods, integrators, tols,
                                            self.budget, fractions)
            all_rows += rows
            _, note = self.bench.reference(scn)
            write_rows(self.out / f"precision_{scn.name}.csv", rows)
            charts.work_precision(rows, self.out / f"precision_{scn.name}.png",
                                  f"work-precision: {scn.title}", f"reference: {note}")
            self.summary.append(f"**{scn.title}** (`precision_{scn.name}.png`): reference "
                                f"{note}. {scn.note}\n")
            self.summary += self._time_to_error(rows, methods, scn)
        self.data["precision"] = all_rows

    def _time_to_error(self, rows, methods, scn) -> list[str]:
        """Least time to reach each error level, per method (any integrator / native)."""
        errs = [r["error"] for r in rows if r["status"] == "ok" and np.isfinite(r["error"])]
        if not errs:
            return []
        levels = [10.0 ** k for k in range(-1, int(np.floor(np.log10(min(errs)))) - 1, -1)]
        out = ["| error <= | " + " | ".join(f"{m} (best / native)" for m in methods) + " |",
               "|---|" + "---|" * len(methods)]
        for lv in levels:
            cells = []
            for m in methods:
                best = precision.time_to_error(rows, m, lv)
                nat = precision.time_to_error(rows, m, lv, "native")
                cells.append(f"{best:.3g} s / {nat:.3g} s" if best is not None and
                             nat is not None else f"{best:.3g} s / -" if best is not None
                             else "not reached")
            out.append(f"| {lv:.0e} | " + " | ".join(cells) + " |")
        out.append("")
        par = [r for r in rows if r["method"] == "parasitic" and r["status"] == "ok"]
        if "lagrange" in methods and par and not self.quick:
            floor = min(r["error"] for r in par)
            t_par = precision.time_to_error(rows, "parasitic", floor)
            t_lag = precision.time_to_error(rows, "lagrange", floor)
            self.targets.append(
                f"{scn.title}: parasitic's best error {floor:.2g} in {t_par:.3g} s; "
                f"lagrange reaches it in "
                + (f"{t_lag:.3g} s: " + ("met" if t_lag <= t_par else "NOT met")
                   if t_lag is not None else "no run: NOT met")
                + " (target: no more time)")
        return out

    def stiffness(self):
        scn = SLIDER if self.quick else sarib("sarib_chirp_window")
        factors = (1.0, 10.0) if self.quick else precision.STIFFNESS_FACTORS
        tols = (1e-5, 1e-8) if self.quick else precision.TOLERANCES[1:]
        self.log(f"stiffness: {scn.title}")
        rows = precision.stiffness_sweep(self.bench, scn, factors, tols, self.budget)
        write_rows(self.out / "stiffness.csv", rows)
        charts.stiffness(rows, self.out / "stiffness.png",
                         f"parasitic stiffness sweep: {scn.title}")
        self.summary.append("## Parasitic stiffness: numerical against modelling error\n")
        self.summary.append(f"{scn.title}, native Radau; error against "
                            f"{self.bench.reference(scn)[1]} (`stiffness.png`). The floor "
                            "of each series is its modelling error:\n")
        floors = []
        for k in sorted({r["stiffness"] for r in rows}):
            ok = [r for r in rows if r["stiffness"] == k and r["status"] == "ok"]
            if ok:
                best = min(ok, key=lambda r: r["error"])
                floors.append({"stiffness": k, "floor": best["error"],
                               "at_rtol": best["setting"], "wall_time": best["wall_time"]})
        self.table(floors, ["stiffness", "floor", "at_rtol", "wall_time"])
        self.data["stiffness"] = rows

    def stability(self):
        stability.report(self)

    def startup(self):
        """A small model (2 states) to its first result, warm: bgc's fixed cost, and
        where it goes (issue 38)."""
        row = startup.measure(MODELS / "rlc.yaml", 2 if self.quick else 7, self.log)
        startup.report(self, row)

    def compile(self):
        """Cold and warm time to first result against model size: chains of N links
        (quick: N = 5, 10) and, unless quick, the SARIB, under each method."""
        cases = compile_cost.models(self.quick, self.bench.build, MODELS / "sarib.yaml")
        rows = compile_cost.sweep(cases, METHODS, self.bench.build / "compile_cost",
                                  self.log, self.compile_timeout)
        compile_cost.report(self, rows)

    def symmetry(self):
        """The one-leg SARIB (issue 7): what the symmetry shortcut costs in accuracy, next
        to what it saves in time."""
        full = sarib("sarib_sine")
        tols = precision.TOLERANCES[:-1]
        if self.quick:
            full = replace(full, t_end=0.1, points=101, title="SARIB pumping sine at 18 Hz, "
                                                              "0.1 s from rest")
            tols = (1e-4, 1e-6)
        self.log(f"symmetry: one leg against the full rig, {full.title}")
        rows = symmetry.symmetry(self.bench, full, tols, self.budget)
        write_rows(self.out / "symmetry.csv", rows)
        charts.work_precision([{**r, "method": r["model"]} for r in rows],
                              self.out / "symmetry.png",
                              f"one leg against the full rig: {full.title}",
                              "error against the full rig (parasitic) at rtol = atol = "
                              f"{full.ref_tol:g}; native Radau")
        self.summary.append("## Symmetry: the one-leg SARIB against the full rig\n")
        self.summary.append(
            f"{full.title}, parasitic, native Radau (`symmetry.png`); outputs "
            f"{', '.join(symmetry.OUTPUTS)}; error against the full rig at rtol = atol = "
            f"{full.ref_tol:g}. The one-leg model's floor is what the shortcut costs; "
            "speed gain = full rig's time / one leg's at the same tolerance.\n")
        by_tol = {}
        for r in rows:
            by_tol.setdefault(r["setting"], {})[r["model"]] = r
        table = []
        for tol, pair in sorted(by_tol.items(), reverse=True):
            f, o = pair.get("sarib"), pair.get("sarib_one_leg")
            if f and o and f["status"] == o["status"] == "ok":
                table.append({"rtol": tol, "full_error": f["error"],
                              "one_leg_error": o["error"], "full_s": f["wall_time"],
                              "one_leg_s": o["wall_time"],
                              "speed_gain": f["wall_time"] / o["wall_time"]})
        self.table(table, ["rtol", "full_error", "one_leg_error", "full_s", "one_leg_s",
                           "speed_gain"], {"speed_gain": lambda v: f"{v:.3g}x"})
        self.data["symmetry"] = rows

    def scenes(self):
        """Each shipped scene (quick: a four-bar scene) reduced against its full model."""
        from bgc.scene.scenes import load_scene
        if self.quick:
            path = self.out / "build" / "four_bar_scene.yaml"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(f"model: {MODELS / 'four_bar.yaml'}\noutputs: [crank_angle, "
                            "rocker_angle]\ntime: {end: 0.5, points: 51}\n"
                            "tolerances: {rtol: 1.0e-8, atol: 1.0e-10}\nsolver: native\n")
            files = [path]
        else:
            files = sorted(SCENES.glob("*.yaml"))
        self.log(f"scenes: {len(files)} scenes, reduced against their full models")
        rows = scenes.measure([load_scene(f) for f in files], self.bench.build, self.log)
        write_rows(self.out / "scenes.csv", rows)
        self.summary.append("## Scenes: what the reduction passes gain\n")
        self.summary.append(
            "Each scene's reduced module (`bgc run SCENE`) against the full model under the "
            "scene's method, on the scene's own settings (`scenes.csv`): derivation (sympy "
            "and emit) and cold numba compile (a fresh interpreter, empty cache), run time "
            "(warm), and the largest difference of the scene's outputs relative to each "
            "output's peak, beside the full model's own integration error on the scene's "
            "tolerances (against a run at 1/1000 of them). The full model's compile is "
            "the model's, shared by its scenes.\n")
        self.table(rows, ["scene", "states_full", "states_reduced", "params_reduced",
                          "derive_full_s", "derive_reduced_s", "numba_cold_full_s",
                          "numba_cold_reduced_s", "run_full_s", "run_reduced_s",
                          "run_gain", "output_difference", "integration_error_full"],
                   {"run_gain": lambda v: f"{v:.3g}x"})
        self.data["scenes"] = rows

    def activity(self):
        """The activity pass on the SARIB chirps under parasitic and zcp (quick: a small
        model with a weak spring, under parasitic)."""
        from bgc.scene.scenes import load_scene
        if self.quick:
            path = self.out / "build" / "msd_scene.yaml"
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(f"model: {MODELS / 'msd_forced.yaml'}\noutputs: [position]\n"
                            "time: {end: 1.0, points: 101}\n"
                            "tolerances: {rtol: 1.0e-8, atol: 1.0e-10}\nsolver: native\n")
            files, methods = [path], ("parasitic",)
        else:
            files = [SCENES / f"{d}_chirp.yaml" for d in ("pumping", "roll", "pitch")]
            methods = ("parasitic", "zcp")
        self.log(f"activity: {len(files)} scenes x {len(methods)} methods")
        rows = activity.measure([load_scene(f) for f in files], methods, self.bench.build,
                                self.log, keep=0.999 if self.quick else activity.KEEP,
                                repeats=self.repeats, junctions=activity.JUNCTIONS)
        write_rows(self.out / "activity.csv", rows)
        self.summary.append("## Scenes: what the activity passes gain\n")
        self.summary.append(
            "The activity pass (`activity: {keep: K}` in a scene: the least active "
            "elements over the scene's run, whose shares of the total activity "
            "int |P| dt sum to at most 1 - K, leave the model; Louca et al. 1997) after "
            "the exact passes (`merge_relays` where exact, `fold_parameters`, "
            "`idle_dofs`, `prune`), on each SARIB chirp scene under parasitic and zcp "
            "(`activity.csv`): states of the full model, after the exact passes and after "
            "activity; the elements removed; the steps and run time (median of repeats) of "
            "both reduced modules (warm, the scene's settings) and the activity-reduced outputs' largest difference from "
            "the full model's run, relative to each output's peak (the pass's report), "
            "and from the exact passes' run. Under parasitic every element of little "
            "activity is a constraint element of the method or acts on a body of "
            "negligible mass (the attach and membrane chains): none may go.\n")
        self.table(rows, ["scene", "method", "keep", "states_full", "states_exact_passes",
                          "states_activity", "elements_removed", "steps_exact",
                          "steps_activity", "run_exact_s",
                          "run_activity_s", "run_gain", "activity_error",
                          "difference_from_exact"], {"run_gain": lambda v: f"{v:.3g}x",
                                                     "keep": lambda v: f"{v:g}"})
        self.summary.append(
            "The junctions pass (`activity: {junctions: J}`: at each 0- or 1-junction, "
            "each component of a body's, the least active bonds that bring the summed "
            "effort or flow in, whose shares of the junction's activity sum to at most "
            "1 - J, are cut there, the other side fed the junction's flow or effort as a "
            "modulated source; Rideout, Stein and Louca 2007) on the same scenes, "
            "instead of the element pass, after the exact ones: the terms cut (of them "
            "below 1e-9 of their junction's activity: no power in the run), the coupled "
            "parts the model split into and the driven states no output needs (removed), "
            "states, steps, run time against the exact passes' module, the error against "
            "the full model's run (the pass's report) and the difference from the exact "
            "passes' run. A cut never goes into a joint's constraint: not a junction sum "
            "a constraint reads, not (lagrange, zcp, augmented) a force that carries a "
            "constraint force.\n")
        self.table(rows, ["scene", "method", "junctions", "states_exact_passes",
                          "junction_cuts", "junction_cuts_roundoff", "junction_parts",
                          "driven_states_removed", "states_junctions", "steps_junctions",
                          "run_exact_s", "run_junctions_s", "junctions_gain",
                          "junctions_error", "junctions_difference_from_exact"],
                   {"junctions_gain": lambda v: f"{v:.3g}x",
                    "junctions": lambda v: f"{v:g}"})
        self.data["activity"] = rows

    def iftomm(self):
        """The IFToMM benchmark problems under every method (quick: A01 and A02 at N = 2,
        two tolerances)."""
        iftomm.report(self)

    def components(self):
        """A02 from the model file to its first result for N = 10, 40, 160 (quick: 2, 4),
        cold, the step loop cached."""
        components.report(self)

    def run_part(self, part: str) -> None:
        """Run one part and keep what it says in ``out/parts/<part>.json``, so a part
        can be run again alone (``--part``) without losing the others' summary."""
        self.summary, self.targets = [], []
        # the machine's load over the part: times taken beside other work are not
        # comparable with times taken alone, and the summary says which these are
        load0 = os.getloadavg()[0]
        getattr(self, part)()
        load = f"load average {load0:.1f} at the start, {os.getloadavg()[0]:.1f} at the end"
        fragment = {"part": part, "quick": self.quick, "date": str(datetime.date.today()),
                    "revision": self.revision, "machine": f"{machine()}; {load}",
                    "summary": self.summary, "targets": self.targets}
        atomic_write(self.out / "parts" / f"{part}.json", json.dumps(fragment, indent=1) + "\n")

    def write_summary(self) -> tuple[Path, list[str]]:
        """summary.md from every part's fragment in ``out/parts`` (in PARTS order), each
        dated with its machine; the targets first."""
        frags = [json.loads((self.out / "parts" / f"{p}.json").read_text()) for p in PARTS
                 if (self.out / "parts" / f"{p}.json").exists()]
        targets = [t for f in frags for t in f["targets"]]
        head = [f"# bgc bench ({'quick' if self.quick else 'full'})", "",
                "Times are wall-clock seconds of one process on a shared machine: compare "
                "the ratios within a part's run, not absolute times across runs.", ""]
        if targets:
            head += ["## Targets", ""] + [f"- {t}" for t in targets] + [""]
        body = []
        for f in frags:
            at = f" at bgc {f['revision']}" if "revision" in f else ""
            body += f["summary"][:1] + [f"*Run {f['date']}{at} on {f['machine']}.*", ""] \
                + f["summary"][1:]
        path = atomic_write(self.out / "summary.md", "\n".join(head + body) + "\n")
        return path, targets


def run(out: str | Path = "bench/results", parts=PARTS, quick: bool = False,
        repeats: int = 3, budget: float = 60.0, log=print, build=None) -> dict:
    """Run the chosen parts; write CSV, PNG and summary.md into ``out`` (generated
    modules into ``build``)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    r = Run(out, quick, repeats, budget, log, build)
    for part in parts:
        r.run_part(part)
    summary, targets = r.write_summary()
    return {"summary": str(summary), "targets": targets, "data": r.data}
