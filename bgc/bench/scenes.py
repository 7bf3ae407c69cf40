"""The measured gain of a scene's reductions (issue 7): for each scene, the full model
under the scene's method against the scene's reduced module (``bgc.scene.scenes``): states,
derivation and cold numba compile time, run time on the scene's own settings, and the
largest difference of the scene's outputs, relative to each output's peak, set beside
the full model's own integration error on the scene's tolerances (against a run at
1/1000 of them): a pass that is exact leaves a difference of that size.

The full model's derivation and cold compile are the model's (measured once, shared by
its scenes); each reduced module is derived and compiled cold on its own, in a fresh
interpreter with an empty numba cache, like ``compile_cost``."""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from bgc.bench.compile_cost import FUNCTIONS, timed_subprocess
from bgc.codegen import emit
from bgc.model import load
from bgc.pipeline import compile_model
from bgc.scene.scenes import Scene, reduced_system, scene_values
from bgc.simulate import simulate


def _cold(path: Path) -> float:
    """Cold numba compile of a module's functions, in a fresh interpreter."""
    with tempfile.TemporaryDirectory() as cache:
        cold = timed_subprocess("cold", path, Path(cache))
    return sum(cold.get(f"{f}_s", 0.0) for f in FUNCTIONS) + cold["entry_points_s"]


def _run(module, scene: Scene, model, tighten: float = 1.0):
    p = np.array(module.PARAMS, dtype=np.float64)
    names = list(module.PARAM_NAMES)
    for name, value in scene_values(scene, model).items():
        if name in names:
            p[names.index(name)] = value
    kw = dict(t_start=scene.t_start, t_end=scene.t_end, rtol=scene.rtol * tighten,
              atol=scene.atol * tighten,
              solver=scene.solver, points=scene.points, params=p)
    simulate(module, **{**kw, "t_end": scene.t_start + 1e-4, "points": 2})   # warm
    return simulate(module, **kw)


def measure(scenes: list[Scene], build: Path, log=print) -> list[dict]:
    """One row per scene (see the module's docstring)."""
    full_cost: dict = {}
    rows = []
    for scene in scenes:
        key = (str(scene.model), scene.method)
        model = load.load(scene.model)
        if key not in full_cost:
            log(f"  {model.name} ({scene.method}): the full model, derived and compiled cold")
            c, path = compile_model(scene.model, build / "scenes_full", scene.method)
            full_cost[key] = (c.timings["equations"] + c.timings["emit"], _cold(path),
                              emit.import_module(path), len(c.system.states))
        derive_full, cold_full, full, n_full = full_cost[key]
        log(f"  {scene.name}: reduce, derive and compile cold")
        t0 = time.perf_counter()
        _, system, reports = reduced_system(scene)
        path = emit.write(system, build / "scenes_reduced")
        derive_red = time.perf_counter() - t0
        reduced = emit.import_module(path)
        cold_red = _cold(path)
        a, b = _run(full, scene, model), _run(reduced, scene, model)
        ref = _run(full, scene, model, tighten=1e-3)
        diff = error = 0.0
        for out in scene.outputs:
            ya, yb, yr = a.column(out), b.column(out), ref.column(out)
            peak = np.abs(yr).max()
            if peak > 0:
                diff = max(diff, float(np.abs(ya - yb).max() / peak))
                error = max(error, float(np.abs(ya - yr).max() / peak))
        rows.append({
            "scene": scene.name, "model": model.name, "method": scene.method,
            "solver": scene.solver, "rtol": scene.rtol,
            "states_full": n_full, "states_reduced": len(reduced.STATE_NAMES),
            "params_full": len(full.PARAM_NAMES), "params_reduced": len(reduced.PARAM_NAMES),
            "passes": "; ".join(f"{r.name} {r.states_before}->{r.states_after}"
                                for r in reports),
            "derive_full_s": derive_full, "derive_reduced_s": derive_red,
            "numba_cold_full_s": cold_full, "numba_cold_reduced_s": cold_red,
            "run_full_s": a.stats.wall_time, "run_reduced_s": b.stats.wall_time,
            "run_gain": a.stats.wall_time / b.stats.wall_time,
            "steps_full": a.stats.steps, "steps_reduced": b.stats.steps,
            "output_difference": diff, "integration_error_full": error})
        log(f"    {scene.name}: states {n_full} -> {len(reduced.STATE_NAMES)}, run "
            f"{a.stats.wall_time:.3g} -> {b.stats.wall_time:.3g} s, difference {diff:.2g} "
            f"(the full model's integration error {error:.2g})")
    return rows
