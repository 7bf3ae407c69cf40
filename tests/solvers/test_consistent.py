"""consistent.project on its own, with a stand-in for a generated module."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from bgc.solvers import consistent


def _module(imposed: bool):
    """Two bodies' poses (states 0, 1) and two momenta (2, 3), two joint directions.
    Imposed (zcp): dg/dt is round-off whatever the momenta, as in a long zcp chain.
    Measured (lagrange): dg/dt = p0 - p1 - 1e-3, and p1 + 2 p0 = 0."""
    def constraints(t, x, p):
        g = np.array([x[0] - x[1], 0.0])
        if imposed:
            r = 1e-15 + 1e-18 * np.array([x[2] + x[3], x[2] - x[3]])
        else:
            r = np.array([x[2] - x[3] - 1e-3, x[3] + 2.0 * x[2]])
        return np.concatenate([g, r])
    return SimpleNamespace(CONSTRAINT_NAMES=("j.tx", "j.ty"), HAS_POSITION=np.array([1, 0]),
                           POSE_STATES=np.array([0, 1]),
                           IMPOSED=np.array([1, 1] if imposed else [0, 0]),
                           constraints=constraints)


def test_imposed_rows_leave_the_momenta_alone():
    """Round-off rows of zcp once gave a 'correction' of 5e8 to a chain at rest."""
    x0 = np.array([0.3, 0.3, 0.0, 0.0])
    x, proj = consistent.project(_module(imposed=True), x0, np.zeros(1))
    assert np.array_equal(x, x0)
    assert proj.velocity_correction == 0.0 and proj.rank == 2


def test_measured_rows_are_projected():
    x0 = np.array([0.3, 0.1, 0.0, 0.0])
    x, proj = consistent.project(_module(imposed=False), x0, np.zeros(1))
    assert abs(x[0] - x[1]) < 1e-12
    assert np.allclose([x[2] - x[3], x[3] + 2.0 * x[2]], [1e-3, 0.0], atol=1e-14)
    assert proj.velocity_correction > 0
