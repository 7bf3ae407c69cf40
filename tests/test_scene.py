"""Scenes and the reduction passes (issue 7): a scene's reduced model answers its question
like the full model; every pass says what it removed; bad scene files get one located
line. The SARIB pumping scene against the full SARIB is marked slow."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from bgc import frf, load
from bgc.cli import main
from bgc.pipeline import ensure_module
from bgc.scene import ensure_scene_module, load_scene, scene_values
from bgc.simulate import simulate
from conftest import MODELS, ROOT

TWO_OSCILLATORS = """
name: two_oscillators
description: A driven mass-spring-damper and a second one that nothing connects to it.
parameters:
  m: 1.5
  k: 600.0
  c: 6.0
  F0: 10.0
  c2: 0.0
signals:
  force: {type: sine, amplitude: F0, frequency: 3.0}
elements:
  drive: {type: Se, effort: force}
  mass: {type: I, I: m}
  spring: {type: C, C: 1/k}
  damper: {type: R, R: c}
  v: {type: "1"}
  mass2: {type: I, I: 2.0, p0: 0.3}
  spring2: {type: C, C: 1/800.0}
  damper2: {type: R, R: c2}
  v2: {type: "1"}
bonds:
  - [drive, v]
  - [v, mass]
  - [v, spring]
  - [v, damper]
  - [v2, mass2]
  - [v2, spring2]
  - [v2, damper2]
outputs:
  position: spring.q
  other: spring2.q
