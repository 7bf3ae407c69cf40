"""Writing results: CSV (``t``, states, outputs by name) and a PNG of the outputs."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bgc.errors import BgcError
from bgc.fileio import atomic_write
from bgc.simulate import Result


def write_csv(result: Result, path: str | Path, states: bool = True) -> Path:
    """``t``, the states (unless ``states`` is False) and the outputs, by name."""
    if not states:
        return write_table(path, ("t",) + result.output_names, [result.t, result.y])
    return write_table(path, ("t",) + result.state_names + result.output_names,
                       [result.t, result.x, result.y])


def write_table(path: str | Path, names, columns) -> Path:
    """A CSV of named columns (arrays of one or more columns each), written atomically:
    a failure never leaves a half-written file."""
    header = ",".join(names)
    data = np.column_stack(columns)
    return atomic_write(path, lambda tmp: np.savetxt(tmp, data, delimiter=",", header=header,
                                                     comments="", fmt="%.12g"), "CSV")


def read_csv(path: str | Path) -> tuple[list[str], np.ndarray]:
    """Header names and data of a CSV written by ``write_csv``."""
    with open(path, encoding="utf-8") as fh:
        names = fh.readline().strip().split(",")
    return names, np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def panels(n: int, height: float, sharex: bool = True):
    """A figure of ``n`` stacked panels, sharing x unless told (matplotlib without a
    display)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt.subplots(max(n, 1), 1, figsize=(8, height * max(n, 1) + 0.8),
                        sharex=sharex, squeeze=False)


def plot_format(path: str | Path, key: str | None = None) -> str:
    """The image format of a plot path, from its suffix (none: PNG); a BgcError naming
    the path (and ``key``, the option) if matplotlib cannot write that format."""
    from matplotlib.backend_bases import FigureCanvasBase
    fmt = Path(path).suffix[1:].lower() or "png"
    formats = FigureCanvasBase.get_supported_filetypes()
    if fmt not in formats:
        raise BgcError(f"cannot write plot {str(path)!r}: unknown image format '.{fmt}'",
                       key=key, hint="use one of " + ", ".join(f".{f}" for f in formats))
    return fmt


def save_figure(fig, path: str | Path, title: str) -> Path:
    """Write ``fig`` (of ``panels``) to ``path`` atomically, in the format its suffix
    names, with ``title`` above; the figure is closed."""
    import matplotlib.pyplot as plt
    try:
        fmt = plot_format(path)     # the temporary file's suffix is .tmp
        # constrained layout keeps room for the title above the panels' tick labels
        # (tight_layout let it sit on the top panel's frame)
        fig.set_layout_engine("constrained")
        if title:
            fig.suptitle(title)
        return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format=fmt), "plot")
    finally:
        plt.close(fig)


def output_units(module) -> dict[str, str]:
    """name -> unit of a generated module's outputs (``OUTPUT_UNITS``; a module written
    before units has none): the units the model declares, for labels and noise floors."""
    units = getattr(module, "OUTPUT_UNITS", ())
    return {n: u for n, u in zip(module.OUTPUT_NAMES, units) if u}


def axis_label(name: str, unit: str | None) -> str:
    """``name [unit]``, a dimensionless unit ("1") as ``[-]``; the name alone where the
    model declares no unit."""
    if not unit:
        return name
    return f"{name} [{'-' if unit.strip() == '1' else unit}]"


# the units of the parameters a joint's values become (``<joint>__<role>``), by role;
# a free direction's own (``<dir>_k`` ...) by whether it turns (r) or slides (t)
_JOINT_UNITS = {"stiffness": "N/m", "rot_stiffness": "N m/rad", "damping": "N s/m",
                "rot_damping": "N m s/rad"}
_DIRECTION_UNITS = {"k": ("N/m", "N m/rad"), "c": ("N s/m", "N m s/rad"),
                    "preload": ("N", "N m"), "load": ("N", "N m")}


