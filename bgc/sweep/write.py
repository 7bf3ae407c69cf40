"""Stage **write**: a sweep's Points -> a table (one row a point: the swept parameters,
each metric's columns, the error), written as CSV and, if pyarrow is importable, Parquet,
and one PNG per metric against each swept parameter.

An FRF metric ``INPUT:OUTPUT`` has the columns ``INPUT:OUTPUT:anti_1``, ... and
``INPUT:OUTPUT:res_1``, ... (as many as the most any point found, at least one; empty
where a point found fewer); a window metric one column named as given
(``rms:a_OF_z:5:28``).
"""

from __future__ import annotations

import csv
import re
from pathlib import Path

import numpy as np

from bgc.fileio import atomic_write
from bgc.sweep.metrics import Frf, Metrics
from bgc.sweep.runner import Point

FRF_KEYS = (("anti", "antiresonances_hz"), ("res", "resonances_hz"))


def table(points: list[Point], names: tuple[str, ...], metrics: Metrics) -> dict[str, list]:
    """The columns by name, in order: parameters, metrics, ``error`` (floats, NaN where a
    point has no value; the error a string, empty if none)."""
    cols: dict[str, list] = {n: [p.params[n] for p in points] for n in names}
    for m in metrics.frf:
        for short, key in FRF_KEYS:
            found = [(p.values.get(m.label) or {}).get(key, []) for p in points]
            for k in range(max([1] + [len(f) for f in found])):
                cols[f"{m.label}:{short}_{k + 1}"] = [f[k] if k < len(f) else np.nan
                                                      for f in found]
    for m in metrics.windows:
        cols[m.label] = [np.nan if p.values.get(m.label) is None else p.values[m.label]
                         for p in points]
    cols["error"] = [p.error or "" for p in points]
    return cols


def write_csv(path: str | Path, cols: dict[str, list]) -> Path:
    """The table as CSV (numbers to 12 digits, an empty field where there is none)."""
    def cell(v):
        return v if isinstance(v, str) else "" if np.isnan(v) else f"{v:.12g}"

    def save(tmp):
        with open(tmp, "w", newline="", encoding="utf-8") as fh:
            w = csv.writer(fh)
            w.writerow(cols)
            w.writerows([cell(v) for v in row] for row in zip(*cols.values()))
    return atomic_write(path, save, "CSV")


def write_parquet(path: str | Path, cols: dict[str, list]) -> Path | None:
    """The table as Parquet beside the CSV (``.parquet``), if pyarrow is importable;
    else None (pyarrow is optional)."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError:
        return None
    data = {k: v if k == "error" else [None if np.isnan(x) else x for x in v]
            for k, v in cols.items()}
    return atomic_write(Path(path).with_suffix(".parquet"),
                        lambda tmp: pq.write_table(pa.table(data), tmp), "Parquet")


def slug(label: str) -> str:
    """A metric's label as a file-name part (``rms:a_OF_z:5:28`` -> ``rms_a_OF_z_5_28``)."""
    return re.sub(r"[^A-Za-z0-9_.-]+", "_", label).strip("_")


def plots(path: str | Path, cols: dict[str, list], names: tuple[str, ...],
          metrics: Metrics, units: dict[str, str], title: str,
          param_units: dict[str, str | None] | None = None) -> dict[str, Path]:
    """One PNG per metric, ``<stem>_<metric>.png`` beside ``path``: a panel per swept
    parameter (``param_units``: its unit, ``results.parameter_unit``), the metric's values
    at every point against it (an FRF's anti-resonances as downward, its resonances as
    upward triangles). Returns label -> path."""
    from bgc.analysis.results import axis_label, panels, save_figure
    path = Path(path)
    out = {}
    for m in metrics.frf + metrics.windows:
        fig, axes = panels(len(names), 2.6, sharex=False)
        for ax, name in zip(axes[:, 0], names):
            x = np.asarray(cols[name])
            if isinstance(m, Frf):
                for short, marker, what in (("anti", "v", "anti-resonance"),
                                            ("res", "^", "resonance")):
                    keys = [k for k in cols if k.startswith(f"{m.label}:{short}_")]
                    for j, k in enumerate(keys):
                        ax.plot(x, cols[k], marker, ms=4, color="C0" if short == "anti"
                                else "C1", label=what if j == 0 else None)
                ax.set_ylabel("frequency [Hz]")
                ax.legend(loc="best", fontsize="small")
            else:
                ax.plot(x, cols[m.label], "o", ms=4)
                ax.set_ylabel(axis_label(f"{m.kind} of {m.output}", units.get(m.output)))
            ax.set_xlabel(axis_label(name, (param_units or {}).get(name))
                          if (param_units or {}).get(name) else f"{name} [unit not declared]")
            ax.grid(True, alpha=0.3)
        target = path.with_name(f"{path.stem}_{slug(m.label)}{path.suffix or '.png'}")
        out[m.label] = save_figure(fig, target, f"{title}: {m.label}")
    return out
