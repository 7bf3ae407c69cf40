"""The chirp-envelope analysis alone, on a synthetic response (no model, no solver): the
helper ``bgc simulate`` and a scene's run share (``envelope.chirp_sweep``)."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

from bgc.analysis.envelope import chirp_sweep, minima_hz
from bgc.errors import Loc
from bgc.model.model import Excitation, Signal
from bgc.model.signals import chirp_frequency
from bgc.simulate import Result

CHIRP = {"t1": 0.5, "t2": 1.0, "t3": 11.0, "f_start": 1.0, "f_end": 6.0}


def _excitation() -> Excitation:
    at = Loc("e.yaml", 1)
    return Excitation({"push": ("j", 1.0)},
                      {"sweep": Signal("sweep", "chirp", sp.S.Zero, at, numbers=CHIRP),
                       "step": Signal("step", "constant", sp.S.One, at)}, None, at)


def _response(t_end: float) -> Result:
    """An output whose amplitude dips at 3 Hz of the sweep, and the excitation g."""
    t = np.linspace(0.0, t_end, int(t_end * 2000) + 1)
    f = chirp_frequency(t, CHIRP["t2"], CHIRP["t3"], CHIRP["f_start"], CHIRP["f_end"])
    phase = 2 * np.pi * np.cumsum(f) * (t[1] - t[0])
    z = (1 - 0.8 * np.exp(-((f - 3.0) / 0.3) ** 2)) * np.sin(phase)
    return Result(t, np.zeros((len(t), 0)), np.column_stack([z, np.sin(phase)]), (),
                  ("z", "g"), "synthetic")


def test_the_envelope_of_a_chirp_run_finds_its_dip():
    curves = chirp_sweep(_excitation(), {"kind": "sweep", "direction": "push"},
                         _response(11.0))
    assert list(curves) == ["z"]                  # g, the excitation, is left out
    freq, amp, minima = curves["z"]
    assert freq.min() < 1.5 and freq.max() > 5.5 and amp.max() == pytest.approx(1, abs=0.01)
    assert minima[0] == pytest.approx(3.0, abs=0.1)
    assert minima_hz(curves, 1)["z"][0] == round(minima[0], 1)


def test_no_envelope_without_a_chirp_or_its_sweep():
    exc = _excitation()
    assert chirp_sweep(exc, None, _response(11.0)) is None
    assert chirp_sweep(exc, {"kind": "step", "direction": "push"}, _response(11.0)) is None
    # a run that stops before a tenth of the sweep [t2, t3] has no envelope to read
    assert chirp_sweep(exc, {"kind": "sweep", "direction": "push"}, _response(1.9)) is None
    assert chirp_sweep(exc, {"kind": "sweep", "direction": "push"}, _response(2.1))
    assert minima_hz(None, 2) is None


def test_the_ends_of_the_sweep_are_no_minima():
    """An envelope that falls towards both ends of the sweep (as the roll chirp's a_OF_z
    does) has its lowest points there; they are no anti-resonance: only the dip inside,
    a window of 0.5 Hz on either side, is reported."""
    from bgc.analysis.envelope import minima
    f = np.linspace(5.0, 25.0, 401)
    amp = (1.5 - 0.5 * np.exp(-(f - 5.0) / 0.4) - 0.5 * np.exp(-(25.0 - f) / 0.4)
           - 0.8 * np.exp(-((f - 17.0) / 0.2) ** 2))
    assert amp[0] < amp[20] and amp[-1] < amp[-30]       # falls towards both ends
    found = minima(f, amp)
    assert found == [pytest.approx(17.0, abs=0.06)]
    assert minima(f[::-1], amp[::-1]) == found            # a downward sweep alike
    assert minima(np.empty(0), np.empty(0)) == []


def test_minima_an_frf_anti_resonance_explains_and_the_sweeps_transients():
    """A minimum at most the sweep's lag after an anti-resonance of the FRF (or two
    envelope periods before it) is that anti-resonance; one elsewhere is the sweep's own
    transient. The window follows the sweep's direction."""
    from bgc.analysis.envelope import explain
    up = {"t2": 0.0, "t3": 10.0, "f_start": 5.0, "f_end": 25.0}        # 2 Hz/s
    curves = {"y": (None, None, [10.5, 9.5, 13.0, 10.05]), "quiet": (None, None, [])}
    out = explain(curves, up, {"y": [10.0]}, lag=0.5)      # late by up to 1 Hz (+0.4)
    assert out["y"] == ([10.5, 10.05], [9.5, 13.0]) and out["quiet"] == ([], [])
    down = dict(up, f_start=25.0, f_end=5.0)
    assert explain(curves, down, {"y": [10.0]}, lag=0.5)["y"] == ([9.5, 10.05], [10.5, 13.0])
    assert explain(curves, up, {}, lag=0.5)["y"] == ([], [10.5, 9.5, 13.0, 10.05])
