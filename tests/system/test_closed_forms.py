"""Shipped models against independent analytic solutions (1e-7 relative), under bgc's own
Radau (native) and scipy's Radau alike: each is checked against the closed form, not
against the other."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import rel_err
from scipy.integrate import quad, solve_ivp
from scipy.linalg import expm

from bgc.simulate import simulate



@pytest.fixture(params=["native", pytest.param("radau", marks=pytest.mark.slow)])
def tight(request):
    """Tight tolerances under each Radau: bgc's numba loop and scipy's (at rtol 1e-11
    scipy's Python loop is the slow one: make test-all; test_every_stiff_solver_agrees
    keeps scipy's in make test)."""
    return dict(rtol=1e-11, atol=1e-13, solver=request.param)


def damped_step(t, wn, zeta):
    """Unit-step response of x'' + 2 zeta wn x' + wn^2 x = wn^2 from rest (zeta < 1)."""
    wd = wn * np.sqrt(1 - zeta ** 2)
    return 1 - np.exp(-zeta * wn * t) * (np.cos(wd * t) + zeta * wn / wd * np.sin(wd * t))


def test_msd_free_vibration(compiled, tight):
    mod = compiled("msd_free")
    m, k, c, x0 = 2.0, 800.0, 4.0, 0.01
    r = simulate(mod, t_end=1.0, points=2001, **tight)
    wn, zeta = np.sqrt(k / m), c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - zeta ** 2)
    x = x0 * np.exp(-zeta * wn * r.t) * (np.cos(wd * r.t) + zeta * wn / wd * np.sin(wd * r.t))
    v = -x0 * np.exp(-zeta * wn * r.t) * (wn ** 2 / wd) * np.sin(wd * r.t)
    assert rel_err(r.column("position"), x) < 1e-7
    assert rel_err(r.column("velocity"), v) < 1e-7
    assert rel_err(r.column("spring_force"), k * x) < 1e-7


def test_msd_forced_response(compiled, tight):
    mod = compiled("msd_forced")
    m, k, c, F0, f = 1.5, 600.0, 6.0, 10.0, 3.0
    r = simulate(mod, t_end=2.0, points=2001, **tight)
    w = 2 * np.pi * f
    wn, zeta = np.sqrt(k / m), c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - zeta ** 2)
    X, phi = F0 / np.hypot(k - m * w ** 2, c * w), np.arctan2(c * w, k - m * w ** 2)
    A = X * np.sin(phi)                                  # x(0) = 0
    B = (zeta * wn * A - X * w * np.cos(phi)) / wd       # v(0) = 0
    t = r.t
    x = X * np.sin(w * t - phi) + np.exp(-zeta * wn * t) * (A * np.cos(wd * t)
                                                            + B * np.sin(wd * t))
    assert rel_err(r.column("position"), x) < 1e-7


def test_series_rlc_step(compiled, tight):
    mod = compiled("rlc")
    V, R, L, C, t0 = 12.0, 10.0, 0.05, 2e-5, 1e-3
    r = simulate(mod, t_end=0.05, points=5001, **tight)
    wn, zeta = 1 / np.sqrt(L * C), R / 2 * np.sqrt(C / L)
    wd = wn * np.sqrt(1 - zeta ** 2)
    tau = np.clip(r.t - t0, 0, None)
    vc = V * damped_step(tau, wn, zeta)
    i = C * V * np.exp(-zeta * wn * tau) * wn ** 2 / wd * np.sin(wd * tau)
    assert rel_err(r.column("v_C"), vc) < 1e-7
    assert rel_err(r.column("current"), i) < 1e-7
    assert rel_err(r.column("v_R"), R * i) < 1e-7


def test_dc_motor_through_gear(compiled, tight):
    """Linear state space written by hand from the physics, solved exactly with expm."""
    mod = compiled("dc_motor")
    Ra, La, km, bm, n, J, bL, TL, U, t_on = 1.2, 3e-3, 0.05, 2e-5, 0.1, 2e-3, 1e-3, 0.05, 24.0, 0.01
    # states: current i, load speed w (motor speed = w / n); torque at the load = motor / n
    A = np.array([[-Ra / La, -km / (n * La)],
                  [km / (n * J), -(bm / n ** 2 + bL) / J]])
    r = simulate(mod, t_end=0.2, points=2001, **tight)

    def exact(t):
        x = np.zeros(2)
        pieces = [(0.0, min(t, t_on), 0.0), (t_on, t, U)]
        for a, b, u in pieces:
            if b <= a:
                continue
            g = np.array([u / La, -TL / J])
            E = expm(A * (b - a))
            x = E @ x + np.linalg.solve(A, (E - np.eye(2)) @ g)
        return x

    ex = np.array([exact(t) for t in r.t])
    assert rel_err(r.column("current"), ex[:, 0]) < 1e-7
    assert rel_err(r.column("load_speed"), ex[:, 1]) < 1e-7
    assert rel_err(r.column("motor_speed"), ex[:, 1] / n) < 1e-7
    assert rel_err(r.column("load_momentum"), J * ex[:, 1]) < 1e-7


