"""Loud failure under the constraint methods (issue 4): initial conditions that cannot be
projected and a singular configuration reached during a run each stop with a message
saying what happened, when and in which joint, and keep the results computed so far. (A
class-4 ZCP kept closed is refused at compile time: tests/methods/test_zcp.py.)"""

from __future__ import annotations

import re

import numpy as np
import pytest

from helpers import T_SINGULAR

from bgc.errors import SimulationError
from bgc.simulate import simulate


@pytest.mark.parametrize("method", ["lagrange", "zcp"])
def test_initial_pose_that_cannot_be_projected_names_the_joint(compiled, method):
    mod = compiled("slider_crank", method)
    names = list(mod.STATE_NAMES)
    x = mod.X0.copy()
    # the slider turned a quarter turn about its x axis: the guide's and wrist pin's
    # blocked rotations sit at a stationary point of their deflection, Newton cannot move
    x[names.index("slider.ax")] += np.pi / 2
    with pytest.raises(SimulationError) as err:
        simulate(mod, t_end=0.1, rtol=1e-8, atol=1e-10, solver="radau", x0=x)
    msg = str(err.value)
    assert "initial positions (t = 0) cannot be made consistent" in msg
    assert "wrist_pin.r" in msg or "guide.r" in msg
    assert "still open by 1" in msg


@pytest.mark.parametrize("method,lost", [
    ("lagrange", "main.tz, crank_pin.tz, wrist_pin.tz, guide.tz"),
    ("zcp", "wrist_pin.tz"),        # the tree's rows hold by construction; the cut joint's
])
def test_singular_configuration_stops_the_run_and_keeps_the_results(compiled, method, lost):
    mod = compiled("isosceles_slider_crank", method)
    with pytest.raises(SimulationError) as err:
        simulate(mod, t_end=0.3, rtol=1e-8, atol=1e-10, solver="radau")
    msg = str(err.value)
    # the event on the constraints' rank stops it there, or (lagrange, Baumgarte
    # alpha = 10 / t_end) the integrator gives up just short of it and the cause is named
    t_stop = float(re.match(r"singular configuration at t = ([0-9.]+): ", msg).group(1))
    assert t_stop == pytest.approx(T_SINGULAR, abs=1e-3)
    assert f"joint directions {lost} became dependent" in msg
    assert "parasitic" in err.value.hint and "--method augmented" in err.value.hint
    r = err.value.result
    assert not r.success and r.t[-1] == pytest.approx(T_SINGULAR, abs=2e-3)
    slider = r.column("slider_x")
    assert np.all(np.diff(slider) < 0) and 0 < slider[-1] < 1e-3   # stopped at the pivot
    assert r.stats.drift_position < 1e-9


def test_parasitic_passes_the_singular_configuration(compiled):
    par = simulate(compiled("isosceles_slider_crank"), t_end=0.3, rtol=1e-8, atol=1e-10,
                   solver="radau")
    with pytest.raises(SimulationError) as err:
        simulate(compiled("isosceles_slider_crank", "lagrange"), t_end=0.3, rtol=1e-8,
                 atol=1e-10, solver="radau")
    lag = err.value.result
    before = par.t <= lag.t[-1]
    # up to the singular pose the methods agree within the parasitic modelling error
    assert np.abs(par.column("slider_x")[before] - lag.column("slider_x")).max() < 1e-5
    assert par.column("slider_x")[-1] < -0.1          # the rod swung on with the crank


NAN_TORQUE = """\
name: nan_torque
description: A pendulum whose hinge torque sqrt(0.5 - t) is not a number after 0.5 s.
gravity: 9.81
bodies:
  rod:
    mass: 2.0
    com: [0.017450, 0.0, -0.499695]
    frame: {x: [0, 1, 0], y: [0, 0, 1], z: [1, 0, 0]}
    inertia: [0.2, 0.2, 0.01]
joints:
  hinge: {type: revolute, between: [fixed_frame, rod], at: [0, 0, 0], axis: [0, 1, 0],
          actuator: "sqrt(0.5 - t)"}
outputs:
  x: {expr: rod.x, unit: m}
"""


@pytest.mark.parametrize("solver,why", [("native", "the step size collapsed"),
                                        ("bdf", "array must not contain infs or NaNs"),
                                        ("lsoda", "the solution became non-finite")])
def test_a_model_law_that_fails_is_not_a_singular_configuration(compiled, tmp_path, solver,
                                                                why):
    """A constrained run whose rhs stops being finite for a reason of its own (a law out of
    its domain) is not diagnosed as a singular configuration: the constraint block is not
    what refuses there (solved at a lower rank it is not finite either), and the
    constraints are as well conditioned as at the start. The run says how it failed and
    keeps its results."""
    path = tmp_path / "nan_torque.yaml"
    path.write_text(NAN_TORQUE)
    mod = compiled(path, "lagrange")
    with pytest.raises(SimulationError) as err:
        simulate(mod, t_end=1.0, rtol=1e-6, atol=1e-8, solver=solver, points=101)
    msg = str(err.value)
    assert why in msg and "singular configuration" not in msg, msg
    assert "augmented" not in (err.value.hint or "")
    r = err.value.result
    assert 0.45 < r.t[-1] <= 0.5 and np.isfinite(r.x).all()
