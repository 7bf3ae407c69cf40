"""Scenes and the reduction passes (issue 7): a scene's reduced model answers its question
like the full model; every pass says what it removed; bad scene files get one located
line. The SARIB pumping scene against the full SARIB is marked slow."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import MODELS, ROOT

from bgc.analysis import frf
from bgc.cli import main
from bgc.model import load
from bgc.pipeline import ensure_module
from bgc.scene.scenes import ensure_scene_module, load_scene, scene_values
from bgc.simulate import simulate

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
    assert list(passes) == ["merge_relays", "fold_parameters", "idle_dofs", "prune"]
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
    res = CliRunner().invoke(main, ["run", str(path), "--results", str(tmp_path / "out"),
                                    "-o", str(tmp_path / "gen"), "-p", "k=700", "--json"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)
    assert summary["states"] == 2 and summary["ok"] and summary["passes"][3]["pass"] == "prune"
    for f in ("csv", "png", "json"):
        assert (tmp_path / "out" / f"scene.{f}").stat().st_size > 100


def test_idle_spin_of_the_four_bar_coupler_is_no_state(tmp_path, compiled):
    """The RSSR coupler between two spherical joints, axisymmetric: its spin momentum is
    dropped, and the mechanism moves as the full model does."""
    model = MODELS / "four_bar.yaml"
    path = _scene(tmp_path, str(model), "outputs: [crank_angle, rocker_angle]\n"
                  "time: {end: 1.0, points: 101}\ntolerances: {rtol: 1.0e-8, atol: 1.0e-10}\n")
    passes = _check(path)
    assert passes["idle_dofs"]["removed"] == ["coupler.J.pz"]
    assert passes["idle_dofs"]["states_after"] == passes["idle_dofs"]["states_before"] - 1
    reduced, _ = ensure_scene_module(load_scene(path), tmp_path / "gen")
    full = compiled("four_bar")
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
    ("outputs: [crank_angle]\ntime: {end: 1.0}\nmerge_relays: maybe\n", ":4:", "merge_relays"),
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
        {"pumping_chirp_one_leg", "pumping_chirp_merged", "pumping_chirp_activity"}
    assert load_scene(ROOT / "scenes" / "pumping_chirp_one_leg.yaml").model.stem == \
        "sarib_one_leg"
    for p in scenes:
        sc = load_scene(p)
        assert sc.excitation["direction"] == p.stem.split("_")[0]
        assert sc.excitation["kind"] == p.stem.split("_")[1]


@pytest.mark.slow      # two SARIB modules compiled cold: minutes
def test_reduced_sarib_pumping_scene_answers_like_the_full_model(tmp_path, compiled):
    scene = load_scene(ROOT / "scenes" / "pumping_sine.yaml")
    reduced, passes = ensure_scene_module(scene, tmp_path / "gen")
    assert passes[0]["states_after"] == passes[0]["states_before"] == 152     # parasitic
    assert passes[2]["removed"] == [f"leg_{i}.bar.J.pz" for i in (1, 2, 3, 4)]
    full, model = compiled("sarib"), load.load(MODELS / "sarib.yaml")
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


RELAY_CHAIN = """
name: relay_chain
gravity: 9.81
bodies:
  s1: {{mass: 0, com: [0, 0, 0]}}
  s2: {{mass: 0, com: [0, 0, 0]}}
  rod: {{mass: 2.0, com: [0.1, 0.05, -0.5], inertia: [0.2, 0.2, 0.01]}}
joints:
{joints}
excitation:
  directions:
    push: {{joint: slide, amplitude: 3.0}}
    twist: {{joint: r2, amplitude: 0.2}}
  kinds:
    sine: {{type: sine, amplitude: 1.0, frequency: 2.0}}
outputs:
  x: rod.x
  y: rod.y
  z: rod.z
