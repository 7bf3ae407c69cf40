"""Part ``components`` of ``bgc bench``: the compile cost of an assembly (issue 40, item
5). The IFToMM A02 N-four-bar (models/n_four_bar.yaml, N windows of the library's
four_bar_window) from the model file to the first result, for N = 10, 40, 160 (21 to 321
bodies), with the generated code's instance loops (bgc.codegen.instances) and, with
``straight``, written out per instance.

Each point is a fresh interpreter running ``bgc simulate MODEL -p N=... --t-end 0.01
--json``: a fresh output directory and a numba cache that holds bgc's native step loop
(compiled once, beforehand: "the step loop cached") and nothing of the model (its
kernels and its numba wrappers compile). Per point: the wall time around the process, the
process's CPU time, the report's per-stage seconds, the module's size and its kernel IR's
code (without the tables). Writes components.csv, components.png and its section of the
summary; the target: N = 160 within ``TARGET_S``.
"""

from __future__ import annotations

import json
import math
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from bgc.bench.cases import MODELS

MODEL = MODELS / "n_four_bar.yaml"
N_FULL, N_QUICK = (10, 40, 160), (2, 4)
TARGET_N, TARGET_S = 160, 30.0
# method augmented (issue 39, item 2): the model build of N = 40 (the report's stages)
AUG_FULL, AUG_QUICK = (10, 40), (2,)
AUG_TARGET_N, AUG_TARGET_S = 40, 10.0
# the report's stages (``bgc simulate --json``'s "stages"), then the run's own two parts
# from its statistics: its start (the step loop loaded from the cache, the module's entry
# points, the start's checks) and the integration
STAGES = ("load", "causality", "equations", "jacobian", "emit", "machine code")
PARTS = [(s, f"{s.replace(' ', '_')}_s") for s in STAGES] + [
    ("start of the run", "run_start_s"), ("integrate", "integrate_s")]
TIMEOUT = 3600.0
# a run with the instance loops off: the same command, the threshold out of reach
STRAIGHT = ("import sys; from bgc.codegen import instances; instances.MIN_COPIES = 10**9; "
            "from bgc.cli import main; sys.exit(main())")
LOOPS = "import sys; from bgc.cli import main; sys.exit(main())"


def loop_cache(root: Path) -> Path:
    """A numba cache with bgc's native step loop in it (compiled once, as bgc simulate's
    ``precompile_loop`` does, and waited for)."""
    cache = root / "loop_cache"
    env = dict(os.environ, NUMBA_CACHE_DIR=str(cache))
    subprocess.run([sys.executable, "-c", "from bgc.solvers import native; "
                    "native.precompile('radau5'); native.await_precompiled('radau5')"],
                   env=env, check=True, capture_output=True, timeout=TIMEOUT)
    return cache


