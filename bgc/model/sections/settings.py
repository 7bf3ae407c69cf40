"""The ``simulation:`` section: the run's defaults (end time, tolerances, solver, points)."""

from __future__ import annotations

from bgc.model.document import YMap
from bgc.model.model import SOLVERS, Settings
from bgc.model.values import check_keys, fail, number, points, string


def settings(sec: YMap) -> Settings:
    """The model's Settings; a key left out keeps Settings' default."""
    allowed = ("t_end", "rtol", "atol", "solver", "points")
    check_keys(sec, allowed, "simulation")
    kw = {}
    for k in allowed:
        if k in sec:
            loc, kk = sec.val_locs[k], f"simulation.{k}"
            if k == "solver":
                kw[k] = string(sec[k], loc, kk, "a solver name")
                if kw[k] not in SOLVERS:
                    fail(f"unknown solver '{kw[k]}'", loc, kk,
                         "valid solvers: " + ", ".join(SOLVERS))
            elif k == "points":
                kw[k] = points(sec[k], loc, kk)
            else:
                kw[k] = number(sec[k], loc, kk, positive=True)
    return Settings(**kw)
