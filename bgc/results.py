"""Writing results: CSV (``t``, states, outputs by name) and a PNG of the outputs."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .simulate import Result


def write_csv(result: Result, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    header = ",".join(("t",) + result.state_names + result.output_names)
    data = np.column_stack([result.t, result.x, result.y])
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    os.close(fd)
    try:
        np.savetxt(tmp, data, delimiter=",", header=header, comments="", fmt="%.12g")
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    return path


def read_csv(path: str | Path) -> tuple[list[str], np.ndarray]:
    """Header names and data of a CSV written by ``write_csv``."""
    with open(path, encoding="utf-8") as fh:
        names = fh.readline().strip().split(",")
    return names, np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2)


def plot(result: Result, path: str | Path, title: str = "") -> Path:
    """One panel per output (per state if the model names no outputs), against time."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = result.output_names or result.state_names
    n = max(len(names), 1)
    fig, axes = plt.subplots(n, 1, figsize=(8, 1.9 * n + 0.8), sharex=True, squeeze=False)
    for ax, name in zip(axes[:, 0], names):
        ax.plot(result.t, result.column(name), lw=1.2)
        ax.set_ylabel(name)
        ax.grid(True, alpha=0.3)
    axes[-1, 0].set_xlabel("t [s]")
    if title:
        fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
