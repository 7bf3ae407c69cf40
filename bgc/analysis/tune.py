"""Tuning (``bgc tune``, issue 28): the value of a parameter that puts an anti-resonance of
an output on a target frequency, by root finding on the linearization
(``bgc.analysis.frf``). The parameter is a module parameter: no step recompiles.

The anti-resonance is followed, not searched afresh at each value. At the start value it
is the one nearest the target in a band. A scan of the bracket walks it from there to
both ends, each value's the one nearest the extrapolation of its neighbours' (in a window
around it): that gives its reachable range and the interval where it crosses the target.
Brent's method solves there, each value's anti-resonance the one nearest the
interpolation of the values already known on either side. dF/dparam is a central
difference at the solution.
"""

from __future__ import annotations

import bisect
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq
from threadpoolctl import threadpool_limits

from bgc.analysis import frf
from bgc.errors import BgcError, SimulationError

SCAN = 9            # values of the scan of the bracket
STEP = 0.01         # Hz: the grid the anti-resonances are found on (bgc frf's), or
WINDOW = 60         # intervals across a window, if coarser
XATOL = 1e-9        # Hz: their refinement (bgc frf's 1e-4 would blur dF/dparam)
MIN_HALF = 0.02     # the least half-width of a window, a fraction of the target
REL_H = 1e-3        # the central difference's step, a fraction of the value


@dataclass
class Tuning:
    value: float                        # the parameter's value that puts it on the target
    frequency: float                    # the anti-resonance there [Hz]
    sensitivity: float                  # dF/dparam there [Hz per unit of the parameter]
    start: float                        # the value it was followed from
    start_frequency: float              # the anti-resonance there [Hz]
    bracket: tuple[float, float]
    reachable: tuple[float, float]      # its range over the scan of the bracket [Hz]
    linearizations: int


class Follower:
    """The anti-resonance of ``output`` against the parameter's value; ``at(v)`` is the
    linearization there. Every value evaluated is kept (``known``), so that a new one is
    looked for near the interpolation of its neighbours'."""

    def __init__(self, at, output: str, target: float, name: str):
        self.at, self.output, self.name = at, output, name
        self.min_half = max(MIN_HALF * target, 5 * STEP)
        self.known: dict[float, float] = {}
        self.count = 0
        self._lin = (None, None)

    def linearization(self, v: float) -> frf.Linearization:
        if self._lin[0] != v:
            self.count += 1
            try:
                self._lin = (v, self.at(v))
            except SimulationError as exc:
                raise SimulationError(f"at {self.name} = {v:g}: {exc.message}",
                                      key=exc.key, hint=exc.hint) from None
        return self._lin[1]

    def within(self, v: float, lo: float, hi: float, step: float | None = None) -> list:
        """The anti-resonances in [lo, hi] at ``v``, found on a grid of ``step`` (default:
        the coarser of STEP and a WINDOW-th of the interval)."""
        lin = self.linearization(v)
        lo = max(lo, STEP)
        grid = frf.sweep(lin, self.output, lo, hi, step or max(STEP, (hi - lo) / WINDOW))
        return frf.extrema(lin, self.output, lo, hi, grid, XATOL)[0]

    def near(self, v: float, f_near: float, half: float) -> float:
        """The anti-resonance at ``v`` nearest ``f_near``, looked for within ``half`` of
        it, then twice and four times as far."""
        if v in self.known:
            return self.known[v]
        half = max(half, self.min_half)
        for widen in (1, 2, 4):
            mins = self.within(v, f_near - widen * half, f_near + widen * half)
            if mins:
                self.known[v] = min(mins, key=lambda f: abs(f - f_near))
                return self.known[v]
        raise BgcError(f"the anti-resonance of {self.output} followed to about "
                       f"{f_near:.3f} Hz is lost at {self.name} = {v:g} (none within "
                       f"{4 * half:.3g} Hz)", key="--bracket",
                       hint="narrow --bracket around the start value")

    def __call__(self, v: float) -> float:
        """The anti-resonance at ``v``, near the interpolation (or extrapolation) of the
        two known values nearest it on either side (from one: within a window as wide as
        an anti-resonance proportional to the value would move)."""
        if v in self.known:
            return self.known[v]
        vs = sorted(self.known)
        if len(vs) < 2:         # no slope yet: as far as a frequency proportional to v
            v0, f0 = vs[0], self.known[vs[0]]
            return self.near(v, f0, f0 * abs(v - v0) / abs(v0) if v0 else self.min_half)
        k = bisect.bisect(vs, v)
        a, b = (k - 1, k) if 0 < k < len(vs) else ((k - 2, k - 1) if k else (0, 1))
        va, vb = vs[a], vs[b]
        fa, fb = self.known[va], self.known[vb]
        pred = fa + (fb - fa) * (v - va) / (vb - va)
        return self.near(v, pred, 2 * max(abs(pred - fa), abs(pred - fb)))


