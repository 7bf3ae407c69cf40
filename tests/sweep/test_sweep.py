"""``bgc sweep`` (issue 28, item 2): the plan of points, the metrics, the runner on a
2-worker Dask LocalCluster (a worker killed mid-sweep loses no point) and the command's
files and JSON."""

from __future__ import annotations

import json
import os
import signal

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import MODELS

from bgc.errors import BgcError
from bgc.sweep import metrics, plan, runner


def test_grid_is_every_combination_last_parameter_fastest():
    axes = [plan.parse_axis("k=1:3:3", False), plan.parse_axis("c=0.5:1:2", False)]
    pl = plan.plan(axes)
    assert pl.names == ("k", "c") and pl.kind == "grid"
    assert pl.values.tolist() == [[1, 0.5], [1, 1], [2, 0.5], [2, 1], [3, 0.5], [3, 1]]


def test_latin_hypercube_puts_one_point_in_each_stratum_and_repeats_with_its_seed():
    axes = [plan.parse_axis("k=100:200", True), plan.parse_axis("c=-1:1", True)]
    pl = plan.plan(axes, samples=8, seed=3)
    assert pl.values.shape == (8, 2) and pl.kind == "latin hypercube"
    for j, (lo, hi) in enumerate(((100, 200), (-1, 1))):
        strata = np.floor((pl.values[:, j] - lo) / (hi - lo) * 8)
        assert sorted(strata) == list(range(8))
    assert np.array_equal(plan.plan(axes, samples=8, seed=3).values, pl.values)


@pytest.mark.parametrize("text, sampled, message", [
    ("k=1:3", False, "'k=1:3' is not NAME=START:STOP:COUNT"),
    ("k=1:3:2", True, "with --samples, an axis has no COUNT"),
    ("k=1:x:2", False, "START and STOP must be numbers"),
    ("k=1:3:0", False, "COUNT must be a whole number >= 1"),
    ("k=2:2:3", False, "3 values of an empty range"),
])
def test_bad_axes_are_refused_in_one_line_naming_the_option(text, sampled, message):
    with pytest.raises(BgcError, match=message) as err:
        plan.parse_axis(text, sampled)
    assert err.value.key == "--param"


@pytest.mark.parametrize("text, message", [
    ("rms", "is not KIND:OUTPUT"), ("mean:z", "unknown metric 'mean'"),
    ("rms:z:2:1", "need 0 <= T0 < T1"), ("peak:z:0", "is not KIND:OUTPUT"),
])
def test_bad_metrics_are_refused(text, message):
    with pytest.raises(BgcError, match=message):
        metrics.parse_window(text)
    with pytest.raises(BgcError, match="is not INPUT:OUTPUT"):
        metrics.parse_frf("pumping")


def test_the_module_is_copied_once_per_machine_where_the_workers_do_not_see_it(
        compiled, tmp_path, monkeypatch):
    """A worker that does not see the client's file writes the source under the
    temporary directory once; another worker (or a restarted one) reuses it untouched, so
    numba's cache beside it stays valid."""
    mod = compiled("msd_forced")
    monkeypatch.setattr(runner.tempfile, "gettempdir", lambda: str(tmp_path))
    source = open(mod.__file__, "rb").read()
    job = runner.Job(str(tmp_path / "elsewhere" / "msd_forced.py"), mod.MODEL_HASH, None,
                     mod.PARAMS, (), (), metrics.Metrics((), (), 1.0, 2.0, None))
    first = runner.place(job, source)
    assert first.parent.parent == tmp_path / "bgc-sweep" and first.read_bytes() == source
    stamp = first.stat().st_mtime_ns
    assert runner.place(job, source) == first and first.stat().st_mtime_ns == stamp
    shared = runner.Job(mod.__file__, mod.MODEL_HASH, None, mod.PARAMS, (), (), job.metrics)
    assert str(runner.place(shared, source)) == mod.__file__      # seen: used as it is