"""


def _scene(tmp_path, model_rel, body, name="scene"):
    path = tmp_path / f"{name}.yaml"
    path.write_text(f"model: {model_rel}\n" + body)
    return path


def _check(path):
    res = CliRunner().invoke(main, ["check", str(path), "--json"])
    assert res.exit_code == 0, res.output
    return {r["pass"]: r for r in json.loads(res.output)}


def test_pruning_and_folding_keep_the_answer_of_a_small_model(tmp_path):
    (tmp_path / "two.yaml").write_text(TWO_OSCILLATORS)
    path = _scene(tmp_path, "two.yaml", "outputs: [position]\ntime: {end: 2.0, points: 201}\n"
                  "tolerances: {rtol: 1.0e-8, atol: 1.0e-10}\nexpose: [k]\n")
    passes = _check(path)
    assert list(passes) == ["fold_parameters", "idle_dofs", "prune"]
    assert (passes["prune"]["states_before"], passes["prune"]["states_after"]) == (4, 2)
    assert set(passes["prune"]["removed"]) == {"mass2.p", "spring2.q", "output other"}
    assert set(passes["fold_parameters"]["removed"]) == {"m", "c", "F0", "c2"}   # k exposed
    scene = load_scene(path)
    reduced, _ = ensure_scene_module(scene, tmp_path / "gen")
    assert list(reduced.PARAM_NAMES) == ["k"] and len(reduced.STATE_NAMES) == 2
    full, _, _ = ensure_module(tmp_path / "two.yaml", tmp_path / "gen")
    for k in (600.0, 900.0):         # an exposed parameter still changes without recompiling
        pf = np.array(full.PARAMS)
        pf[list(full.PARAM_NAMES).index("k")] = k
        a = simulate(full, t_end=2.0, rtol=1e-8, atol=1e-10, params=pf, points=201)
        b = simulate(reduced, t_end=2.0, rtol=1e-8, atol=1e-10, params=[k], points=201)
        assert np.abs(a.column("position") - b.column("position")).max() < 1e-7
    res = CliRunner().invoke(main, ["run", str(path), "--out", str(tmp_path / "out"),
                                    "-o", str(tmp_path / "gen"), "-p", "k=700", "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    assert summary["states"] == 2 and summary["ok"] and summary["passes"][2]["pass"] == "prune"
    for f in ("csv", "png", "json"):
        assert (tmp_path / "out" / f"scene.{f}").stat().st_size > 100


def test_idle_spin_of_the_four_bar_coupler_is_no_state(tmp_path):
    """The RSSR coupler between two spherical joints, axisymmetric: its spin momentum is
    dropped, and the mechanism moves as the full model does."""
    model = MODELS / "four_bar.yaml"
    path = _scene(tmp_path, str(model), "outputs: [crank_angle, rocker_angle]\n"
                  "time: {end: 1.0, points: 101}\ntolerances: {rtol: 1.0e-8, atol: 1.0e-10}\n")
    passes = _check(path)
    assert passes["idle_dofs"]["removed"] == ["coupler.J.pz"]
    assert passes["idle_dofs"]["states_after"] == passes["idle_dofs"]["states_before"] - 1
    reduced, _ = ensure_scene_module(load_scene(path), tmp_path / "gen")
    full, _, _ = ensure_module(model, ROOT / "generated")
    a = simulate(full, t_end=1.0, rtol=1e-8, atol=1e-10, points=101, solver="native")
    b = simulate(reduced, t_end=1.0, rtol=1e-8, atol=1e-10, points=101, solver="native")
    for out in ("crank_angle", "rocker_angle"):
        assert np.abs(a.column(out) - b.column(out)).max() < 1e-6, out
    assert np.ptp(a.column("crank_angle")) > 0.5           # it moved
    # a scene that reads the spin keeps it
    path2 = _scene(tmp_path, str(model), "outputs: [crank_angle, coupler_spin]\n"
                   "time: {end: 1.0}\n", name="spin")
    assert _check(path2)["idle_dofs"]["removed"] == []


@pytest.mark.parametrize("body, where, key", [
    ("outputs: [nope]\ntime: {end: 1.0}\n", ":2:", "outputs[0]"),
    ("outputs: [crank_angle]\ntime: {end: 1.0}\nsolver: euler\n", ":4:", "solver"),
    ("outputs: [crank_angle]\ntime: {end: 1.0}\ncolour: red\n", ":4:", "scene.colour"),
    ("outputs: [crank_angle]\ntime: {end: -1.0}\n", ":3:", "time.end"),
])
def test_bad_scene_gets_one_located_line(tmp_path, body, where, key):
    path = _scene(tmp_path, str(MODELS / "four_bar.yaml"), body)
    res = CliRunner().invoke(main, ["check", str(path)])
    assert res.exit_code == 2
    line = res.output.strip()
    assert "\n" not in line and where in line and key in line, line
    assert not (tmp_path / "generated").exists()


def test_shipped_scenes_load():
    scenes = sorted((ROOT / "scenes").glob("*.yaml"))
    assert {p.stem for p in scenes} == {f"{d}_{k}" for d in ("pumping", "roll", "pitch")
                                        for k in ("constant", "sine", "chirp")} | \
        {"pumping_chirp_one_leg"}
    assert load_scene(ROOT / "scenes" / "pumping_chirp_one_leg.yaml").model.stem == \
        "sarib_one_leg"
    for p in scenes:
        sc = load_scene(p)
        assert sc.excitation["direction"] == p.stem.split("_")[0]
        assert sc.excitation["kind"] == p.stem.split("_")[1]


@pytest.mark.slow      # two SARIB modules compiled cold: minutes
def test_reduced_sarib_pumping_scene_answers_like_the_full_model(tmp_path):
    scene = load_scene(ROOT / "scenes" / "pumping_sine.yaml")
    reduced, passes = ensure_scene_module(scene, tmp_path / "gen")
    assert passes[1]["removed"] == [f"bar_{i}.J.pz" for i in (1, 2, 3, 4)]
    full, model, _ = ensure_module(MODELS / "sarib.yaml", ROOT / "generated")
    p = np.array(full.PARAMS)
    for name, v in scene_values(scene, model).items():
        p[list(full.PARAM_NAMES).index(name)] = v
    pr = np.array(reduced.PARAMS)
    for name, v in scene_values(scene, model).items():
        if name in reduced.PARAM_NAMES:
            pr[list(reduced.PARAM_NAMES).index(name)] = v
    a = simulate(full, t_end=0.5, rtol=1e-7, atol=1e-7, params=p, points=501, solver="native")
    b = simulate(reduced, t_end=0.5, rtol=1e-7, atol=1e-7, params=pr, points=501,
                 solver="native")
    for out in ("a_OF_z", "F_A1_z", "F_A2_z"):
        ya, yb = a.column(out), b.column(out)
        assert np.abs(ya - yb).max() < 1e-4 * np.abs(ya).max(), out
    sarib = load.load(MODELS / "sarib.yaml")
    for out in ("a_OF_z", "F_A1_z"):
        fa, _ = frf.extrema(frf.linearize(full, sarib, "pumping"), out, 15.0, 20.0)
        fb, _ = frf.extrema(frf.linearize(reduced, sarib, "pumping"), out, 15.0, 20.0)
        assert len(fa) == len(fb) == 1 and abs(fa[0] - fb[0]) < 0.01, (out, fa, fb)