def parameter_unit(model, name: str) -> str | None:
    """The unit of a module parameter: the model's declared one (``parameters:``), else
    that of the joint value it holds (``hinge__rx_k``: N m/rad); None if not known."""
    par = model.parameters.get(name) if model is not None else None
    if par is not None and par.unit:
        return par.unit
    joint, sep, role = name.rpartition("__")
    if not sep or model is None or joint not in model.joints:
        return None
    if role in _JOINT_UNITS:
        return _JOINT_UNITS[role]
    label, _, kind = role.partition("_")
    if kind in _DIRECTION_UNITS and len(label) == 2 and label[0] in "tr":
        return _DIRECTION_UNITS[kind][label[0] == "r"]
    return None


def noise_panel(ax, peaks: dict, unit: str | None, floor: float, what: str = "peak") -> None:
    """A panel whose outputs (``peaks``: name -> largest value, the ``what``) are numerical
    noise (``bgc.analysis.noise``): what they are, in words, over a zero line and the band
    +-``floor`` the run resolves, instead of the noise drawn as a signal."""
    u = f" {unit}" if unit else ""
    ax.axhline(0.0, color="0.5", lw=0.8)
    if floor > 0:
        ax.set_ylim(-floor, floor)
    lines = [f"{n}: numerical noise, {what} {p:.2g}{u}" for n, p in peaks.items()]
    lines.append(f"(below {floor:.2g}{u}, rtol times the largest{u} output: not resolved)")
    ax.text(0.5, 0.5, "\n".join(lines), transform=ax.transAxes, ha="center", va="center",
            fontsize=9, bbox=dict(boxstyle="round", fc="white", ec="0.7"))


def plot(result: Result, path: str | Path, title: str = "", window=None,
         overlay: bool = False, units: dict | None = None, floor: dict | None = None) -> Path:
    """One panel per output (per state if the model names no outputs), against time;
    over ``window`` (t0, t1) only; with ``overlay``, outputs of one unit whose names differ
    only by their numbers (F_A1_z, F_A2_z) share a panel, so phase shifts show. Each y
    label carries the output's unit (``units``: name -> unit); an output below its noise
    ``floor`` (``noise.floors``, over the whole run) is stated, not drawn."""
    import re

    from bgc.analysis.noise import noisy
    units, floor = units or {}, floor or {}
    names = result.output_names or result.state_names
    quiet = noisy(result.output_names, result.y, floor) if result.output_names else {}
    groups: dict[tuple, list[str]] = {}
    for name in names:
        key = re.sub(r"\d+", "#", name) if overlay else name
        groups.setdefault((key, units.get(name)), []).append(name)
    sel = np.ones(len(result.t), dtype=bool)
    if window is not None:
        sel = (result.t >= window[0]) & (result.t <= window[1])
    fig, axes = panels(len(groups), 1.9)
    for ax, ((label, unit), members) in zip(axes[:, 0], groups.items()):
        shown = [n for n in members if n not in quiet]
        for name in shown:
            ax.plot(result.t[sel], result.column(name)[sel], lw=1.2, label=name)
        noise = {n: quiet[n] for n in members if n in quiet}
        if noise and not shown:
            noise_panel(ax, noise, unit, max(floor[n] for n in noise))
        elif noise:
            ax.text(0.01, 0.97, "; ".join(f"{n}: numerical noise, peak {p:.2g}"
                                          for n, p in noise.items()),
                    transform=ax.transAxes, va="top", fontsize=8)
        ax.set_ylabel(axis_label(label if len(members) == 1 else label.replace("#", "i"),
                                 unit))
        if len(shown) > 1:
            ax.legend(fontsize=8, loc="upper right")
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("t [s]")
    return save_figure(fig, path, title)


