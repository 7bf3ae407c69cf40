"""The benchmarks' tables: rows (dicts) written as CSV, and read back as numbers."""

from __future__ import annotations

import csv
import math
from pathlib import Path

from bgc.fileio import atomic_write


def write_rows(path: Path, rows: list[dict]) -> Path:
    """Rows (dicts) as a CSV, columns in first-seen order, written atomically."""
    keys = list(dict.fromkeys(k for r in rows for k in r))

    def writer(tmp):
        with open(tmp, "w", newline="") as fh:
            w = csv.DictWriter(fh, keys)
            w.writeheader()
            w.writerows(rows)
    return atomic_write(path, writer, "CSV")


def as_number(v) -> float:
    """A CSV cell (or a row's value) as a float, NaN for none."""
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan
