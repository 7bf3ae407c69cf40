"""The names the compile side takes from the run-time numerics of constrained runs, which
live in ``bgc.solvers.consistent`` (the start's projection, static loads, rank, drift):
the run side imports no method. ``RANK_PARAM`` is the generated module's parameter that
holds the rank its constraint block keeps (declared by lagrange, set by the run)."""

from bgc.solvers.consistent import (  # noqa: F401
    RANK_PARAM,
    RANK_TOL,
    _dependent,
    _rank,
    equilibrate,
    equilibration,
    static_loads,
)
