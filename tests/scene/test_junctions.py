"""The junctions pass (issue 42, item 3): Rideout, Stein and Louca's junction inactivity.
A heavy mass driving a light one through a spring loses exactly the light one's force on
the heavy one (one effort term at one 1-junction), splits into a driving and a driven
part, and the driven part goes where no output needs it and stays, fed one-way, where
one does; a buffered RC stage (a light load on a node) loses its current at the node's
0-junction and is fed the node's voltage; where the masses are equal every bond matters
and nothing is cut; bad ``activity.junctions`` values get one located line."""

from __future__ import annotations

import re

import pytest
from click.testing import CliRunner
from helpers import ROOT

from bgc.cli import main
from bgc.scene.scenes import check_scene, ensure_scene_module, load_scene

# docs/energy.md's worked examples: a heavy mass driving a light one (the light one's
# force on the heavy one a few 1e-5 of the heavy one's forces), and two RC stages whose
# second draws 1e-4 of the node's current
PAIR = (ROOT / "docs" / "energy" / "pair.yaml").read_text()
STAGES = (ROOT / "docs" / "energy" / "stages.yaml").read_text()
NAME = re.compile(r"^name: (\w+)$", re.M)


@pytest.fixture(scope="module")
def gen(tmp_path_factory):
    """One directory for the module's scenes: each model's junctions variant is
    compiled once."""
    return tmp_path_factory.mktemp("junctions_gen")


def scene(tmp_path, model, outputs, junctions="0.99", extra="", t_end="2.0"):
    name = NAME.search(model).group(1)
    (tmp_path / f"{name}.yaml").write_text(model)
    path = tmp_path / f"{name}_scene.yaml"
    path.write_text(f"name: {name}_{'_'.join(outputs)}\nmodel: {name}.yaml\n"
                    f"outputs: [{', '.join(outputs)}]\n"
                    f"time: {{end: {t_end}, points: 2001}}\n"
                    "tolerances: {rtol: 1.0e-8, atol: 1.0e-10}\n"
                    f"activity: {{junctions: {junctions}}}\n" + extra)
    return path


def junctions(passes):
    return next(p for p in passes if p["pass"] == "junctions")


def test_a_heavy_mass_drives_a_light_one_one_way(tmp_path, gen):
    """Exactly the back-coupling goes: the light mass's spring force leaves the heavy
    mass's balance (the effort of bond 'coupling' at its 1-junction), the spring's
    junction takes the heavy mass's velocity as a modulated flow source; the model
    splits into the heavy part (driving) and the light part (driven), which no output
    needs: it goes, and the heavy mass's motion stays within the threshold's error."""
    module, passes = ensure_scene_module(load_scene(scene(tmp_path, PAIR, ["x_heavy"])),
                                         gen)
    jn = junctions(passes)
    (cut,) = jn["cuts"]
    assert (cut["junction"], cut["bond"], cut["component"], cut["cut"], cut["into"],
            cut["source"]) == ("v_heavy", "coupling", None, "effort", "force_link", "MSf")
    assert 0 < cut["share"] < 1e-4
    assert jn["states_before"] == jn["states_after"] == 4     # the states all stay
    assert [(p["states"], p["driven_by"], p["needed"]) for p in jn["parts"]] == [
        (["heavy.p", "suspension.q"], [], True),
        (["link.q", "light.p"], [0], False)]
    assert list(module.STATE_NAMES) == ["heavy.p", "suspension.q"]
    assert 0 < jn["output_error"]["x_heavy"] < 1e-3      # threshold 1e-2
    assert "prune removes it" in jn["note"]


def test_the_driven_part_an_output_needs_stays_fed_one_way(tmp_path, gen):
    sc = load_scene(scene(tmp_path, PAIR, ["x_heavy", "light_speed"]))
    jn = junctions(check_scene(sc, gen))
    assert [c["bond"] for c in jn["cuts"]] == ["coupling"]
    assert [p["needed"] for p in jn["parts"]] == [True, True]
    assert "it stays, fed one-way" in jn["note"]
    prune = next(p for p in check_scene(sc, gen) if p["pass"] == "prune")
    assert prune["states_after"] == 4


