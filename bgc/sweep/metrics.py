"""What a sweep computes at each point: the metrics, parsed from the command line, and
``evaluate``, which computes them for one parameter vector on a worker.

- ``--frf INPUT:OUTPUT``: the anti-resonances and resonances of OUTPUT's response to the
  excitation direction INPUT in the band, as ``bgc frf`` finds them
  (``bgc.analysis.frf``: linearize, then extrema);
- ``--metric KIND:OUTPUT[:T0:T1]``: KIND ``rms`` (root mean square) or ``peak`` (largest
  absolute value) of OUTPUT over the output times in [T0, T1] (the whole run without a
  window) of one simulation (``bgc.simulate``), shared by all such metrics of a point.

A metric that fails at a point (a run that stops, a state that is no equilibrium) leaves
its values empty and its message in the point's ``error``; the others still count.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from bgc.errors import BgcError

KINDS = {"rms": "root mean square", "peak": "largest absolute value"}


@dataclass(frozen=True)
class Frf:
    """Anti-resonances and resonances of ``output`` driven along ``direction``."""
    direction: str
    output: str

    @property
    def label(self) -> str:
        return f"{self.direction}:{self.output}"


@dataclass(frozen=True)
class Window:
    """``kind`` of ``output`` over the run's output times in [t0, t1]."""
    kind: str
    output: str
    t0: float | None = None
    t1: float | None = None

    @property
    def label(self) -> str:
        window = "" if self.t0 is None else f":{self.t0:g}:{self.t1:g}"
        return f"{self.kind}:{self.output}{window}"


def parse_frf(text: str) -> Frf:
    """``INPUT:OUTPUT`` of ``--frf``."""
    direction, colon, output = text.partition(":")
    if not colon or not direction or not output or ":" in output:
        raise BgcError(f"{text!r} is not INPUT:OUTPUT", key="--frf",
                       hint="an excitation direction and an output, e.g. pumping:a_OF_z")
    return Frf(direction, output)


def parse_window(text: str) -> Window:
    """``KIND:OUTPUT`` or ``KIND:OUTPUT:T0:T1`` of ``--metric``."""
    parts = text.split(":")
    hint = f"KIND: {', '.join(KINDS)}; e.g. rms:a_OF_z:5:28 (T0 < T1 in s) or peak:z"
    if len(parts) not in (2, 4) or not parts[1]:
        raise BgcError(f"{text!r} is not KIND:OUTPUT[:T0:T1]", key="--metric", hint=hint)
    if parts[0] not in KINDS:
        raise BgcError(f"{text!r}: unknown metric '{parts[0]}'", key="--metric", hint=hint)
    if len(parts) == 2:
        return Window(parts[0], parts[1])
    try:
        t0, t1 = float(parts[2]), float(parts[3])
    except ValueError:
        raise BgcError(f"{text!r}: T0 and T1 must be numbers", key="--metric",
                       hint=hint) from None
    if not 0 <= t0 < t1 < np.inf:
        raise BgcError(f"{text!r}: need 0 <= T0 < T1", key="--metric", hint=hint)
    return Window(parts[0], parts[1], t0, t1)


@dataclass(frozen=True)
class Run:
    """The one simulation of a point that its window metrics read."""
    t_end: float
    rtol: float
    atol: float
    solver: str
    points: int


@dataclass(frozen=True)
class Metrics:
    """Everything computed at each point: FRF metrics in [f_min, f_max] and window
    metrics on the simulation ``run`` (None without window metrics)."""
    frf: tuple[Frf, ...]
    windows: tuple[Window, ...]
    f_min: float
    f_max: float
    run: Run | None

    @property
    def labels(self) -> list[str]:
        return [m.label for m in self.frf + self.windows]


def evaluate(metrics: Metrics, module, model, p: np.ndarray) -> tuple[dict, str | None]:
    """The metrics at parameters ``p``: ``{label: value}`` (an FRF's value is
    ``{"antiresonances_hz": [...], "resonances_hz": [...]}``; a window's a number; None
    where it failed) and the failures' messages (None if none)."""
    from bgc.analysis import frf, modes
    values: dict = {}
    errors = []
    for m in metrics.frf:
        try:
            lin = frf.linearize(module, model, m.direction, p)
            anti, res, _ = modes.resonances(module, model, lin, m.output, metrics.f_min,
                                            metrics.f_max)
            values[m.label] = {"antiresonances_hz": [round(f, 4) for f in anti],
                               "resonances_hz": [round(f, 4) for f in res]}
        except (BgcError, np.linalg.LinAlgError, FloatingPointError) as exc:
            values[m.label] = None
            errors.append(f"{m.label}: {exc}")
    if metrics.windows:
        try:
            values.update(_windows(metrics, module, p))
        except (BgcError, FloatingPointError) as exc:
            values.update({m.label: None for m in metrics.windows})
            errors.append(f"simulation: {exc}")
    return values, "; ".join(errors) or None


def _windows(metrics: Metrics, module, p) -> dict:
    """The window metrics of one simulation at ``p``."""
    from bgc.simulate import simulate
    r = metrics.run
    result = simulate(module, t_end=r.t_end, rtol=r.rtol, atol=r.atol, solver=r.solver,
                      points=r.points, params=p)
    out = {}
    for m in metrics.windows:
        y = result.column(m.output)
        if m.t0 is not None:
            y = y[(result.t >= m.t0) & (result.t <= m.t1)]
        if not len(y):
            raise BgcError(f"{m.label}: no output time in the window", key="--metric")
        value = np.sqrt(np.mean(y ** 2)) if m.kind == "rms" else np.abs(y).max()
        out[m.label] = float(value)
    return out
