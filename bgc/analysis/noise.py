"""Which outputs of a run are numerical noise: signals below what the run resolves, which
the plots state instead of drawing, and whose envelope minima are no anti-resonances.

The criterion is free of units. An output's noise floor is ``rtol`` times the largest peak
|y| over the run among the outputs that share its declared unit (itself included): the
integrator holds each state's error near rtol of its size, the outputs computed from the
states carry that relative error, so a signal below rtol of a like quantity of the same run
cannot be told from the error (the SARIB under pumping: F_A1_y, 5e-9 N of round-off, beside
F_A1_z, 300 N, at rtol 1e-5: floor 3e-3 N). Both sides are in one unit and rtol is a ratio,
so rescaling the units changes nothing. An output whose unit the model does not declare has
no floor (it is never noise): its size cannot be set against another quantity's. A tighter
rtol lowers the floor, so a real signal that small is resolved by asking for it.
"""

from __future__ import annotations

import numpy as np


def peaks(y: np.ndarray) -> np.ndarray:
    """Each column's largest |value| (NaN ignored; 0 for no rows)."""
    y = np.asarray(y, dtype=float)
    if y.ndim != 2 or y.shape[0] == 0:
        return np.zeros(y.shape[1] if y.ndim == 2 else 0)
    a = np.abs(y)
    return np.where(np.isnan(a), 0.0, a).max(axis=0)


def floors(names, y: np.ndarray, units: dict, rtol: float) -> dict[str, float]:
    """name -> noise floor (``rtol`` times the largest peak of the outputs of its unit) of
    every output (column of ``y``) whose unit ``units`` declares; the others have none."""
    pk = peaks(y)
    largest: dict[str, float] = {}
    for name, p in zip(names, pk):
        if units.get(name):
            largest[units[name]] = max(largest.get(units[name], 0.0), float(p))
    return {n: rtol * largest[units[n]] for n in names if units.get(n)}


def noisy(names, y: np.ndarray, floor: dict) -> dict[str, float]:
    """name -> peak |y| of each output whose peak is below its ``floor``: numerical noise."""
    return {n: float(p) for n, p in zip(names, peaks(y)) if n in floor and p < floor[n]}


def of_result(result, units: dict, rtol: float) -> tuple[dict, dict]:
    """(floors, noisy) of a Result's outputs at tolerance ``rtol``."""
    fl = floors(result.output_names, result.y, units, rtol)
    return fl, noisy(result.output_names, result.y, fl)
