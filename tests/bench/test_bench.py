"""bgc bench (issue 6) at small scale: every part writes its CSV, chart and summary, and
what it measures holds (errors fall with the tolerance, the parasitic error floor falls
with the stiffness). Compile cost: tests/bench/test_bench_compile_cost.py. The full benchmark
is ``make bench``."""

from __future__ import annotations

import csv
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from bgc.cli import main


def _rows(path):
    with open(path) as fh:
        return list(csv.DictReader(fh))


def _bench(gen_dir, out, *parts, extra=()):
    args = ["bench", "--quick", "--results", str(out), "--build", str(gen_dir), "--repeats", "2",
            "--budget", "20", "--json"]
    for p in parts:
        args += ["--part", p]
    res = CliRunner().invoke(main, args + list(extra))
    assert res.exit_code == 0, res.output
    # stdout alone: the parts' progress lines go to stderr (a row's log holds JSON too)
    return json.loads(res.stdout[res.stdout.index("{"):])


@pytest.mark.slow       # 6 s: make bench runs it in full
def test_peers_precision_and_stiffness_at_small_scale(gen_dir, tmp_path):
    rep = _bench(gen_dir, tmp_path, "peers", "precision", "stiffness")
    summary = (tmp_path / "summary.md").read_text()
    for head in ("## Peers", "## Work-precision", "## Parasitic stiffness"):
        assert head in summary
    peers = _rows(tmp_path / "peers.csv")
    assert [r["integrator"] for r in peers] == ["native", "bdf", "cvode"]
    for r in peers:
        assert r["status"] == "ok" and int(r["repeats"]) == 2 and float(r["wall_median"]) > 0
        assert float(r["error"]) < 1e-2
    assert float(peers[0]["time_vs_native"]) == 1.0
    # work-precision: every method x integrator series; the error falls with the tolerance
    wp = _rows(tmp_path / "precision_slider_crank.csv")
    assert {(r["method"], r["integrator"]) for r in wp} == {
        (m, i) for m in ("parasitic", "lagrange", "zcp", "augmented")
        for i in ("native", "bdf", "rk4")}
    for m in ("lagrange", "zcp"):
        errs = [float(r["error"]) for r in wp if r["method"] == m and r["integrator"] == "native"]
        assert errs[0] > 10 * errs[-1], (m, errs)
    assert (tmp_path / "precision_slider_crank.png").stat().st_size > 10000
    # stiffness: the floor of each series (its modelling error) falls as 1/k
    st = _rows(tmp_path / "stiffness.csv")
    floor = {}
    for r in st:
        if r["status"] == "ok":
            k = float(r["stiffness"])
            floor[k] = min(floor.get(k, np.inf), float(r["error"]))
    ks = sorted(floor)
    assert floor[ks[-1]] < 0.2 * floor[ks[0]], floor
    assert (tmp_path / "stiffness.png").exists() and rep["summary"].endswith("summary.md")


@pytest.mark.slow       # 4-5 minutes: RK4, drift, redundancy and zcp maps, small scale
def test_stability_maps_at_small_scale(gen_dir, tmp_path):
    _bench(gen_dir, tmp_path, "stability")
    rk = _rows(tmp_path / "stability_rk4.csv")
    assert all(r["bgc"] == ("refused" if float(r["fraction"]) > 1 else "ran") for r in rk)
    assert not [r for r in rk if r["stable"] == "False" and r["bgc"] == "ran"]
    drift = _rows(tmp_path / "stability_drift.csv")
    assert any(r["bgc"] == "failed" for r in drift if float(r["alpha"]) == 0)
    assert all(r["bgc"] == "ran" for r in drift if float(r["alpha"]) >= 10)
    zc = _rows(tmp_path / "stability_zcp.csv")
    assert all(r["status"] == "ran" for r in zc if "index-2" in r["integrator"])
    assert all(r["status"] == "failed" for r in zc if r["integrator"] == "ida")
    for name in ("stability_rk4.png", "stability_drift.png", "stability_zcp.png"):
        assert (tmp_path / name).exists()


