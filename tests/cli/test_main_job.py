"""`bgc simulate` without MODEL: the main job, the run the Makefile's `run` (and `demo`)
makes, from the SARIB bgc ships (bgc.data), its files under the current directory."""

from __future__ import annotations

import re
import shlex
from dataclasses import replace

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import MODELS, ROOT

from bgc import data
from bgc.cli import main
from bgc.cli.simulate import resolve, simulate


def resolved(*args):
    """The options ``bgc simulate ARGS`` runs with."""
    ctx = simulate.make_context("simulate", [str(a) for a in args])
    return resolve(ctx.params, ctx)


def makefile_runs() -> dict[str, list[str]]:
    """The Makefile's SARIB runs, target by target: ``$(SARIB)`` expanded, continuation
    lines joined."""
    text = (ROOT / "Makefile").read_text()
    sarib = re.search(r"^SARIB = bgc simulate (.*)$", text, re.M).group(1)
    runs = {}
    for target, recipe in re.findall(r"^(\w+):.*\n((?:\t.*\n)+)", text, re.M):
        for line in recipe.replace("\\\n", " ").splitlines():
            if line.strip().startswith("$(SARIB)"):
                runs.setdefault(target, []).append(
                    shlex.split(line.strip().replace("$(SARIB)", sarib)))
    return runs


def test_no_model_is_the_run_the_makefile_makes():
    runs = makefile_runs()
    assert len(runs["run"]) == 1 and len(runs["demo"]) == 2
    for args in runs["run"] + runs["demo"]:
        make = resolved(*args)
        job = resolved("--excitation", "chirp", "--direction", make.exc_dir)
        assert data.path("models", "sarib.yaml").read_bytes() == \
            (ROOT / make.model).read_bytes()      # the shipped model is the repository's
        assert replace(job, model=None) == replace(make, model=None), args
    assert resolved() == resolved("--excitation", "chirp", "--direction", "pumping")


def test_options_given_win_over_the_main_jobs():
    o = resolved("--direction", "roll", "--out", "x.csv", "--states", "--t-end", "6",
                 "--solver", "bdf")
    assert (o.exc_kind, o.exc_dir, o.solver, o.out, o.plot, o.states, o.zoom, o.report) == \
        ("chirp", "roll", "bdf", "x.csv", "results/sarib_roll_chirp.png", True, None,
         "results/sarib_roll_chirp.html")
    assert resolved("--t-end", "6", "--zoom", "1", "2").zoom == (1.0, 2.0)
    assert resolved("--excitation", "sine").out == "results/sarib_pumping_sine.csv"
    given = resolved(MODELS / "rlc.yaml")            # with MODEL: nothing of the main job
    assert (given.exc_kind, given.out, given.plot, given.states, given.zoom,
            given.report) == (None, None, None, True, None, None)


def test_no_model_writes_the_main_jobs_files_in_the_current_directory(
        tmp_path, monkeypatch, gen_dir, compiled):
    compiled("sarib")           # compiled once for the session (-o gen_dir: found fresh)
    monkeypatch.chdir(tmp_path)
    # the files, not the method: the session's parasitic module, not the main job's zcp
    r = CliRunner().invoke(main, ["simulate", "--excitation", "chirp", "--t-end", "0.02",
                                  "--method", "parasitic", "-o", str(gen_dir), "--quiet"])
    assert r.exit_code == 0, r.output
    assert "sarib: native to t = 0.02 s" in r.output
    files = sorted(str(p.relative_to(tmp_path)) for p in tmp_path.rglob("*"))
    assert files == ["results", "results/sarib_pumping_chirp.csv",
                     "results/sarib_pumping_chirp.html",      # the report
                     "results/sarib_pumping_chirp.png"]       # no zoom: the run ends first
    csv = tmp_path / "results/sarib_pumping_chirp.csv"
    header = csv.read_text().splitlines()[0].split(",")
    assert header == ["t", *compiled("sarib").OUTPUT_NAMES]      # --no-states
    assert np.loadtxt(csv, delimiter=",", skiprows=1)[-1, 0] == pytest.approx(0.02)
