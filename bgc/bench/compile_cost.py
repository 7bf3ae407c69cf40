"""Compile cost: from a model file to the first result, against the model's size.

- cold time to first result: ``bgc simulate MODEL --t-end 0.01`` in a fresh interpreter,
  with an empty cache (``NUMBA_CACHE_DIR``) and a fresh output directory, timed around the
  process: all of load, sympy, emit, machine-code compile and the integrator loop; the
  report's per-stage seconds beside it (``--json``: ``stages`` or ``timings``);
- warm start: the same command again, the cache and module now present;
- model size: states and assignments (the report's, else derived in process), the
  generated module's size and operation count (arithmetic and calls in ``rhs``, ``jac``,
  ``outputs``, on its syntax tree);
- over chains of N spatial links (``chain.py``) and the SARIB, per method: the growth from
  N = 10 to N = 40 is the test of a compile cost that follows the model's size;
- the operation count against N: linear growth is the sign of no expression swell.

``WORKER`` (a fresh interpreter timing the first call of each generated function) is
the per-function numba compile that ``scenes.py`` reports.
"""

from __future__ import annotations

import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bgc.bench.chain import write_chain
from bgc.bench.rows import as_number, write_rows
from bgc.codegen.kernels import program_functions
from bgc.pipeline import build

# the stages bgc reports (read as given: a stage a report lacks is NaN, one it adds is kept)
STAGES = ("load", "causality", "equations", "jacobian", "emit", "machine code", "integrate")
# environment variables pointed at the fresh, empty cache of a cold run
CACHE_ENV = ("NUMBA_CACHE_DIR",)
T_END = 0.01
TIMEOUT = 900.0
CHAIN_N = (5, 10, 20, 40, 80)
# the targets (issue 24, item 1 and 2)
TARGETS = {"sarib_cold_s": 10.0, "chain40_cold_s": 15.0, "growth_10_40": 4.5,
           "warm_s": 1.0}

FUNCTIONS = ("rhs", "jac", "outputs", "guards", "constraints")


def operations(path: Path) -> dict[str, int]:
    """Instructions of the LLVM IR of ``rhs``, ``jac`` (its partials) and ``outputs`` in a
    generated module (``bgc.codegen.kernels``): arithmetic, calls, loads and stores."""
    text = Path(path).read_text()
    return {name: sum(body.count("\n  ") for body in program_functions(text, program))
            for name, program in (("rhs", "rhs"), ("jac", "jac"), ("outputs", "out"))}


def module_size(path: Path) -> dict:
    """A generated module's bytes and the operation count of its functions."""
    text = Path(path).read_text()
    return {"module_bytes": len(text.encode()),
            **{f"ops_{k}": v for k, v in operations(path).items()}}


# What runs in the fresh interpreter (for ``scenes.py``): only what a user's script
# imports (``bgc.codegen.emit``, ``bgc.simulate``), not this benchmark package. ``cold`` times each
# function's first call (its compile) and the entry points' and stops there (the native
# loop is bgc's, not the module's: compiling it into the empty cache took 11 s per module
# for nothing scenes reports); ``warm`` (the cache filled) imports the module and takes
# the first step, reporting the time from the interpreter's launch (BGC_LAUNCH, the
# parent's clock just before it starts the process) to the end of that step.
WORKER = """
import json, os, sys, time
from pathlib import Path
t0 = time.perf_counter()
from bgc.codegen.emit import import_module
from bgc.simulate import simulate
mode, path = sys.argv[1], sys.argv[2]
out = {"import_s": time.perf_counter() - t0}
mod = import_module(Path(path))
p = mod.PARAMS
x = mod.initial_state(p)
if mode == "cold":
    for name in %r:
        if hasattr(mod, name):
            t1 = time.perf_counter()
            getattr(mod, name)(0.0, x, p)
            out[name + "_s"] = time.perf_counter() - t1
    t1 = time.perf_counter()
    mod.native_entry_points()
    out["entry_points_s"] = time.perf_counter() - t1
else:
    t1 = time.perf_counter()
    r = simulate(mod, t_end=1e-4, solver="native", points=2)
    out["first_step_s"] = time.perf_counter() - t1
    out["launch_to_first_step_s"] = time.time() - float(os.environ["BGC_LAUNCH"])
    out["loop_and_setup_s"] = r.stats.compile_time
print(json.dumps(out))
""" % (FUNCTIONS,)


