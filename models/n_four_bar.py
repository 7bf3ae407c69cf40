"""IFToMM benchmark A02, the N-four-bar mechanism: the exact reference of B0 for any N
(the model itself is models/n_four_bar.yaml, N windows of the library's four_bar_window;
another N: ``-p N=40``).

The mechanism (IFToMM library of computational benchmark problems, problem A02; M.
Gonzalez, D. Dopico, U. Lugris, J. Cuadrado, Multibody System Dynamics 16, 2006): 2N + 1
uniform slender rods of 1 m and 1 kg in the x-y plane, gravity 9.81 m/s^2 along -y. N + 1
cranks pinned to the ground at x = 0, 1, ..., N; N couplers joining the cranks' tops;
3N + 1 revolute joints about z. The cranks start vertical, the top of the first crank
(B0) moving at 1 m/s along +x; 20 s. Every crank stays parallel to the first, so the
mechanism is a chain of parallelograms with one degree of freedom; each time the cranks
pass horizontal, every link lies on the x axis and the instantaneous mobility jumps from
1 to N + 1 (a singular configuration, 2 per turn). Modelled in 3D, each revolute blocks 5
directions: 15N + 5 scalar constraints on 12N + 6 coordinates, of rank 12N + 5 (the
out-of-plane ones are redundant): 3N redundant constraints.

The exact solution (``reference``): with theta the cranks' angle from the vertical
(clockwise, B0 = (sin theta, cos theta)), every crank turns by theta and every coupler
translates with the cranks' tips, so the kinetic energy is ((N + 1)/3 + N) theta'^2 / 2
(crank: m L^2 / 3 about its pin; coupler: m (L theta')^2 / 2) and the potential energy
((N + 1)/2 + N) g cos theta; Lagrange's equation is

    ((N + 1)/3 + N) theta'' = ((N + 1)/2 + N) g sin theta,   theta(0) = 0, theta'(0) = 1,

a pendulum upside down, which the mechanism goes round and round. Its closed form is an
elliptic function (``theta_exact``); ``reference`` integrates it as a check.
"""

from __future__ import annotations

import math

import numpy as np

G = 9.81


def coefficients(n: int) -> tuple[float, float]:
    """(a, b) of a theta'' = b sin theta: the reduced inertia and gravity moment."""
    return (n + 1) / 3.0 + n, ((n + 1) / 2.0 + n) * G


def theta_exact(n: int, t, theta_dot0: float = 1.0):
    """theta(t) in closed form. With k2 = b/a and E = theta'^2/2 + k2 cos theta (the
    energy, constant), theta goes round (E > k2); phi = (theta - pi)/2, half the angle from
    the bottom, obeys phi' = sqrt((E + k2)/2) sqrt(1 - m sin^2 phi), m = 2 k2/(E + k2) < 1, so
    phi is Jacobi's amplitude am(u | m) with u = sqrt((E + k2)/2) t + F(phi0 | m)."""
    from scipy.special import ellipkinc, ellipj
    a, b = coefficients(n)
    k2 = b / a
    energy = 0.5 * theta_dot0 ** 2 + k2
    c = math.sqrt((energy + k2) / 2.0)
    m = 2.0 * k2 / (energy + k2)
    phi0 = -math.pi / 2.0                    # theta = 0: the top
    u = c * np.asarray(t, dtype=float) + ellipkinc(phi0, m)
    # am(u|m) = atan2(sn, cn), unwrapped by whole half-periods of am: 2K per turn of pi
    from scipy.special import ellipk
    K = ellipk(m)
    turns = np.floor((u + K) / (2.0 * K))
    sn, cn, _, _ = ellipj(u - 2.0 * K * turns, m)
    phi = np.arctan2(sn, cn) + math.pi * turns
    return 2.0 * phi + math.pi


def reference(n: int, t, theta_dot0: float = 1.0, rtol: float = 1e-13):
    """B0 = (x, y) at the times ``t`` from the reduced equation integrated to ``rtol``
    (DOP853), checked against the closed form."""
    from scipy.integrate import solve_ivp
    a, b = coefficients(n)
    t = np.asarray(t, dtype=float)
    sol = solve_ivp(lambda _, y: [y[1], b / a * math.sin(y[0])], (0.0, float(t[-1])),
                    [0.0, theta_dot0], method="DOP853", t_eval=t, rtol=rtol, atol=rtol)
    theta = sol.y[0]
    closed = theta_exact(n, t, theta_dot0)
    if not np.allclose(theta, closed, atol=1e-8):
        raise AssertionError("A02's reduced equation and its closed form disagree by "
                             f"{np.abs(theta - closed).max():.3g} rad")
    return np.sin(theta), np.cos(theta)