def mark_minima(ax, mins) -> list:
    """Dashed lines at the envelope's two deepest minima (the deepest red), each labelled
    beside its line near the bottom, one row per minimum in order of frequency (rows 13 pt
    apart, text 8 pt high), so two labels cannot overlap however close the minima: the
    lower frequency's to the left of its line and the higher's to the right, unless that
    would leave the axes (a minimum near an end of the sweep). The annotations."""
    from matplotlib.transforms import blended_transform_factory
    trans = blended_transform_factory(ax.transData, ax.transAxes)
    marked = sorted(enumerate(mins[:2]), key=lambda km: km[1])
    x0, x1 = ax.get_xlim()
    out = []
    for row, (k, fm) in enumerate(marked):
        colour = "C3" if k == 0 else "C1"
        ax.axvline(fm, color=colour, lw=0.8, ls="--")
        at = (fm - x0) / (x1 - x0) if x1 > x0 else 0.5
        left = at > 0.85 or (row == 0 and len(marked) > 1 and at > 0.15)
        out.append(ax.annotate(f"{fm:.2f} Hz", (fm, 0.0), xycoords=trans,
                               xytext=(-4 if left else 4, 8 + 13 * row),
                               textcoords="offset points", ha="right" if left else "left",
                               va="bottom", fontsize=8, color=colour))
    return out


def mark_transients(ax, freqs) -> None:
    """Envelope minima that no anti-resonance of the linearization explains (the sweep's
    transients, ``envelope.explain``): thin grey dotted lines, unlabelled, named once in
    the legend, so they cannot be read as anti-resonances."""
    for i, f in enumerate(freqs):
        ax.axvline(f, color="0.55", lw=0.8, ls=":",
                   label="minimum of the sweep's transient" if i == 0 else None)


def mark_frf(ax, freqs) -> None:
    """The linearization's anti-resonances (``bgc frf``) as triangles on the bottom edge."""
    from matplotlib.transforms import blended_transform_factory
    trans = blended_transform_factory(ax.transData, ax.transAxes)
    if freqs:
        ax.plot(freqs, [0.0] * len(freqs), "^", color="C2", ms=6, transform=trans,
                clip_on=False, label="anti-resonance of the FRF (bgc frf)")


def plot_envelopes(curves: dict, path: str | Path, title: str = "",
                   units: dict | None = None, floor: dict | None = None,
                   explained: dict | None = None, frf_anti: dict | None = None) -> Path:
    """One panel per output: its envelope over a chirp against the instantaneous
    frequency, the minima marked (``curves``: name -> (freq, amplitude, minima)); an
    envelope below its noise ``floor`` is stated, not drawn, and has no minima. With
    ``explained`` (``envelope.explain``: name -> (anti-resonances, transients)) only the
    minima an anti-resonance of the linearization explains are marked as such, the
    sweep's transients drawn apart, and ``frf_anti`` (name -> [Hz]) shown on the axis."""
    units, floor = units or {}, floor or {}
    fig, axes = panels(len(curves), 2.2)
    for ax, (name, (f, a, mins)) in zip(axes[:, 0], curves.items()):
        if name in floor and not a.max(initial=0.0) >= floor[name]:
            noise_panel(ax, {name: float(a.max(initial=0.0))}, units.get(name), floor[name],
                        "envelope at most")
        else:
            ax.semilogy(f, a, lw=1.2)
            if explained is not None and name in explained:
                anti, trans = explained[name]
                mark_transients(ax, trans)
                mark_minima(ax, anti)
            else:
                mark_minima(ax, mins)
            if frf_anti is not None:
                mark_frf(ax, [x for x in frf_anti.get(name, []) if f.min() <= x <= f.max()])
            if ax.get_legend_handles_labels()[0]:
                ax.legend(fontsize=7, loc="upper right")
        ax.set_ylabel(axis_label(f"|{name}|", units.get(name)))
        ax.grid(True, which="both", alpha=0.3)
    axes[-1, 0].set_xlabel("instantaneous excitation frequency [Hz]")
    return save_figure(fig, path, title)
