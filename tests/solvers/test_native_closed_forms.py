"""bgc's own Radau (the native numba loop, ``NativeRadau``) against closed-form solutions,
alone through the ``Solver`` interface on hand-written problems (C entry points as ctypes
callbacks, no model compiled): a stiff scalar problem (Prothero-Robinson), DAEs of index 1
and 2 with a singular mass matrix, the error falling with the tolerance, and its step
count where it is known exactly (the step budget)."""

from __future__ import annotations

import ctypes
import math
import types

import numpy as np
import pytest

from bgc.simulate import SOLVERS
from bgc.solvers.base import Problem

_ENTRY = ctypes.CFUNCTYPE(None, ctypes.c_double, ctypes.POINTER(ctypes.c_double),
                          ctypes.POINTER(ctypes.c_double), ctypes.POINTER(ctypes.c_double))


def c_module(names, rhs, jac):
    """A module-like namespace whose rhs(t, x, out) and jac(t, x, out) (dense, row-major)
    are C entry points, as the native loop calls a generated module's."""
    n = len(names)

    @_ENTRY
    def rhs_entry(t, x, p, out):
        rhs(t, x, out)

    @_ENTRY
    def jac_entry(t, x, p, out):
        jac(t, x, out)

    def py(fun, size):
        def call(t, x, p):
            out = np.zeros(size)
            fun(t, np.asarray(x, dtype=float), out)
            return out.reshape(n, -1) if size > n else out
        return call

    entries = tuple(ctypes.cast(f, ctypes.c_void_p).value for f in (rhs_entry, jac_entry))
    rows, cols = np.divmod(np.arange(n * n), n)
    return types.SimpleNamespace(
        rhs=py(rhs, n), jac=py(jac, n * n), STATE_NAMES=tuple(names), GUARD_NAMES=(),
        JAC_I=rows, JAC_J=cols, native_entry_points=lambda: (*entries, 0),
        _keep=(rhs_entry, jac_entry))


def radau(module, **problem):
    return SOLVERS["native"](Problem(module, np.zeros(0), **problem))


LAMBDA = -1e6        # Prothero-Robinson: y' = lambda (y - sin t) + cos t, y = sin t


def prothero_robinson():
    def rhs(t, x, out):
        out[0] = LAMBDA * (x[0] - math.sin(t)) + math.cos(t)

    def jac(t, x, out):
        out[0] = LAMBDA
    return c_module(("y",), rhs, jac)


@pytest.mark.parametrize("rtol", [1e-4, 1e-7])
def test_stiff_prothero_robinson_in_few_steps_within_its_tolerance(rtol):
    """Stiffness 1e6 over 10 s: an explicit method's step would be held below 2e-6 s
    (5e6 steps); Radau's follows the smooth solution sin t alone, in a few steps of
    seconds, its end within the tolerance (the error is controlled at the steps' ends)."""
    solver = radau(prothero_robinson(), rtol=rtol, atol=rtol)
    seg = solver.integrate(0.0, 10.0, np.array([0.0]), np.empty(0))
    assert seg.ok and seg.t_reached == 10.0
    assert abs(seg.x_end[0] - math.sin(10.0)) < rtol
    assert 0 < solver.counts.steps < 20


def test_dense_output_between_steps_at_the_signals_step_limit():
    """Between its steps the solution is the collocation polynomial (order 3): with the
    step limit a generated module sets for a sine input (8 steps a period,
    ``STEPS_PER_PERIOD``) it is within 3e-4 of sin t at every output time, whatever the
    tolerance; the steps' ends stay within it."""
    t_eval = np.linspace(0.0, 10.0, 101)
    for rtol in (1e-4, 1e-8):
        solver = radau(prothero_robinson(), rtol=rtol, atol=rtol, max_step=2 * math.pi / 8)
        seg = solver.integrate(0.0, 10.0, np.array([0.0]), t_eval)
        assert seg.ok and seg.x_eval.shape == (101, 1)
        assert np.abs(seg.x_eval[:, 0] - np.sin(t_eval)).max() < 3e-4
        assert abs(seg.x_end[0] - math.sin(10.0)) < rtol


