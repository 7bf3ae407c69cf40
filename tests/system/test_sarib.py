"""The SARIB helicopter suspension (issue 5) at CI scale: Table 11.1's counts, the static
equilibrium, the static offset under the constant excitation, the linear model's
anti-resonances and modes against the paper's figures, and a short sine run against the
linear model. The 28 s chirp is `make run`; the long sine dwell, the roll and pitch chirps
and the closed forms of a blocked fuselage are marked slow.

The paper's figures are its rig's (section 11.5.2), whose numbers it does not publish:
models/sarib.yaml holds the project's SARIB data set, built to the paper's pumping
anti-resonances. Each figure is asserted to the accuracy the paper's text gives it: a
frequency stated to the hertz ("at 18 Hz") is +-0.5 Hz, one stated to a tenth ("18.2 Hz")
+-0.05 Hz, beside bgc's own snapshot of its value. Where the data set's fuselage, not bgc,
puts a figure outside that accuracy, the test says so and asserts what the paper's
statement still fixes."""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from helpers import (MODELS, PAPER_PUMPING_VERTICAL, PAPER_PUMPING_X, ROOT,
                     dwell_amplitude, within_paper)
from scipy.signal import StateSpace, lsim

from bgc.analysis import frf, modes
from bgc.cli import main
from bgc.model import load
from bgc.simulate import simulate

SARIB = MODELS / "sarib.yaml"


def anti_resonances(lin, outputs, f_min: float, f_max: float,
                    step: float = frf.STEP_HZ) -> dict[str, list[float]]:
    """Each output's anti-resonances in the band, as bgc frf finds them (its grid, each
    minimum refined to 1e-4 Hz), from one sweep of every output (one linear solve per
    frequency, not one per frequency and output). A coarser ``step`` finds the same
    minima where no two extrema lie within two steps."""
    f = frf.grid(f_min, f_max, step)
    h = lin.responses(f)
    names = list(lin.output_names)
    return {out: frf.extrema(lin, out, f_min, f_max, grid=(f, h[:, names.index(out)]))[0]
            for out in outputs}


@pytest.fixture(scope="module")
def sarib_model():
    return load.load(SARIB)


@pytest.fixture(scope="module")
def sarib(compiled, sarib_model):
    return compiled("sarib"), sarib_model


def _params(mod, model, kind, direction, **kw):
    p = np.array(mod.PARAMS)
    for name, value in model.excitation.select(kind, direction, **kw).items():
        p[list(mod.PARAM_NAMES).index(name)] = value
    return p


