"""Free rigid bodies (Tiernego-Bos rotational + translational parts, EJS, Cardan
kinematics) against invariants and closed forms."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from helpers import body_model

from bgc.errors import ModelError, SimulationError
from bgc.mechanics import cardan
from bgc.model.load import loads
from bgc.simulate import simulate

TIGHT = dict(rtol=1e-12, atol=1e-14, solver="radau")
J = np.array([0.1, 0.2, 0.3])


def columns(mod, r, *names):
    return [r.x[:, mod.STATE_NAMES.index(n)] for n in names]


def test_torque_free_body_conserves_energy_and_angular_momentum(compiled):
    mod = compiled("tumbling_box")
    # about 20 revolutions; native Radau (scipy's: 5.5 s, the same errors to 1e-14)
    r = simulate(mod, t_end=25.0, points=2001, **{**TIGHT, "solver": "native"})
    h = np.column_stack(columns(mod, r, "box.J.px", "box.J.py", "box.J.pz"))
    ang = np.column_stack(columns(mod, r, "box.ax", "box.ay", "box.az"))
    energy = 0.5 * (h ** 2 / J).sum(axis=1)
    assert np.abs(energy / energy[0] - 1).max() < 1e-8
    # angular momentum in R0: L = P_0^j h, constant in every component
    R = sp.lambdify(sp.symbols("a b c"), cardan.rotation(*sp.symbols("a b c")), "numpy")
    L = np.array([np.asarray(R(*a), dtype=float) @ hh for a, hh in zip(ang, h)])
    assert np.abs(L - L[0]).max() / np.linalg.norm(L[0]) < 1e-8
    # the centre of mass moves uniformly
    x, = columns(mod, r, "box.x")
    assert np.abs(x - 0.5 * r.t).max() < 1e-10


@pytest.mark.parametrize("inertia, axis, unstable", [
    ([0.1, 0.2, 0.3], 0, False),
    ([0.2, 0.1, 0.3], 0, True),     # the intermediate moment on body x
    pytest.param([0.1, 0.2, 0.3], 2, False, marks=pytest.mark.slow)])   # as body x's
def test_rotation_about_the_intermediate_axis_is_unstable(tmp_path, inertia, axis, unstable):
    """Spin about principal axis `axis` with a 1e-4 rad/s disturbance on the other two.
    The spin is about body x or z, never body y: Cardan angles (measured from the initial
    frame) would reach gimbal lock after a quarter turn about body y."""
    omega = [1.0e-4, 1.0e-4, 1.0e-4]
    omega[axis] = 3.0
    mod = body_model(tmp_path, f"spin{axis}{int(unstable)}",
                     f"{{mass: 1, com: [0, 0, 0], inertia: {inertia}, omega: {omega}}}")
    r = simulate(mod, t_end=20.0, points=4001, rtol=1e-10, atol=1e-12, solver="radau")
    h = np.column_stack(columns(mod, r, "box.J.px", "box.J.py", "box.J.pz"))
    w = h / np.array(inertia)
    others = np.delete(w, axis, axis=1)
    drift = np.abs(others).max()
    if unstable:
        assert drift > 1.0          # the spin axis flips: the wobble grows to order omega
        assert w[:, axis].min() < 0
    else:
        assert drift < 1e-3         # the wobble stays of the size of the disturbance


def test_free_fall_under_gravity(tmp_path):
    mod = body_model(tmp_path, "fall", "{mass: 3, com: [0, 0, 10], inertia: [1, 1, 1], "
                     "velocity: [1, 0, 2]}", extra="gravity: 9.81\n")
    r = simulate(mod, t_end=1.0, **TIGHT)
    x, z = columns(mod, r, "box.x", "box.z")
    assert np.abs(z - (10 + 2 * r.t - 9.81 / 2 * r.t ** 2)).max() < 1e-10
    assert np.abs(x - r.t).max() < 1e-10


def test_gimbal_lock_is_detected_with_its_time(tmp_path):
    """A spin of 2 rad/s about the body y axis reaches b = 90 deg at t = pi/4: native
    Radau's guard stops there (cos b = 1e-3) to 1e-6."""
    mod = body_model(tmp_path, "lock", "{mass: 1, com: [0, 0, 0], inertia: [0.1, 0.2, 0.3], "
                     "omega: [0, 2.0, 0]}")
    with pytest.raises(SimulationError, match="gimbal lock") as exc:
        simulate(mod, t_end=2.0, solver="native")
    t_lock = float(str(exc.value).split("t = ")[1].split()[0])
    assert abs(t_lock - np.arccos(1e-3) / 2.0) < 1e-6
    partial = exc.value.result
    assert partial.t[-1] <= t_lock and len(partial.t) > 10


@pytest.mark.parametrize("body, key, words", [
    ("{mass: -1, com: [0, 0, 0], inertia: [1, 1, 1]}", "bodies.box.mass", "must be >= 0"),
    ("{mass: 1, com: [0, 0, 0], inertia: [1, 1, -1]}", "bodies.box.inertia",
     "positive definite"),
    ("{mass: 1, com: [0, 0, 0], inertia: [1, 1, 3]}", "bodies.box.inertia",
     "triangle inequality"),
    ("{mass: 1, com: [0, 0, 0], inertia: [[1, 0.5, 0], [0, 1, 0], [0, 0, 1]]}",
     "bodies.box.inertia", "not symmetric"),
    ("{mass: 1, com: [0, 0], inertia: [1, 1, 1]}", "bodies.box.com", "3 numbers"),
    ("{mass: 1, com: [0, 0, 0], inertia: [1, 1, 1], frame: {x: [1, 0, 0], y: [1, 1, 0], "
     "z: [0, 0, 1]}}", "bodies.box.frame", "orthogonal"),
])
def test_bad_bodies_are_refused_with_their_line(body, key, words):
    text = f"name: bad\nbodies:\n  box: {body}\n"
    with pytest.raises(ModelError) as exc:
        loads(text, "bad.yaml")
    msg = str(exc.value)
    assert msg.startswith("bad.yaml:3:") and key in msg and words in msg


def test_full_inertia_matrix_gives_the_principal_frame(tmp_path):
    """A full tensor is diagonalized: the body frame becomes its principal frame."""
    c, s = np.cos(0.4), np.sin(0.4)
    Q = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    M = Q @ np.diag([0.1, 0.2, 0.25]) @ Q.T
    rows = ", ".join("[" + ", ".join(repr(float(v)) for v in row) + "]" for row in M)
    m = loads(f"bodies:\n  box: {{mass: 1, com: [0, 0, 0], inertia: [{rows}]}}\n", "m.yaml")
    body = m.bodies["box"]
    F = np.array(body.frame)
    assert np.allclose(sorted(body.inertia), [0.1, 0.2, 0.25])
    assert np.allclose(F.T @ M @ F, np.diag(body.inertia), atol=1e-12)
    assert np.isclose(np.linalg.det(F), 1.0)
