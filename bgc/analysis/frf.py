"""Frequency response about the static equilibrium (paper 11.5: the anti-resonances read
from the linear model, to set beside the chirp's envelope).

The generated module is linearized at its initial state, which must be at rest with no
excitation:
dx/dt = A dx + B u, y = C dx + D u, u the amplitude of one excitation direction with
g(t) = 1. A is the analytic Jacobian; B and D are exact differences (the rhs and the
outputs are affine in an actuator's force); C is central differences of the outputs.
H(f) = C (j 2 pi f - A)^-1 B + D is solved per frequency (the idle spins of the SARIB's
bars make A defective, so no eigen-decomposition). Extrema of |H| are found on a grid and
refined by bounded Brent search.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar
from threadpoolctl import threadpool_limits

from bgc.errors import BgcError, SimulationError
from bgc.solvers.consistent import static_loads


@dataclass
class Linearization:
    A: np.ndarray
    B: np.ndarray           # (n,)
    C: np.ndarray           # (outputs, n)
    D: np.ndarray           # (outputs,)
    x: np.ndarray           # the equilibrium
    residual: float         # max |dx/dt| there
    output_names: tuple
    p: np.ndarray           # the parameters there (no excitation; static loads set)

    def response(self, freqs, output: str) -> np.ndarray:
        """Complex H at the frequencies [Hz] for one output."""
        return self.responses(freqs)[:, list(self.output_names).index(output)]

    def responses(self, freqs) -> np.ndarray:
        """Complex H at the frequencies [Hz] for every output: (frequencies, outputs).
        One thread: BLAS threads only slow solves of this size (30 times on a loaded
        2-core machine)."""
        freqs = np.atleast_1d(freqs)
        n = len(self.x)
        out = np.empty((len(freqs), len(self.output_names)), dtype=complex)
        with threadpool_limits(1):
            for i, f in enumerate(freqs):
                z = np.linalg.solve(2j * np.pi * f * np.eye(n) - self.A, self.B)
                out[i] = self.C @ z + self.D
        return out


def linearize(module, model, direction: str | None = None, p=None,
              x0=None) -> Linearization:
    """Linearize about the initial state (an equilibrium with no excitation); input:
    ``direction``'s amplitude with the constant kind (g = 1). Without ``direction``, A
    alone (B and D zero: what ``bgc modes`` reads), every excitation off and none
    needed."""
    exc = model.excitation
    if len(getattr(module, "ALGEBRAIC", ())):
        raise BgcError("a module whose kinematic loops are kept closed (an index-2 DAE, zcp "
                       "--keep-loops) is not linearized", key="--keep-loops",
                       hint="drop --keep-loops: the loops opened give the same motion")
    names = list(module.PARAM_NAMES)
    p0 = np.array(module.PARAMS if p is None else p, dtype=np.float64)
    if direction is not None:
        if exc is None:
            raise BgcError(f"{model.file} has no 'excitation' section", key="--input",
                           hint="declare excitation: {directions: ..., kinds: ...} in the "
                                "model")
        const = [k for k, s in exc.kinds.items() if s.kind == "constant"]
        if not const:
            raise BgcError("the excitation has no constant kind to linearize with",
                           key="--input", hint="add kinds: {constant: {type: constant, "
                                               "value: 1.0}}")
        for name, value in exc.select(const[0], direction, amplitude=0.0).items():
            p0[names.index(name)] = value
        value = float(exc.kinds[const[0]].expr)
    elif exc is not None:       # every direction's amplitude off
        for d in exc.directions:
            p0[names.index(exc.param(d))] = 0.0
    x0 = module.initial_state(p0) if x0 is None else x0
    if getattr(module, "STATIC_LOADS", False):
        p0 = static_loads(module, x0, p0)
    # The initial state must be the equilibrium: a Newton polish could not be trusted, it
    # would shift the functional springs' integrated deflections against the poses.
    x = np.array(x0, dtype=np.float64)
    f0 = module.rhs(0.0, x, p0)
    if direction is not None:
        p1 = p0.copy()
        p1[names.index(exc.param(direction))] = 1.0
        f1 = module.rhs(0.0, x, p1)
    res = float(np.abs(f0).max(initial=0.0))
    scale = float(np.abs(f1).max()) if direction is not None else 0.0
    if res > 1e-6 * max(1.0, scale):
        worst = module.STATE_NAMES[int(np.argmax(np.abs(f0)))]
        raise SimulationError(f"the initial state is not a static equilibrium: "
                              f"d{worst}/dt = {res:.3g}", hint="give the preloads that hold "
                              "it (or parasitic: {loads: static}), or start from a state at rest")
    A = module.jac(0.0, x, p0)
    bad = ~np.isfinite(A).all(axis=1)
    if bad.any():       # a constraint block without an inverse (redundant, or singular)
        names = [module.STATE_NAMES[i] for i in np.flatnonzero(bad)]
        raise SimulationError(
            f"the Jacobian at the equilibrium is not finite in the rows of "
            f"{', '.join(names[:4])}{' ...' if len(names) > 4 else ''}: no linearization "
            "there", hint="the constraints' block is rank-deficient here (redundant "
                          "constraints or a singular configuration): --method augmented "
                          "linearizes through both")
    if direction is not None:
        B = (f1 - f0) / value
        D = (module.outputs(0.0, x, p1) - module.outputs(0.0, x, p0)) / value
    else:
        B, D = np.zeros(len(x)), np.zeros(len(module.OUTPUT_NAMES))
    C = central_differences(lambda y: module.outputs(0.0, y, p0), x)
    return Linearization(A, B, C, D, x, res, tuple(module.OUTPUT_NAMES), p0)


def central_differences(fun, x, cols=None, rel: float = 1e-6) -> np.ndarray:
    """d fun / d x[cols] (every column of ``x`` by default) by central differences of
    step ``rel`` times max(1, |x_j|): the outputs' C and the constraints' rows."""
    cols = range(len(x)) if cols is None else cols
    out = None
    for k, j in enumerate(cols):
        h = rel * max(1.0, abs(x[j]))
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        col = (np.asarray(fun(xp)) - np.asarray(fun(xm))) / (2 * h)
        if out is None:
            out = np.empty((len(col), len(cols)))
        out[:, k] = col
    return out if out is not None else np.zeros((len(np.asarray(fun(x))), 0))


def grid(f_min: float, f_max: float, step: float = 0.01) -> np.ndarray:
    """The frequencies of a ``step`` grid over [f_min, f_max]."""
    return np.linspace(f_min, f_max, int(round((f_max - f_min) / step)) + 1)


# The grid H is computed on: 0.01 Hz, at most this many frequencies (a 2 kHz band; one
# linear solve of the model's size each), refused before any allocation.
STEP_HZ = 0.01
MAX_FREQUENCIES = 200_001


def check_band(f_min: float, f_max: float, key: str = "--f-max") -> None:
    """A band [f_min, f_max] the grid can cover: 0 < f_min < f_max and at most
    ``MAX_FREQUENCIES`` grid points."""
    if not 0 < f_min < f_max:
        raise BgcError(f"need 0 < --f-min < --f-max, got {f_min:g} and {f_max:g}",
                       key="--f-min" if key == "--f-max" else key,
                       hint="give the band's start first, e.g. --f-min 5 --f-max 25")
    n = (f_max - f_min) / STEP_HZ + 1
    if not n <= MAX_FREQUENCIES:
        raise BgcError(f"the band {f_min:g}..{f_max:g} Hz is {n:.3g} frequencies at "
                       f"{STEP_HZ} Hz, more than bgc's limit of {MAX_FREQUENCIES}", key=key,
                       hint=f"narrow the band to at most "
                            f"{(MAX_FREQUENCIES - 1) * STEP_HZ:g} Hz")


def sweep(lin: Linearization, output: str, f_min: float, f_max: float,
          step: float = STEP_HZ) -> tuple[np.ndarray, np.ndarray]:
    """The frequencies of a ``step`` grid over [f_min, f_max] and H there."""
    check_band(f_min, f_max)
    f = grid(f_min, f_max, step)
    return f, lin.response(f, output)


def extrema(lin: Linearization, output: str, f_min: float, f_max: float,
            grid=None, xatol: float = 1e-4) -> tuple[list[float], list[float]]:
    """Anti-resonances (local minima of |H|) and resonances (local maxima) in
    [f_min, f_max] (found on ``grid`` = ``sweep(...)``, computed if not given), each
    refined to ``xatol`` Hz (``bgc tune`` asks for more)."""
    f, h = grid if grid is not None else sweep(lin, output, f_min, f_max)
    mag = np.abs(h)
    found: dict[str, list[float]] = {"min": [], "max": []}
    for k in range(1, len(f) - 1):
        for kind, sign in (("min", 1.0), ("max", -1.0)):
            if sign * mag[k] < sign * mag[k - 1] and sign * mag[k] <= sign * mag[k + 1]:
                r = minimize_scalar(lambda x, s=sign: s * abs(lin.response([x], output)[0]),
                                    bounds=(f[k - 1], f[k + 1]), method="bounded",
                                    options={"xatol": xatol})
                found[kind].append(float(r.x))
    return found["min"], found["max"]
