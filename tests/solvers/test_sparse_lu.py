"""The sparse LU of the Newton matrices (``bgc/sparse_lu.py``): the elimination plan of a
Jacobian's structure, factors and solves that agree with dense LAPACK, the growth check
that hands a matrix needing pivoting back to LAPACK, and native Radau giving the same
trajectory either way."""

from __future__ import annotations

import numpy as np
import pytest

from bgc.simulate import simulate
from bgc.solvers import sparse_lu
from bgc.solvers.radau5 import _MU_COMPLEX, _MU_REAL


def _mechanical(n_bodies: int, rng):
    """The structure of a chain of masses and stiff springs, as the parasitic method makes
    it: d(p_k)/dt reads the springs' deflections at its ends, d(q_k)/dt the momenta on
    both sides; a few long-range couplings (a closed loop)."""
    n = 2 * n_bodies
    J = np.zeros((n, n))
    for k in range(n_bodies):
        p, q = 2 * k, 2 * k + 1
        J[p, q] = -1e7 * rng.uniform(1, 3)           # stiffness
        J[p, p] = -rng.uniform(0, 50)                 # damping
        J[q, p] = rng.uniform(0.1, 10)                # 1 / mass
        if k + 1 < n_bodies:
            J[p, q + 2] = 1e7 * rng.uniform(1, 3)
            J[q, p + 2] = -rng.uniform(0.1, 10)
    J[0, n - 1] = 5e6
    J[n - 2, 1] = -3e6
    return J


@pytest.mark.parametrize("mu", [_MU_REAL, _MU_COMPLEX])
def test_sparse_factors_solve_like_dense_lapack(mu):
    """On a 60-state mechanical structure: far less fill than dense, and the solution of
    mu/h - J agrees with numpy's (partial pivoting) to round-off of its condition."""
    rng = np.random.default_rng(1)
    J = _mechanical(30, rng)
    n = J.shape[0]
    rows, cols = np.nonzero(J)
    plan = sparse_lu.analyse(n, rows, cols)
    assert plan[0].shape[0] == n and sorted(plan[0]) == list(range(n))
    assert len(plan[2]) + len(plan[4]) + n < 0.35 * n * n
    c = mu / 1e-3
    dtype = np.complex128 if isinstance(mu, complex) else np.float64
    a = np.zeros((n, n), dtype=dtype)
    sparse_lu.newton_matrix(J, np.empty((0, 0)), c, plan, a)
    assert sparse_lu.factor(a, plan)
    b = rng.standard_normal(n).astype(dtype)
    A = c * np.eye(n) - J
    x = sparse_lu.solve(a, plan, b)
    ref = np.linalg.solve(A, b)
    assert np.abs(x - ref).max() <= 1e-9 * np.abs(ref).max()
    # packed: the factors are the first n + nl + nu entries of the array they are given
    # (the integrator's n x n, which LAPACK takes where the plan does not), and a plan
    # without its update table (an FMU's) finds each target in the lists, to the bit
    used = n + len(plan[2]) + len(plan[4])
    assert not a.reshape(-1)[used:].any()
    plain = plan[:8] + (np.empty(0, dtype=np.int32), np.empty(0))
    a2 = np.zeros(used, dtype=dtype)
    sparse_lu.newton_matrix(J, np.empty((0, 0)), c, plain, a2)
    assert sparse_lu.factor(a2, plain)
    assert np.array_equal(sparse_lu.solve(a2, plain, b), x)
    # a mass matrix (singular: an algebraic state) enters the pattern and the values
    M = np.eye(n)
    M[3, 3] = 0.0
    J[3, 3] = 2.0
    plan = sparse_lu.analyse(n, *np.nonzero(J), M)
    a = np.zeros((n, n), dtype=dtype)
    sparse_lu.newton_matrix(J, M, c, plan, a)
    assert sparse_lu.factor(a, plan)
    x = sparse_lu.solve(a, plan, b)
    ref = np.linalg.solve(c * M - J, b)
    assert np.abs(x - ref).max() <= 1e-9 * np.abs(ref).max()
    # from the Jacobian's values, M from the plan (``mv``) or read in M itself
    rows, cols = np.nonzero(J)
    plan = sparse_lu.analyse(n, rows, cols, M)
    for pl in (plan, plan[:9] + (np.empty(0),)):
        a = np.zeros((n, n), dtype=dtype)
        sparse_lu.newton_matrix_values(J[rows, cols], M, c, pl, a)
        assert sparse_lu.factor(a, pl)
        assert np.abs(sparse_lu.solve(a, pl, b) - x).max() <= 1e-12 * np.abs(x).max()


def test_a_matrix_that_needs_pivoting_goes_back_to_lapack():
    """A structurally zero pivot leaves the plan dense; an entry growing past the limit
    (a tiny pivot) makes factor say so, so the integrator factors it with pivoting."""
    n = 30
    J = np.eye(n) * 5.0
    M = np.eye(n)
    M[0, 0] = M[1, 1] = 0.0    # two algebraic states that only see each other: the
    J[0, 0] = J[1, 1] = 0.0    # first eliminated has a zero pivot, in any order
    J[0, 1] = J[1, 0] = 1.0
    assert sparse_lu.analyse(n, *np.nonzero(J), M)[0].size == 0
    J = np.diag(np.full(n, -1.0))
    J[0, 1], J[1, 0] = 1.0, 1.0
    plan = sparse_lu.analyse(n, *np.nonzero(J))
    a = np.zeros((n, n))
    sparse_lu.newton_matrix(J, np.empty((0, 0)), -1.0 + 1e-9, plan, a)  # pivot 1e-9
    assert not sparse_lu.factor(a, plan)
    assert sparse_lu.analyse(10, *np.nonzero(J[:10, :10]))[0].size == 0   # small


def test_native_radau_takes_the_same_steps_with_sparse_and_dense_factors(compiled,
                                                                         monkeypatch):
    """The slider-crank (36 states) with the sparse plan and forced dense: the same
    number of factorizations and the same trajectory to round-off of the tolerance."""
    mod = compiled("slider_crank")
    runs = {}
    for kind, min_size in (("sparse", sparse_lu.MIN_SIZE), ("dense", 10 ** 9)):
        monkeypatch.setattr(sparse_lu, "MIN_SIZE", min_size)
        runs[kind] = simulate(mod, t_end=0.2, rtol=1e-8, atol=1e-8, solver="native",
                              points=51)
    s, d = runs["sparse"], runs["dense"]
    assert abs(s.stats.steps - d.stats.steps) <= 0.02 * d.stats.steps
    assert np.abs(s.x - d.x).max() <= 1e-6 * np.abs(d.x).max()