def test_check_reports_the_papers_table_11_1(sarib_model):
    """Table 11.1: 84 coordinates (14 bodies), 74 constraints, 10 DoF; its 8 spherical, 8
    revolute and 2 prismatic joints (section 11.4.1's "four revolute joints" is a
    misprint: 4 + 8 + 2 is not its 18 joints; 11.4.4.1 counts eight revolute joints, two
    in each universal joint and four hinges)."""
    r = CliRunner().invoke(main, ["check", str(SARIB), "--json"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    assert (rep["coordinates"], rep["constraints"], rep["dof"]) == (84, 74, 10)
    assert rep["bodies"] == 14
    kinds = Counter(j.kind for j in sarib_model.joints.values())
    assert kinds == {"revolute": 8, "spherical": 8, "prismatic": 2}


def test_the_chirp_and_the_tolerances_are_the_papers(sarib_model):
    """Section 11.4.2: t1 = 3 s, t2 = 5 s, t3 = 25 s, from f_start = 5 Hz to f_end = 25 Hz
    (the excitation at t s between t2 and t3 is at t Hz: tests/analysis/test_excitation.py);
    amplitudes are not given (200 N and 40 N m are the data set's). Section 11.4.4.4:
    20-sim's BDF ran at absolute and relative tolerances of 1e-5, the model's own (the main
    job chooses 1e-4: docs/main-job.md)."""
    chirp = sarib_model.excitation.kinds["chirp"].numbers
    assert chirp == {"t1": 3.0, "t2": 5.0, "t3": 25.0, "f_start": 5.0, "f_end": 25.0}
    assert (sarib_model.settings.rtol, sarib_model.settings.atol) == (1e-5, 1e-5)


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


def test_linear_model_pumping_anti_resonances_against_the_papers(sarib):
    """Section 11.5.2.1, bgc frf's anti-resonances beside bgc's snapshot: the vertical
    acceleration of O_F and the vertical hinge forces at 18 Hz (Figs 11.27, 11.28); the
    x-force's "does not occur at the same frequency" (Fig. 11.29): 16.8 against 18 Hz, 1.2
    +- 0.55 Hz below at the two figures' accuracy.

    The x-force's 16.8 Hz itself is not met: 17.10 Hz is 0.30 Hz above it (6 times its
    +-0.05 Hz). The data set's fuselage, not bgc: with the fuselage blocked bgc gives the
    beater's closed form K / I_O, 16.66 Hz (test_pumping_anti_resonances_with_the_fuselage
    _blocked_are_the_closed_forms); the data set's 80 kg fuselage, free on its soft
    membrane, moves it up, and the vertical ones hardly (a fuselage of four times that
    mass, gravity off: 16.81 and 18.03 Hz, zcp)."""
    mod, model = sarib
    lin = frf.linearize(mod, model, "pumping")
    anti = anti_resonances(lin, ("a_OF_z", "F_A1_z", "F_A2_z", "F_A1_x"), 15.0, 20.0)
    assert anti["a_OF_z"] == [pytest.approx(18.054, abs=0.01)]
    assert anti["F_A1_z"] == [pytest.approx(18.032, abs=0.01)]
    assert anti["F_A2_z"] == [pytest.approx(anti["F_A1_z"][0], abs=1e-4)]   # the legs alike
    assert anti["F_A1_x"] == [pytest.approx(17.100, abs=0.01)]
    for out in ("a_OF_z", "F_A1_z", "F_A2_z"):                 # Figs 11.27, 11.28
        assert within_paper(anti[out][0], PAPER_PUMPING_VERTICAL), (out, anti[out])
    gap = anti["F_A1_z"][0] - anti["F_A1_x"][0]                # Fig. 11.29 against 11.28
    paper_gap = (PAPER_PUMPING_VERTICAL[0] - PAPER_PUMPING_X[0],      # 1.2 +- 0.55 Hz
                 PAPER_PUMPING_VERTICAL[1] + PAPER_PUMPING_X[1])
    assert within_paper(gap, paper_gap), gap


def test_roll_and_pitch_hinge_forces_against_the_paper(sarib):
    """Section 11.5.2.2: under roll an anti-resonance of the vertical hinge force (Fig.
    11.30) and a phase shift between F_A1_z and F_A2_z (Fig. 11.31, no value given);
    11.5.2.3: "similar results" under pitch. Hinges A1 and A2 (azimuth 45 and 135 deg)
    mirror each other across the plane x = 0: roll (about y) moves them in opposite senses,
    F_A2_z = -F_A1_z at every frequency (the phase shift: 180 deg); pitch (about x) in
    the same sense, F_A2_z = F_A1_z.

    The roll anti-resonance's 18.2 Hz is not met: bgc's 19.63 Hz is 1.43 Hz above it
    (zcp: 19.59). The data set's fuselage, not bgc: under roll the fuselage moves with the
    MGB, and its roll inertia, which the paper does not give, sets this zero. The data
    set's, 4 kg m^2 (a radius of gyration of 0.22 m for 80 kg), is small: at 40 and 160
    kg m^2, everything else the data set's, bgc gives 18.68 and 18.21 Hz (zcp)."""
    mod, model = sarib
    f = np.arange(5.0, 25.01, 0.5)
    for direction, sign, snapshot in (("roll", -1.0, 19.627), ("pitch", 1.0, 19.689)):
        lin = frf.linearize(mod, model, direction)
        h = lin.responses(f)
        a1, a2 = (h[:, list(lin.output_names).index(n)] for n in ("F_A1_z", "F_A2_z"))
        assert np.abs(a2 / a1 - sign).max() < 1e-6, direction                # Fig. 11.31
        anti = anti_resonances(lin, ("F_A1_z", "F_A2_z"), 15.0, 22.0, step=0.1)  # 11.30
        assert anti["F_A1_z"] == [pytest.approx(snapshot, abs=0.01)], direction
        assert anti["F_A2_z"] == [pytest.approx(anti["F_A1_z"][0], abs=1e-4)], direction


@pytest.mark.xfail(strict=True, reason="the shared parameter set's fuselage (80 kg, 4 kg m^2) "
                   "is not the paper's rig, which the paper does not give: see the two tests above")
@pytest.mark.parametrize("direction, output, paper", [
    ("pumping", "F_A1_x", PAPER_PUMPING_X),     # Fig. 11.29: "around 16.8 Hz"
    ("roll", "F_A1_z", (18.2, 0.05))])          # Fig. 11.30: "at ... 18.2 Hz"
def test_the_papers_figures_that_the_parameter_set_does_not_reach(sarib, direction, output,
                                                                   paper):
    """The paper's x-force anti-resonance under pumping and vertical one under roll, to
    its stated accuracy: bgc's 17.10 and 19.63 Hz miss them because of the data set's
    fuselage (with it blocked bgc gives the closed forms exactly). Strict: a parameter set
    that reaches the paper's figures turns this into a failure, to be made a plain test."""
    mod, model = sarib
    anti = anti_resonances(frf.linearize(mod, model, direction), (output,), 15.0, 22.0,
                           step=0.1)
    assert len(anti[output]) == 1 and within_paper(anti[output][0], paper), anti


def test_modes_are_table_11_1s_six_and_the_attach_is_below_2_hz(sarib):
    """Table 11.1's 10 DoF are "6 + 4": bgc modes' six functional modes (the rig's pumping,
    roll and pitch on the attach; the fuselage's against the MGB, on the membrane and the
    beaters) and the four idle bar spins (rigid motions, not listed). Section 11.3.4: the
    rig hangs on an attach "designed so that the natural frequency induced by the overall
    stiffness is below 2 Hz" (11.4.1: "distant from the excitation frequency"): its three
    modes, beside bgc's snapshot; the other three, the absorber's, lie in 15..20 Hz."""
    mod, model = sarib
    modal = modes.analyse(mod, model, frf.linearize(mod, model))
    f = [m.frequency_hz for m in modal.modes if m.kind == "functional"]
    assert f == pytest.approx([0.4992, 0.5017, 1.4937, 16.209, 16.680, 17.176], abs=1e-3)
    assert all(x < 2.0 for x in f[:3])                          # 11.3.4
    assert all(15.0 < x < 20.0 for x in f[3:])


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


@pytest.mark.slow
def test_roll_and_pitch_chirps_turn_the_hinge_forces_against_and_with_each_other(
        sarib_model, compiled):
    """Fig. 11.31 as the paper draws it, in time: make demo's roll chirp (zcp, native Radau,
    rtol = atol = 1e-4) to the end of its zoom, 17.8..18.2 s (the sweep at 17.8..18.2 Hz):
    the vertical forces at hinges A1 and A2 swing in antiphase (correlation -1: a phase
    shift of 180 deg) with equal amplitudes; under the pitch chirp (section 11.5.2.3), in
    phase. Measured: correlation -0.999995 and +1 - 4e-11, amplitudes within 0.03 %."""
    mod, model = compiled("sarib", "zcp"), sarib_model
    for direction, sign in (("roll", -1.0), ("pitch", 1.0)):
        p = _params(mod, model, "chirp", direction)
        r = simulate(mod, t_end=18.2, rtol=1e-4, atol=1e-4, params=p, points=18201)
        zoom = r.t >= 17.8
        a1, a2 = (y - y.mean() for y in (r.column(n)[zoom] for n in ("F_A1_z", "F_A2_z")))
        assert sign * np.corrcoef(a1, a2)[0, 1] > 0.9999, direction
        assert np.ptp(a2) == pytest.approx(np.ptp(a1), rel=1e-3), direction
        assert np.ptp(a1) > 1.0, direction                      # N: the forces do swing


@pytest.mark.slow
def test_pumping_anti_resonances_with_the_fuselage_blocked_are_the_closed_forms(
        compiled, tmp_path):
    """What sets the pumping anti-resonances: bgc against the closed forms of a beater on a
    hinge fixed in space (the SARIB data set's own estimates). A beater of moment of
    inertia I_O and first moment S_O about its hinge, hinge stiffness K, driven by a bar at
    lever arm r, passes no vertical force at omega^2 = K / (I_O - r S_O) and no radial
    force at omega^2 = K / I_O (the bar's force keeps its direction; its vertical part
    makes the hinge moment). The SARIB as written out (tests/model/sarib_written_out.yaml)
    with its fuselage 1e4 times heavier (blocked), its bars 1e3 times lighter, no gravity
    (no static loads) and no hinge damping, under zcp: within 5e-4 Hz of 17.9634 and
    16.6644 Hz (measured below 1e-4). The data set's free 80 kg fuselage moves the radial
    one to 17.10 Hz and the vertical one to 18.03 (test_linear_model_pumping_anti_resonances
    _against_the_papers): the paper's 16.8 Hz (Fig. 11.29) is its rig's, whose fuselage it
    does not give."""
    doc = yaml.safe_load((ROOT / "tests/model/sarib_written_out.yaml").read_text())
    doc.update(name="sarib_blocked", gravity=0.0)
    fuselage = doc["bodies"]["fuselage"]
    fuselage["mass"] *= 1e4
    fuselage["inertia"] = [v * 1e4 for v in fuselage["inertia"]]
    doc["joints"]["attach_pumping"]["spring"]["preload"] = 0.0
    for i in range(1, 5):
        bar = doc["bodies"][f"bar_{i}"]
        bar["mass"] *= 1e-3
        bar["inertia"] = [v * 1e-3 for v in bar["inertia"]]
        doc["joints"][f"hinge_{i}"]["spring"].update(c=0.0, preload=0.0)
    path = tmp_path / "sarib_blocked.yaml"
    path.write_text(yaml.safe_dump(doc))
    model = load.load(path)
    beater, hinge = model.bodies["beater_1"], model.joints["hinge_1"]
    e_r = np.array(beater.frame)[:, 0]                          # the beater's arm, radial
    arm = np.array(beater.com) - np.array(hinge.at)
    assert np.allclose(arm, arm @ e_r * e_r)                    # G level with the hinge
    d = arm @ e_r                                               # hinge -> G
    lever = d + beater.points["B_1"][0]                         # hinge -> B, along e_r
    i_o = beater.inertia[1] + beater.mass * d ** 2              # about the hinge axis e_t
    k = hinge.functional["rx"].k
    f_z = np.sqrt(k / (i_o - lever * beater.mass * d)) / (2 * np.pi)
    f_x = np.sqrt(k / i_o) / (2 * np.pi)
    assert (f_z, f_x) == (pytest.approx(17.964, abs=1e-3), pytest.approx(16.664, abs=1e-3))
    lin = frf.linearize(compiled(path, "zcp"), model, "pumping")
    anti = anti_resonances(lin, ("F_A1_z", "F_A1_x"), 15.0, 20.0)
    assert anti["F_A1_z"] == [pytest.approx(f_z, abs=5e-4)]
    assert anti["F_A1_x"] == [pytest.approx(f_x, abs=5e-4)]


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
