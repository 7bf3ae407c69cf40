"""Input signals: functions of time built from a model's ``signals:`` section.

Each becomes a sympy expression in ``t``; a table becomes the function ``table(k, t)``
whose derivative is ``table_slope(k, t)``, both printed as numba calls by the emitter.
Discontinuities (step times, table knots) are returned as breakpoints so the integrator
can stop there instead of stepping across them.
"""

from __future__ import annotations

import sympy as sp

from . import symbols


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
}


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
    raise KeyError(kind)
