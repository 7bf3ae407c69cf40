"""The command line: check / compile / simulate, human and --json forms."""

from __future__ import annotations

import json

import numpy as np
from click.testing import CliRunner
from helpers import MODELS

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


def test_simulate_writes_csv_png_and_statistics(tmp_path):
    csv, png = tmp_path / "out.csv", tmp_path / "out.png"
    r = run("simulate", MODELS / "rlc.yaml", "--t-end", "0.02", "--solver", "radau",
            "--rtol", "1e-8", "--atol", "1e-10", "--out", csv, "--plot", png,
            "-o", tmp_path / "gen")
    assert r.exit_code == 0, r.output
    assert "steps" in r.output and "rhs" in r.output and "Jacobian" in r.output
    names, data = read_csv(csv)
    assert names == ["t", "inductor.p", "capacitor.q", "current", "v_C", "v_R"]
    assert data[0, 0] == 0 and abs(data[-1, 0] - 0.02) < 1e-12
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
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
