"""A chirp response read against frequency (paper 11.5, Figs 11.27-11.31): the envelope
of an output over the sweep, against the excitation's instantaneous frequency, and its
minima (the anti-resonances as the chirp shows them; the sweep's finite rate delays and
skews them against the linear model's, ``bgc frf``)."""

from __future__ import annotations

import numpy as np

from bgc.model.signals import chirp_frequency


def envelope(t, y, chirp: dict) -> tuple[np.ndarray, np.ndarray]:
    """(frequency [Hz], amplitude) of ``y`` over the sweep [t2, t3] of a chirp signal's
    ``numbers`` (t1, t2, t3, f_start, f_end): half the peak-to-peak of y over each period
    of the excitation, at that period's instantaneous frequency."""
    t, y = np.asarray(t), np.asarray(y)
    t2, t3 = chirp["t2"], min(chirp["t3"], float(t[-1]))
    freq = []
    amp = []
    a = t2
    while True:
        f = float(chirp_frequency(a, chirp["t2"], chirp["t3"], chirp["f_start"],
                                  chirp["f_end"]))
        b = a + 1.0 / f
        if b > t3:
            break
        sel = (t >= a) & (t < b)
        if sel.sum() >= 4:
            freq.append(float(chirp_frequency((a + b) / 2, chirp["t2"], chirp["t3"],
                                              chirp["f_start"], chirp["f_end"])))
            amp.append((y[sel].max() - y[sel].min()) / 2)
        a = b
    return np.array(freq), np.array(amp)


def minima(freq, amp, separation: float = 0.5) -> list[float]:
    """The frequencies of the envelope's local minima, deepest first: each the lowest
    point within ``separation`` Hz on either side and 5 % below the highest there. A
    point closer than ``separation`` to an end of the sweep has no such window, and the
    envelope falling towards the end is no minimum: none is reported there (the roll
    chirp's a_OF_z 'minima' at 5.10 and 24.97 Hz were its ends)."""
    freq, amp = np.asarray(freq), np.asarray(amp)
    if not freq.size:
        return []
    lo, hi = freq.min() + separation, freq.max() - separation
    out = []
    for i in np.argsort(amp):
        if not lo <= freq[i] <= hi:
            continue
        near = np.abs(freq - freq[i]) <= separation
        if (amp[i] <= amp[near].min() and amp[near].max() > amp[i] * 1.05
                and all(abs(freq[i] - f) > separation for f in out)):
            out.append(float(freq[i]))
    return out


def analyse(result, chirp: dict, skip=("g",), floor: dict | None = None) -> dict:
    """Every output's envelope over the sweep and its minima: name -> (freq, amp, minima).
    An output whose envelope stays below its ``floor`` (``noise.floors``) is numerical
    noise: its minima are those of the noise, no anti-resonance, so it has none."""
    out = {}
    for name in result.output_names:
        if name in skip:
            continue
        f, a = envelope(result.t, result.column(name), chirp)
        quiet = name in (floor or {}) and not a.max(initial=0.0) >= floor[name]
        out[name] = (f, a, [] if quiet else minima(f, a))
    return out


def chirp_sweep(excitation, selected: dict | None, result,
                floor: dict | None = None) -> dict | None:
    """``analyse`` of a run whose selected excitation (``selected``: {kind, direction,
    ...}, a kind of the model's ``excitation``) is a chirp, once the run has covered a
    tenth of the sweep [t2, t3], the outputs below their noise ``floor`` without minima;
    None for any other run. What ``bgc simulate`` and a scene's run report."""
    if not selected:
        return None
    signal = excitation.kinds[selected["kind"]]
    if signal.kind != "chirp":
        return None
    chirp = signal.numbers
    if not result.t[-1] > chirp["t2"] + 0.1 * (chirp["t3"] - chirp["t2"]):   # some sweep
        return None
    return analyse(result, chirp, floor=floor)


def minima_hz(curves: dict | None, digits: int) -> dict | None:
    """The envelope minima of ``chirp_sweep``'s curves, rounded to ``digits``: name ->
    [Hz, ...], deepest first (None for None)."""
    if curves is None:
        return None
    return {name: [round(f, digits) for f in c[2]] for name, c in curves.items()}


def sweep_rate(chirp: dict) -> float:
    """The chirp's sweep rate [Hz/s] (negative: downwards)."""
    return (chirp["f_end"] - chirp["f_start"]) / (chirp["t3"] - chirp["t2"])


def explain(curves: dict, chirp: dict, frf_anti: dict, lag: float) -> dict:
    """Which envelope minima are the structure's: name -> (anti-resonances, transients).

    A chirp's envelope follows the steady state |H(f)| late: the response builds up and
    decays with the modes' time constants, so a minimum of |H| shows up to ``lag``
    [s] of sweep later (``lag``: the slowest functional mode's 1/(zeta omega) in the
    band) and two envelope periods either way. A minimum of the envelope within that
    window of an anti-resonance of the FRF (``frf_anti``: name -> [Hz]) is that
    anti-resonance; one no anti-resonance explains is the sweep's own: the beating of a
    mode's free vibration, started as the sweep passed its resonance, against the forced
    response (the ripples after a resonance), or a nonlinear effect the FRF cannot show."""
    rate = sweep_rate(chirp)
    out = {}
    for name, (_, _, mins) in curves.items():
        anti, trans = [], []
        for fm in mins:
            step = 2 * abs(rate) / max(fm, 1e-9)          # two envelope periods
            ok = any(-step <= (fm - fa) * np.sign(rate) <= abs(rate) * lag + step
                     for fa in frf_anti.get(name, ()))
            (anti if ok else trans).append(fm)
        out[name] = (anti, trans)
    return out
