"""Tuning (``bgc tune``, bgc.analysis.tune) on a two-mass absorber whose anti-resonance is
sqrt(k / m) in closed form: the tuned mass against the formula and dF/dm against its
derivative, on the linear model written out (no compile) and through the command's --json
report on the compiled model; the command's one-line refusals (a target out of reach)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from bgc.cli import main

# the upper mass m_t on an undamped spring k = 2000 N/m: anti-resonance of the lower
# mass at sqrt(k / m_t) / 2 pi, 10.07 Hz at m_t = 0.5 kg
ABSORBER = """
name: tune_absorber
gravity: 0.0
parameters:
  m_t: {value: 0.5, unit: kg}
bodies:
  main: {mass: 2.0, com: [0, 0, 0], inertia: [0.1, 0.1, 0.1]}
  tuned: {mass: m_t, com: [0, 0, 0.2], inertia: [0.01, 0.01, 0.01]}
joints:
  base: {type: prismatic, between: [fixed_frame, main], at: [0, 0, 0], axis: [0, 0, 1],
         spring: {k: 20000.0, c: 2.0}}
  top: {type: prismatic, between: [main, tuned], at: [0, 0, 0.2], axis: [0, 0, 1],
        spring: {k: 2000.0, c: 0.0}}
excitation:
  directions:
    push: {joint: base, amplitude: 10.0}
  kinds:
    constant: {type: constant, value: 1.0}
outputs:
  z: main.z
"""
K = 2000.0


@pytest.fixture(scope="module")
def absorber(tmp_path_factory):
    from bgc.codegen.emit import import_module
    from bgc.pipeline import compile_model
    d = tmp_path_factory.mktemp("tune")
    (d / "tune_absorber.yaml").write_text(ABSORBER)
    c, path = compile_model(d / "tune_absorber.yaml", d)
    return import_module(path), c.model, d


def mass_for(f):
    return K / (2 * math.pi * f) ** 2


def linearization(m_t: float):
    """The absorber's linear model written out: states (z, v, z_t, v_t), input the force
    on the lower mass, output z."""
    from bgc.analysis import frf
    m, k, c = 2.0, 20000.0, 2.0
    A = np.array([[0.0, 1.0, 0.0, 0.0], [-(k + K) / m, -c / m, K / m, 0.0],
                  [0.0, 0.0, 0.0, 1.0], [K / m_t, 0.0, -K / m_t, 0.0]])
    return frf.Linearization(A, np.array([0.0, 1 / m, 0.0, 0.0]), np.eye(4)[:1],
                             np.zeros(1), np.zeros(4), 0.0, ("z",), np.zeros(0))


def test_tuned_mass_is_k_over_omega_squared_and_its_sensitivity_the_derivative():
    from bgc.analysis import tune
    r = tune.solve(linearization, "z", 12.0, 0.5, band=(8.0, 16.0), name="m_t")
    assert r.value == pytest.approx(mass_for(12.0), rel=1e-6)
    assert r.frequency == pytest.approx(12.0, abs=1e-6)
    assert r.start == 0.5 and r.start_frequency == pytest.approx(
        math.sqrt(K / 0.5) / (2 * math.pi), abs=1e-6)
    assert r.sensitivity == pytest.approx(-12.0 / (2 * r.value), rel=1e-4)   # dF/dm
    # the default bracket, half to twice the start: sqrt(2) either way in frequency
    assert r.bracket == (0.25, 1.0)
    assert r.reachable == pytest.approx((math.sqrt(K) / (2 * math.pi),
                                         math.sqrt(K / 0.25) / (2 * math.pi)), abs=1e-6)


def test_cli_json_reports_value_frequency_sensitivity(absorber):
    _, _, d = absorber
    r = CliRunner().invoke(main, ["tune", str(d / "tune_absorber.yaml"), "-o", str(d),
                                  "--target-frequency", "9", "--tune", "m_t", "--input",
                                  "push", "--output", "z", "--bracket", "0.4:0.8", "--json",
                                  "-q"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert rep["value"] == pytest.approx(mass_for(9.0), rel=1e-6)
    assert rep["frequency"] == pytest.approx(9.0, abs=1e-6)
    assert rep["sensitivity"] == pytest.approx(-9.0 / (2 * rep["value"]), rel=1e-4)
    assert (rep["unit"], rep["sensitivity_unit"], rep["bracket"]) == ("kg", "Hz/kg",
                                                                     [0.4, 0.8])


@pytest.mark.parametrize("args, key, words", [
    (["--target-frequency", "20", "--bracket", "0.4:0.8"], "--target-frequency",
     ["out of reach", "m_t in [0.4, 0.8]", "between 7.958 and 11.25 Hz"]),
    (["--target-frequency", "9", "--bracket", "0.8:0.4"], "--bracket", ["LO < HI"]),
    (["--target-frequency", "9", "--bracket", "-1:0.4"], "--bracket", ["m_t=-1"]),
    (["--target-frequency", "9", "--tune", "nope"], "--tune", ["m_t"]),
    (["--target-frequency", "9", "--param", "m_t"], "--param", ["--tune m_t"]),
    (["--target-frequency", "9", "--tune", "m_t", "--set", "m_t=0.5"], "--set",
     ["-p NAME=VALUE"]),
])
def test_cli_refuses_in_one_line(absorber, args, key, words):
    _, _, d = absorber
    base = ["tune", str(d / "tune_absorber.yaml"), "-o", str(d), "--input", "push",
            "--output", "z", "-q"]
    if "--tune" not in args and "--param" not in args:
        base += ["--tune", "m_t"]
    r = CliRunner().invoke(main, base + args)
    assert r.exit_code == 2
    [line] = r.output.strip().splitlines()
    assert line.startswith("error: ") and key in line, line
    assert all(w in line for w in words), line
