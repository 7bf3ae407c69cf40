"""What the activity pass gains (issue 42): each SARIB chirp scene (pumping, roll, pitch)
under parasitic and zcp, reduced by the exact passes (``merge_relays``, ``fold_parameters``,
``idle_dofs``, ``prune``) and then also by ``activity`` (Louca et al.'s element activity
over the scene's run, ``keep``), side by side: states after each, the elements removed,
the steps and run time of both reduced modules (warm, the scene's own settings, medians
of repeats), and the outputs' largest difference from the full model's run (the activity
pass's own report) and from the exact passes' run."""

from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from bgc.model import load
from bgc.scene.scenes import Scene, ensure_scene_module, scene_values
from bgc.simulate import simulate

KEEP = 0.99999


def _variant(scene: Scene, method: str, keep: float | None) -> Scene:
    name = f"{scene.name}_{method}" + ("_activity" if keep is not None else "")
    digest = hashlib.sha256(f"{scene.digest}|{method}|{keep}".encode()).hexdigest()[:16]
    return replace(scene, method=method, name=name, activity_keep=keep, digest=digest)


def _run(module, scene: Scene, model):
    p = np.array(module.PARAMS, dtype=np.float64)
    names = list(module.PARAM_NAMES)
    for name, value in scene_values(scene, model).items():
        if name in names:
            p[names.index(name)] = value
    kw = dict(t_start=scene.t_start, t_end=scene.t_end, rtol=scene.rtol, atol=scene.atol,
              solver=scene.solver, points=scene.points, params=p)
    simulate(module, **{**kw, "t_end": scene.t_start + 1e-4, "points": 2})      # warm
    return simulate(module, **kw)


def measure(scenes: list[Scene], methods, build: Path, log=print,
            keep: float = KEEP, repeats: int = 3) -> list[dict]:
    """One row per scene and method (see the module's docstring); run times are the
    medians of ``repeats`` runs of each module, taken in turns."""
    rows = []
    for base in scenes:
        model = load.load(base.model)
        for method in methods:
            exact, reduced = _variant(base, method, None), _variant(base, method, keep)
            log(f"  {exact.name}: the exact passes, then activity (keep {keep:g})")
            m0, passes0 = ensure_scene_module(exact, build / "activity")
            m1, passes1 = ensure_scene_module(reduced, build / "activity")
            act = next(p for p in passes1 if p["pass"] == "activity")
            times = {0: [], 1: []}
            for _ in range(max(1, repeats)):
                a, b = _run(m0, exact, model), _run(m1, reduced, model)
                times[0].append(a.stats.wall_time)
                times[1].append(b.stats.wall_time)
            t0, t1 = float(np.median(times[0])), float(np.median(times[1]))
            # the exact passes' module against the full run the activity pass measured
            # against is the reduced run's reference: compare the two reduced runs too
            diff = max((float(np.abs(a.column(o) - b.column(o)).max()
                              / (np.abs(a.column(o)).max() or 1.0)) for o in base.outputs),
                       default=0.0)
            removed = [r for r in act["removed"] if not r.endswith((".q", ".p"))]
            rows.append({
                "scene": base.name, "method": method, "keep": keep,
                "states_full": passes0[0]["states_before"],
                "states_exact_passes": len(m0.STATE_NAMES),
                "states_activity": len(m1.STATE_NAMES),
                "elements_removed": len(removed),
                "removed": " ".join(removed),
                "steps_exact": a.stats.steps, "steps_activity": b.stats.steps,
                "run_exact_s": t0, "run_activity_s": t1, "run_gain": t0 / t1,
                "activity_error": max(act.get("output_error", {}).values(), default=0.0),
                "difference_from_exact": diff,
                "kept_because": act["note"].split("kept below the threshold: ")[-1]
                if not removed else ""})
            log(f"    {exact.name}: states {rows[-1]['states_full']} -> "
                f"{rows[-1]['states_exact_passes']} -> {rows[-1]['states_activity']}, "
                f"{len(removed)} elements removed, {a.stats.steps} -> {b.stats.steps} "
                f"steps, run {t0:.3g} -> {t1:.3g} s, error "
                f"{rows[-1]['activity_error']:.2g}")
    return rows