def test_a_light_load_on_a_node_is_fed_the_nodes_voltage(tmp_path, gen):
    """At the 0-junction 'node' the second stage's current is 1e-4 of the node's: its
    flow leaves the node's balance, the second stage takes the node's voltage (MSe)."""
    sc = load_scene(scene(tmp_path, STAGES, ["v_node"], t_end="0.1"))
    passes = check_scene(sc, gen)
    jn = junctions(passes)
    (cut,) = jn["cuts"]
    assert (cut["junction"], cut["bond"], cut["cut"], cut["source"]) == \
        ("node", "load", "flow", "MSe")
    assert [(p["states"], p["needed"]) for p in jn["parts"]] == [
        (["c1.q"], True), (["c2.q"], False)]
    assert next(p for p in passes if p["pass"] == "prune")["states_after"] == 1


def test_where_every_bond_matters_nothing_is_cut(tmp_path, gen):
    """Equal masses and springs: the link's force is as large as the suspension's at
    the driven mass's junction; every term there carries more than 1 % of its
    activity."""
    sc = load_scene(scene(tmp_path, PAIR, ["x_heavy"],
                          extra="params: {m: 100.0, k: 4.0e4}\n"))
    jn = junctions(check_scene(sc, gen))
    assert jn["cuts"] == [] and jn["parts"] == []
    assert "no junction term" in jn["note"]


@pytest.mark.parametrize("activity, key, words", [
    ("{junctions: 0}", "activity.junctions", "must be > 0"),
    ("{junctions: 1.5}", "activity.junctions", "0 < junctions <= 1"),
    ("{junction: 0.99}", "activity", "junction"),
    ("{}", "activity", "'keep' or 'junctions'")])
def test_bad_junctions_is_one_located_line(tmp_path, activity, key, words):
    path = scene(tmp_path, PAIR, ["x_heavy"])
    path.write_text(path.read_text().replace("activity: {junctions: 0.99}",
                                             f"activity: {activity}"))
    res = CliRunner().invoke(main, ["check", str(path), "-o", str(tmp_path / "gen")])
    assert res.exit_code == 2, res.output
    line = res.output.strip()
    assert "\n" not in line and ":6:" in line and key in line and words in line, line


@pytest.mark.slow      # the SARIB's junctions variant, its reduced module and two 28 s chirps
def test_the_sarib_pumping_chirp_under_zcp_does_not_split(tmp_path):
    """Every coupling between the SARIB's bodies passes through joints with blocked
    directions: under zcp the bodies' balances carry the joints' constraint forces and
    the points' velocities are read by the constraints, so nothing there is cut; what
    is cut carries no power in this run (the bars' and beaters' gyroscopic torques about
    their own axes, the fuselage's rotation in the hinges' rates: zero by the rig's
    symmetry under pumping), no part splits off, and the outputs stay within the
    integration's error of the full model's run."""
    path = tmp_path / "pumping_junctions.yaml"
    path.write_text((ROOT / "scenes" / "pumping_chirp_activity.yaml").read_text()
                    .replace("../models/sarib.yaml", str(ROOT / "models" / "sarib.yaml"))
                    .replace("activity: {keep: 0.99999}", "activity: {junctions: 0.99}"))
    _, passes = ensure_scene_module(load_scene(path), tmp_path / "gen")
    jn = junctions(passes)
    assert jn["cuts"] and all(c["share"] < 1e-9 for c in jn["cuts"])
    assert jn["parts"] == [] and jn["states_before"] == jn["states_after"]
    assert "it carries an ideal joint's constraint force" in jn["note"]
    assert "a joint's constraint reads the junction's flow" in jn["note"]
    assert max(jn["output_error"].values()) < 1e-4