def test_table_has_a_column_per_extremum_found_and_a_failed_point_keeps_its_row(tmp_path):
    """As many anti-resonance and resonance columns as the most any point found, empty
    where a point found fewer or failed; the CSV and (if pyarrow is importable, else
    none) the Parquet beside it hold the same table."""
    from bgc.sweep import write
    ms = metrics.Metrics((metrics.Frf("push", "z"),), (metrics.parse_window("rms:z:1:2"),),
                         5.0, 25.0, None)
    points = [runner.Point(0, {"k": 1.0}, {"push:z": {"antiresonances_hz": [6.5, 18.0],
                                                      "resonances_hz": [16.1]},
                                           "rms:z:1:2": 0.5}, None),
              runner.Point(1, {"k": 2.0}, {"push:z": None, "rms:z:1:2": None},
                           "push:z: no equilibrium; simulation: no equilibrium")]
    cols = write.table(points, ("k",), ms)
    assert list(cols) == ["k", "push:z:anti_1", "push:z:anti_2", "push:z:res_1",
                          "rms:z:1:2", "error"]
    csv = write.write_csv(tmp_path / "t.csv", cols)
    assert csv.read_text().splitlines() == [
        "k,push:z:anti_1,push:z:anti_2,push:z:res_1,rms:z:1:2,error", "1,6.5,18,16.1,0.5,",
        "2,,,,,push:z: no equilibrium; simulation: no equilibrium"]
    parquet = write.write_parquet(csv, cols)
    try:
        import pyarrow.parquet as pq
    except ImportError:
        assert parquet is None
    else:
        rows = pq.read_table(parquet).to_pylist()
        assert rows[0]["push:z:anti_2"] == 18.0 and rows[1]["push:z:anti_1"] is None


def _window_job(mod, names, t_end=2.0):
    ms = (metrics.parse_window("rms:position:1:2"), metrics.parse_window("peak:velocity"))
    run = metrics.Run(t_end, 1e-6, 1e-8, "native", 201)
    swept = tuple(list(mod.PARAM_NAMES).index(n) for n in names)
    return runner.Job(mod.__file__, mod.MODEL_HASH, None, np.array(mod.PARAMS), names,
                      swept, metrics.Metrics((), ms, 5.0, 25.0, run))


def test_window_metrics_are_the_rms_and_the_peak_of_the_output_over_the_window(compiled):
    from bgc.simulate import simulate
    mod = compiled("msd_forced")
    job = _window_job(mod, ())
    values, error = metrics.evaluate(job.metrics, mod, None, np.array(mod.PARAMS))
    r = simulate(mod, t_end=2.0, rtol=1e-6, atol=1e-8, points=201)
    inside = (r.t >= 1.0) & (r.t <= 2.0)
    assert np.count_nonzero(inside) == 101 and error is None
    assert values == {"rms:position:1:2": np.sqrt(np.mean(r.column("position")[inside] ** 2)),
                      "peak:velocity": np.abs(r.column("velocity")).max()}


@pytest.mark.parametrize("args, line", [
    (["-p", "kk=1:2:2", "--metric", "peak:position"],
     "error: --param: unknown parameter 'kk' of model msd_forced (hint: did you mean k? "
     "parameters: m, k, c, F0, f_drive)"),
    (["-p", "k=400:800:2", "--metric", "peak:speed"],
     "error: --metric: peak:speed: unknown output 'speed' of model msd_forced (hint: "
     "outputs: position, "),
    (["-p", "k=400:800:2", "--frf", "push:position"],
     "error: --frf: push:position: "),
    (["-p", "k=-400:800:2", "--metric", "peak:position"],
     "error: --param: k=-400: capacitance C of C 'spring' must be > 0"),
    (["-p", "k=400:800:2"], "error: --frf: no metric to compute"),
    (["-p", "k=400:800:2", "--metric", "rms:position:1:3", "--t-end", "2"],
     "error: --metric: rms:position:1:3: the window ends after the run (t_end = 2 s)"),
])
def test_bad_sweeps_are_refused_before_any_worker_starts(compiled, args, line):
    from bgc.cli import main
    gen = os.path.dirname(compiled("msd_forced").__file__)
    r = CliRunner().invoke(main, ["sweep", str(MODELS / "msd_forced.yaml"), "-o", gen,
                                  "-q", *args])
    assert r.exit_code == 2 and r.output.startswith(line), r.output
    assert len(r.output.strip().splitlines()) == 1


@pytest.fixture(scope="module")
def client():
    """A 2-worker LocalCluster (worker processes, each with its nanny) for this file's
    sweeps, started as ``bgc sweep`` starts its own."""
    with runner.connect(workers=2) as c:
        yield c


