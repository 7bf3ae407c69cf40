"""XYZ Cardan angles (paper Fig. 11.2): rotation matrix, angle rates from the body-frame
angular velocity, and the gimbal singularity.

Convention: P_0^j = Rx(a) Ry(b) Rz(c) maps components in the body frame R_j to the
inertial frame R_0. The body-frame angular velocity is omega = E(a, b, c) [a', b', c']; E is
singular when cos(b) = 0 (the gimbal lock), where the angle rates are undefined.
Everything is sympy, so the same code serves the equations and numeric set-up.
"""

from __future__ import annotations

import sympy as sp


def rotation(a, b, c) -> sp.Matrix:
    """P_0^j = Rx(a) Ry(b) Rz(c)."""
    ca, sa, cb, sb, cc, sc = sp.cos(a), sp.sin(a), sp.cos(b), sp.sin(b), sp.cos(c), sp.sin(c)
    return sp.Matrix([
        [cb * cc, -cb * sc, sb],
        [ca * sc + sa * sb * cc, ca * cc - sa * sb * sc, -sa * cb],
        [sa * sc - ca * sb * cc, sa * cc + ca * sb * sc, ca * cb],
    ])


def rate_matrix(a, b, c) -> sp.Matrix:
    """E with omega (body frame) = E [a', b', c']."""
    cb, sb, cc, sc = sp.cos(b), sp.sin(b), sp.cos(c), sp.sin(c)
    return sp.Matrix([[cb * cc, sc, 0], [-cb * sc, cc, 0], [sb, 0, 1]])


def angle_rates(a, b, c, omega) -> sp.Matrix:
    """[a', b', c'] = E^-1 omega, in closed form (divides by cos b)."""
    w1, w2, w3 = omega
    cb, cc, sc = sp.cos(b), sp.cos(c), sp.sin(c)
    u = (w1 * cc - w2 * sc) / cb
    return sp.Matrix([u, w1 * sc + w2 * cc, w3 - sp.sin(b) * u])


def angles(R) -> tuple[float, float, float]:
    """XYZ Cardan angles of a rotation matrix (the inverse of ``rotation`` for |b| < pi/2)."""
    R = sp.Matrix(R)
    b = sp.asin(max(-1.0, min(1.0, float(R[0, 2]))))
    a = sp.atan2(-float(R[1, 2]), float(R[2, 2]))
    c = sp.atan2(-float(R[0, 1]), float(R[0, 0]))
    return float(a), float(b), float(c)


def gimbal_margin(b):
    """cos b: positive for |b| < 90 deg, zero at gimbal lock. Signed, so that an
    integrator stepping across the singularity still sees the margin change sign."""
    return sp.cos(b)