def timed_subprocess(mode: str, path: Path, cache: Path) -> dict:
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache), BGC_LAUNCH=repr(time.time()))
    t0 = time.perf_counter()
    res = subprocess.run([sys.executable, "-c", WORKER, mode, str(path)],
                         capture_output=True, text=True, env=env, check=False)
    wall = time.perf_counter() - t0
    if res.returncode != 0:
        raise RuntimeError(f"{mode} compile of {path} failed: {res.stderr[-2000:]}")
    out = json.loads(res.stdout.strip().splitlines()[-1])
    out["process_s"] = wall
    return out


# --- cold and warm time to first result ---------------------------------------------


def _bgc(args: list[str], env: dict, timeout: float) -> dict:
    """``bgc ARGS`` in a fresh interpreter (``python -m bgc.cli``), timed around the
    process: ``wall_s``, ``status`` ('ok', 'failed: <last stderr line>' or 'timeout
    after T s') and the JSON report it printed (``report``, None unless ok). A process
    past ``timeout`` is killed with its process group, so one slow case cannot hang the
    bench."""
    t0 = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "bgc.cli", *args], env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate()
        return {"wall_s": math.nan, "status": f"timeout after {timeout:g} s", "report": None}
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        last = (err.strip().splitlines() or [f"exit status {proc.returncode}"])[-1]
        return {"wall_s": wall, "status": f"failed: {last[:200]}", "report": None}
    try:
        report = json.loads(out[out.index("{"):])
    except ValueError:
        return {"wall_s": wall, "status": "failed: no JSON report on stdout", "report": None}
    return {"wall_s": wall, "status": "ok", "report": report}


def stages(report: dict | None) -> dict[str, float]:
    """The per-stage seconds of a ``--json`` report (``stages`` or ``timings``, at the top
    or in ``stats``), as given; empty if it has none."""
    if not report:
        return {}
    for where in (report, report.get("stats") or {}):
        for key in ("stages", "timings"):
            got = where.get(key)
            if isinstance(got, dict):
                out = {}
                for k, v in got.items():
                    if isinstance(v, dict):     # {stage: {"seconds": ...}} is read too
                        v = v.get("seconds", v.get("elapsed"))
                    if isinstance(v, (int, float)):
                        out[str(k)] = float(v)
                return out
    return {}


def column(stage: str) -> str:
    """The CSV column of a stage ('machine code' -> 'machine_code_s')."""
    return stage.strip().replace(" ", "_").replace("-", "_") + "_s"


def measure(model: str | Path, method: str, work: Path, timeout: float = TIMEOUT) -> dict:
    """One row: the cold and warm time to first result of ``model`` under ``method``,
    per stage, and its size. Cold: a fresh output directory and empty caches (every
    variable in ``CACHE_ENV``); warm: the same command again with both now filled."""
    model = Path(model)
    with tempfile.TemporaryDirectory(prefix=f"{model.stem}_{method}_", dir=work) as tmp:
        return _measure(model, method, Path(tmp), timeout)


def _measure(model: Path, method: str, run_dir: Path, timeout: float) -> dict:
    cache, gen = run_dir / "cache", run_dir / "generated"
    cache.mkdir()
    env = dict(os.environ, **{k: str(cache) for k in CACHE_ENV})
    args = ["simulate", str(model), "--method", method, "--t-end", repr(T_END), "--json",
            "-o", str(gen), "--out", str(run_dir / "first.csv")]
    row = {"model": model.stem, "method": method}
    cold = _bgc(args, env, timeout)
    warm = (_bgc(args, env, timeout) if cold["status"] == "ok" else
            {"wall_s": math.nan, "status": "not run", "report": None})
    row.update(_size(model, method, gen, cold["report"]))
    row["cold_s"], row["warm_s"] = cold["wall_s"], warm["wall_s"]
    # what the runs' own reports say: the integrator's JIT/cache load, and whether the warm
    # run found the module current (a warm run that recompiles is no warm run)
    for name, r in (("cold", cold), ("warm", warm)):
        st = (r["report"] or {}).get("stats") or {}
        row[f"{name}_jit_s"] = float(st.get("compile_time", math.nan))
    row["warm_recompiled"] = (warm["report"] or {}).get("compiled")
    got = stages(cold["report"])
    for stage in dict.fromkeys([*STAGES, *got]):
        row[column(stage)] = got.get(stage, math.nan)
    row["stages_reported"] = len(got)
    row["status"] = cold["status"] if cold["status"] != "ok" else (
        "ok" if warm["status"] == "ok" else f"warm {warm['status']}")
    return row


