"""Compile cost of an assembly (issue 40, item 5): the IFToMM A02 N-four-bar
(models/n_four_bar.yaml, N windows of the library's four_bar_window) from the model file
to the first result, for N = 10, 40, 160 (21 to 321 bodies), with the generated code's
instance loops (bgc.codegen.instances) and written out per instance.

Each point is a fresh interpreter running ``bgc simulate MODEL -p N=... --t-end 0.01
--json``: a fresh output directory and a numba cache that holds bgc's native step loop
(compiled once, beforehand: "the step loop cached") and nothing of the model (its
kernels and its numba wrappers compile). Per point: the wall time around the process, the
process's CPU time, the report's per-stage seconds, the module's size and its kernel IR's
code (without the tables). ``python bench/components.py --out DIR [--n 10 40 160]``
writes compile_cost.csv and summary.md there.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MODEL = ROOT / "models" / "n_four_bar.yaml"
STAGES = ("load", "causality", "equations", "jacobian", "emit", "machine code", "integrate")
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
                   env=env, check=True, capture_output=True, timeout=1800)
    return cache


def point(n: int, loops: bool, root: Path, cache: Path) -> dict:
    """One cold build and first result."""
    work = Path(tempfile.mkdtemp(dir=root))
    own_cache = work / "cache"
    shutil.copytree(cache, own_cache)
    env = dict(os.environ, NUMBA_CACHE_DIR=str(own_cache))
    cmd = [sys.executable, "-c", LOOPS if loops else STRAIGHT, "simulate", str(MODEL),
           "-p", f"N={n}", "-o", str(work / "gen"), "--t-end", "0.01", "--json", "--quiet"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    r = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=3600)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if r.returncode != 0:
        raise SystemExit(f"N = {n}: {r.stderr[-2000:]}")
    rep = json.loads(r.stdout)
    module = next((work / "gen").glob("n_four_bar*.py"))
    text = module.read_text()
    ir = "".join(re.findall(r'^_KERNEL_IR(?:_STRAIGHT)? = """\\\n(.*?)"""', text, re.S | re.M))
    code = sum(len(line) + 1 for line in ir.splitlines() if not line.startswith("@"))
    stages = rep.get("stages") or rep.get("timings") or {}
    out = {"N": n, "bodies": 2 * n + 1, "loops": loops, "wall_s": round(wall, 2),
           "cpu_s": round(cpu, 2), "module_mb": round(len(text.encode()) / 1e6, 2),
           "kernel_code_mb": round(code / 1e6, 2),
           "loop_functions": len(re.findall(r"_loop\d+\(", text)) // 2}
    out.update({f"{s}_s": round(stages[s], 2) for s in STAGES if s in stages})
    shutil.rmtree(work, ignore_errors=True)
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="bench/results/components")
    ap.add_argument("--n", type=int, nargs="+", default=[10, 40, 160])
    ap.add_argument("--straight", action="store_true",
                    help="also each N with the instance loops off")
    a = ap.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    root = Path(tempfile.mkdtemp(prefix="bgc_components_"))
    cache = loop_cache(root)
    rows = []
    for n in a.n:
        for loops in (True, False) if a.straight else (True,):
            rows.append(point(n, loops, root, cache))
            print(json.dumps(rows[-1]), flush=True)
    keys = list(dict.fromkeys(k for r in rows for k in r))
    (out / "compile_cost.csv").write_text(
        ",".join(keys) + "\n" + "".join(",".join(str(r.get(k, "")) for k in keys) + "\n"
                                        for r in rows))
    lines = ["# A02 N-four-bar: model file to first result (cold module, native loop "
             "cached)", "", "| " + " | ".join(keys) + " |",
             "|" + "---|" * len(keys)]
    lines += ["| " + " | ".join(str(r.get(k, "")) for k in keys) + " |" for r in rows]
    lines += ["", f"load average at the end: {os.getloadavg()[0]:.1f} on {os.cpu_count()} "
              "cores (the wall times are the machine's at that load; cpu_s is the "
              "process's own)"]
    (out / "summary.md").write_text("\n".join(lines) + "\n")
    shutil.rmtree(root, ignore_errors=True)


if __name__ == "__main__":
    main()