"""
SPRINGS = {"slide": "{k: 200.0, c: 2.0, preload: 25.0}", "r1": "{k: 5.0, c: 0.1, preload: 0.3}",
           "r2": "{k: 3.0, c: 0.05, preload: -0.2}"}
# the chain written from the fixed frame, every joint's body 1 on its side
FORWARD = f"""  slide: {{type: prismatic, between: [fixed_frame, s1], at: [0, 0, 0], axis: [0, 0, 1],
           spring: {SPRINGS['slide']}}}
  r1: {{type: revolute, between: [s1, s2], at: [0, 0, 0], axis: [1, 0, 0],
        spring: {SPRINGS['r1']}}}
  r2: {{type: revolute, between: [s2, rod], at: [0, 0.2, 0], axis: [0, 1, 0],
        spring: {SPRINGS['r2']}}}"""
# from the rod, the slider last, joints pointing both ways, axes and points shifted along them
MIXED = f"""  r2: {{type: revolute, between: [rod, s2], at: [0, 0.3, 0], axis: [0, -1, 0],
        spring: {SPRINGS['r2']}}}
  r1: {{type: revolute, between: [s2, s1], at: [0.4, 0, 0], axis: [1, 0, 0],
        spring: {SPRINGS['r1']}}}
  slide: {{type: prismatic, between: [fixed_frame, s1], at: [1, 1, 1], axis: [0, 0, -1],
           spring: {SPRINGS['slide']}}}"""


def test_relay_chain_becomes_the_prismatic_universal_it_is():
    """merge_relays finds the slider and the two revolutes on bodies of negligible mass and
    writes the joint one would write by hand (test_joints compares that joint with the
    chain), springs on its free directions, the excitation following them; outputs or
    exposed parameters that read the chain, or axes that do not meet, leave it alone."""
    from dataclasses import replace

    from bgc.scene.merge_relays import merge_relays
    m = load.loads(RELAY_CHAIN.format(joints=FORWARD), "chain.yaml")
    out, removed, note = merge_relays(m)
    assert removed == ["s1", "s2", "slide", "r1", "r2"] and "-> relay_chain" not in note
    (name, j), = out.joints.items()
    pu = ("  pu: {type: prismatic_universal, between: [fixed_frame, rod], at: [0, 0, 0], "
          "axis: [1, 0, 0], axis2: [0, 1, 0], directions: {"
          f"tz: {SPRINGS['slide']}, rx: {SPRINGS['r1']}, ry: {SPRINGS['r2']}}}}}")
    text = RELAY_CHAIN.format(joints=pu).replace("joint: slide", "joint: pu")
    hand = load.loads(text.replace("joint: r2", "joint: pu, direction: ry"), "h.yaml").joints["pu"]
    assert (j.kind, j.body1, j.body2, j.frame) == (hand.kind, None, "rod", hand.frame)
    assert np.allclose(j.at, [0, 0, 0.0]) and list(out.bodies) == ["rod"]
    assert {lab: (f.k, f.c, f.preload) for lab, f in j.functional.items()} == \
        {lab: (f.k, f.c, f.preload) for lab, f in hand.functional.items()}
    assert {lab: str(f.actuator) for lab, f in j.functional.items() if f.actuator} == \
        {lab: str(f.actuator) for lab, f in hand.functional.items() if f.actuator}
    assert out.excitation.directions == {"push": (name, 3.0), "twist": (name, 0.2)}
    assert f"{name}__tz_preload" in out.parameters and "slide__tx_k" not in out.parameters
    # what leaves a chain alone, and says why
    assert merge_relays(m, outputs=["x"], keep_params=["r1__rx_k"])[2] == \
        "slide - r1 - r2 left: r1__rx_k read it"
    text = RELAY_CHAIN.format(joints=FORWARD) + "  spin: s2.wx\n"
    assert "output spin read it" in merge_relays(load.loads(text, "c.yaml"))[2]
    assert merge_relays(load.loads(text, "c.yaml"), outputs=["x", "z"])[0].outputs[-1].name \
        == "z"                          # not asked for: the output goes with the chain
    skew = RELAY_CHAIN.format(joints=FORWARD.replace("at: [0, 0.2, 0]", "at: [0.1, 0, 0.1]"))
    assert merge_relays(load.loads(skew, "c.yaml"))[2] == \
        "slide - r1 - r2 left: the axes of r1 and r2 do not meet"
    assert replace(m, name="x").joints == m.joints         # the input is left as it was
    # one relay between two revolutes is a universal joint (test_joints' chain)
    pair = RELAY_CHAIN.replace("  s2: {{mass: 0, com: [0, 0, 0]}}\n", "").format(joints=(
        "  r1: {type: revolute, between: [fixed_frame, s1], at: [0, 0, 0], axis: [1, 0, 0]}\n"
        "  r2: {type: revolute, between: [s1, rod], at: [0, 0, 0], axis: [0, 1, 0]}"))
    pair = pair.replace("joint: slide", "joint: r1")
    out, removed, note = merge_relays(load.loads(pair, "pair.yaml"))
    (j,) = out.joints.values()
    assert (j.kind, j.body1, j.body2, removed) == ("universal", None, "rod", ["s1", "r1", "r2"])


@pytest.mark.parametrize("joints", [pytest.param(FORWARD, marks=pytest.mark.slow), MIXED],
                         ids=["forward", "mixed"])     # mixed: both orientations of a relay
def test_merged_relay_chain_moves_as_the_chain(tmp_path, joints):
    """Under ideal joints (lagrange) the merged joint is the chain: preloads, springs,
    dampers and both excitation directions (a force on the slide, a moment on the second
    revolute) keep their sense whichever way the chain's joints were written."""
    from dataclasses import replace

    from bgc.codegen.emit import import_module
    from bgc.pipeline import compile_model
    from bgc.scene.merge_relays import merge_relays
    m = load.loads(RELAY_CHAIN.format(joints=joints), "chain.yaml")
    merged, removed, _ = merge_relays(m)
    assert len(removed) == 5
    runs, states = {}, {}
    for tag, model in (("chain", m), ("merged", replace(merged, name="relay_merged"))):
        c, path = compile_model(model, tmp_path / "gen", method="lagrange")
        mod = import_module(path)
        states[tag] = len(mod.STATE_NAMES)
        p = np.array(mod.PARAMS)
        for k, v in {**m.excitation.select("sine", "push"), "excitation__twist": 0.2}.items():
            p[list(mod.PARAM_NAMES).index(k)] = v
        runs[tag] = simulate(mod, t_end=1.5, rtol=1e-9, atol=1e-11, params=p, points=151,
                             solver="native")
    assert states["chain"] - states["merged"] == 24     # the relays' poses and twists
    a, b = runs["chain"], runs["merged"]
    for out in ("x", "y", "z"):
        swing = np.ptp(a.column(out))
        assert swing > 0.01, (out, swing)
        assert np.abs(a.column(out) - b.column(out)).max() < 1e-6 * swing, out


