"""Compile cost: where the time goes between a model file and the first step.

- derivation (load, expand + causality, equations in sympy) and emitting, in process;
- numba's cold compile of each generated function, in a fresh interpreter with an empty
  cache (``NUMBA_CACHE_DIR``), and bgc's native step loop, which is compiled once per
  machine, not per model, reported apart;
- warm start: a fresh interpreter with that cache, from its launch to the end of the
  first step (what a user waits for on the second run);
- the generated module's size and operation count (arithmetic and calls in ``rhs``,
  ``jac``, ``outputs``, counted on its syntax tree), and how that count grows with the
  SARIB's legs (1 to 4): linear growth is the sign of no expression swell.

The subprocess parts run ``WORKER``, which imports only what a user's script would.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from ..pipeline import compile_model

FUNCTIONS = ("rhs", "jac", "outputs", "guards", "constraints")


def operations(path: Path) -> dict[str, int]:
    """Arithmetic operations and calls in each generated function (its syntax tree)."""
    tree = ast.parse(Path(path).read_text())
    out = {}
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name in ("rhs", "jac", "outputs"):
            out[node.name] = sum(isinstance(n, (ast.BinOp, ast.UnaryOp, ast.Call))
                                 for n in ast.walk(node))
    return out


def derive(model: str | Path, method: str) -> dict:
    """Derivation and emit times, size and operation counts of a fresh compile."""
    with tempfile.TemporaryDirectory() as tmp:
        c, path = compile_model(model, tmp, method)
        text = path.read_text()
        ops = operations(path)
    return {"states": len(c.system.states), "load_s": c.timings["load"],
            "causality_s": c.timings["causality"], "sympy_s": c.timings["equations"],
            "emit_s": c.timings["emit"], "module_bytes": len(text.encode()),
            "module_lines": text.count("\n"), **{f"ops_{k}": v for k, v in ops.items()}}


# What runs in the fresh interpreter: only what a user's script imports (``bgc.emit``,
# ``bgc.simulate``), not this benchmark package. ``cold`` times each function's first call
# (its compile) and the native loop's; ``warm`` (the cache filled) imports the module and
# takes the first step. Both report the time from the interpreter's launch (BGC_LAUNCH,
# the parent's clock just before it starts the process) to the end of the first step.
WORKER = """
import json, os, sys, time
from pathlib import Path
t0 = time.perf_counter()
from bgc.emit import import_module
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
t1 = time.perf_counter()
r = simulate(mod, t_end=1e-4, solver="native", points=2)
out["first_step_s"] = time.perf_counter() - t1
out["launch_to_first_step_s"] = time.time() - float(os.environ["BGC_LAUNCH"])
out["loop_and_setup_s"] = r.stats.compile_time
print(json.dumps(out))
""" % (FUNCTIONS,)


def _subprocess(mode: str, path: Path, cache: Path) -> dict:
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


def measure(model: str | Path, method: str, build: Path) -> dict:
    """Derivation, cold numba compile and warm start of one model under one method."""
    row = {"model": Path(model).stem, "method": method, **derive(model, method)}
    build.mkdir(parents=True, exist_ok=True)
    c, path = compile_model(model, build / f"cost_{method}", method)
    with tempfile.TemporaryDirectory() as cache:
        cold = _subprocess("cold", path, Path(cache))
        warm = _subprocess("warm", path, Path(cache))
    row.update({f"cold_{k}": v for k, v in cold.items()})
    row["numba_cold_model_s"] = sum(cold.get(f"{f}_s", 0.0) for f in FUNCTIONS) + \
        cold["entry_points_s"]
    # the first step in the cold process compiled the step loop too (once per machine)
    row["native_loop_cold_s"] = cold["loop_and_setup_s"]
    row["warm_to_first_step_s"] = warm["launch_to_first_step_s"]
    row["warm_process_s"] = warm["process_s"]        # with the interpreter's exit
    row["warm_import_s"] = warm["import_s"]
    return row


def sarib_legs(source: Path, legs: int, out: Path) -> Path:
    """The SARIB with only its first ``legs`` legs (beater, bar, hinge and the bar's two
    spherical joints each): same bodies and joints otherwise."""
    data = yaml.safe_load(Path(source).read_text())
    gone = range(legs + 1, 5)
    for i in gone:
        for key in (f"beater_{i}", f"bar_{i}"):
            data["bodies"].pop(key)
        for key in (f"hinge_{i}", f"bar_bottom_{i}", f"bar_top_{i}"):
            data["joints"].pop(key)
    data["outputs"] = {k: v for k, v in data["outputs"].items()
                       if not any(f"hinge_{i}." in str(v) for i in gone)}
    data["name"] = f"sarib_{legs}leg"
    path = out / f"sarib_{legs}leg.yaml"
    out.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(data, sort_keys=False))
    return path


def growth(source: Path, methods, build: Path, legs=(1, 2, 3, 4)) -> list[dict]:
    """Operation counts and derivation time of the SARIB with 1..4 legs, per method."""
    rows = []
    for n in legs:
        path = sarib_legs(source, n, build / "legs")
        for method in methods:
            rows.append({"legs": n, "method": method, **derive(path, method)})
    return rows
