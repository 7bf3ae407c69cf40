"""The semi-active SARIB (issue 26, models/sarib_semiactive.yaml), scripted with bgc's API
as a user would: ``make semiactive`` (or ``python -m bgc.bench.semiactive --out DIR``).

1. The pumping anti-resonance of ``a_OF_z`` against the flapping masses' setpoint
   ``x_set`` (-10 ... +10 mm), from the linearization of the whole coupled model (the
   motors, screws and PI loops included), under each constraint method: Hz per mm.
2. The setpoints that put the anti-resonance on 17.5 and on 18.5 Hz (``bgc tune``'s root
   finding, bgc.analysis.tune).
3. A run in which the rotor frequency steps from 17.5 to 18.5 Hz at 2 s while the
   setpoint follows (a 0.5 s ramp from 2 s): the absorber retunes. Beside it the same
   run with the setpoint held, and each method's run, compared with lagrange's.

Writes frf.csv, retune.csv, frf.png, retune.png and summary.md to ``--out``.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
from bgc.analysis import frf, tune
from bgc.analysis.results import panels, save_figure, write_table
from bgc.bench.cases import MODELS
from bgc.pipeline import ensure_module
from bgc.simulate import simulate

MODEL = MODELS / "sarib_semiactive.yaml"
METHODS = ("parasitic", "lagrange", "zcp")
SETPOINTS_MM = (-10.0, -5.0, 0.0, 5.0, 10.0)
BAND = (15.0, 21.0)
F_A, F_B, T_STEP, T_END = 17.5, 18.5, 2.0, 6.0
RUN = dict(t_end=T_END, rtol=1e-7, atol=1e-9, points=12001, solver="native")


def params(mod, **values) -> np.ndarray:
    """The module's parameters with ``values`` set by name."""
    p = np.array(mod.PARAMS, dtype=float)
    names = list(mod.PARAM_NAMES)
    for k, v in values.items():
        p[names.index(k)] = v
    return p


def antiresonance(mod, model, x_set: float) -> float:
    """The pumping anti-resonance of a_OF_z [Hz] with the masses at ``x_set`` [m]."""
    lin = frf.linearize(mod, model, "pumping", params(mod, x_set=x_set))
    mins, _ = frf.extrema(lin, "a_OF_z", *BAND)
    if len(mins) != 1:
        sys.exit(f"expected one anti-resonance in {BAND} Hz at x_set = {x_set}, got {mins}")
    return mins[0]


def retune(mod, model, x_a: float, x_b: float, follow: bool = True):
    """The frequency-step run: masses at ``x_a``, moved to ``x_b`` from 2 s if
    ``follow``."""
    exc = model.excitation.select("step", "pumping")
    p = params(mod, x_set=x_a, dx_retune=(x_b - x_a) if follow else 0.0, f_a=F_A, f_b=F_B,
               t_step=T_STEP, t_retune=T_STEP, **exc)
    return simulate(mod, params=p, **RUN)


def amplitude(t, y, f, t0, t1) -> float:
    """Amplitude of the component of ``y`` at ``f`` over [t0, t1] (least squares)."""
    sel = (t >= t0) & (t <= t1)
    M = np.column_stack([np.sin(2 * np.pi * f * t[sel]), np.cos(2 * np.pi * f * t[sel]),
                         np.ones(sel.sum())])
    c = np.linalg.lstsq(M, y[sel], rcond=None)[0]
    return float(np.hypot(c[0], c[1]))


def main(out: Path):
    out.mkdir(parents=True, exist_ok=True)
    rows, runs, notes, built = [], {}, [], {}
    for method in METHODS:
        t0 = time.perf_counter()
        mod, model, _ = built[method] = ensure_module(MODEL, out / "build", method)
        f = [antiresonance(mod, model, x / 1000) for x in SETPOINTS_MM]
        slope = np.polyfit(SETPOINTS_MM, f, 1)[0]
        x_a, x_b = (tune.tune(mod, model, "pumping", "a_OF_z", "x_set", target, params(mod),
                              (-0.015, 0.015), BAND).value for target in (F_A, F_B))
        rows += [(method, x, fx) for x, fx in zip(SETPOINTS_MM, f)]
        notes.append((method, f, slope, x_a, x_b, time.perf_counter() - t0))
        print(f"{method}: {', '.join(f'{v:.3f}' for v in f)} Hz; {slope:.4f} Hz/mm; "
              f"x(17.5 Hz) = {x_a * 1e3:.3f} mm, x(18.5 Hz) = {x_b * 1e3:.3f} mm",
              file=sys.stderr)
    # every method runs the reference's (lagrange's) schedule, so that the runs differ
    # by the methods only
    _, _, _, x_a, x_b, _ = notes[METHODS.index("lagrange")]
    for method in METHODS:
        mod, model, _ = built[method]
        runs[method] = retune(mod, model, x_a, x_b)
        if method == "parasitic":
            runs["held"] = retune(mod, model, x_a, x_b, follow=False)
    write_table(out / "frf.csv", ["x_set_mm"] + [f"{m}_hz" for m in METHODS],
                [SETPOINTS_MM] + [[f for mm, _, f in rows if mm == m] for m in METHODS])
    _tables(out, runs)
    _figures(out, runs, rows, built["lagrange"])
    _summary(out, runs, notes)


