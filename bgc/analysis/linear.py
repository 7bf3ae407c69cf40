"""The linear picture of a run, in one pass: the linearization about the static equilibrium
(``frf.linearize``), its modes (``modes.analyse``) and every output's frequency response
to the run's excitation direction over a band, with its anti-resonances and resonances as
``bgc frf`` finds them. What ``bgc simulate`` checks a chirp's envelope minima against and
what ``bgc report`` draws."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bgc.analysis import frf, modes


@dataclass
class LinearView:
    lin: frf.Linearization
    modal: modes.Modal
    direction: str | None
    f: np.ndarray = field(default_factory=lambda: np.zeros(0))       # the 0.01 Hz grid
    H: np.ndarray = field(default_factory=lambda: np.zeros((0, 0)))  # (f, outputs)
    anti: dict = field(default_factory=dict)        # output -> anti-resonances [Hz]
    res: dict = field(default_factory=dict)         # output -> resonances (modes) [Hz]
    peaks: dict = field(default_factory=dict)       # output -> peaks of |H| [Hz]

    def lag(self, f_min: float, f_max: float) -> float:
        """The slowest decay time 1 / (zeta omega) [s] of the functional oscillatory
        modes in [f_min, f_max] (0 if none): how long a chirp's envelope trails |H|."""
        rates = [-m.eigenvalue.real for m in self.modal.band(f_min, f_max)
                 if m.kind == "functional" and m.eigenvalue.real < 0]
        return 1.0 / min(rates) if rates else 0.0


def analyse(module, model, direction: str | None, p, f_min: float | None = None,
            f_max: float | None = None, mechanism=None, skip=()) -> LinearView:
    """The LinearView of ``module`` at ``p`` (the run's parameters: the linearization
    turns the excitation off itself) with the response to ``direction`` (None: modes
    only) over [f_min, f_max] (default: ``band``) for every output but ``skip``."""
    lin = frf.linearize(module, model, direction, p)
    modal = modes.analyse(module, model, lin, mechanism)
    view = LinearView(lin, modal, direction)
    if direction is None:
        return view
    if f_min is None or f_max is None:
        f_min, f_max = band(modal)
    view.f = frf.grid(f_min, f_max)
    view.H = lin.responses(view.f)
    for k, name in enumerate(lin.output_names):
        if name in skip or not np.abs(view.H[:, k]).max(initial=0.0) > 0:
            continue
        anti, peaks = frf.extrema(lin, name, f_min, f_max, (view.f, view.H[:, k]))
        behind = modal.behind(name, peaks) if peaks else []
        view.anti[name], view.peaks[name] = anti, peaks
        view.res[name] = modes.natural(behind, peaks)
    return view


def band(modal: modes.Modal) -> tuple[float, float]:
    """A band that shows the functional modes: from half the lowest to 1.5 times the
    highest, rounded outwards to 0.1 Hz (1 to 100 Hz without any)."""
    f = [m.frequency_hz for m in modal.modes if m.kind == "functional"]
    if not f:
        return 1.0, 100.0
    lo, hi = np.floor(5 * min(f)) / 10, np.ceil(15 * max(f)) / 10
    return max(lo, 0.1), max(hi, lo + 1.0)