@pytest.mark.slow       # the relay chain merge stays in make test on small models
def test_sarib_relay_chains_merge_where_the_scene_allows():
    """The SARIB's attach and membrane chains: under parasitic the pass names what it
    would merge and leaves it (each joint's compliance is part of that model) unless the
    scene says merge_relays: true; then 152 -> 128 states and the relays' algebraic loops
    are gone."""
    from bgc.scene.scenes import reduced_system
    plain = _check(ROOT / "scenes" / "pumping_chirp.yaml")["merge_relays"]
    assert plain["states_before"] == plain["states_after"] == 152 and not plain["removed"]
    assert plain["note"].startswith("would merge attach_pumping - attach_roll - attach_pitch "
                                    "-> attach (prismatic_universal); membrane_roll")
    _, system, reports = reduced_system(load_scene(ROOT / "scenes" / "pumping_chirp_merged.yaml"))
    merged = reports[0].to_dict()
    assert (merged["states_before"], merged["states_after"]) == (152, 128)
    assert set(merged["removed"]) == {f"{c}_{b}" for c in ("attach", "membrane")
                                      for b in ("int_1", "int_2", "pumping", "roll", "pitch")}
    assert not system.loops and len(system.states) == 124       # idle bar spins: 128 -> 124


@pytest.mark.slow      # two lagrange SARIB modules compiled cold: minutes
def test_merged_relays_answer_the_sarib_pumping_scene_exactly_under_ideal_joints(tmp_path):
    """The pumping scene under lagrange: the merge applies (ideal joints: exact), 176 ->
    128 states, outputs within the integration error of the full model (measured 1.9e-7
    of peak at rtol 1e-8) and anti-resonances within 1e-6 Hz (measured 4e-8)."""
    text = (ROOT / "scenes" / "pumping_sine.yaml").read_text()
    path = tmp_path / "pumping_sine_lagrange.yaml"
    path.write_text(text.replace("method: parasitic", "method: lagrange").replace(
        "../models/sarib.yaml", str(MODELS / "sarib.yaml")))
    scene = load_scene(path)
    reduced, passes = ensure_scene_module(scene, tmp_path / "gen")
    assert (passes[0]["states_before"], passes[0]["states_after"]) == (176, 128)
    full, model, _ = ensure_module(MODELS / "sarib.yaml", tmp_path / "gen", "lagrange")
    runs = {}
    for tag, mod in (("full", full), ("reduced", reduced)):
        p = np.array(mod.PARAMS)
        for name, v in scene_values(scene, model).items():
            if name in mod.PARAM_NAMES:
                p[list(mod.PARAM_NAMES).index(name)] = v
        runs[tag] = simulate(mod, t_end=0.5, rtol=1e-8, atol=1e-8, params=p, points=501,
                             solver="native")
    for out in ("a_OF_z", "F_A1_z", "F_A2_z"):
        ya, yb = runs["full"].column(out), runs["reduced"].column(out)
        assert np.abs(ya - yb).max() < 1e-5 * np.abs(ya).max(), out
    for direction in ("pumping", "roll", "pitch"):
        fa, _ = frf.extrema(frf.linearize(full, model, direction), "F_A1_z", 15.0, 20.0)
        fb, _ = frf.extrema(frf.linearize(reduced, model, direction), "F_A1_z", 15.0, 20.0)
        assert len(fa) == len(fb) == 1 and abs(fa[0] - fb[0]) < 1e-6, (direction, fa, fb)