@pytest.mark.slow       # 6 s: make bench runs it in full
def test_symmetry_part_charts_the_one_leg_model_against_the_full_rig(gen_dir, compiled,
                                                                      tmp_path):
    """The one-leg SARIB and the full rig over the same tolerances, both measured against
    the full rig: both run at every tolerance, and the one leg's error falls with the tolerance to
    its modelling error; the summary tabulates both with the speed gain. (Which is faster is
    a benchmark's claim, measured in one run by `make bench`, not a test's: on a loaded
    machine these millisecond wall times swap.)"""
    compiled("sarib")          # the full rig, compiled once for the session
    _bench(gen_dir, tmp_path, "symmetry")
    rows = _rows(tmp_path / "symmetry.csv")
    assert {r["model"] for r in rows} == {"sarib", "sarib_one_leg"}
    assert all(r["status"] == "ok" for r in rows)
    by = {(r["model"], float(r["setting"])): r for r in rows}
    for tol in (1e-4, 1e-6):
        assert int(by["sarib_one_leg", tol]["steps"]) > 0
        assert 0 < float(by["sarib_one_leg", tol]["wall_time"]) < math.inf
    assert float(by["sarib_one_leg", 1e-6]["error"]) < \
        0.5 * float(by["sarib_one_leg", 1e-4]["error"])
    assert float(by["sarib_one_leg", 1e-6]["error"]) < 1e-2
    summary = (tmp_path / "summary.md").read_text()
    assert "## Symmetry" in summary and "speed_gain" in summary
    assert (tmp_path / "symmetry.png").stat().st_size > 10000


@pytest.mark.slow       # 7 s: make bench runs it in full
def test_scenes_part_measures_each_reduction_against_its_full_model(gen_dir, tmp_path):
    """A four-bar scene: the reduced module has fewer states (the coupler's spin), both
    were derived and compiled cold and run, and they answer alike."""
    _bench(gen_dir, tmp_path, "scenes")
    (row,) = _rows(tmp_path / "scenes.csv")
    assert int(row["states_reduced"]) == int(row["states_full"]) - 1
    for k in ("derive_reduced_s", "numba_cold_full_s", "numba_cold_reduced_s",
              "run_full_s", "run_reduced_s"):
        assert float(row[k]) > 0, k
    assert float(row["output_difference"]) < 1e-6
    assert 0 < float(row["integration_error_full"]) < 1e-4    # the run's own error, beside it
    assert "idle_dofs 36->35" in row["passes"]
    assert "## Scenes" in (tmp_path / "summary.md").read_text()


@pytest.mark.slow       # ~15 s: make bench runs it in full
def test_activity_part_sets_the_pass_beside_the_exact_ones(gen_dir, tmp_path):
    """msd_forced at keep 0.999: every element carries more than 1e-3 of the activity
    or cannot go (the mass, the source): nothing removed, the same steps, the error the
    pass reports is the integration's. Its one junction holds elements only: the
    junctions pass (0.99) has nothing to cut."""
    _bench(gen_dir, tmp_path, "activity")
    (row,) = _rows(tmp_path / "activity.csv")
    assert int(row["states_exact_passes"]) == int(row["states_activity"]) == 2
    assert row["elements_removed"] == "0" and row["steps_exact"] == row["steps_activity"]
    assert float(row["activity_error"]) < 1e-6
    assert (row["junctions"], row["junction_cuts"], row["junction_parts"]) == ("0.99", "0", "0")
    assert int(row["states_junctions"]) == 2 and float(row["junctions_error"]) < 1e-6
    summary = (tmp_path / "summary.md").read_text()
    assert "## Scenes: what the activity passes gain" in summary
    assert "| junction_cuts |" in summary


@pytest.mark.slow       # ~10 s: make bench runs it in full
def test_startup_part_times_the_command_and_its_phases(gen_dir, tmp_path):
    rep = _bench(gen_dir, tmp_path, "startup")
    [row] = _rows(tmp_path / "startup.csv")
    phases = [float(row[f"{p}_s"]) for p in ("launch", "imports", "module",
                                             "numba_first_load", "loop", "integrate", "csv")]
    assert all(v >= 0 for v in phases) and float(row["command_s"]) > 0.1
    # the phases are the command's work: together about its time (the process's own exit
    # and argument parsing are the rest)
    assert 0.5 < sum(phases) / float(row["command_s"]) < 1.5
    assert "## Start-up" in (tmp_path / "summary.md").read_text()
    assert (tmp_path / "startup.png").stat().st_size > 5000
    assert any("small model warm start" in t for t in rep["targets"])


