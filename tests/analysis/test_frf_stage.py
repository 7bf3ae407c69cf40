"""The frequency response on its own: a hand-written linearization (``frf.Linearization``,
``extrema``) of one and two masses against closed forms; no model is compiled. (The
linearization of a compiled model: analysis/test_excitation.py.)"""

from __future__ import annotations

import numpy as np
import pytest

from bgc.analysis import frf


def oscillators(m1, k1, c1, m2=None, k2=None) -> frf.Linearization:
    """A mass m1 on a spring k1 and damper c1 to ground, forced by u, with (if m2) an
    undamped absorber m2 on a spring k2; states (z1, v1[, z2, v2]), outputs z1[, z2]."""
    if m2 is None:
        A = np.array([[0.0, 1.0], [-k1 / m1, -c1 / m1]])
    else:
        A = np.array([[0.0, 1.0, 0.0, 0.0],
                      [-(k1 + k2) / m1, -c1 / m1, k2 / m1, 0.0],
                      [0.0, 0.0, 0.0, 1.0],
                      [k2 / m2, 0.0, -k2 / m2, 0.0]])
    n = len(A)
    B = np.zeros(n)
    B[1] = 1.0 / m1
    C = np.eye(n)[::2]
    names = ("z1", "z2")[:len(C)]
    return frf.Linearization(A, B, C, np.zeros(len(C)), np.zeros(n), 0.0, names,
                             np.zeros(0))


def test_one_mass_resonates_at_its_damped_peak_and_has_static_gain_one_over_k():
    m, k, c = 2.0, 800.0, 4.0
    lin = oscillators(m, k, c)
    fn = np.sqrt(k / m) / (2 * np.pi)
    zeta = c / (2 * np.sqrt(k * m))
    anti, res = frf.extrema(lin, "z1", 0.5, 10.0)
    # the peak of |z/F| sits at fn sqrt(1 - 2 zeta^2), 1/(2 zeta) times the static 1/k
    assert anti == [] and res == pytest.approx([fn * np.sqrt(1 - 2 * zeta ** 2)], abs=2e-4)
    assert abs(lin.response([1e-6], "z1")[0]) == pytest.approx(1 / k, rel=1e-9)
    peak = abs(lin.response(res, "z1")[0]) * k
    assert peak == pytest.approx(1 / (2 * zeta * np.sqrt(1 - zeta ** 2)), rel=1e-6)


def test_tuned_absorber_cancels_the_main_mass_at_its_own_frequency():
    m1, k1, c1, m2, k2 = 10.0, 4.0e4, 2.0, 1.0, 2.5e3
    lin = oscillators(m1, k1, c1, m2, k2)
    anti, res = frf.extrema(lin, "z1", 1.0, 20.0)
    fa = np.sqrt(k2 / m2) / (2 * np.pi)
    assert anti == pytest.approx([fa], abs=2e-4)
    assert abs(lin.response([fa], "z1")[0]) < 1e-9 / k1        # an exact zero
    # the two resonances straddle it: the undamped system's eigenfrequencies
    K = np.array([[(k1 + k2) / m1, -k2 / m1], [-k2 / m2, k2 / m2]])
    modes = sorted(np.sqrt(np.linalg.eigvals(K).real) / (2 * np.pi))
    assert res == pytest.approx(modes, abs=0.01)
    assert res[0] < fa < res[1]
    # there the absorber's spring holds the force off: k2 z2 = -F
    assert lin.response([fa], "z2")[0] == pytest.approx(-1 / k2, rel=1e-9)
