"""Scenes: the question a simulation asks of a model (YAML -> Scene -> reduced module).

A scene names a model and the method, excitation, outputs, time span, tolerances and
solver of one run; ``expose`` lists the parameters it keeps adjustable (``-p``), every
other is folded into the equations; ``merge_relays: true`` lets the relay merge change a
parasitic model (see ``reduce``). ``ensure_scene_module`` builds the model, runs the passes
of ``reduce`` and writes ``<out_dir>/<model>_<method>_<scene>.py``; ``run_scene``
simulates it.

    model: ../models/sarib.yaml
    method: parasitic
    excitation: {kind: chirp, direction: pumping}      # amplitude, frequency: optional
    outputs: [a_OF_z, F_A1_z, F_A2_z]
    time: {end: 28.0, points: 28001}                   # start: 0
    tolerances: {rtol: 1.0e-5, atol: 1.0e-5}
    solver: native
    expose: []
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field, replace
from pathlib import Path

from bgc import methods
from bgc.codegen import emit
from bgc.errors import Loc, ModelError
from bgc.fileio import atomic_write
from bgc.model import document, limits, load
from bgc.model.document import YMap
from bgc.model.values import check_keys, fail, mapping, number, points, string, strings
from bgc.pipeline import build
from bgc.scene import reduce
from bgc.scene.merge_relays import merge_relays

KEYS = ("name", "description", "model", "method", "excitation", "outputs", "time",
        "tolerances", "solver", "expose", "params", "merge_relays", "activity")


@dataclass
class Scene:
    name: str
    file: str
    model: Path
    method: str
    excitation: dict | None       # kind, direction, amplitude?, frequency?
    outputs: list[str]
    t_start: float
    t_end: float
    points: int
    rtol: float
    atol: float
    solver: str
    expose: list[str]
    params: dict[str, float]      # values the scene sets (folded unless exposed)
    digest: str
    # merge relay chains: None = where exact (ideal joints); True also under parasitic
    merge_relays: bool | None = None
    # where each name of ``expose`` and ``params`` stands in the scene file
    name_locs: dict = field(default_factory=dict)
    # activity: {keep: K}: the activity pass keeps the elements that carry K of the
    # activity over the scene's run (``reduce.activity``); None: no such pass
    activity_keep: float | None = None
    # activity: {junctions: J}: each junction keeps the bond terms that carry J of its
    # activity, the others are cut (``reduce.junctions``); None: no such pass
    activity_junctions: float | None = None


def load_scene(path: str | Path) -> Scene:
    """Read a scene file; every mistake is one located line."""
    from bgc.model.model import SOLVERS
    path = Path(path)
    doc = document.read(path, "scene file", "scene")
    if not isinstance(doc, YMap):
        raise ModelError("a scene file is a mapping", loc=Loc(str(path), 1),
                         hint="keys: " + ", ".join(KEYS))
    check_keys(doc, KEYS, "scene")
    for key in ("model", "outputs", "time"):
        if key not in doc:
            fail(f"missing key '{key}'", doc.loc, key,
                 "a scene needs " + ", ".join(("model", "outputs", "time")))
    model_path = (path.parent / string(doc["model"], _at(doc, "model"), "model",
                                       "a model file path")).resolve()
    if not model_path.is_file():
        fail(f"no such model file: {model_path}" if not model_path.exists() else
             f"{model_path} is not a regular file", _at(doc, "model"), "model",
             "a path relative to the scene file")
    model = load.load(model_path)
    method = string(doc.get("method", "parasitic"), _at(doc, "method"), "method",
                    "a method name")
    if method not in methods.NAMES:
        fail(f"unknown method '{method}'", _at(doc, "method"), "method",
             "valid methods: " + ", ".join(methods.NAMES))
    solver = string(doc.get("solver", "native"), _at(doc, "solver"), "solver",
                    "a solver name")
    if solver not in SOLVERS:
        fail(f"unknown solver '{solver}'", _at(doc, "solver"), "solver",
             "valid solvers: " + ", ".join(SOLVERS))
    outputs = _outputs(doc, model)
    exc = _excitation(doc, model)
    t_start, t_end, n_points = _time(doc, exc)
    rtol, atol = _tolerances(doc, model)
    params, name_locs = _params(doc)
    expose = (strings(doc["expose"], _at(doc, "expose"), "expose", "parameter names")
              if doc.get("expose") is not None else [])
    for k, name in enumerate(expose):
        loc = doc["expose"].item_locs[k]
        if name in expose[:k]:
            fail(f"'{name}' is exposed twice", loc, f"expose[{k}]",
                 f"it is listed already at line {name_locs[name].line}")
        name_locs[name] = loc
    _check_parameters(model, method, expose, params, name_locs)
    merge = doc.get("merge_relays")
    if merge is not None and not isinstance(merge, bool):
        fail(f"merge_relays is true or false, got {merge!r}", _at(doc, "merge_relays"),
             "merge_relays", "true: merge also under parasitic (changes the joints' "
             "parasitic compliance); false: never; absent: where exact")
    keep, junctions = _activity(doc)
    name = doc.get("name", path.stem)
    if not isinstance(name, str) or not name.isidentifier():
        fail(f"scene name {name!r} is not a valid module name", _at(doc, "name"), "name",
             "letters, digits and '_'")
    digest = hashlib.sha256(json.dumps(
        [model.digest, method, exc, outputs, params, expose, merge] +
        ([keep, t_start, t_end, n_points, rtol, atol, solver] if keep is not None else []) +
        ([junctions, t_start, t_end, n_points, rtol, atol, solver]
         if junctions is not None else []),
        sort_keys=True, default=str).encode()).hexdigest()[:16]
    return Scene(name, str(path), model_path, method, exc, list(outputs), t_start, t_end,
                 n_points, rtol, atol, solver, expose, params, digest, merge, name_locs,
                 keep, junctions)


_SHARES = {"keep": "remove the least active elements that carry 0.1 % of the model's "
                   "activity",
           "junctions": "at each junction, cut the bonds that carry 0.1 % of its activity"}


def _activity(doc: YMap) -> tuple[float | None, float | None]:
    """``activity: {keep: K, junctions: J}``, each 0 < share <= 1, at least one: the
    share of the run's activity the element pass keeps, and of each junction's the
    junctions pass keeps; None for a pass not asked for."""
    if doc.get("activity") is None:
        return None, None
    a = mapping(doc["activity"], _at(doc, "activity"), "activity")
    check_keys(a, tuple(_SHARES), "activity")
    if not any(k in a for k in _SHARES):
        fail("activity needs 'keep' or 'junctions'", a.loc, "activity",
             "keep: the share of the run's activity the elements keep, e.g. {keep: "
             "0.999}; junctions: the share of each junction's the bonds keep, e.g. "
             "{junctions: 0.99}")
    out = []
    for key, example in _SHARES.items():
        if key not in a:
            out.append(None)
            continue
        v = number(a[key], _at(a, key), f"activity.{key}", positive=True)
        if v > 1:
            fail(f"activity.{key} is a share of the activity, 0 < {key} <= 1, got {v:g}",
                 _at(a, key), f"activity.{key}", f"e.g. 0.999: {example}")
        out.append(v)
    return out[0], out[1]


def _check_parameters(model, method: str, expose, params, locs) -> None:
    """Every exposed or set parameter is one the model declares (with the method's):
    refused at its own line in the scene, before any build."""
    from bgc.pipeline import Declared
    known = Declared.of_model(model, method).params
    for name in list(expose) + list(params):
        if name not in known:
            fail(f"unknown parameter '{name}' of model {model.name}", locs[name],
                 "expose" if name in expose else f"params.{name}",
                 "its parameters: " + (", ".join(n for n in known if "__" not in n)
                                       or "none") + " (and the joints' values bgc adds, "
                 "<joint>__<value>)")


def _at(m: YMap, key):
    """Where ``key`` of ``m`` stands (where ``m`` does, if it is missing)."""
    return m.val_locs.get(key, m.loc)


def _outputs(doc: YMap, model):
    """``outputs:``, a non-empty list of the model's output names."""
    outputs = doc["outputs"]
    names = [o.name for o in model.outputs]
    valid = ("model outputs: " + ", ".join(names) if names else
             f"model {model.name} declares no outputs: add an 'outputs:' section to it")
    if not isinstance(outputs, list) or not outputs:
        fail("expected a non-empty list of outputs", _at(doc, "outputs"), "outputs", valid)
    strings(outputs, _at(doc, "outputs"), "outputs", "output names")
    for k, o in enumerate(outputs):
        if o not in names:
            fail(f"unknown output '{o}' of model {model.name}", outputs.item_locs[k],
                 f"outputs[{k}]", valid)
        if o in outputs[:k]:
            fail(f"output '{o}' is listed twice", outputs.item_locs[k], f"outputs[{k}]",
                 f"it is listed already at line "
                 f"{outputs.item_locs[outputs.index(o)].line}")
    return outputs


def _excitation(doc: YMap, model) -> dict | None:
    """``excitation:`` {kind, direction, amplitude?, frequency?}, one the model's
    ``Excitation.select`` accepts; None without it."""
    if doc.get("excitation") is None:
        return None
    e = mapping(doc["excitation"], _at(doc, "excitation"), "excitation")
    check_keys(e, ("kind", "direction", "amplitude", "frequency"), "excitation")
    if model.excitation is None:
        fail(f"model {model.name} has no excitation section", e.loc, "excitation",
             "drop 'excitation:' or name a model that has one")
    exc = {k: string(e.get(k), _at(e, k), f"excitation.{k}", f"a {k} name")
           for k in ("kind", "direction")}
    for k in ("amplitude", "frequency"):
        if k in e:
            exc[k] = number(e[k], _at(e, k), f"excitation.{k}", positive=True)
    try:
        model.excitation.select(exc["kind"], exc["direction"], exc.get("amplitude"),
                                exc.get("frequency"))
    except Exception as err:          # BgcError naming the CLI option: relocate it
        fail(getattr(err, "message", str(err)), e.loc, "excitation",
             getattr(err, "hint", None))
    return exc


def _time(doc: YMap, exc: dict | None) -> tuple[float, float, int]:
    """``time:`` {start?, end, points?} -> (start, end, points); a sine's frequency must
    be slow enough for the span (``limits.too_fast``)."""
    tm = mapping(doc["time"], _at(doc, "time"), "time")
    check_keys(tm, ("start", "end", "points"), "time")
    t_start = number(tm.get("start", 0.0), _at(tm, "start"), "time.start", nonneg=True)
    if "end" not in tm:
        fail("missing key 'end'", tm.loc, "time.end")
    t_end = number(tm["end"], _at(tm, "end"), "time.end", positive=True)
    if t_end <= t_start:
        fail(f"end {t_end:g} must be after start {t_start:g}", _at(tm, "end"), "time.end")
    n_points = points(tm.get("points", 1001), _at(tm, "points"), "time.points")
    if exc is not None and "frequency" in exc:
        why = limits.too_fast(exc["frequency"], t_end - t_start)
        if why:
            fail(why, _at(doc["excitation"], "frequency"), "excitation.frequency",
                 "lower the frequency or shorten time.end")
    return t_start, t_end, n_points


def _tolerances(doc: YMap, model) -> tuple[float, float]:
    """``tolerances:`` {rtol?, atol?} -> (rtol, atol), each the model's if not given."""
    tol = (mapping(doc["tolerances"], _at(doc, "tolerances"), "tolerances")
           if doc.get("tolerances") is not None else None)
    tols = {}
    for k in ("rtol", "atol"):
        default = getattr(model.settings, k, None) or (1e-6 if k == "rtol" else 1e-8)
        tols[k] = (number(tol[k], _at(tol, k), f"tolerances.{k}", positive=True)
                   if tol is not None and k in tol else default)
    if tol is not None:
        check_keys(tol, ("rtol", "atol"), "tolerances")
    return tols["rtol"], tols["atol"]


def _params(doc: YMap) -> tuple[dict[str, float], dict]:
    """``params:`` {name: value}, the values the scene sets, and where each name stands."""
    params, locs = {}, {}
    if doc.get("params") is not None:
        pm = mapping(doc["params"], _at(doc, "params"), "params")
        for k, v in pm.items():
            string(k, pm.key_locs[k], "params", "a parameter name")
            params[k] = number(v, _at(pm, k), f"params.{k}")
            locs[k] = pm.key_locs[k]
    return params, locs


def scene_values(scene: Scene, model) -> dict[str, float]:
    """Parameter values the scene fixes: its excitation's and its ``params``."""
    values = {}
    if scene.excitation is not None:
        e = scene.excitation
        values.update(model.excitation.select(e["kind"], e["direction"], e.get("amplitude"),
                                              e.get("frequency")))
    values.update(scene.params)
    return values


def reduced_system(scene: Scene, gen_dir: str | Path = "generated/scenes"):
    """(full Compiled, reduced EquationSystem, pass reports). ``merge_relays`` works on
    the model, so its report compares the full model's build with the merged one's. A
    scene with ``activity`` runs its model's energy variant (in ``gen_dir``) first."""
    c = build(scene.model, scene.method)
    known = {name for _, name, _ in c.system.params}
    for name in list(scene.expose) + list(scene.params):
        if name not in known:       # a parameter the method does not keep
            raise ModelError(f"model {c.model.name} has no parameter '{name}' under method "
                             f"{scene.method}", key="expose" if name in scene.expose
                             else f"params.{name}",
                             loc=scene.name_locs.get(name, Loc(scene.file, 1)),
                             hint="its parameters under this method: " + ", ".join(
                                 n for n in sorted(known) if "__" not in n))
    merged, removed, note = merge_relays(
        c.model, scene.outputs, list(scene.expose) + list(scene.params))
    merged_c = c
    wanted = methods.get(scene.method).ideal if scene.merge_relays is None \
        else scene.merge_relays
    if removed and wanted:
        merged_c = build(merged, scene.method)
    elif removed:
        why = ("the scene says merge_relays: false" if scene.merge_relays is False else
               "under parasitic each joint's compliance is part of the model "
               "(merge_relays: true accepts the change)")
        removed, note = [], f"would merge {note}; left: {why}"
    first = reduce.report("merge_relays", c.system, merged_c.system, removed, note)
    activity_of = junctions_of = None
    if scene.activity_keep is not None or scene.activity_junctions is not None:
        shares, terms, reference = activity_shares(scene, merged_c.model, gen_dir)
        if scene.activity_keep is not None:
            activity_of = (merged_c.causal, shares, scene.activity_keep)
        if scene.activity_junctions is not None:
            junctions_of = (merged_c.causal, terms, scene.activity_junctions)
    system, reports = reduce.reduce(merged_c.system, scene.outputs,
                                    scene_values(scene, merged_c.model), scene.expose,
                                    activity_of, junctions_of)
    for r in reports:
        if r.name in ("activity", "junctions"):
            r.reference = reference
    model = replace(merged_c.model, digest=scene.digest)
    return c, replace(system, model=model, scene=scene.name), [first] + reports


def _values(module, scene: Scene, model) -> "np.ndarray":
    """The module's parameters with the scene's values (its excitation's, ``params``)."""
    import numpy as np
    p = np.array(module.PARAMS, dtype=np.float64)
    names = list(module.PARAM_NAMES)
    for name, value in scene_values(scene, model).items():
        if name in names:
            p[names.index(name)] = value
    return p


def activity_shares(scene: Scene, model, gen_dir: str | Path = "generated/scenes"):
    """Each element's share of the activity over the scene's run, from the energy
    variant (``bgc energy``) of ``model`` (the scene's, its relays merged if they were)
    run on the scene's settings; each junction term's activity (``activity[...]``, the
    states of the junctions' variant, ``codegen.energy.junction_terms``; empty unless
    the scene asks for the junctions pass, which then runs that variant instead); and
    that run's outputs (the reference the reduced module's error is measured against).
    The variant is kept in ``gen_dir``/energy."""
    from bgc import progress
    from bgc.analysis import energy
    from bgc.pipeline import compile_model
    from bgc.simulate import simulate
    junctions = scene.activity_junctions is not None
    kind = f"{methods.variant(scene.method)}_{'junctions' if junctions else 'energy'}"
    where = Path(gen_dir) / "energy"
    path = emit.module_path(model.name, where, kind)
    if emit.is_stale(path, model.digest, kind):
        compile_model(model, where, scene.method, **{"junctions" if junctions else
                                                      "energy": True})
    module = emit.import_module(path)
    with progress.stage("activity") as st:
        res = simulate(module, t_start=scene.t_start, t_end=scene.t_end, rtol=scene.rtol,
                       atol=scene.atol, solver=scene.solver, points=scene.points,
                       params=_values(module, scene, model))
        bal = energy.account(module, res)
        terms = {}
        if junctions:
            names = list(res.state_names)
            terms = {n: float(res.x[-1, k] - res.x[0, k]) for k, n in enumerate(names)
                     if n.startswith("activity[")}
        st.done(f"{len(bal.elements)} elements' activity over the scene's run" +
                (f", {len(terms)} junction terms'" if junctions else ""))
    return {ln.name: ln.share for ln in bal.elements}, terms, res


def ensure_scene_module(scene: Scene, out_dir: str | Path = "generated/scenes"):
    """The scene's reduced module, rebuilt only when the scene or its model changed.
    Returns (module, the pass reports as dicts, kept beside it in ``.passes.json``)."""
    from bgc.methods import variant
    path = emit.module_path(load.load(scene.model).name, out_dir,
                            f"{variant(scene.method)}_{scene.name}")
    passes = path.with_suffix(".passes.json")
    if emit.is_stale(path, scene.digest, f"{variant(scene.method)}_{scene.name}") or \
            not passes.exists():
        _, system, reports = reduced_system(scene, out_dir)
        path = emit.write(system, out_dir)
        measured = None
        for r in reports:       # the reduced module against the full model's run, once
            if getattr(r, "reference", None) is not None:
                measured = measured or activity_error(scene, emit.import_module(path),
                                                      r.reference)
                r.error, failed = measured
                if failed:
                    r.note += f"; the reduced module's run failed: {failed}"
        atomic_write(passes, json.dumps([r.to_dict() for r in reports], indent=2))
    return emit.import_module(path), json.loads(passes.read_text())


def activity_error(scene: Scene, module, reference) -> tuple[dict[str, float], str]:
    """The reduced module's outputs against the full model's over the scene's run: the
    largest difference relative to each output's peak; and '' or, where the reduced
    module's run failed, why (the difference is then over the run up to there)."""
    import numpy as np

    from bgc.errors import SimulationError
    from bgc.simulate import simulate
    model = load.load(scene.model)
    failed = ""
    try:
        res = simulate(module, t_start=scene.t_start, t_end=scene.t_end, rtol=scene.rtol,
                       atol=scene.atol, solver=scene.solver, points=scene.points,
                       params=_values(module, scene, model))
    except SimulationError as exc:
        if exc.result is None:
            raise
        res, failed = exc.result, str(exc)
    out = {}
    n = len(res.t)
    for name in scene.outputs:
        ref = reference.column(name)[:n]
        peak = float(np.abs(reference.column(name)).max())
        out[name] = (float(np.abs(res.column(name)[:n] - ref).max() / peak)
                     if peak > 0 and n else 0.0)
    return out, failed


def is_scene(path: str | Path) -> bool:
    """A scene file names a model (``model:``); a model file has bodies or elements."""
    try:        # the same bounded reader as the loader: a hostile file is refused there
        doc = document.read(path)
    except ModelError:
        return False
    return isinstance(doc, dict) and "model" in doc


def check_scene(scene: Scene, gen_dir: str | Path = "generated/scenes") -> list[dict]:
    """The state count before and after each reduction pass."""
    _, _, reports = reduced_system(scene, gen_dir)
    return [r.to_dict() for r in reports]


def run_scene(scene: Scene, out_dir: str | Path, gen_dir: str | Path = "generated/scenes",
              params=None) -> dict:
    """Simulate the scene's reduced module; write ``<out_dir>/<scene>.csv``, ``.png`` and
    ``.json`` (the summary: states, passes, statistics, envelope minima of a chirp).
    A failing run keeps its results up to the failure (the CSV is still written)."""
    import time

    import numpy as np

    from bgc.analysis import noise
    from bgc.analysis.results import output_units, plot, write_csv
    from bgc.errors import SimulationError
    from bgc.simulate import simulate
    t0 = time.perf_counter()
    module, reports = ensure_scene_module(scene, gen_dir)
    build_s = time.perf_counter() - t0
    model = load.load(scene.model)
    p = np.array(module.PARAMS, dtype=np.float64)
    names = list(module.PARAM_NAMES)
    for name, value in {**scene_values(scene, model), **(params or {})}.items():
        if name in names:
            p[names.index(name)] = value
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    error = None
    try:
        result = simulate(module, t_start=scene.t_start, t_end=scene.t_end, rtol=scene.rtol,
                          atol=scene.atol, solver=scene.solver, points=scene.points,
                          params=p)
    except SimulationError as exc:
        if exc.result is None:
            raise
        result, error = exc.result, str(exc)
    units = output_units(module)
    floor, quiet = noise.of_result(result, units, scene.rtol)
    files = {"csv": str(write_csv(result, out_dir / f"{scene.name}.csv", states=False)),
             "png": str(plot(result, out_dir / f"{scene.name}.png",
                             title=f"{scene.name}: {model.name} ({scene.method}, "
                                   f"{result.solver})", units=units, floor=floor))}
    minima = None
    if error is None:
        from bgc.analysis.envelope import chirp_sweep, minima_hz
        minima = minima_hz(chirp_sweep(model.excitation, scene.excitation, result, floor),
                           3)
    summary = {"scene": scene.name, "file": scene.file, "model": model.name,
               "method": scene.method, "solver": result.solver,
               "excitation": scene.excitation, "outputs": scene.outputs,
               "states": len(module.STATE_NAMES), "passes": reports,
               "t_end": float(result.t[-1]) if len(result.t) else scene.t_start,
               "build_s": build_s, "stats": result.stats.to_dict(),
               "envelope_minima_hz": minima, "noise_outputs": quiet, "ok": error is None,
               "error": error, "files": files}
    path = out_dir / f"{scene.name}.json"
    atomic_write(path, json.dumps(summary, indent=2, default=str) + "\n")
    summary["files"]["json"] = str(path)
    return summary
