"""Warm start (issue 24): ``bgc simulate`` on a model whose generated module is fresh
reads the model file's YAML, finds the module by the digest and integrates, without
importing sympy, jinja2 or the equation builder; whatever needs the Model (a stale
module, ``-p`` values, an excitation) still goes through the full load and its checks.

Each run whose imports are checked is a fresh interpreter (a subprocess), so what it
imported is what it needed."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest
from helpers import MODELS, ROOT, bgc

from bgc.codegen import module_file

# what `bgc simulate` runs in the subprocess, then which of these it imported
SCRIPT = """
import json, sys
from bgc.cli import main
rc = 0
try:
    main(sys.argv[1:], standalone_mode=False)
except SystemExit as exc:
    rc = exc.code
heavy = ("sympy", "jinja2", "bgc.model.load", "bgc.codegen.equations", "bgc.codegen.emit", "scipy.integrate",
         "bgc.solvers.radau5")
print(json.dumps({"rc": rc, "loaded": [m for m in heavy if m in sys.modules]}))
"""


def _simulate(model, out_dir, *args):
    """Run ``bgc simulate MODEL -o OUT_DIR ARGS`` in a new interpreter: its report (exit
    status, heavy modules imported) and the completed process."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    cmd = [sys.executable, "-c", SCRIPT, "simulate", str(model), "-o", str(out_dir),
           "--t-end", "0.002", "--points", "2", "--quiet", *args]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert proc.stdout.strip(), proc.stderr
    return json.loads(proc.stdout.strip().splitlines()[-1]), proc


@pytest.mark.parametrize("solver, scipy_ivp", [("bdf", True), ("native", False)])
def test_fresh_module_runs_without_sympy(compiled, gen_dir, tmp_path, solver, scipy_ivp):
    """A fresh module: no sympy, jinja2, loader, equation builder or emitter is imported,
    and scipy.integrate (0.3 s) or the Radau loop only by the solver that uses it. A
    comment added to the model file leaves its digest, so its module stays fresh."""
    compiled("rlc")
    model = tmp_path / "rlc.yaml"
    model.write_text((MODELS / "rlc.yaml").read_text() + "# a comment\n")
    report, proc = _simulate(model, gen_dir, "--solver", solver)
    assert report["rc"] == 0, proc.stderr
    assert "rlc: " + solver in proc.stdout and "recompiled" not in proc.stdout
    heavy = {"scipy.integrate"} if scipy_ivp else {"bgc.solvers.radau5"}
    assert set(report["loaded"]) == heavy, report


def test_a_stale_or_unproven_module_takes_the_full_load(tmp_path):
    """A document the digest cannot tell from one that loaded (a date where text was,
    both hashed as "2020-01-01") is loaded in full and refused; a missing module is
    compiled (sympy and all) and the next run of the same file finds it fresh."""
    text = (MODELS / "rlc.yaml").read_text()
    good, bad = tmp_path / "good" / "rlc.yaml", tmp_path / "bad" / "rlc.yaml"
    good.parent.mkdir()
    bad.parent.mkdir()
    good.write_text(text.replace("description: Series RLC circuit switched onto a DC "
                                 "source at t = 1 ms.", 'description: "2020-01-01"'))
    bad.write_text(good.read_text().replace('"2020-01-01"', "2020-01-01"))
    gen = tmp_path / "gen"
    report, proc = _simulate(good, gen)
    assert report["rc"] == 0 and "recompiled" in proc.stdout, proc.stderr
    assert {"sympy", "bgc.model.load", "bgc.codegen.equations", "bgc.codegen.emit"} <= set(report["loaded"])
    report, proc = _simulate(good, gen)
    assert report["rc"] == 0 and "sympy" not in report["loaded"], proc.stderr
    report, proc = _simulate(bad, gen)
    assert report["rc"] == 2 and "sympy" in report["loaded"]
    assert proc.stderr.startswith(f"error: {bad}:2:") and "description" in proc.stderr


def test_fresh_module_still_checks_options_against_the_model(compiled, gen_dir, tmp_path):
    """``-p`` values and ``--excitation`` are checked against the Model, fresh module or
    not: a capacitance not > 0, an excitation the model does not declare. (What these
    runs import is not in question: they run forked, ``helpers.bgc``.)"""
    compiled("rlc")
    args = ("simulate", MODELS / "rlc.yaml", "-o", gen_dir, "--t-end", "0.002", "--points",
            "2", "--quiet")
    proc = bgc(*args, "-p", "C=-1", cwd=tmp_path, timeout=60)
    assert proc.returncode == 2 and proc.stderr.startswith("error: --param: C=-1: "), \
        proc.stderr
    proc = bgc(*args, "--excitation", "sine", "--direction", "x", cwd=tmp_path, timeout=60)
    assert proc.returncode == 2 and "has no 'excitation' section" in proc.stderr, proc.stderr


def test_installed_names_are_those_importlib_finds():
    """The names a model may not take (``module_file._installed_top_level``, read
    without parsing every distribution's METADATA) are importlib's own."""
    import importlib.metadata
    assert module_file._installed_top_level() == \
        frozenset(importlib.metadata.packages_distributions())