def test_sweep_command_writes_the_frf_and_window_metrics_and_reports_failing_points(
        compiled, client, tmp_path, figures):
    """The SARIB's one leg on the cluster of a running scheduler (--scheduler): its FRF
    extrema as ``bgc frf`` finds them, and the peak of a_OF_z in a window of a sine run,
    at each point. A preload that no longer holds the weight is no equilibrium: the FRF
    and the run fail at those points, their row says why, and the sweep goes on."""
    from bgc.analysis import frf, modes
    from bgc.cli import main
    from bgc.model import load
    from bgc.simulate import simulate
    mod = compiled("sarib_one_leg")
    gen = os.path.dirname(mod.__file__)
    csv, png = tmp_path / "s.csv", tmp_path / "s.png"
    r = CliRunner().invoke(main, [
        "sweep", str(MODELS / "sarib_one_leg.yaml"), "-o", gen,
        "--scheduler", client.scheduler.address,
        "-p", "hinge_1__rx_k=600:800:2", "-p", "attach_pumping__tx_preload=305.5815:400:2",
        "--frf", "pumping:a_OF_z", "--metric", "peak:a_OF_z:0.05:0.1",
        "--excitation", "sine", "--direction", "pumping", "--frequency", "12",
        "--out", str(csv), "--plot", str(png), "--json"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    points = rep["points"]
    assert rep["workers"] == 2 and len(points) == 4
    assert [p["params"]["hinge_1__rx_k"] for p in points] == [600, 600, 800, 800]
    model = load.load(MODELS / "sarib_one_leg.yaml")
    names = list(mod.PARAM_NAMES)
    for p in points:
        at = np.array(mod.PARAMS)
        for n, v in p["params"].items():
            at[names.index(n)] = v
        held = p["params"]["attach_pumping__tx_preload"] == 305.5815
        if held:
            lin = frf.linearize(mod, model, "pumping", at)
            anti, res, _ = modes.resonances(mod, model, lin, "a_OF_z", 5.0, 25.0)
            assert p["metrics"]["pumping:a_OF_z"] == {
                "antiresonances_hz": [round(f, 4) for f in anti],
                "resonances_hz": [round(f, 4) for f in res]}
            assert p["error"] is None
        else:
            assert p["metrics"] == {"pumping:a_OF_z": None, "peak:a_OF_z:0.05:0.1": None}
            assert p["error"].startswith("pumping:a_OF_z: the initial state (t = 0) is not a "
                                         "static equilibrium")
            assert "; simulation: the initial state" in p["error"]
            continue
        for k, v in model.excitation.select("sine", "pumping", frequency=12.0).items():
            at[names.index(k)] = v
        run = simulate(mod, t_end=0.1, rtol=mod.SETTINGS["rtol"], atol=mod.SETTINGS["atol"],
                       points=points_of(mod, 0.1), params=at)
        window = (run.t >= 0.05) & (run.t <= 0.1)
        peak = np.abs(run.column("a_OF_z")[window]).max()
        assert p["metrics"]["peak:a_OF_z:0.05:0.1"] == pytest.approx(peak, rel=1e-12)
    header = csv.read_text().splitlines()[0].split(",")
    assert header[:3] == ["hinge_1__rx_k", "attach_pumping__tx_preload",
                          "pumping:a_OF_z:anti_1"]
    assert header[-2:] == ["peak:a_OF_z:0.05:0.1", "error"]
    assert sorted(rep["files"]["plots"]) == ["peak:a_OF_z:0.05:0.1", "pumping:a_OF_z"]
    assert len(figures) == 2 and figures[0]["ylabels"] == ["frequency [Hz]"] * 2
    assert (tmp_path / "s_peak_a_OF_z_0.05_0.1.png").read_bytes()[:4] == b"\x89PNG"


def points_of(mod, t_end):
    """The output times ``bgc simulate --t-end`` gives: the model's spacing kept."""
    from bgc.cli.options import output_points
    from bgc.model.model import Settings
    return output_points(Settings(**mod.SETTINGS), t_end)


def test_a_worker_killed_mid_sweep_loses_no_point(compiled, client):
    """A 2-worker LocalCluster (worker processes, each with its nanny): one worker is
    killed (SIGKILL) while it works on a point; its points run again (on the other worker
    or on the one the nanny starts in its place, which the plugin reaches too). Every
    point comes back, with the values of an undisturbed sweep."""
    mod = compiled("msd_forced")
    pl = plan.plan([plan.parse_axis("k=400:800:6", False),
                    plan.parse_axis("c=2:8:4", False)])
    job = _window_job(mod, pl.names)
    source = open(mod.__file__, "rb").read()
    killed = []

    def kill_a_busy_worker(point):
        if killed:
            return
        busy = [w for w, keys in client.processing().items() if keys]
        if not busy:                    # between two points: at the next one
            return
        pids = client.run(os.getpid, workers=busy[:1])
        for address, pid in pids.items():
            os.kill(pid, signal.SIGKILL)
            killed.append(address)

    calm = runner.run(client, job, pl.values, source)
    hit = runner.run(client, job, pl.values, source, on_point=kill_a_busy_worker)
    assert len(killed) == 1 and killed[0] not in client.scheduler_info()["workers"]
    assert len(hit) == len(pl) == 24
    assert [p.error for p in hit] == [None] * 24
    assert [(p.params, p.values) for p in hit] == [(p.params, p.values) for p in calm]
