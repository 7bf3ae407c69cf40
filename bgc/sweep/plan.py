"""Stage **plan**: the swept parameters' ranges -> the points of a sweep (``Plan``).

``-p NAME=START:STOP:COUNT`` gives an axis; the axes make a full grid (every combination,
the last parameter varying fastest), or, with ``samples``, a Latin hypercube of that many
points over the ranges (``scipy.stats.qmc``; ``seed`` makes it repeatable), for which the
COUNT is not given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from bgc.errors import BgcError

# more points than this is a typing mistake (a count of 1000 on three axes), not a sweep
MAX_POINTS = 100_000


@dataclass(frozen=True)
class Axis:
    """One swept parameter: its range and, on a grid, its number of values."""
    name: str
    start: float
    stop: float
    count: int | None         # None: a Latin hypercube's axis


@dataclass(frozen=True)
class Plan:
    """The points of a sweep: ``values[i, j]`` is parameter ``names[j]`` at point i."""
    names: tuple[str, ...]
    values: np.ndarray
    kind: str                 # "grid" | "latin hypercube"

    def __len__(self) -> int:
        return len(self.values)


def parse_axis(text: str, sampled: bool) -> Axis:
    """``NAME=START:STOP:COUNT`` (a grid) or, ``sampled``, ``NAME=START:STOP``; a
    one-line error naming the option and what is valid."""
    name, eq, rng = text.partition("=")
    want = "NAME=START:STOP" + ("" if sampled else ":COUNT")
    parts = rng.split(":")
    if not eq or not name or len(parts) != (2 if sampled else 3):
        hint = ("with --samples, an axis has no COUNT" if sampled and len(parts) == 3
                else "e.g. -p k=1000:5000:5 (a grid) or -p k=1000:5000 with --samples N")
        raise BgcError(f"{text!r} is not {want}", key="--param", hint=hint)
    try:
        start, stop = float(parts[0]), float(parts[1])
    except ValueError:
        raise BgcError(f"{text!r}: START and STOP must be numbers", key="--param") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise BgcError(f"{text!r}: START and STOP must be finite", key="--param")
    count = None
    if not sampled:
        if not parts[2].isdigit() or int(parts[2]) < 1:
            raise BgcError(f"{text!r}: COUNT must be a whole number >= 1", key="--param")
        count = int(parts[2])
        if count > 1 and start == stop:
            raise BgcError(f"{text!r}: {count} values of an empty range", key="--param",
                           hint="give START < STOP, or COUNT 1")
    return Axis(name, start, stop, count)


def plan(axes: list[Axis], samples: int | None = None, seed: int | None = None) -> Plan:
    """The grid of the axes, or ``samples`` points of a Latin hypercube over them."""
    names = tuple(a.name for a in axes)
    if not axes:
        raise BgcError("nothing to sweep", key="--param",
                       hint="give at least one -p NAME=START:STOP:COUNT")
    if len(set(names)) != len(names):
        twice = next(n for n in names if names.count(n) > 1)
        raise BgcError(f"parameter '{twice}' is swept twice", key="--param")
    if samples is not None:
        from scipy.stats import qmc
        if not 1 <= samples <= MAX_POINTS:
            raise BgcError(f"--samples must be in 1..{MAX_POINTS}, got {samples}",
                           key="--samples")
        unit = qmc.LatinHypercube(d=len(axes), seed=seed).random(samples)
        lo, hi = np.array([a.start for a in axes]), np.array([a.stop for a in axes])
        return Plan(names, lo + unit * (hi - lo), "latin hypercube")
    n = math.prod(a.count for a in axes)
    if n > MAX_POINTS:
        raise BgcError(f"the grid has {n} points, more than {MAX_POINTS}", key="--param",
                       hint="fewer values per axis, or a Latin hypercube (--samples N)")
    mesh = np.meshgrid(*[np.linspace(a.start, a.stop, a.count) for a in axes],
                       indexing="ij")
    return Plan(names, np.column_stack([m.ravel() for m in mesh]), "grid")
