"""The equations of the control blocks (``blocks:``): one rule per kind, each defining
the block's input ``u``, its output ``y`` and its states' rates in the equations
``Builder``. Saturation is ``Min(Max(v, lo), hi)`` and a clamping integrator's rate a
``Piecewise``: both are lowered to the LLVM kernels and differentiated there (the
Jacobian is exact away from the kinks). Gains, time constants and limits stay
expressions of parameters, so ``-p`` retunes a controller without recompiling."""

from __future__ import annotations

import sympy as sp

from bgc.codegen.builder import Builder, State
from bgc.model import symbols
from bgc.model.model import Block


def build(bld: Builder):
    """Every block's equations, in the order the model gives them."""
    for name, blk in bld.m.blocks.items():
        u = _signal(bld, blk, "u", blk.input)
        RULES[blk.kind](bld, blk, u)


def _signal(bld: Builder, blk: Block, attr: str, expr) -> sp.Symbol:
    """The block's signal ``attr`` (u, v, y) defined as ``expr``."""
    sym = symbols.block(blk.name, attr)
    bld.define(sym, expr, blk.name)
    bld.display[sym] = f"{blk.name}.{attr}"
    return sym


def _state(bld: Builder, blk: Block, label: str, rate, initial) -> sp.Symbol:
    """A state ``block.label`` with its rate and initial value (parameters)."""
    x, dx = symbols.state(blk.name, label), symbols.dstate(blk.name, label)
    bld.define(dx, rate, blk.name)
    name = f"{blk.name}.{label}"
    bld.states.append(State(name, x, dx, sp.sympify(initial), blk.name))
    bld.display[x], bld.display[dx] = name, f"d({name})/dt"
    return x


def _saturated(blk: Block, v):
    """``v`` held within the block's limits (itself without limits)."""
    if blk.limits is None:
        return v
    lo, hi = blk.limits
    return sp.Min(sp.Max(v, lo), hi)


def _gain(bld: Builder, blk: Block, u):
    _signal(bld, blk, "y", _saturated(blk, blk.values["k"] * u))


def _sum(bld: Builder, blk: Block, u):
    _signal(bld, blk, "y", _saturated(blk, u))


def _integrator(bld: Builder, blk: Block, u):
    """y' = k u; with limits a clamping integrator: at a limit it integrates only back
    inside, so it never winds up (y is the state held within the limits, against the
    integrator's overshoot of a step)."""
    x = symbols.state(blk.name, "x")
    rate = blk.values["k"] * u
    if blk.limits is not None:
        lo, hi = blk.limits
        rate = sp.Piecewise((sp.Min(rate, 0), x >= hi), (sp.Max(rate, 0), x <= lo),
                            (rate, True))
    _state(bld, blk, "x", rate, blk.initial)
    _signal(bld, blk, "y", _saturated(blk, x))


def _lag(bld: Builder, blk: Block, u):
    """T y' = k u - y."""
    x = symbols.state(blk.name, "x")
    _state(bld, blk, "x", (blk.values["k"] * u - x) / blk.values["T"], blk.initial)
    _signal(bld, blk, "y", _saturated(blk, x))


def _pi(bld: Builder, blk: Block, u):
    """Parallel form v = kp u + xi (+ the filtered derivative of a PID), xi' = ki u the
    integral action; with limits y = sat(v) and, by back-calculation (Astrom and
    Hagglund), xi' gets (y - v)/Tt, Tt = ``tt`` or Ti = kp/ki (PI), sqrt(Ti Td) =
    sqrt(kd/ki) (PID). The derivative kd s/(1 + s Tf) u, Tf = Td/n = kd/(kp n), is
    (kd/Tf)(u - xd) with xd' = (u - xd)/Tf: no derivative of the input is needed."""
    val = blk.values
    xi = symbols.state(blk.name, "xi")
    v = val["kp"] * u + xi
    if blk.kind == "PID":
        xd = symbols.state(blk.name, "xd")
        tf = val["kd"] / (val["kp"] * val["n"])
        v += val["kd"] / tf * (u - xd)
    rate = val["ki"] * u
    if blk.limits is not None:
        v = _signal(bld, blk, "v", v)
        y = _signal(bld, blk, "y", _saturated(blk, v))
        if blk.anti_windup:
            rate += (y - v) * _inverse_tracking_time(blk)
    else:
        _signal(bld, blk, "y", v)
    _state(bld, blk, "xi", rate, blk.initial)
    if blk.kind == "PID":       # the filter starts at 0: a kick if u(0) is not 0
        _state(bld, blk, "xd", (u - xd) / tf, 0)


def _inverse_tracking_time(blk: Block):
    """1/Tt of back-calculation: 1/tt, or 1/Ti = ki/kp (PI), 1/sqrt(Ti Td) = sqrt(ki/kd)
    (PID); written so that ki = 0 (no integral action) gives 0, not a division by 0."""
    val = blk.values
    if "tt" in val:
        return 1 / val["tt"]
    return val["ki"] / val["kp"] if blk.kind == "PI" else sp.sqrt(val["ki"] / val["kd"])


RULES = {"gain": _gain, "sum": _sum, "integrator": _integrator, "lag": _lag, "PI": _pi,
         "PID": _pi}
