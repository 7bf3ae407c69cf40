"""The command line: check / compile / simulate, human and --json forms."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner
from helpers import MODELS, ROOT

from bgc.analysis.results import read_csv
from bgc.cli import main


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def test_check_reports_derivative_causality():
    r = run("check", MODELS / "geared_inertias.yaml")
    assert r.exit_code == 0, r.output
    assert "I J_l: derivative (dependent state J_l.p)" in r.output
    assert "I J_r: integral" in r.output
    assert "derivative loop through" in r.output


def test_check_json_reports_loops_with_elements_and_bonds():
    r = run("check", MODELS / "rr_loop.yaml", "--json")
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert rep["states"] == ["cap.q"]
    assert rep["storage"] == {"cap": "integral"}
    [loop] = rep["algebraic_loops"]
    assert loop["kind"] == "algebraic"
    assert {"r1", "r2", "r3"} <= set(loop["elements"])
    assert {"b2", "b4", "b6"} <= set(loop["bonds"])
    assert rep["conflicts"] == []


def test_compile_writes_module(tmp_path):
    r = run("compile", MODELS / "rlc.yaml", "-o", tmp_path, "--json")
    assert r.exit_code == 0, r.output
    info = json.loads(r.output)
    assert info["states"] == 2 and (tmp_path / "rlc.py").exists()
    assert set(info["timings"]) == {"load", "causality", "equations", "jacobian", "emit",
                                    "machine code"}


def test_simulate_writes_csv_png_and_statistics(tmp_path, figures, compiled, gen_dir):
    """(The module: the session's, found fresh in its directory; compiling is
    test_compile_writes_module's.)"""
    compiled("rlc")
    csv, png = tmp_path / "out.csv", tmp_path / "out.png"
    r = run("simulate", MODELS / "rlc.yaml", "--t-end", "0.02", "--solver", "radau",
            "--rtol", "1e-8", "--atol", "1e-10", "--out", csv, "--plot", png,
            "-o", gen_dir)
    assert r.exit_code == 0, r.output
    assert "steps" in r.output and "rhs" in r.output and "Jacobian" in r.output
    names, data = read_csv(csv)
    assert names == ["t", "inductor.p", "capacitor.q", "current", "v_C", "v_R"]
    assert data[0, 0] == 0 and abs(data[-1, 0] - 0.02) < 1e-12
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    [fig] = figures        # every axis carries its unit (models/rlc.yaml declares them)
    assert fig["ylabels"] == ["current [A]", "v_C [V]", "v_R [V]"]
    assert fig["xlabel"] == "t [s]"
    # the capacitor's charge over C is its voltage
    assert np.allclose(data[:, 2] / 2e-5, data[:, 4])


def test_simulate_json_and_parameter_override(tmp_path):
    gen = tmp_path / "gen"
    r1 = run("simulate", MODELS / "msd_free.yaml", "--json", "-o", gen, "--out",
             tmp_path / "a.csv")
    r2 = run("simulate", MODELS / "msd_free.yaml", "--json", "-o", gen, "-p", "x0=0.03",
             "--out", tmp_path / "b.csv")
    assert r1.exit_code == 0 and r2.exit_code == 0, r1.output + r2.output
    j1, j2 = json.loads(r1.output), json.loads(r2.output)
    assert j1["compiled"] is True and j2["compiled"] is False   # no recompilation
    for key in ("steps", "rhs_calls", "jac_calls", "lu_decompositions", "wall_time"):
        assert key in j1["stats"]
    a, b = read_csv(tmp_path / "a.csv")[1], read_csv(tmp_path / "b.csv")[1]
    assert np.allclose(b[:, 3], 3 * a[:, 3], rtol=1e-4, atol=1e-9)  # linear in x0


def test_failed_simulation_keeps_partial_results(tmp_path):
    """A run that cannot continue says where and keeps what it computed."""
    model = tmp_path / "blowup.yaml"
    model.write_text(
        "elements:\n"
        "  s: {type: Se, effort: 1.0}\n"
        "  j: {type: '1'}\n"
        "  mass: {type: I, flow: 'p**3'}\n"
        "  spring: {type: C, effort: '-q**3'}\n"
        "bonds: [[s, j], [j, mass], [j, spring]]\n"
        "outputs: {v: mass.f}\n")
    csv = tmp_path / "partial.csv"
    r = CliRunner().invoke(main, ["simulate", str(model), "--t-end", "10", "--out", str(csv),
                                  "-o", str(tmp_path / "gen")])
    assert r.exit_code == 2
    assert "failed at t =" in r.stderr or "non-finite at t =" in r.stderr
    assert "Traceback" not in r.output
    names, data = read_csv(csv)
    assert len(data) > 1 and data[-1, 0] < 10


# bgc check --stage STAGE: each stage's output alone, as text and as JSON


def stage(name, model, *args):
    """``bgc check --stage NAME MODEL ARGS --quiet``: the text and the JSON report."""
    text = run("check", "--stage", name, model, "--quiet", *args)
    js = run("check", "--stage", name, model, "--quiet", "--json", *args)
    assert text.exit_code == 0 and js.exit_code == 0, text.output + js.output
    return text.stdout, json.loads(js.stdout)


def test_stage_load_shows_the_model():
    text, rep = stage("load", MODELS / "rlc.yaml")
    assert rep["stage"] == "load" and rep["model"] == "rlc"
    assert rep["counts"]["elements"] == 5 and rep["counts"]["bonds"] == 4
    assert rep["elements"]["capacitor"] == "C" and rep["parameters"]["R"]["value"] == 10
    assert rep["outputs"] == ["current", "v_C", "v_R"]
    assert "5 elements, 4 bonds, 0 bodies" in text
    assert "parameter R = 10 [ohm]" in text and "element capacitor: C" in text
    assert "bond b2: loop -> resistor" in text
    assert "outputs: current, v_C, v_R" in text


def test_stage_expand_shows_the_bond_graph_of_a_mechanism():
    text, rep = stage("expand", MODELS / "pendulum.yaml", "--method", "lagrange")
    assert rep["stage"] == "expand" and rep["method"] == "lagrange"
    assert rep["bodies"] == ["rod"]
    assert rep["joints"] == {"hinge": {"blocked": ["tx", "ty", "tz", "ry", "rz"],
                                       "free": ["rx"]}}
    assert rep["constraints"] == ["hinge.tx", "hinge.ty", "hinge.tz", "hinge.ry", "hinge.rz"]
    assert rep["by_kind"]["EJS"] == 1 and rep["by_kind"]["I"] == 2     # mass, inertia
    assert set(rep["bond_dimensions"]) == {"1", "3"}
    assert sum(rep["by_kind"].values()) == rep["elements"]
    assert sum(rep["bond_dimensions"].values()) == rep["bonds"]
    assert "joint hinge: blocked tx, ty, tz, ry, rz; free rx" in text
    assert "constraint elements: 5" in text and "EJS: 1" in text
    # under parasitic the blocked directions are spring-dampers, not constraint elements
    _, rep = stage("expand", MODELS / "pendulum.yaml")
    assert rep["method"] == "parasitic" and rep["constraints"] == []


def test_stage_causality_shows_storage_causality_and_strokes():
    text, rep = stage("causality", MODELS / "geared_inertias.yaml")
    assert rep["storage"]["J_l"] == {"kind": "I", "causality": "derivative"}
    assert rep["storage"]["J_r"] == {"kind": "I", "causality": "integral"}
    assert rep["conflicts"] == [] and rep["strokes"]
    assert {"bond", "from", "to", "effort_into"} == set(rep["strokes"][0])
    assert "causality: no conflicts" in text
    assert "I J_l: derivative" in text and "R damper: resistance" in text


def test_stage_equations_shows_states_and_algebraic_loops():
    text, rep = stage("equations", MODELS / "rr_loop.yaml")
    assert rep["states"] == ["cap.q"] and rep["assignments"] > 0
    [loop] = rep["algebraic_loops"]
    assert loop["kind"] == "algebraic" and {"r1", "r2", "r3"} <= set(loop["elements"])
    assert "1 state, " in text and "algebraic loops: 1" in text
    assert "algebraic loop through" in text
    text, rep = stage("equations", MODELS / "geared_inertias.yaml")
    assert rep["dependent"] == {"J_l": "J_l.p"}
    assert "dependent state J_l.p (J_l: derivative causality)" in text


def test_stage_equations_shows_the_lagrange_multipliers_block():
    _, rep = stage("equations", MODELS / "pendulum.yaml", "--method", "lagrange")
    [block] = rep["linear_blocks"]
    assert len(block["unknowns"]) == 5 and len(rep["constraints"]) == 5


def test_stage_emit_renders_the_module_compile_writes(tmp_path):
    """--stage emit renders the source without writing it; it is the module bgc compile
    writes, byte for byte, and once written it is reported fresh."""
    text, rep = stage("emit", MODELS / "rlc.yaml", "-o", tmp_path)
    path = tmp_path / "rlc.py"
    assert rep["module"] == str(path) and rep["fresh"] is False and not path.exists()
    assert rep["kernels"]["rhs"] >= 1 and rep["kernel_functions"] >= len(rep["kernels"])
    assert f"{path} (not written yet or stale), {rep['bytes']} bytes" in text
    r = run("compile", MODELS / "rlc.yaml", "-o", tmp_path, "--quiet")
    assert r.exit_code == 0, r.output
    assert len(path.read_bytes()) == rep["bytes"]
    _, again = stage("emit", MODELS / "rlc.yaml", "-o", tmp_path)
    assert again["fresh"] is True


def test_stage_of_a_scene_is_refused():
    r = run("check", "--stage", "load", ROOT / "scenes" / "pumping_chirp.yaml")
    assert r.exit_code == 2
    assert r.stderr.startswith("error: --stage: --stage applies to a model file"), r.stderr