def _size(model: Path, method: str, gen: Path, report: dict | None) -> dict:
    """States and assignments (from the report if it gives them, else derived here, in
    process: ``bgc compile --json``'s numbers without its emit and machine code), and
    the size and operation count of the module the cold run generated."""
    if report and "states" in report and "assignments" in report:
        out = {"states": report["states"], "assignments": report["assignments"]}
    else:
        c = build(model, method)
        out = {"states": len(c.system.states), "assignments": len(c.system.assignments)}
    modules = sorted(p for p in gen.glob("*.py") if p.name != "__init__.py") \
        if gen.is_dir() else []
    if modules:
        out.update(module_size(modules[0]))
    return out


def models(quick: bool, build: Path, sarib: Path | None = None) -> list[tuple[str, Path]]:
    """(label, model file): the chains (quick: N = 5, 10) and, unless quick, the SARIB."""
    ns = CHAIN_N[:2] if quick else CHAIN_N
    out = [(str(n), write_chain(n, build / "chains")) for n in ns]
    if not quick and sarib is not None:
        out.append(("sarib", Path(sarib)))
    return out


def sweep(cases, methods, work: Path, log=print, timeout: float = TIMEOUT) -> list[dict]:
    """``measure`` over models x methods; each row's ``N`` is the chain's N or 'sarib'."""
    work.mkdir(parents=True, exist_ok=True)
    rows = []
    for label, path in cases:
        for method in methods:
            log(f"compile: {path.stem} under {method}: cold, then warm (fresh interpreters)")
            row = measure(path, method, work, timeout=timeout)
            rows.append({"N": label, **row})
            log(f"  cold {row['cold_s']:.3g} s, warm {row['warm_s']:.3g} s, "
                f"{row['states']} states ({row['status']})")
    return rows


# --- what the rows say ----------------------------------------------------------------


def _verdict(value: float, limit: float, *runs) -> str:
    """pass/FAIL against ``limit``; a run that timed out or failed fails the target (its
    status said), one not run is 'not measured'."""
    if math.isnan(value):
        bad = [str(r["status"]) for r in runs if r and r.get("status", "ok") != "ok"]
        return f"FAIL ({bad[0]})" if bad else "not measured"
    return "pass" if value <= limit else "FAIL"


def growth_ratios(rows, a: str = "10", b: str = "40") -> dict[str, float]:
    """Cold time of chain N=b over chain N=a, per method (NaN where either is missing)."""
    out = {}
    for method in dict.fromkeys(r["method"] for r in rows):
        t = {str(r["N"]): as_number(r["cold_s"]) for r in rows if r["method"] == method}
        out[method] = t.get(b, math.nan) / t.get(a, math.nan) if a in t and b in t \
            else math.nan
    return out


def targets(rows) -> list[dict]:
    """The issue's targets, one row per target x method: measured value and verdict."""
    out = []
    methods = list(dict.fromkeys(r["method"] for r in rows))
    by = {(str(r["N"]), r["method"]): r for r in rows}
    ratio = growth_ratios(rows)
    for m in methods:
        sar, c10, c40 = (by.get((n, m), {}) for n in ("sarib", "10", "40"))
        for name, what, value, runs in (
                ("sarib_cold_s", "SARIB cold time to first result [s]",
                 as_number(sar.get("cold_s")), (sar,)),
                ("chain40_cold_s", "chain N=40 cold time to first result [s]",
                 as_number(c40.get("cold_s")), (c40,)),
                ("growth_10_40", "cold time N=40 / N=10", ratio.get(m, math.nan),
                 (c10, c40)),
                ("warm_s", "SARIB warm start to first result [s]",
                 as_number(sar.get("warm_s")), (sar,))):
            limit = TARGETS[name]
            out.append({"target": what, "method": m, "measured": value, "limit": limit,
                        "verdict": _verdict(value, limit, *runs), "key": name})
    return out