def _tables(out: Path, runs):
    names, cols = ["t"], [runs["parasitic"].t]
    for key, r in runs.items():
        for o in ("a_OF_z", "x_1", "i_1"):
            names.append(f"{o}_{key}")
            cols.append(r.column(o))
    write_table(out / "retune.csv", names, cols)


def _figures(out: Path, runs, rows, reference):
    fig, ax = panels(2, 3.2, sharex=False)
    ax = ax[:, 0]
    for method in METHODS:
        pts = [(x, f) for m, x, f in rows if m == method]
        ax[0].plot(*zip(*pts), "o-", label=method)
    ax[0].set(xlabel="x_set [mm]", ylabel="anti-resonance [Hz]")
    ax[0].legend()
    mod, model, _ = reference
    for x in (-10.0, 0.0, 10.0):
        lin = frf.linearize(mod, model, "pumping", params(mod, x_set=x / 1000))
        f, h = frf.sweep(lin, "a_OF_z", *BAND)
        ax[1].semilogy(f, np.abs(h), label=f"x_set = {x:g} mm")
    ax[1].set(xlabel="f [Hz]", ylabel="|a_OF_z / F_pumping| [m/s^2/N]")
    ax[1].legend()
    save_figure(fig, out / "frf.png", "semi-active SARIB: pumping anti-resonance of a_OF_z")
    fig, ax = panels(3, 2.6)
    ax = ax[:, 0]
    r, held = runs["parasitic"], runs["held"]
    ax[0].plot(held.t, held.column("a_OF_z"), lw=0.5, color="0.6", label="setpoint held")
    ax[0].plot(r.t, r.column("a_OF_z"), lw=0.5, label="retuned")
    ax[0].set(ylabel="a_OF_z [m/s^2]")
    ax[0].legend(loc="upper left")
    for method in METHODS:
        rm = runs[method]
        for i in (1, 2, 3, 4):
            kw = dict(lw=0.8, label=method if i == 1 else None,
                      ls={"parasitic": "-", "lagrange": "--", "zcp": ":"}[method])
            ax[1].plot(rm.t, 1e3 * rm.column(f"x_{i}"), **kw)
            ax[2].plot(rm.t, rm.column(f"i_{i}"), **kw)
    ax[1].set(ylabel="mass positions x_1..4 [mm]")
    ax[1].legend(loc="upper right")
    ax[2].set(ylabel="motor currents i_1..4 [A]", xlabel="t [s]")
    save_figure(fig, out / "retune.png",
                f"rotor frequency {F_A} -> {F_B} Hz at {T_STEP} s; the absorber retunes")


def _summary(out: Path, runs, notes):
    ref = runs["lagrange"]
    lines = ["# Semi-active SARIB", "",
             f"Model: models/sarib_semiactive.yaml. Pumping anti-resonance of a_OF_z "
             f"(linearization, {BAND[0]}-{BAND[1]} Hz) at x_set = "
             + ", ".join(f"{x:g}" for x in SETPOINTS_MM) + " mm:", "",
             "| method | anti-resonances [Hz] | Hz/mm | x_set for 17.5 Hz [mm] | "
             "for 18.5 Hz [mm] | time [s] |", "|---|---|---|---|---|---|"]
    for method, f, slope, x_a, x_b, sec in notes:
        lines.append(f"| {method} | {', '.join(f'{v:.3f}' for v in f)} | {slope:.4f} | "
                     f"{x_a * 1e3:.3f} | {x_b * 1e3:.3f} | {sec:.0f} |")
    lines += ["", f"Frequency step {F_A} -> {F_B} Hz at {T_STEP} s, the setpoint moved "
              "from lagrange's x_set for 17.5 Hz to its x_set for 18.5 Hz over 0.5 s (rtol "
              f"{RUN['rtol']:g}), amplitude of a_OF_z at the rotor frequency:", "",
              "| run | 1-2 s at 17.5 Hz | 5-6 s at 18.5 Hz |", "|---|---|---|"]
    for key in ("held", "parasitic", "lagrange", "zcp"):
        r = runs[key]
        a = amplitude(r.t, r.column("a_OF_z"), F_A, 1.0, 2.0)
        b = amplitude(r.t, r.column("a_OF_z"), F_B, 5.0, 6.0)
        label = "parasitic, setpoint held" if key == "held" else f"{key}, retuned"
        lines.append(f"| {label} | {a:.4g} m/s^2 | {b:.4g} m/s^2 |")
    lines += ["", "Each method's retuning run against lagrange's (largest difference over "
              "the run, relative to lagrange's peak):", "",
              "| method | a_OF_z | x_1 | i_1 |", "|---|---|---|---|"]
    for method in ("parasitic", "zcp"):
        r = runs[method]
        errs = [np.abs(r.column(o) - ref.column(o)).max() / np.abs(ref.column(o)).max()
                for o in ("a_OF_z", "x_1", "i_1")]
        lines.append(f"| {method} | " + " | ".join(f"{e:.2e}" for e in errs) + " |")
    lines += ["", "Retuning runs: " + ", ".join(
        f"{k} {runs[k].stats.steps} steps in {runs[k].stats.wall_time:.1f} s"
        for k in METHODS) + ".", ""]
    (out / "summary.md").write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="results/semiactive", type=Path)
    main(ap.parse_args().out)
