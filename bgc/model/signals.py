"""Input signals: functions of time built from a model's ``signals:`` section.

Each becomes a sympy expression in ``t``; a table becomes the function ``table(k, t)``
whose derivative is ``table_slope(k, t)``, both printed as numba calls by the emitter.
Discontinuities (step times, table knots) are returned as breakpoints so the integrator
can stop there instead of stepping across them.
"""

from __future__ import annotations

import sympy as sp

from bgc.model import symbols


class table(sp.Function):
    """Linear interpolation in table number ``k`` (held constant outside its range)."""
    nargs = 2

    def fdiff(self, argindex=2):
        if argindex == 2:
            return table_slope(*self.args)
        return sp.S.Zero


class table_slope(sp.Function):
    """Slope of ``table(k, t)``: piecewise constant, so its own derivative is zero."""
    nargs = 2

    def fdiff(self, argindex=2):
        return sp.S.Zero


# type -> (required keys, optional keys with defaults)
SIGNAL_TYPES: dict[str, tuple[tuple[str, ...], dict[str, float]]] = {
    "constant": (("value",), {}),
    "step": (("time",), {"initial": 0.0, "final": 1.0}),
    "sine": (("amplitude", "frequency"), {"phase": 0.0, "offset": 0.0}),
    "ramp": (("slope",), {"time": 0.0, "initial": 0.0}),
    "table": (("t", "values"), {}),
    "expression": (("expr",), {}),
    "chirp": (("t1", "t2", "t3", "f_start", "f_end"), {"amplitude": 1.0}),
}
# signal fields that are plain numbers, not expressions: times (breakpoints) and the
# chirp's frequencies (its sweep is analysed after the run)
NUMBER_FIELDS = ("time", "t1", "t2", "t3", "f_start", "f_end")


def chirp(t, t1: float, t2: float, t3: float, f_start, f_end, amplitude=1.0):
    """The paper's excitation g(t) (eqs 11.11-11.14, as intended: see the SARIB data set's
    README): a sine at f_start whose envelope rises as 2 t^2/t1^2 on [0, t1/2] and
    1 - 2 (t - t1)^2/t1^2 on [t1/2, t1] (value and slope continuous, 1 with zero slope at
    t1), held at f_start until t2, a linear chirp to f_end at t3, then f_end, with a
    continuous phase (``chirp_phase``)."""
    envelope = sp.Piecewise((2 * t ** 2 / t1 ** 2, t < t1 / 2),
                            (1 - 2 * (t - t1) ** 2 / t1 ** 2, t < t1), (1, True))
    return amplitude * envelope * sp.sin(chirp_phase(t, t2, t3, f_start, f_end))


def chirp_phase(t, t2: float, t3: float, f_start, f_end):
    """2 pi times the integral of the instantaneous frequency f_start (t < t2),
    f_start + (f_end - f_start) (t - t2) / (t3 - t2) (t2 <= t <= t3), f_end (t > t3)."""
    rate = (f_end - f_start) / (t3 - t2)
    return 2 * sp.pi * sp.Piecewise(
        (f_start * t, t < t2),
        (f_start * t + rate * (t - t2) ** 2 / 2, t < t3),
        (f_start * t3 + rate * (t3 - t2) ** 2 / 2 + f_end * (t - t3), True))


def chirp_frequency(t, t2: float, t3: float, f_start: float, f_end: float):
    """The chirp's instantaneous frequency [Hz] at (numpy) times ``t``."""
    import numpy as np
    return np.clip(f_start + (f_end - f_start) * (np.asarray(t) - t2) / (t3 - t2),
                   min(f_start, f_end), max(f_start, f_end))


def frequency(kind: str, v: dict) -> sp.Expr | None:
    """The highest frequency (Hz) a signal contains: a sine's, a chirp's larger end."""
    if kind == "sine":
        return sp.sympify(v["frequency"])
    if kind == "chirp":
        return sp.Max(sp.sympify(v["f_start"]), sp.sympify(v["f_end"]))
    return None


def build(kind: str, v: dict, table_index: int) -> tuple[sp.Expr, tuple[float, ...]]:
    """The expression and breakpoints of a signal whose numeric fields are ``v``."""
    t = symbols.t
    if kind == "constant":
        return v["value"], ()
    if kind == "step":
        expr = sp.Piecewise((v["initial"], t < v["time"]), (v["final"], True))
        return expr, (float(v["time"]),)
    if kind == "sine":
        return (v["offset"] + v["amplitude"] * sp.sin(2 * sp.pi * v["frequency"] * t
                                                        + v["phase"])), ()
    if kind == "ramp":
        expr = sp.Piecewise((v["initial"], t < v["time"]),
                            (v["initial"] + v["slope"] * (t - v["time"]), True))
        return expr, (float(v["time"]),)
    if kind == "table":
        return table(sp.Integer(table_index), t), tuple(float(x) for x in v["t"])
    if kind == "expression":
        return v["expr"], ()
    if kind == "chirp":
        t1, t2, t3 = (float(v[k]) for k in ("t1", "t2", "t3"))
        return (chirp(t, t1, t2, t3, v["f_start"], v["f_end"], v["amplitude"]),
                (t1 / 2, t1, t2, t3))
    raise KeyError(kind)
