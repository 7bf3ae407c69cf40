"""Start-up: a small model file to its first result, warm, and where the fixed cost goes.

A 2-state model (``models/rlc.yaml``) has nothing to compute: the time ``bgc simulate``
takes on it, once its module and numba's cache exist (a machine where bgc has run
before), is bgc's fixed cost. Measured two ways, each in fresh interpreters:

- ``command``: ``bgc simulate MODEL --out FILE -q`` timed around the process, the
  median of ``repeats`` runs (the figure a user sees; issue 38's target: <= 1.5 s);
- ``phases``: the same work step by step in one interpreter (``WORKER``), each step's
  wall and CPU seconds: launch (interpreter start, to the first line of the script),
  the imports (numpy, numba, bgc's CLI), the module (the YAML read, the fresh module
  found and imported, its kernels loaded), numba's first load (its registries, the
  module's wrappers from the cache), the native loop (loaded from the cache), the
  integration, the CSV. Medians over the same repeats.
"""

from __future__ import annotations

import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

TARGET_S = 1.5
PHASES = ("launch", "imports", "module", "numba_first_load", "loop", "integrate", "csv")

WORKER = r"""
import json, os, sys, time
marks = [("launch", float(os.environ["BGC_LAUNCH"]), 0.0)]
def mark(name):
    marks.append((name, time.time(), time.process_time()))
mark("start")
import numpy, numba
import bgc.cli
mark("imports")
from bgc.pipeline import ensure_module
module, _, _ = ensure_module(sys.argv[1], sys.argv[2], need_model=False)
mark("module")
module.rhs(0.0, module.X0, module.PARAMS)
module.jac(0.0, module.X0, module.PARAMS)
mark("numba_first_load")
from bgc.simulate import SOLVERS
from bgc.solvers.base import Problem
SOLVERS["native"](Problem(module, module.PARAMS)).warm_up(module.X0)
mark("loop")
from bgc.simulate import simulate
r = simulate(module, t_end=module.SETTINGS["t_end"], solver="native")
mark("integrate")
from bgc.analysis.results import write_csv
write_csv(r, sys.argv[3], True)
mark("csv")
out, (n0, w0, c0) = {}, marks[1]
out["launch_s"] = w0 - marks[0][1]
for (name, w, c), (_, wp, cp) in zip(marks[2:], marks[1:-1]):
    out[name + "_s"] = w - wp
    out[name + "_cpu_s"] = c - cp
print(json.dumps(out))
"""


def _command(model: Path, gen: Path, csv: Path, env: dict) -> float:
    t0 = time.perf_counter()
    subprocess.run([sys.executable, "-m", "bgc.cli", "simulate", str(model), "-o", str(gen),
                    "--out", str(csv), "-q"], env=env, check=True,
                   stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def _phases(model: Path, gen: Path, csv: Path, env: dict) -> dict:
    env = dict(env, BGC_LAUNCH=repr(time.time()))
    res = subprocess.run([sys.executable, "-c", WORKER, str(model), str(gen), str(csv)],
                         env=env, check=True, capture_output=True, text=True)
    return json.loads(res.stdout.strip().splitlines()[-1])


def measure(model: Path, repeats: int = 5, log=print) -> dict:
    """The command's and the phases' medians over ``repeats`` warm runs of ``model`` (its
    module and numba's cache made first, in a temporary directory and cache)."""
    with tempfile.TemporaryDirectory(prefix="bgc_startup_") as tmp:
        tmp = Path(tmp)
        env = dict(os.environ, NUMBA_CACHE_DIR=str(tmp / "cache"))
        gen, csv = tmp / "generated", tmp / "first.csv"
        _command(model, gen, csv, env)          # cold: the module and the caches made
        _command(model, gen, csv, env)
        commands, phases = [], []
        for k in range(repeats):
            commands.append(_command(model, gen, csv, env))
            phases.append(_phases(model, gen, csv, env))
            log(f"startup: run {k + 1}/{repeats}: {commands[-1]:.3f} s")
    row = {"model": model.stem, "repeats": repeats,
           "command_s": statistics.median(commands), "command_min_s": min(commands),
           "command_max_s": max(commands)}
    for key in phases[0]:
        row[key] = statistics.median(p[key] for p in phases)
    row["phases_s"] = sum(row[f"{p}_s"] for p in PHASES)
    return row


def report(run, row: dict) -> None:
    """startup.csv, startup.png (the phases as one bar) and the summary's section."""
    from bgc.bench import charts
    from bgc.bench.rows import write_rows
    write_rows(run.out / "startup.csv", [row])
    charts.startup(row, PHASES, run.out / "startup.png",
                   f"{row['model']}: warm start to first result, by phase", TARGET_S)
    verdict = "pass" if row["command_s"] <= TARGET_S else "FAIL"
    run.summary.append("## Start-up: a small model to its first result, warm\n")
    run.summary.append(
        f"`bgc simulate models/{row['model']}.yaml --out FILE -q` (2 states) with its "
        "module and numba's cache present, timed around a fresh interpreter: median "
        f"{row['command_s']:.3f} s over {row['repeats']} runs (min "
        f"{row['command_min_s']:.3f}, max {row['command_max_s']:.3f}); target <= "
        f"{TARGET_S} s: **{verdict}**. Where it goes (`startup.csv`, `startup.png`; the "
        "same steps in one interpreter, medians, wall and CPU seconds):\n")
    run.table([{"phase": p, "wall_s": row[f"{p}_s"],
                "cpu_s": row.get(f"{p}_cpu_s", float("nan"))} for p in PHASES],
              ["phase", "wall_s", "cpu_s"])
    run.targets.append(f"small model warm start to first result (target <= {TARGET_S} s): "
                       f"{row['command_s']:.3g} s {verdict}")
    run.data["startup"] = row