def test_derivative_causality_geared_inertias(compiled, tight):
    """J_load has derivative causality; the result is one oscillator with the reflected
    inertia J_load + J_rotor / n^2 and torque T0 / n."""
    mod = compiled("geared_inertias")
    assert mod.STATE_NAMES == ("J_r.p", "shaft.q")
    T0, Jr, Jl, n, k, b = 2.0, 1e-3, 5e-2, 0.25, 40.0, 0.2
    r = simulate(mod, t_end=2.0, points=2001, **tight)
    Jeff = Jl + Jr / n ** 2
    wn, zeta = np.sqrt(k / Jeff), b / (2 * np.sqrt(k * Jeff))
    theta = T0 / (n * k) * damped_step(r.t, wn, zeta)
    assert rel_err(r.column("load_angle"), theta) < 1e-7
    assert rel_err(r.column("rotor_speed"), r.column("load_speed") / n) < 1e-9
    # the dependent momentum follows the load speed
    assert rel_err(r.column("load_momentum"), Jl * r.column("load_speed")) < 1e-9


def test_algebraic_loop_rr_network(compiled, tight):
    mod = compiled("rr_loop")
    E, R1, R2, R3, C = 10.0, 1000.0, 3000.0, 500.0, 1e-6
    r = simulate(mod, t_end=0.01, points=2001, **tight)
    Rth, Vth = R1 * R2 / (R1 + R2) + R3, E * R2 / (R1 + R2)
    vc = Vth * (1 - np.exp(-r.t / (Rth * C)))
    i3 = (Vth - vc) / Rth
    v_node = vc + R3 * i3
    assert rel_err(r.column("v_C"), vc) < 1e-7
    assert rel_err(r.column("v_node"), v_node) < 1e-7
    assert rel_err(r.column("i_source"), (E - v_node) / R1) < 1e-7


def test_table_signal_drives_rc(compiled, tight):
    mod = compiled("rc_table")
    R, C, a, t1 = 2000.0, 1e-6, 500.0, 0.01
    tau = R * C
    r = simulate(mod, t_end=0.03, points=3001, **tight)
    ramp = a * (r.t - tau * (1 - np.exp(-r.t / tau)))
    v1 = a * (t1 - tau * (1 - np.exp(-t1 / tau)))
    held = 5.0 + (v1 - 5.0) * np.exp(-(r.t - t1) / tau)
    vc = np.where(r.t <= t1, ramp, held)
    assert rel_err(r.column("v_C"), vc) < 1e-7
    assert np.allclose(r.column("v_in"), np.interp(r.t, [0, 0.01, 0.03], [0, 5, 5]))


def test_duffing_energy_and_period(compiled, tight):
    """Cubic spring: energy is conserved; the period matches the quadrature of the
    energy integral T = 4 int_0^A dx / sqrt(2 (V(A) - V(x)) / m)."""
    mod = compiled("duffing")
    m, k, k3, A = 0.5, 200.0, 4.0e6, 0.02
    r = simulate(mod, t_end=1.0, points=20001, **tight)
    energy = r.column("energy")
    assert abs(energy - energy[0]).max() / energy[0] < 1e-7

    def V(x):
        return k * x ** 2 / 2 + k3 * x ** 4 / 4
    T, _ = quad(lambda x: 1 / np.sqrt(2 * (V(A) - V(x)) / m), 0, A, limit=200)
    T *= 4
    x = r.column("position")
    # downward zero crossings, located by linear interpolation
    idx = np.where((x[:-1] > 0) & (x[1:] <= 0))[0]
    tc = r.t[idx] - x[idx] * (r.t[idx + 1] - r.t[idx]) / (x[idx + 1] - x[idx])
    period = np.diff(tc).mean()
    assert abs(period - T) / T < 1e-6


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the reference ODE overflows in trial steps
def test_rectifier_against_independent_ode(compiled):
    """The diode is a nonlinear R in conductance form; compare with the circuit ODE
    C dv/dt = Is (exp((Vs - v)/Vt) - 1) - v/R written by hand."""
    mod = compiled("rectifier")
    Vpk, f, Is, Vt, C, R = 10.0, 50.0, 1e-12, 0.02585, 1e-4, 1000.0
    r = simulate(mod, t_end=0.1, points=1001, rtol=1e-10, atol=1e-12, solver="radau")

    def ode(t, v):
        vs = Vpk * np.sin(2 * np.pi * f * t)
        return [(Is * np.expm1((vs - v[0]) / Vt) - v[0] / R) / C]
    ref = solve_ivp(ode, (0, 0.1), [0.0], method="Radau", rtol=1e-11, atol=1e-13,
                    t_eval=r.t, jac=lambda t, v: [[(-Is / Vt * np.exp(
                        (Vpk * np.sin(2 * np.pi * f * t) - v[0]) / Vt) - 1 / R) / C]])
    assert rel_err(r.column("v_out"), ref.y[0]) < 1e-6
    assert r.column("v_out").max() < Vpk


def test_servo_settles_on_reference(compiled):
    mod = compiled("servo")
    r = simulate(mod, t_end=1.0, rtol=1e-9, atol=1e-11)
    assert abs(r.column("theta")[-1] - 1.0) < 1e-4
    assert abs(r.column("voltage")[-1]) < 1e-2


@pytest.mark.parametrize("solver", ["native", "bdf", "radau", "lsoda"])
def test_every_stiff_solver_agrees(compiled, solver):
    mod = compiled("msd_free")
    r = simulate(mod, t_end=0.5, rtol=1e-9, atol=1e-12, solver=solver)
    m, k, c, x0 = 2.0, 800.0, 4.0, 0.01
    wn, zeta = np.sqrt(k / m), c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - zeta ** 2)
    x = x0 * np.exp(-zeta * wn * r.t) * (np.cos(wd * r.t) + zeta * wn / wd * np.sin(wd * r.t))
    assert rel_err(r.column("position"), x) < 1e-5
    assert r.stats.steps > 0 and r.stats.rhs_calls > 0
