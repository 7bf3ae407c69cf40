"""--parasitic auto's accuracy rule (issue 27, item 2): a parasitic compliance in series
with a functional spring shifts an anti-resonance by what the analytic series stiffness
says, and ``auto`` raises that joint's stiffness until the shift is under its accuracy."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

from bgc.analysis import frf
from bgc.cli import main
from bgc.codegen.emit import import_module
from bgc.methods import parasitic
from bgc.pipeline import compile_model

# A tuned absorber: the primary mass on its spring, driven; the absorber (1 kg) on a
# 400 N/m spring through a massless link and a pin whose blocked tx is the parasitic
# spring in series with it. The primary's anti-resonance is the absorber's own
# frequency, sqrt(k_s / m) with k_s = 400 k / (400 + k): 20 rad/s for ideal joints.
_ABSORBER = """\
name: absorber
gravity: 0
parasitic: {stiffness: 4000.0, damping: 1.0, rot_stiffness: 1.0e4, rot_damping: 1.0}
bodies:
  primary: {mass: 10.0, com: [0, 0, 0], inertia: [1.0, 1.0, 1.0]}
  link: {mass: 0, com: [0.1, 0, 0]}
  absorber: {mass: 1.0, com: [0.1, 0, 0], inertia: [0.01, 0.01, 0.01]}
joints:
  ground: {type: prismatic, between: [fixed_frame, primary], at: [0, 0, 0], axis: [1, 0, 0],
           spring: {k: 10000.0}}
  tuned: {type: prismatic, between: [primary, link], at: [0.1, 0, 0], axis: [1, 0, 0],
          spring: {k: 400.0}}
  pin: {type: revolute, between: [link, absorber], at: [0.1, 0, 0], axis: [0, 0, 1],
        spring: {k: 1.0}}
excitation:
  directions: {push: {joint: ground, amplitude: 1.0}}
  kinds: {constant: {type: constant, value: 1.0}}
outputs:
  x: primary.x
simulation: {t_end: 1.0}
"""


def _anti_hz(mod, model, p) -> float:
    lin = frf.linearize(mod, model, "push", p)
    anti, _ = frf.extrema(lin, "x", 2.0, 5.0)
    assert len(anti) == 1, anti
    return anti[0]


def _series_hz(k) -> float:
    return np.sqrt(400.0 * k / (400.0 + k) / 1.0) / (2 * np.pi)


def test_auto_stiffens_a_compliance_in_series_with_a_functional_spring(tmp_path):
    path = tmp_path / "absorber.yaml"
    path.write_text(_ABSORBER)
    c, mod_path = compile_model(path, tmp_path)
    mod = import_module(mod_path)
    names = list(mod.PARAM_NAMES)
    k = names.index("pin__stiffness")
    given = np.array(mod.PARAMS)
    ideal = 20.0 / (2 * np.pi)
    # the given 4000 N/m: the anti-resonance where the series stiffness puts it, 4.7 % low
    assert _anti_hz(mod, c.model, given) == pytest.approx(_series_hz(4000.0), rel=1e-5)
    # separation 10 asks ~1e5 N/m of the pin (fastest mode 32 rad/s, 1 kg): too soft
    p, choice = parasitic.auto(mod, c.model, mod.X0, given, separation=10.0)
    assert choice.reasons["pin__stiffness"] == "accuracy"
    assert choice.shift <= choice.accuracy
    # the shift of the absorber's mode is 400 / (2 k): k >= 400 / (2 accuracy)
    assert p[k] >= 400 / (2 * parasitic.ACCURACY) * 0.9
    got = _anti_hz(mod, c.model, p)
    assert got == pytest.approx(_series_hz(p[k]), rel=1e-5)   # its damper: 2.5e-6
    assert abs(got - ideal) / ideal < 3 * parasitic.ACCURACY
    assert "pin__stiffness" in choice.table() and "accuracy" in choice.describe()
    # never less accurate than given: a stiffer pin is kept, with its damping
    stiff = p.copy()
    stiff[k] *= 10
    q, again = parasitic.auto(mod, c.model, mod.X0, stiff, separation=10.0)
    assert q[k] == stiff[k] and "pin__stiffness" in again.kept
    assert abs(_anti_hz(mod, c.model, q) - ideal) <= abs(got - ideal)
    # bgc frf --parasitic auto (separation 100: stiffer than accuracy asks): auto's
    # choice, and the anti-resonance where its series stiffness puts it
    p100, _ = parasitic.auto(mod, c.model, mod.X0, given)
    res = CliRunner().invoke(main, ["frf", str(path), "--input", "push", "--output", "x",
                                    "--f-min", "2", "--f-max", "5", "--parasitic", "auto",
                                    "-o", str(tmp_path), "--json"])
    assert res.exit_code == 0, res.output
    rep = json.loads(res.output)
    assert rep["parasitic"]["values"]["pin__stiffness"] == pytest.approx(p100[k])
    assert rep["antiresonances_hz"] == [round(_series_hz(p100[k]), 2)]