def test_index1_dae_with_a_singular_mass_matrix():
    """x' = z, 0 = -x - z (M = diag(1, 0)): x = e^-t, z = -e^-t."""
    def rhs(t, x, out):
        out[0], out[1] = x[1], -x[0] - x[1]

    def jac(t, x, out):
        out[0], out[1], out[2], out[3] = 0.0, 1.0, -1.0, -1.0
    solver = radau(c_module(("x", "z"), rhs, jac), rtol=1e-9, atol=1e-12,
                   mass=np.diag([1.0, 0.0]))
    t_eval = np.linspace(0.0, 3.0, 31)
    seg = solver.integrate(0.0, 3.0, np.array([1.0, -1.0]), t_eval)
    assert seg.ok
    exact = np.exp(-t_eval)
    assert np.abs(seg.x_eval[:, 0] - exact).max() < 1e-8
    assert np.abs(seg.x_eval[:, 1] + exact).max() < 1e-8


def test_index2_dae_with_its_error_scaling():
    """y' = z, 0 = y - sin t: z is algebraic of index 2 (it enters only through y'):
    y = sin t, z = cos t. Radau's index-2 error scaling (``Problem.index2``) keeps the
    step from collapsing on z's error."""
    def rhs(t, x, out):
        out[0], out[1] = x[1], x[0] - math.sin(t)

    def jac(t, x, out):
        out[0], out[1], out[2], out[3] = 0.0, 1.0, 1.0, 0.0
    solver = radau(c_module(("y", "z"), rhs, jac), rtol=1e-9, atol=1e-9,
                   mass=np.diag([1.0, 0.0]), index2=np.array([0.0, 1.0]))
    t_eval = np.linspace(0.0, 5.0, 51)
    seg = solver.integrate(0.0, 5.0, np.array([0.0, 1.0]), t_eval)
    assert seg.ok
    assert abs(seg.x_end[0] - math.sin(5.0)) < 1e-12       # the constraint, at a step
    assert abs(seg.x_end[1] - math.cos(5.0)) < 1e-8
    assert np.abs(seg.x_eval[:, 0] - np.sin(t_eval)).max() < 1e-8
    assert np.abs(seg.x_eval[:, 1] - np.cos(t_eval)).max() < 1e-6


K, C = 4.0, 0.5                                 # x'' + C x' + K x = 0, x(0) = 1


def oscillator():
    def rhs(t, x, out):
        out[0], out[1] = x[1], -K * x[0] - C * x[1]

    def jac(t, x, out):
        out[0], out[1], out[2], out[3] = 0.0, 1.0, -K, -C
    return c_module(("x", "v"), rhs, jac)


def oscillator_exact(t):
    wd = math.sqrt(K - C * C / 4)
    return np.exp(-C * t / 2) * (np.cos(wd * t) + C / (2 * wd) * np.sin(wd * t))


def test_the_error_falls_with_the_tolerance():
    """Over 10 s of the damped oscillator the error at the output times stays within a
    few tolerances of the closed form and falls by four decades over six of rtol."""
    t_eval = np.linspace(0.0, 10.0, 201)
    errors = []
    for tol in (1e-4, 1e-6, 1e-8, 1e-10):
        seg = radau(oscillator(), rtol=tol, atol=tol).integrate(
            0.0, 10.0, np.array([1.0, 0.0]), t_eval)
        assert seg.ok
        errors.append(np.abs(seg.x_eval[:, 0] - oscillator_exact(t_eval)).max())
        assert errors[-1] < 30 * tol, (tol, errors)
    assert all(b < a for a, b in zip(errors, errors[1:])), errors
    assert errors[-1] < 1e-4 * errors[0], errors


def test_the_step_budget_stops_it_after_exactly_so_many_steps():
    """A run of 10 s that needs hundreds of steps, given 7: the loop takes exactly 7
    (counted where it takes them) and says where the budget ran out."""
    solver = radau(oscillator(), rtol=1e-10, atol=1e-10, max_steps=7)
    seg = solver.integrate(0.0, 10.0, np.array([1.0, 0.0]), np.linspace(0.0, 10.0, 11))
    assert not seg.ok and seg.message.startswith("the step budget (7 steps) is spent at t = ")
    assert solver.counts.steps == 7 and 0.0 < seg.t_reached < 10.0
    assert abs(seg.x_end[0] - oscillator_exact(seg.t_reached)) < 1e-8