def point(n: int, loops: bool, root: Path, cache: Path, method: str = "parasitic") -> dict:
    """One cold build and first result of A02 with ``n`` windows under ``method`` (a
    failed one: its status, no times)."""
    work = Path(tempfile.mkdtemp(dir=root))
    own_cache = work / "cache"
    shutil.copytree(cache, own_cache)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(own_cache))
    cmd = [sys.executable, "-c", LOOPS if loops else STRAIGHT, "simulate", str(MODEL),
           "-p", f"N={n}", "-o", str(work / "gen"), "--t-end", "0.01", "--json", "--quiet",
           "--method", method]
    out = {"N": n, "bodies": 2 * n + 1, "method": method, "loops": loops}
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    try:
        r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=TIMEOUT)
    except subprocess.TimeoutExpired:
        shutil.rmtree(work, ignore_errors=True)
        return {**out, "status": f"timeout after {TIMEOUT:g} s"}
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if r.returncode != 0:
        shutil.rmtree(work, ignore_errors=True)
        return {**out, "status": "failed: " + (r.stderr.strip().splitlines() or ["?"])[-1]}
    rep = json.loads(r.stdout)
    module = next((work / "gen").glob("n_four_bar*.py"))
    text = module.read_text()
    ir = "".join(re.findall(r'^_KERNEL_IR(?:_STRAIGHT)? = """\\\n(.*?)"""', text, re.S | re.M))
    code = sum(len(line) + 1 for line in ir.splitlines() if not line.startswith("@"))
    stages = rep.get("stages") or rep.get("timings") or {}
    out.update({"wall_s": round(wall, 2), "cpu_s": round(cpu, 2),
                "module_mb": round(len(text.encode()) / 1e6, 2),
                "kernel_code_mb": round(code / 1e6, 2),
                "loop_functions": len(re.findall(r"_loop\d+\(", text)) // 2})
    out.update({f"{s.replace(' ', '_')}_s": round(stages[s], 2) for s in STAGES
                if s in stages})
    # the model build: the stages but the Jacobian's, which is part of emit's
    out["build_s"] = round(sum(stages.get(s, 0.0) for s in STAGES if s != "jacobian"), 2)
    stats = rep.get("stats") or {}
    out.update({"run_start_s": round(stats.get("compile_time", math.nan), 2),
                "integrate_s": round(stats.get("wall_time", math.nan), 3)})
    out["status"] = "ok"
    shutil.rmtree(work, ignore_errors=True)
    return out


def measure(ns, straight: bool = False, log=print, augmented=()) -> list[dict]:
    """A row per N (and per N with the instance loops off, ``straight``), then a row per
    N of ``augmented`` under method augmented."""
    root = Path(tempfile.mkdtemp(prefix="bgc_components_"))
    try:
        log("components: the native step loop into a fresh numba cache")
        cache = loop_cache(root)
        rows = []
        for n in ns:
            for loops in (True, False) if straight else (True,):
                log(f"components: A02 with N = {n} ({'instance loops' if loops else 'straight'})"
                    ", cold, from the model file to the first result")
                rows.append(point(n, loops, root, cache))
                log(f"components: {json.dumps(rows[-1])}")
        for n in augmented:
            log(f"components: A02 with N = {n} under method augmented, cold")
            rows.append(point(n, True, root, cache, "augmented"))
            log(f"components: {json.dumps(rows[-1])}")
        return rows
    finally:
        shutil.rmtree(root, ignore_errors=True)


def chart(rows, path: Path, title: str) -> Path:
    """Wall time to the first result against N, split into the stages the report gives
    (the rest: interpreter start and imports), with the target."""
    import numpy as np

    from bgc.analysis.results import panels, save_figure
    ok = [r for r in rows if r.get("status") == "ok" and r.get("loops", True)]
    fig, axes = panels(1, 3.4)
    ax = axes[0, 0]
    x = np.arange(len(ok))
    bottom = np.zeros(len(ok))
    for s, col in PARTS:
        h = np.array([float(r.get(col, 0.0)) for r in ok])
        ax.bar(x, h, bottom=bottom, label=s)
        bottom += h
    rest = np.array([float(r["wall_s"]) for r in ok]) - bottom
    ax.bar(x, np.maximum(rest, 0.0), bottom=bottom, color="0.8",
           label="the rest (interpreter, imports)")
    ax.axhline(TARGET_S, color="k", ls="--", lw=0.8)
    ax.set_xticks(x, [f"N = {r['N']}\n{r['bodies']} bodies"
                      + ("" if r.get("method", "parasitic") == "parasitic" else f"\n{r['method']}")
                      for r in ok])
    ax.set_ylabel(f"wall time [s] (dashed: target {TARGET_S:g} s at N = {TARGET_N})")
    ax.legend(fontsize=7, ncol=2)
    return save_figure(fig, path, title)


def report(run) -> None:
    """components.csv, components.png and the summary's section (``run``: its
    ``bench.Run``)."""
    from bgc.bench.rows import write_rows
    rows = measure(N_QUICK if run.quick else N_FULL, log=run.log,
                   augmented=AUG_QUICK if run.quick else AUG_FULL)
    write_rows(run.out / "components.csv", rows)
    chart(rows, run.out / "components.png",
          "A02 N-four-bar: model file to first result, cold module, step loop cached")
    run.summary.append("## Components: an assembly's model file to its first result\n")
    run.summary.append(
        "The IFToMM A02 N-four-bar (`models/n_four_bar.yaml`, N windows of the library's "
        "`four_bar_window`) with `bgc simulate -p N=... --t-end 0.01` in a fresh "
        "interpreter: a fresh output directory, a numba cache holding bgc's step loop and "
        "nothing of the model (`components.csv`, `components.png`). `cpu_s` is the "
        "process's own; the stage columns are the report's.\n")
    run.table(rows, ["N", "bodies", "method", "wall_s", "build_s", "cpu_s", "load_s", "causality_s",
                     "equations_s", "jacobian_s", "emit_s", "machine_code_s", "run_start_s",
                     "integrate_s", "module_mb", "loop_functions", "status"])
    big = next((r for r in rows if r["N"] == TARGET_N and r.get("status") == "ok"
                and r.get("method") == "parasitic"), None)
    if big is not None:
        verdict = "pass" if big["wall_s"] <= TARGET_S else "FAIL"
        run.targets.append(f"A02 with N = {TARGET_N} from the model file to its first result, "
                           f"step loop cached (target <= {TARGET_S:g} s): {big['wall_s']:.1f} s "
                           f"**{verdict}** ({big['cpu_s']:.1f} s of CPU: the wall time on a "
                           "machine with a core to itself)")
    aug = next((r for r in rows if r["N"] == AUG_TARGET_N and r.get("status") == "ok"
                and r.get("method") == "augmented"), None)
    if aug is not None:
        verdict = "pass" if aug["build_s"] <= AUG_TARGET_S else "FAIL"
        run.targets.append(f"A02 with N = {AUG_TARGET_N} under method augmented, the model "
                           f"build (the report's stages, target <= {AUG_TARGET_S:g} s): "
                           f"{aug['build_s']:.1f} s **{verdict}** (from the model file to "
                           f"the first result: {aug['wall_s']:.1f} s wall, "
                           f"{aug['cpu_s']:.1f} s of CPU)")
    run.data["components"] = rows
