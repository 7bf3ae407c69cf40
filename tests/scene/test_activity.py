"""The activity pass (issue 42, item 3): model order reduction by element activity. A
model with a known inactive element loses it (and its state) and nothing else, the other
states keep their names, the scene's report gives the outputs' error against the full
model; keep 1 removes nothing; bad ``activity:`` values get one located line."""

from __future__ import annotations

import pytest
from click.testing import CliRunner

from bgc.cli import main
from bgc.scene.scenes import ensure_scene_module, load_scene

# msd_forced with a second spring beside the first, a million times weaker, and a
# damper in parallel with the mass's junction through a 0-junction that carries almost
# no flow (a leak): two elements whose power is negligible, one with a state
WEAK = """\
name: msd_weak
parameters:
  m: {value: 1.5, unit: kg}
  k: {value: 600.0, unit: N/m}
  k_weak: {value: 6.0e-4, unit: N/m}
  c: {value: 6.0, unit: N s/m}
  F0: {value: 10.0, unit: N}
  f_drive: {value: 3.0, unit: Hz}
signals:
  force: {type: sine, amplitude: F0, frequency: f_drive}
elements:
  drive:  {type: Se, effort: force}
  mass:   {type: I, I: m}
  spring: {type: C, C: 1/k}
  weak:   {type: C, C: 1/k_weak}
  damper: {type: R, R: c}
  v:      {type: "1"}
bonds:
  - [drive, v]
  - [v, mass]
  - [v, spring]
  - [v, weak]
  - [v, damper]
outputs:
  position: {expr: spring.q, unit: m}
  velocity: {expr: mass.f, unit: m/s}
simulation: {t_end: 2.0}
"""


@pytest.fixture(scope="module")
def gen(tmp_path_factory):
    """One directory of generated modules for the module's scenes: the model's energy
    variant is compiled once."""
    return tmp_path_factory.mktemp("activity_gen")


def scene(tmp_path, keep="0.9999", extra=""):
    (tmp_path / "weak.yaml").write_text(WEAK)
    path = tmp_path / "weak_scene.yaml"
    name = "weak_" + "".join(c if c.isalnum() else "_" for c in keep)
    path.write_text(f"name: {name}\nmodel: weak.yaml\noutputs: [position, velocity]\n"
                    "time: {end: 2.0, points: 2001}\n"
                    "tolerances: {rtol: 1.0e-8, atol: 1.0e-10}\n"
                    f"activity: {{keep: {keep}}}\n" + extra)
    return path


def test_a_known_inactive_element_goes_and_nothing_else(tmp_path, gen):
    sc = load_scene(scene(tmp_path))
    module, passes = ensure_scene_module(sc, gen)
    act = next(p for p in passes if p["pass"] == "activity")
    assert act["removed"] == ["weak", "weak.q"]
    assert (act["states_before"], act["states_after"]) == (3, 2)
    assert list(module.STATE_NAMES) == ["mass.p", "spring.q"]
    # the weak spring's force is 1e-6 of the spring's: the outputs move by that much
    for name, err in act["output_error"].items():
        assert err < 2e-5, name
    assert "1 elements" in act["note"]


def test_keep_everything_removes_nothing(tmp_path, gen):
    sc = load_scene(scene(tmp_path, keep="1"))
    _, passes = ensure_scene_module(sc, gen)
    act = next(p for p in passes if p["pass"] == "activity")
    assert act["removed"] == [] and act["states_before"] == act["states_after"] == 3


def test_a_mass_that_carries_its_junctions_velocity_stays(tmp_path, gen):
    """Keep 0.5: the budget covers the weak spring and the damper (11.5 %), and would
    cover the mass, but the mass sets its junction's common flow (removing it would
    change the causality) and the drive is a source: they stay, and the report says
    why."""
    sc = load_scene(scene(tmp_path, keep="0.5"))
    _, passes = ensure_scene_module(sc, gen)
    act = next(p for p in passes if p["pass"] == "activity")
    assert act["removed"] == ["weak", "damper", "weak.q"]
    assert "mass (it sets its 1-junction's common flow)" in act["note"]
    assert "drive (a Se)" in act["note"]


@pytest.mark.parametrize("value, words", [("0", "activity.keep"), ("2", "0 < keep <= 1"),
                                          ("[1]", "activity")])
def test_bad_activity_is_one_located_line(tmp_path, value, words):
    path = scene(tmp_path, keep=value)
    res = CliRunner().invoke(main, ["check", str(path), "-o", str(tmp_path / "gen")])
    assert res.exit_code == 2, res.output
    line = res.output.strip()
    assert "\n" not in line and ":6:" in line and words in line, line


@pytest.mark.slow      # the SARIB's energy variant, its reduced module and two 28 s chirps
def test_the_shipped_activity_scene(tmp_path):
    """scenes/pumping_chirp_activity.yaml: the merged attach and membrane joints' roll and
    pitch springs and dampers go (the pumping chirp leaves them still), the membrane's
    pumping spring stays, and the outputs stay within 1e-4 of the full model's run."""
    from helpers import ROOT
    sc = load_scene(ROOT / "scenes" / "pumping_chirp_activity.yaml")
    module, passes = ensure_scene_module(sc, tmp_path / "gen")
    act = next(p for p in passes if p["pass"] == "activity")
    gone = {r for r in act["removed"] if not r.endswith((".q", ".p"))}
    assert gone == {f"{j}.{d}.{e}" for j in ("attach", "membrane") for d in ("rx", "ry")
                    for e in ("damper",)} | {"membrane.rx.spring", "membrane.ry.spring"}
    assert act["states_before"] - act["states_after"] == 2
    assert max(act["output_error"].values()) < 1e-4
    assert len(module.STATE_NAMES) == act["states_after"]