def report(run, rows) -> None:
    """compile_cost.csv, its chart and its summary (tables and targets) from ``rows``, for
    ``bgc bench`` (``run``: its ``bench.Run``)."""
    import numpy as np

    from bgc.bench import charts
    write_rows(run.out / "compile_cost.csv", rows)
    charts.compile_cost(rows, run.out / "compile_cost.png",
                        "cold time to first result against model size")
    num = as_number
    run.summary.append("## Compile cost: time to first result against model size\n")
    run.summary.append(
        f"`bgc simulate MODEL --method M --t-end {T_END:g} --json` timed "
        "around a fresh interpreter (`compile_cost.csv`, `compile_cost.png`): **cold** "
        "with an empty cache (`NUMBA_CACHE_DIR`) and a fresh output directory, so it "
        "holds load, sympy, emit, machine-code compile and the integrator loop; "
        "**warm**: the same command again, module and cache present. Models: chains "
        "of N spatial links (`bgc.bench.chain`) and the SARIB; states and assignments "
        "of the derived equations, operations counted in the generated `rhs` and "
        f"`jac`. A run longer than {run.compile_timeout:g} s is stopped and recorded "
        "as such. Stage columns are the cold run's report's own seconds (NaN: the "
        "report does not give that stage).\n")
    stage_cols = [c for c in dict.fromkeys(k for r in rows for k in r)
                  if c.endswith("_s") and c not in ("cold_s", "warm_s", "cold_jit_s",
                                                    "warm_jit_s")
                  and any(np.isfinite(num(r.get(c))) for r in rows)]
    if not stage_cols:
        run.summary.append("The reports gave no per-stage timings; `cold_jit_s` is "
                            "the run's own JIT/cache-load time (solver statistics).\n")
    run.table(rows, ["N", "method", "states", "assignments", "ops_rhs", "ops_jac",
                      "cold_s", "warm_s", "cold_jit_s", *stage_cols, "status"],
               {"status": lambda v: str(v)[:60]})
    # the pair, N = 10 to 40; else (quick) the smallest and largest chain run
    ns = sorted({int(r["N"]) for r in rows if str(r["N"]) != "sarib"})
    a, b = ("10", "40") if {10, 40} <= set(ns) or len(ns) < 2 else (str(ns[0]),
                                                                    str(ns[-1]))
    ratios = growth_ratios(rows, a, b)
    run.summary.append(f"Growth of the cold time from N = {a} to N = {b} "
                        f"({int(b) / int(a):g}x the links; linear: at most "
                        f"{int(b) / int(a):g}x): " + ", ".join(
                            f"{m} {v:.3g}x" if np.isfinite(v) else f"{m} not measured"
                            for m, v in ratios.items()) + ".\n")
    tg = [t for t in targets(rows) if t["verdict"] != "not measured"]
    if tg:
        run.summary.append("Targets (issue 24):\n")
        run.table(tg, ["target", "method", "measured", "limit", "verdict"])
    else:
        run.summary.append("The targets (issue 24: the SARIB, chains of 10 and 40 "
                            "links) need the full run.\n")
    if not run.quick:
        for key in dict.fromkeys(t["key"] for t in tg):
            ts = [t for t in tg if t["key"] == key]
            run.targets.append(
                f"{ts[0]['target']} (target <= {ts[0]['limit']:g}): " + ", ".join(
                    f"{t['method']} {t['measured']:.3g} {t['verdict']}"
                    if np.isfinite(t["measured"]) else f"{t['method']} {t['verdict']}"
                    for t in ts))
    run.data["compile"] = rows
