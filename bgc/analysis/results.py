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
        if title:
            fig.suptitle(title)
        fig.tight_layout()
        return atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=110, format=fmt), "plot")
    finally:
        plt.close(fig)


def plot(result: Result, path: str | Path, title: str = "", window=None,
         overlay: bool = False) -> Path:
    """One panel per output (per state if the model names no outputs), against time;
    over ``window`` (t0, t1) only; with ``overlay``, outputs whose names differ only by
    their numbers (F_A1_z, F_A2_z) share a panel, so phase shifts show."""
    import re

    names = result.output_names or result.state_names
    groups: dict[str, list[str]] = {}
    for name in names:
        groups.setdefault(re.sub(r"\d+", "#", name) if overlay else name, []).append(name)
    sel = np.ones(len(result.t), dtype=bool)
    if window is not None:
        sel = (result.t >= window[0]) & (result.t <= window[1])
    fig, axes = panels(len(groups), 1.9)
    for ax, (label, members) in zip(axes[:, 0], groups.items()):
        for name in members:
            ax.plot(result.t[sel], result.column(name)[sel], lw=1.2, label=name)
        ax.set_ylabel(label if len(members) == 1 else label.replace("#", "i"))
        if len(members) > 1:
            ax.legend(fontsize=8, loc="upper right")
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("t [s]")
    return save_figure(fig, path, title)


def plot_envelopes(curves: dict, path: str | Path, title: str = "") -> Path:
    """One panel per output: its envelope over a chirp against the instantaneous
    frequency, the minima marked (``curves``: name -> (freq, amplitude, minima))."""
    fig, axes = panels(len(curves), 2.2)
    for ax, (name, (f, a, mins)) in zip(axes[:, 0], curves.items()):
        ax.semilogy(f, a, lw=1.2)
        for k, fm in enumerate(mins[:2]):
            ax.axvline(fm, color="C3" if k == 0 else "C1", lw=0.8, ls="--")
            ax.annotate(f"{fm:.2f} Hz", (fm, a.min()), xytext=(4, 4),
                        textcoords="offset points", fontsize=8)
        ax.set_ylabel(f"|{name}|")
        ax.grid(True, which="both", alpha=0.3)
    axes[-1, 0].set_xlabel("instantaneous excitation frequency [Hz]")
    return save_figure(fig, path, title)
