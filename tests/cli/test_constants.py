"""A model's compile-time constants (``constants:``) given with ``-p`` on the commands that
build a model: another value is another mechanism, built and analysed as such; a
constant cannot be tuned or swept (each value is another module), refused before any
work."""

from __future__ import annotations

import json
import math

import pytest
from click.testing import CliRunner

from bgc.cli import main
from helpers import MODELS

A02 = str(MODELS / "n_four_bar.yaml")


def _run(args, tmp_path):
    return CliRunner().invoke(main, [*args, "-q", "-o", str(tmp_path / "gen")])


def test_a_constant_is_refused_as_a_swept_or_tuned_name_before_any_work(tmp_path):
    r = _run(["sweep", A02, "-p", "N=1:3:3", "--metric", "rms:B0_x"], tmp_path)
    assert r.exit_code == 2 and "compile-time constant" in r.output
    r = _run(["tune", A02, "--tune", "N", "--target-frequency", "1", "--input", "x",
              "--output", "B0_x"], tmp_path)
    assert r.exit_code == 2 and "compile-time constant" in r.output
    assert not (tmp_path / "gen").exists()          # nothing built, nothing written


@pytest.mark.slow       # an augmented build; constants are built in tests/model/test_components
def test_modes_of_another_n_are_that_mechanisms(tmp_path):
    """A02 at rest with its cranks up (``-p v0=0``) for N = 1 under augmented: one
    inverted pendulum, ((N+1)/3 + N) theta'' = ((N+1)/2 + N) g theta, whose rate
    sqrt(b/a) bgc modes finds as its unstable mode (and the overdamped one beside it)."""
    r = _run(["modes", A02, "-p", "N=1", "-p", "v0=0", "--method", "augmented", "--json"],
             tmp_path)
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    n, g = 1, 9.81
    rate = math.sqrt(((n + 1) / 2 + n) * g / ((n + 1) / 3 + n))
    kinds = sorted(m["kind"] for m in rep["modes"])
    assert kinds == ["overdamped", "unstable"], rep["modes"]
    for m in rep["modes"]:
        assert abs(m["frequency_hz"] - rate / (2 * math.pi)) < 1e-4, m
    names = {b["name"] for m in rep["modes"] for b in m["bodies"]}
    assert names <= {"crank_0", "w_1.crank", "w_1.coupler"}
