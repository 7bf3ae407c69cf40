"""The SARIB helicopter suspension (issue 5) at CI scale: Table 11.1's counts, the static
equilibrium, the static offset under the constant excitation, the linear model's
anti-resonances, and a short sine run against the linear model. The 28 s chirp is
`make run`; the long sine dwell is marked slow."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import MODELS, dwell_amplitude
from scipy.signal import StateSpace, lsim

from bgc.analysis import frf
from bgc.cli import main
from bgc.model import load
from bgc.simulate import simulate

SARIB = MODELS / "sarib.yaml"


@pytest.fixture(scope="module")
def sarib(compiled):
    return compiled("sarib"), load.load(SARIB)


def _params(mod, model, kind, direction, **kw):
    p = np.array(mod.PARAMS)
    for name, value in model.excitation.select(kind, direction, **kw).items():
        p[list(mod.PARAM_NAMES).index(name)] = value
    return p


def test_check_reports_the_papers_table_11_1():
    r = CliRunner().invoke(main, ["check", str(SARIB), "--json"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert (rep["coordinates"], rep["constraints"], rep["dof"]) == (84, 74, 10)
    assert rep["bodies"] == 14


def test_nominal_configuration_is_a_static_equilibrium(sarib):
    """The joints' parasitic springs start with their static loads (parasitic: {loads:
    static}); without them the rig would first sag by load / stiffness (0.12 mm at the
    attach). Integrated with the native Radau (18 steps): from this rest state scipy's BDF
    at these tolerances crawled through the parasitic modes' lightly damped 5 kHz band
    (still running after 10 min and 4 GB of dense output, on the old code too), and how
    long it takes turns on the last bits of the residual loads."""
    mod, model = sarib
    assert mod.STATIC_LOADS
    p = _params(mod, model, "constant", "pumping", amplitude=0.0)
    r = simulate(mod, t_end=2.0, rtol=1e-8, atol=1e-10, params=p, points=201,
                 solver="native")
    pose = [i for i, n in enumerate(mod.STATE_NAMES) if "." in n and n.rsplit(".", 1)[1] in
            ("x", "y", "z", "ax", "ay", "az")]
    assert len(pose) == 84
    dev = np.abs(r.x[:, pose] - mod.X0[pose]).max()
    assert dev < 1e-6, dev                                  # m and rad


def test_constant_pumping_lifts_the_suspended_rig_by_force_over_attach_stiffness(sarib):
    """200 N between the fixed frame and the attach, held 12 s (the attach mode's decay
    time is 1.25 s): everything below the attach spring rises by F / k = 200 / 11000 =
    18.18 mm; the hinges carry the same load as before (196.2 N, a quarter of the
    fuselage's weight)."""
    mod, model = sarib
    p = _params(mod, model, "constant", "pumping")
    r = simulate(mod, t_end=12.0, rtol=1e-6, atol=1e-8, params=p, points=121)
    names = list(mod.STATE_NAMES)
    for body in ("mgb", "fuselage", "leg_1.beater"):
        dz = r.column(f"{body}.z") - mod.X0[names.index(f"{body}.z")]
        assert dz[-1] == pytest.approx(200.0 / 11000.0, rel=1e-3)     # measured 3.5e-5
        assert np.ptp(dz[-10:]) < 1e-5                                 # at rest by then
    assert r.column("F_A1_z")[-1] == pytest.approx(196.2, rel=1e-4)
    assert abs(r.column("leg_1.beater.ay")[-1] - mod.X0[names.index("leg_1.beater.ay")]) \
        < 1e-6


def test_linear_model_anti_resonances_near_the_papers(sarib):
    mod, model = sarib
    lin = frf.linearize(mod, model, "pumping")
    anti_a, _ = frf.extrema(lin, "a_OF_z", 15.0, 20.0)
    anti_z, _ = frf.extrema(lin, "F_A1_z", 15.0, 20.0)
    anti_x, _ = frf.extrema(lin, "F_A1_x", 15.0, 20.0)
    assert anti_a == [pytest.approx(18.054, abs=0.01)]      # paper: 18 Hz
    assert anti_z == [pytest.approx(18.032, abs=0.01)]
    assert anti_x == [pytest.approx(17.100, abs=0.01)]      # paper: 16.8 Hz


def test_short_sine_run_follows_the_linear_model(sarib):
    """0.5 s of a 12 Hz pumping sine: the nonlinear run against the linear model's exact
    response from rest (same A, B, C, D as the frequency response). Measured: 0.04 % (a_OF_z,
    F_A1_z), 0.28 % (F_A1_x); at 18 Hz, where the beaters swing hardest, F_A1_x is 2.2 %
    off: the radial hinge force carries the beater's centrifugal term, quadratic in its
    swing rate, which no linear model has."""
    mod, model = sarib
    p = _params(mod, model, "sine", "pumping", frequency=12.0)
    r = simulate(mod, t_end=0.5, rtol=1e-7, atol=1e-9, params=p, points=1001)
    lin = frf.linearize(mod, model, "pumping")
    u = 200.0 * np.sin(2 * np.pi * 12.0 * r.t)
    for out in ("a_OF_z", "F_A1_z", "F_A1_x"):
        k = list(mod.OUTPUT_NAMES).index(out)
        ss = StateSpace(lin.A, lin.B[:, None], lin.C[k:k + 1], lin.D[k:k + 1, None])
        y = lsim(ss, u, r.t)[1] + mod.outputs(0.0, lin.x, lin.p)[k]
        assert np.abs(r.column(out) - y).max() < 0.01 * np.abs(y - y[0]).max(), out


@pytest.mark.slow
def test_sine_dwell_matches_the_frequency_response(sarib):
    mod, model = sarib
    lin = frf.linearize(mod, model, "pumping")
    for f in (12.0, 18.0):
        p = _params(mod, model, "sine", "pumping", frequency=f)
        r = simulate(mod, t_end=12.0, rtol=1e-7, atol=1e-9, params=p, points=24001)
        for out in ("a_OF_z", "F_A1_z", "F_A1_x"):
            h = abs(lin.response([f], out)[0]) * 200.0
            assert dwell_amplitude(r.t, r.column(out), f) == pytest.approx(h, rel=0.01)


# (direction, output) pairs whose anti-resonances issue 5 compares across methods
ANTI = (("pumping", "a_OF_z"), ("pumping", "F_A1_z"), ("pumping", "F_A1_x"),
        ("roll", "F_A1_z"), ("pitch", "F_A1_z"))


def _stiffer(mod, p, factor):
    """``p`` with every parasitic stiffness x factor, damping x sqrt(factor) (the same
    damping ratio)."""
    q = np.array(p)
    for i, n in enumerate(mod.PARAM_NAMES):
        if n.endswith(("__stiffness", "__rot_stiffness")):
            q[i] *= factor
        elif n.endswith(("__damping", "__rot_damping")):
            q[i] *= np.sqrt(factor)
    return q


@pytest.mark.slow
@pytest.mark.parametrize("method", ["lagrange", "zcp"])
def test_ideal_joints_agree_with_parasitic_within_its_modelling_error(sarib, compiled,
                                                                    method):
    """The SARIB under lagrange and zcp (the four bodies of negligible mass: twist states
    whose rates the constraint block solves). Anti-resonances within 0.05 Hz of parasitic
    (measured <= 0.034 Hz, roll, with the model's 3e7 N/m joints); 1 s of an 18 Hz pumping
    sine: the outputs differ from parasitic by what parasitic itself moves when its
    stiffness is raised tenfold (its modelling error falls as 1/k: the distance to the
    limit is 10/9 of that move)."""
    mod, model = sarib
    ideal = compiled("sarib", method)
    assert sum(".M0" in n for n in ideal.STATE_NAMES) == 24      # 4 bodies' twists
    for direction, out in ANTI:
        a = frf.extrema(frf.linearize(mod, model, direction), out, 15.0, 22.0)[0]
        b = frf.extrema(frf.linearize(ideal, model, direction), out, 15.0, 22.0)[0]
        assert b == [pytest.approx(x, abs=0.05) for x in a], (direction, out)
    runs = {}
    for name, m, factor in (("ideal", ideal, None), ("k", mod, 1.0), ("10k", mod, 10.0)):
        p = _params(m, model, "sine", "pumping", frequency=18.0)
        p = p if factor is None else _stiffer(m, p, factor)
        runs[name] = simulate(m, t_end=1.0, rtol=1e-8, atol=1e-10, params=p, points=2001)
    assert runs["ideal"].stats.drift_position < 1e-7
    for out in ("a_OF_z", "F_A1_z", "F_A1_x"):
        y, yk, y10 = (runs[n].column(out) for n in ("ideal", "k", "10k"))
        scale = np.ptp(yk)
        err, model_err = np.abs(yk - y).max(), np.abs(yk - y10).max()
        assert err <= 1.5 * model_err + 1e-4 * scale, (out, err, model_err)


@pytest.mark.slow       # the one-leg rig: its own module; the SARIB itself stays in make test
def test_one_leg_variant_has_the_rigs_pumping_response(sarib, compiled):
    """models/sarib_one_leg.yaml (issue 7): the rig reduced by its symmetry under pumping.
    Its linear model has the rig's symmetric modes and the rig's anti-resonances within
    0.01 Hz, and the same frequency response (a quarter of the force on a quarter of the
    rig: per newton at its attach, four times the rig's) within 1 %; 51 states instead
    of 152."""
    mod, model = sarib
    one = compiled("sarib_one_leg")
    one_model = load.load(MODELS / "sarib_one_leg.yaml")
    assert len(one.STATE_NAMES) < len(mod.STATE_NAMES) / 2.5
    full_lin = frf.linearize(mod, model, "pumping")
    one_lin = frf.linearize(one, one_model, "pumping")
    for out in ("a_OF_z", "F_A1_z", "F_A1_x"):
        f_full, _ = frf.extrema(full_lin, out, 15.0, 20.0)
        f_one, _ = frf.extrema(one_lin, out, 15.0, 20.0)
        assert f_one == pytest.approx(f_full, abs=0.01), out
        h_full = frf.sweep(full_lin, out, 5.0, 25.0)
        h_one = frf.sweep(one_lin, out, 5.0, 25.0)
        assert np.allclose(np.abs(h_one[1]) / 4, np.abs(h_full[1]), rtol=0.01), out
