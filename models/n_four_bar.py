"""IFToMM benchmark A02, the N-four-bar mechanism: write its model for any N, and its exact
reference.

    python models/n_four_bar.py N [-o FILE]      # default: models/n_four_bar.yaml for N = 2

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

import argparse
import math
from pathlib import Path

import numpy as np

G = 9.81
T_END = 20.0
ROD_AXIAL = 1.0e-4        # a slender rod's moment about its own axis (kg m^2): small, > 0


def _vec(v) -> str:
    return "[" + ", ".join(_num(x) for x in v) + "]"


def _num(x: float) -> str:
    return repr(float(x)) if x != int(x) else f"{int(x)}"


def model(n: int, t_end: float = T_END) -> str:
    """The YAML text of A02 with ``n`` couplers (``n + 1`` cranks)."""
    if n < 1:
        raise ValueError("A02 needs at least one coupler (N >= 1)")
    lines = [f"name: n_four_bar{'' if n == 2 else f'_{n}'}",
             "description: >",
             f"  IFToMM benchmark A02, the N-four-bar mechanism, N = {n} (written by",
             f"  models/n_four_bar.py {n}): {n + 1} cranks of 1 m and 1 kg pinned to the "
             f"ground at x = 0..{n},",
             f"  {n} couplers of 1 m and 1 kg joining their tops, {3 * n + 1} revolute joints "
             "about z, gravity 9.81",
             "  along -y; the cranks start vertical with the top of the first (B0) moving at "
             "1 m/s along +x.",
             "  Every time the cranks pass horizontal the mobility jumps from 1 to N + 1 (a "
             "singular",
             f"  configuration); in 3D the {15 * n + 5} scalar constraints have rank "
             f"{12 * n + 5} ({3 * n} redundant).",
             "  Exact solution: ((N+1)/3 + N) theta'' = ((N+1)/2 + N) g sin theta, theta(0) "
             "= 0,",
             "  theta'(0) = 1 rad/s, B0 = (sin theta, cos theta) (models/n_four_bar.py, "
             "reference).",
             f"gravity: [0, {-G}, 0]",
             "bodies:"]
    # body frames: x along R0 z (the axis every link turns about: its Cardan angle ax
    # turns freely, b stays 0), z along the rod
    inertia = _vec([1.0 / 12.0, 1.0 / 12.0, ROD_AXIAL])
    for i in range(n + 1):
        lines += [f"  crank{i}:",
                  "    mass: 1.0",
                  f"    com: {_vec([i, 0.5, 0])}",
                  "    frame: {x: [0, 0, 1], y: [1, 0, 0], z: [0, 1, 0]}",
                  f"    inertia: {inertia}",
                  f"    points: {{A: {_vec([i, 0, 0])}, B: {_vec([i, 1, 0])}}}",
                  "    velocity: [0.5, 0, 0]",
                  "    omega: [0, 0, -1.0]"]
    for j in range(n):
        lines += [f"  coupler{j}:",
                  "    mass: 1.0",
                  f"    com: {_vec([j + 0.5, 1, 0])}",
                  "    frame: {x: [0, 0, 1], y: [0, 1, 0], z: [-1, 0, 0]}",
                  f"    inertia: {inertia}",
                  "    velocity: [1.0, 0, 0]"]
    lines.append("joints:")
    for i in range(n + 1):
        lines.append(f"  pivot{i}: {{type: revolute, between: [fixed_frame, crank{i}], "
                     f"at: crank{i}.A, axis: [0, 0, 1]}}")
    for j in range(n):
        lines.append(f"  pin{j}a: {{type: revolute, between: [crank{j}, coupler{j}], "
                     f"at: crank{j}.B, axis: [0, 0, 1]}}")
        lines.append(f"  pin{j}b: {{type: revolute, between: [coupler{j}, crank{j + 1}], "
                     f"at: crank{j + 1}.B, axis: [0, 0, 1]}}")
    lines += ["outputs:",
              "  B0_x: {expr: crank0.B.x, unit: m}",
              "  B0_y: {expr: crank0.B.y, unit: m}",
              f"  B{n}_x: {{expr: crank{n}.B.x, unit: m}}",
              f"  B{n}_y: {{expr: crank{n}.B.y, unit: m}}",
              f"simulation: {{t_end: {_num(t_end)}, rtol: 1.0e-6, atol: 1.0e-8, "
              "points: 2001}"]
    return "\n".join(lines) + "\n"


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


def main(argv=None):
    ap = argparse.ArgumentParser(description="Write IFToMM A02 (the N-four-bar) for any N.")
    ap.add_argument("n", type=int, nargs="?", default=2, help="couplers (cranks: N + 1)")
    ap.add_argument("-o", "--out", help="file to write (default: models/n_four_bar.yaml "
                                        "for N = 2, n_four_bar_<N>.yaml beside it else)")
    ap.add_argument("--t-end", type=float, default=T_END)
    args = ap.parse_args(argv)
    here = Path(__file__).resolve().parent
    out = Path(args.out) if args.out else here / (
        "n_four_bar.yaml" if args.n == 2 else f"n_four_bar_{args.n}.yaml")
    out.write_text(model(args.n, args.t_end))
    print(out)


if __name__ == "__main__":
    main()
