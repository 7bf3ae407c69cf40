"""Closed-loop benchmark mechanisms (issue 4) under the parasitic method, against their
closed-form kinematics: the loop closes to the parasitic modelling error, and that error
falls as the parasitic stiffness grows."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import REFERENCE_SOLVERS, slider_closure, stiffer

from bgc.simulate import simulate


@pytest.mark.parametrize("solver", REFERENCE_SOLVERS)
def test_slider_crank_closes_its_loop_to_the_parasitic_error(compiled, solver):
    mod = compiled("slider_crank")
    runs = [simulate(mod, t_end=1.0, rtol=1e-8, atol=1e-10, solver=solver,
                     params=stiffer(mod, f)) for f in (1.0, 10.0)]
    (err1, th), (err10, _) = (slider_closure(r) for r in runs)
    assert np.unwrap(th)[-1] - th[0] > 2 * np.pi               # the crank turns over
    # measured: 2.18e-5, 2.18e-6 (and 2.18e-7 at x100): the error goes as 1/k
    assert 0 < err1 < 1e-4 and err10 < err1 / 8, (err1, err10)
    drift = [np.abs(r.column("energy") - r.column("energy")[0]).max() for r in runs]
    assert drift[0] < 2e-3 * 0.9085 and drift[1] < drift[0] / 8, drift   # so does energy
