"""XYZ Cardan kinematics against their definitions."""

from __future__ import annotations

import numpy as np
import sympy as sp

from bgc.mechanics import cardan


def num(M):
    return np.array(M.evalf(), dtype=float)


def test_rotation_is_rx_ry_rz_and_orthonormal():
    a, b, c = 0.3, -0.7, 1.9
    Rx = sp.Matrix([[1, 0, 0], [0, sp.cos(a), -sp.sin(a)], [0, sp.sin(a), sp.cos(a)]])
    Ry = sp.Matrix([[sp.cos(b), 0, sp.sin(b)], [0, 1, 0], [-sp.sin(b), 0, sp.cos(b)]])
    Rz = sp.Matrix([[sp.cos(c), -sp.sin(c), 0], [sp.sin(c), sp.cos(c), 0], [0, 0, 1]])
    R = num(cardan.rotation(a, b, c))
    assert np.allclose(R, num(Rx * Ry * Rz), atol=1e-15)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-15)
    assert np.isclose(np.linalg.det(R), 1.0)


def test_rate_matrix_is_the_body_angular_velocity():
    """skew(omega_body) = R^T dR/dt along any angle trajectory."""
    t = sp.Symbol("t")
    a, b, c = sp.sin(t), 0.4 * sp.cos(2 * t), t ** 2
    R = cardan.rotation(a, b, c)
    W = (R.T * R.diff(t)).subs(t, 0.7)
    omega = sp.Matrix([W[2, 1], W[0, 2], W[1, 0]])
    rates = sp.Matrix([a, b, c]).diff(t).subs(t, 0.7)
    E = cardan.rate_matrix(a, b, c).subs(t, 0.7)
    assert np.allclose(num(E * rates), num(omega), atol=1e-13)
    # and the closed-form inverse returns the rates
    back = cardan.angle_rates(a.subs(t, 0.7), b.subs(t, 0.7), c.subs(t, 0.7), omega)
    assert np.allclose(num(back), num(rates), atol=1e-13)


def test_angles_inverts_rotation():
    rng = np.random.default_rng(0)
    for _ in range(20):
        a, c = rng.uniform(-np.pi, np.pi, 2)
        b = rng.uniform(-1.5, 1.5)
        assert np.allclose(cardan.angles(num(cardan.rotation(a, b, c))), (a, b, c), atol=1e-12)


def test_gimbal_margin_vanishes_at_the_singularity():
    assert abs(float(cardan.gimbal_margin(sp.pi / 2))) < 1e-15
    assert float(cardan.gimbal_margin(2.0)) < 0     # beyond the singularity
    assert np.isclose(float(cardan.gimbal_margin(0.0)), 1.0)
