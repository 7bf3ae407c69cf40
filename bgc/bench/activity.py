"""What the activity passes gain (issue 42): each SARIB chirp scene (pumping, roll, pitch)
under parasitic and zcp, reduced by the exact passes (``merge_relays``, ``fold_parameters``,
``idle_dofs``, ``prune``), then also by ``activity`` (Louca et al.'s element activity over
the scene's run, ``keep``), and apart from that by ``junctions`` (Rideout, Stein and
Louca's junction inactivity, ``junctions``), side by side: states after each, the elements
removed, the junction terms cut and the parts the model split into, the steps and run
time of each reduced module (warm, the scene's own settings, medians of repeats), and the
outputs' largest difference from the full model's run (each pass's own report) and from
the exact passes' run."""

from __future__ import annotations

import hashlib
from dataclasses import replace
from pathlib import Path

import numpy as np

from bgc.model import load
from bgc.scene.scenes import Scene, ensure_scene_module, scene_values
from bgc.simulate import simulate

KEEP = 0.99999
JUNCTIONS = 0.99


def _variant(scene: Scene, method: str, keep: float | None,
             junctions: float | None = None) -> Scene:
    name = f"{scene.name}_{method}" + ("_activity" if keep is not None else "") + \
        ("_junctions" if junctions is not None else "")
    digest = hashlib.sha256(f"{scene.digest}|{method}|{keep}|{junctions}".encode()
                            ).hexdigest()[:16]
    return replace(scene, method=method, name=name, activity_keep=keep,
                   activity_junctions=junctions, digest=digest)


def _difference(a, b, outputs) -> float:
    """The largest difference of ``b``'s outputs from ``a``'s, relative to each peak."""
    return max((float(np.abs(a.column(o) - b.column(o)).max()
                      / (np.abs(a.column(o)).max() or 1.0)) for o in outputs), default=0.0)


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
            keep: float = KEEP, repeats: int = 3,
            junctions: float | None = JUNCTIONS) -> list[dict]:
    """One row per scene and method (see the module's docstring); run times are the
    medians of ``repeats`` runs of each module, taken in turns. ``junctions`` None: no
    junctions variant."""
    rows = []
    for base in scenes:
        model = load.load(base.model)
        for method in methods:
            exact, reduced = _variant(base, method, None), _variant(base, method, keep)
            variants = [exact, reduced]
            if junctions is not None:
                variants.append(_variant(base, method, None, junctions))
            log(f"  {exact.name}: the exact passes, then activity (keep {keep:g})" +
                ("" if junctions is None else f", and junctions {junctions:g}"))
            built = [ensure_scene_module(v, build / "activity") for v in variants]
            act = next(p for p in built[1][1] if p["pass"] == "activity")
            times = [[] for _ in variants]
            for _ in range(max(1, repeats)):
                runs = [_run(m, v, model) for (m, _), v in zip(built, variants)]
                for k, r in enumerate(runs):
                    times[k].append(r.stats.wall_time)
            t0, t1 = float(np.median(times[0])), float(np.median(times[1]))
            a, b = runs[0], runs[1]
            # the exact passes' module against the full run the activity pass measured
            # against is the reduced run's reference: compare the two reduced runs too
            diff = _difference(a, b, base.outputs)
            removed = [r for r in act["removed"] if not r.endswith((".q", ".p"))]
            (m0, passes0), (m1, _) = built[0], built[1]
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
            if junctions is not None:
                rows[-1].update(_junctions_row(built[2], runs[2], times[2], a, t0, base,
                                              junctions))
            row = rows[-1]
            log(f"    {exact.name}: states {row['states_full']} -> "
                f"{row['states_exact_passes']} -> {row['states_activity']}, "
                f"{len(removed)} elements removed, {a.stats.steps} -> {b.stats.steps} "
                f"steps, run {t0:.3g} -> {t1:.3g} s, error {row['activity_error']:.2g}" +
                ("" if junctions is None else
                 f"; junctions: {row['junction_cuts']} terms cut, {row['junction_parts']} "
                 f"parts, states {row['states_junctions']}, run {row['run_junctions_s']:.3g}"
                 f" s, error {row['junctions_error']:.2g}"))
    return rows


def _junctions_row(built, run, times, exact_run, t_exact: float, base: Scene,
                   junctions: float) -> dict:
    """The junctions variant's columns of a row: its terms cut (of them at round-off,
    with no power in the run), the parts the model split into, the states after it and
    after prune, steps, run time and gain against the exact passes, its error against
    the full model's run (its report) and its difference from the exact passes' run."""
    module, passes = built
    jn = next(p for p in passes if p["pass"] == "junctions")
    t = float(np.median(times))
    return {"junctions": junctions, "junction_cuts": len(jn["cuts"]),
            "junction_cuts_roundoff": sum(c["share"] < 1e-9 for c in jn["cuts"]),
            "junction_parts": len(jn["parts"]),
            "driven_states_removed": sum(len(p["states"]) for p in jn["parts"]
                                         if p["driven_by"] and not p["needed"]),
            "states_junctions": len(module.STATE_NAMES),
            "steps_junctions": run.stats.steps, "run_junctions_s": t,
            "junctions_gain": t_exact / t,
            "junctions_error": max(jn.get("output_error", {}).values(), default=0.0),
            "junctions_difference_from_exact": _difference(exact_run, run, base.outputs)}