@pytest.mark.slow       # compiles A01 and A02 (N = 2) under every method
def test_iftomm_part_at_small_scale(gen_dir, tmp_path):
    """The IFToMM part: A01 and A02 N = 2 under every method, their work-precision charts
    and the summary's table; augmented within A02's limit, lagrange and zcp stopping at
    a singular configuration, parasitic off by its modelling error."""
    _bench(gen_dir, tmp_path, "iftomm")
    rows = _rows(tmp_path / "iftomm.csv")
    a02 = [r for r in rows if r["problem"] == "A02_N2"]
    aug = [float(r["error"]) for r in a02 if r["method"] == "augmented" and r["status"] == "ok"]
    assert min(aug) < 1e-3 and aug[0] > aug[-1]
    for m in ("lagrange", "zcp"):       # the first stops there; the series with it
        runs = [r["status"] for r in a02 if r["method"] == m]
        assert "singular configuration" in runs[0], runs
        assert all(s == "skipped: the previous run failed" for s in runs[1:]), runs
    assert all(float(r["error"]) > 1e-2 for r in a02 if r["method"] == "parasitic")
    summary = (tmp_path / "summary.md").read_text()
    assert "## IFToMM benchmark problems" in summary and "| A02_N2 | augmented |" in summary
    for name in ("iftomm_A01.png", "iftomm_A02_N2.png"):
        assert (tmp_path / name).stat().st_size > 10000


def test_components_part_writes_its_rows_chart_and_target(tmp_path, monkeypatch):
    """The components part's report from its rows (the measurement stubbed: a failed
    N = 40 among them): the CSV as measured, the chart, its summary section and the target
    at N = 160 judged from the row's wall time, augmented's at N = 40 from its build."""
    from bgc.bench import Run, components
    rows = [{"N": 10, "bodies": 21, "method": "parasitic", "loops": True, "wall_s": 12.5,
             "cpu_s": 9.0, "load_s": 1.5, "equations_s": 2.0, "machine_code_s": 6.0,
             "build_s": 9.5, "status": "ok"},
            {"N": 40, "bodies": 81, "method": "parasitic", "loops": True,
             "status": "timeout after 3600 s"},
            {"N": 160, "bodies": 321, "method": "parasitic", "loops": True, "wall_s": 31.0,
             "cpu_s": 25.0, "load_s": 3.0, "equations_s": 8.0, "machine_code_s": 15.0,
             "build_s": 26.0, "status": "ok"},
            {"N": 40, "bodies": 81, "method": "augmented", "loops": True, "wall_s": 14.0,
             "cpu_s": 13.0, "load_s": 0.5, "equations_s": 4.0, "machine_code_s": 3.0,
             "build_s": 9.5, "status": "ok"}]
    monkeypatch.setattr(components, "measure", lambda ns, log=print, augmented=(): rows)
    run = Run(tmp_path, False, 1, 1.0, lambda m: None)
    run.run_part("components")
    got = _rows(tmp_path / "components.csv")
    assert [(r["N"], r["method"]) for r in got] == [
        ("10", "parasitic"), ("40", "parasitic"), ("160", "parasitic"), ("40", "augmented")]
    assert got[1]["status"] == "timeout after 3600 s" and got[1]["wall_s"] == ""
    assert (tmp_path / "components.png").stat().st_size > 10000
    fragment = json.loads((tmp_path / "parts" / "components.json").read_text())
    assert fragment["summary"][0].startswith("## Components")
    assert fragment["targets"] == [
        "A02 with N = 160 from the model file to its first result, step loop cached "
        "(target <= 30 s): 31.0 s **FAIL** (25.0 s of CPU: the wall time on a machine "
        "with a core to itself)",
        "A02 with N = 40 under method augmented, the model build (the report's stages, "
        "target <= 10 s): 9.5 s **pass** (from the model file to the first result: 14.0 s "
        "wall, 13.0 s of CPU)"]


@pytest.mark.slow       # two cold compiles of A02 (N = 2, 4) in fresh interpreters
def test_components_part_at_small_scale(gen_dir, tmp_path):
    _bench(gen_dir, tmp_path, "components")
    rows = _rows(tmp_path / "components.csv")
    assert [(r["N"], r["bodies"], r["method"], r["status"]) for r in rows] == [
        ("2", "5", "parasitic", "ok"), ("4", "9", "parasitic", "ok"),
        ("2", "5", "augmented", "ok")]
    for r in rows:
        stages = sum(float(r[k]) for k in ("load_s", "equations_s", "machine_code_s"))
        assert 0 < stages <= float(r["build_s"]) < float(r["wall_s"]) and float(r["cpu_s"]) > 0
    assert "## Components" in (tmp_path / "summary.md").read_text()