def solve(at, output: str, target: float, start: float, bracket=None, band=None,
          name: str = "the parameter") -> Tuning:
    """The value of the parameter in ``bracket`` (default: half to twice ``start``) at
    which the anti-resonance of ``output`` that sits nearest ``target`` within ``band``
    (default: half to twice the target) at ``start`` is on ``target``. ``at(v)``: the
    linearization at the parameter's value ``v``."""
    # one BLAS thread: its solves (n ~ 150) lose to a second's overhead, badly on a busy
    # machine (the SARIB's tuning: 17 s with one, 240 s with two beside other work)
    with threadpool_limits(limits=1, user_api="blas"):
        return _solve(at, output, target, start, bracket, band, name)


def _solve(at, output, target, start, bracket, band, name) -> Tuning:
    lo, hi = sorted(bracket) if bracket is not None else default_bracket(start, name)
    if not lo < hi:
        raise BgcError(f"the bracket [{lo:g}, {hi:g}] is empty", key="--bracket")
    f_lo, f_hi = band if band is not None else (target / 2, 2 * target)
    follow = Follower(at, output, target, name)
    found = follow.within(start, f_lo, f_hi, STEP)
    if not found:
        raise BgcError(f"no anti-resonance of {output} in [{f_lo:g}, {f_hi:g}] Hz at "
                       f"{name} = {start:g}", key="--output",
                       hint="widen --f-min/--f-max, or check the output and the input")
    follow.known[start] = f0 = min(found, key=lambda f: abs(f - target))
    values = np.linspace(lo, hi, SCAN)
    i0 = int(np.searchsorted(values, start))
    for seq in (values[i0:], values[:i0][::-1]):        # walked out from the start
        for v in seq:
            follow(float(v))
    fs = [follow.known[float(v)] for v in values]
    reach = (min(fs), max(fs))
    cross = [k for k in range(SCAN - 1) if (fs[k] - target) * (fs[k + 1] - target) <= 0]
    if not cross:
        raise BgcError(f"{target:g} Hz is out of reach: {name} in [{lo:g}, {hi:g}] puts "
                       f"the anti-resonance of {output} between {reach[0]:.4g} and "
                       f"{reach[1]:.4g} Hz", key="--target-frequency",
                       hint="widen --bracket, or tune another parameter")
    k = min(cross, key=lambda k: abs(values[k] + values[k + 1] - 2 * start))
    va, vb = float(values[k]), float(values[k + 1])
    scale = max(abs(va), abs(vb))
    v = brentq(lambda v: follow(v) - target, va, vb, xtol=1e-10 * scale, rtol=1e-10)
    f = follow(v)
    h = REL_H * (abs(v) if v else hi - lo)
    slope = (fs[k + 1] - fs[k]) / (vb - va)
    fp = follow.near(v + h, f + slope * h, follow.min_half)
    fm = follow.near(v - h, f - slope * h, follow.min_half)
    return Tuning(v, f, (fp - fm) / (2 * h), start, f0, (lo, hi), reach, follow.count)


def default_bracket(start: float, name: str) -> tuple[float, float]:
    """Half to twice the start value (a parameter starting at 0 needs a bracket)."""
    if start == 0:
        raise BgcError(f"{name} starts at 0, so no bracket follows from it",
                       key="--bracket", hint="give --bracket LO:HI")
    return tuple(sorted((start / 2, 2 * start)))


def tune(module, model, direction: str, output: str, name: str, target: float, p=None,
         bracket=None, band=None) -> Tuning:
    """``solve`` for the module parameter ``name``, from its value in ``p`` (default:
    the module's), the input being the excitation ``direction``."""
    names = list(module.PARAM_NAMES)
    if name not in names:
        raise BgcError(f"unknown parameter '{name}'", key="--param",
                       hint="parameters: " + ", ".join(names))
    base = np.array(module.PARAMS if p is None else p, dtype=np.float64)
    i = names.index(name)

    def at(v):
        q = base.copy()
        q[i] = v
        return frf.linearize(module, model, direction, q)
    return solve(at, output, target, float(base[i]), bracket, band, name)
