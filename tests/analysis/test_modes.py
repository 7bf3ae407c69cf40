"""bgc modes against independent eigen-analyses: a damped two-mass absorber (its M, C, K
written out by hand) and a damped compound pendulum (sqrt(m g d / I_O)); the constraint
subspace (no mode from a multiplier or a Baumgarte term), the parasitic modes marked, and
every resonance bgc frf finds on a mode. The SARIB's modes: test_modes_sarib (slow)."""

from __future__ import annotations

import json

import numpy as np
import pytest
import yaml
from click.testing import CliRunner
from helpers import TUTORIAL_MODEL

from bgc.cli import main

# the tutorial's absorber (docs/tutorial/absorber.yaml): a cabin on its suspension along
# z (the library's spring_damper) and a tuned mass on its spring above it (tuned_mass)
TUTORIAL = yaml.safe_load(TUTORIAL_MODEL.read_text())
M1 = TUTORIAL["bodies"]["cabin"]["mass"]
K1, C1 = (TUTORIAL["instances"]["mount"]["parameters"][k] for k in ("k", "c"))
M2 = TUTORIAL["parameters"]["m_t"]["value"]
K2 = TUTORIAL["parameters"]["k_t"]["value"]
C2 = TUTORIAL["instances"]["absorber"]["parameters"]["c"]

M, D, I_G, C_H = 2.0, 0.5, 0.2, 0.05     # rod mass, hinge to G, inertia about G, damper
PENDULUM = f"""
name: hanging
description: a rod hanging at rest from a damped hinge
gravity: 9.81
parasitic: {{loads: static}}
bodies:
  rod:
    mass: {M}
    com: [0, 0, {-D}]
    frame: {{x: [0, 1, 0], y: [0, 0, 1], z: [1, 0, 0]}}
    inertia: [{I_G}, {I_G}, 0.01]
    points: {{tip: [0, 0, -1.0]}}
joints:
  hinge: {{type: revolute, between: [fixed_frame, rod], at: [0, 0, 0], axis: [0, 1, 0],
          spring: {{k: 0.0, c: {C_H}}}}}
outputs:
  x_tip: {{expr: rod.tip.x, unit: m}}
"""


def reference_absorber() -> list[tuple[float, float]]:
    """(natural frequency [Hz], damping ratio) of the two-mass system from its M, C, K:
    the eigenvalues of [[0, I], [-M^-1 K, -M^-1 C]], by numpy, not bgc."""
    Mm = np.diag([M1, M2])
    K = np.array([[K1 + K2, -K2], [-K2, K2]])
    C = np.array([[C1 + C2, -C2], [-C2, C2]])
    A = np.block([[np.zeros((2, 2)), np.eye(2)],
                  [-np.linalg.solve(Mm, K), -np.linalg.solve(Mm, C)]])
    lam = [z for z in np.linalg.eigvals(A) if z.imag > 0]
    return sorted((abs(z) / (2 * np.pi), -z.real / abs(z)) for z in lam)


def modes_json(path, *args):
    r = CliRunner().invoke(main, ["modes", str(path), "--json", "-q", *args])
    assert r.exit_code == 0, r.output
    return json.loads(r.output)


@pytest.mark.parametrize("method", ["parasitic", pytest.param("lagrange", marks=pytest.mark.slow),
                                    pytest.param("zcp", marks=pytest.mark.slow)])
def test_absorber_modes_are_the_hand_written_systems(compiled, gen_dir, method):
    """Two functional modes at the M, C, K system's natural frequencies and damping
    ratios (1e-6 for the ideal joints; parasitic's compliant joints move them by their
    compliance), each carried by the mass it is named after; lagrange and zcp show no
    other mode (no multiplier, no Baumgarte term), parasitic's others are all parasitic,
    far above."""
    compiled(TUTORIAL_MODEL, method)
    rep = modes_json(TUTORIAL_MODEL, "--method", method, "-o", str(gen_dir))
    functional = [m for m in rep["modes"] if m["kind"] == "functional"]
    ref = reference_absorber()
    tol = 1e-6 if method != "parasitic" else 1e-3
    assert len(functional) == 2
    for m, (f, z) in zip(functional, ref):
        assert m["frequency_hz"] == pytest.approx(f, rel=tol)
        assert m["damping_ratio"] == pytest.approx(z, rel=10 * tol)
    # the lower mode is the absorber's (the tuned mass moves most), the upper the main's
    assert [m["bodies"][0]["name"] for m in functional] == ["cabin", "absorber.mass"]
    assert functional[1]["bodies"][0]["share"] > 0.5
    assert set(functional[0]["shape"]) == {"cabin", "absorber.mass"}
    if method == "parasitic":
        others = [m for m in rep["modes"] if m["kind"] != "functional"]
        assert others and all(m["kind"] == "parasitic" for m in others)
        assert min(m["frequency_hz"] for m in others) > 2 * ref[-1][0]
    else:
        assert len(rep["modes"]) == 2 and rep["subspace"] < rep["states"]
        assert rep["invariance"] < 1e-8


def test_every_resonance_of_bgc_frf_lies_on_a_mode(compiled, gen_dir):
    """Each peak of |H| is attributed to its mode: the resonances bgc frf reports are
    natural frequencies of bgc modes to 0.01 Hz, for a displacement and an acceleration
    alike. The peaks themselves sit where damping and the zeros put them, apart for the
    two outputs and up to 0.14 Hz off the modes (the suspension's 11 % damping, the
    anti-resonance beside the upper mode): the same structure, two sets of peaks, one
    set of resonances."""
    compiled(TUTORIAL_MODEL)
    d = str(gen_dir)
    modes = [m["frequency_hz"] for m in modes_json(TUTORIAL_MODEL, "-o", d)["modes"]
             if m["kind"] == "functional"]
    peaks, res = {}, {}
    for out in ("x_tuned", "a_cabin"):
        r = CliRunner().invoke(main, ["frf", str(TUTORIAL_MODEL), "--input", "rotor",
                                      "--output", out, "--f-min", "2", "--f-max", "30",
                                      "--json", "-q", "-o", d])
        assert r.exit_code == 0, r.output
        rep = json.loads(r.output)
        assert len(rep["resonances_hz"]) == 2
        for f in rep["resonances_hz"]:
            assert min(abs(f - m) for m in modes) <= 0.01
        peaks[out], res[out] = rep["peaks_hz"], rep["resonances_hz"]
    assert res["x_tuned"] == res["a_cabin"] and peaks["x_tuned"] != peaks["a_cabin"]
    assert max(abs(a - b) for p in peaks.values() for a, b in zip(p, modes)) > 0.1


@pytest.mark.parametrize("method", [pytest.param("parasitic", marks=pytest.mark.slow), "zcp"])
def test_pendulum_mode_is_sqrt_mgd_over_io(tmp_path, method):
    """A compound pendulum hanging at rest: one functional mode at sqrt(m g d / I_O)
    with damping ratio c / (2 sqrt(m g d I_O)), the rod carrying all of it; the other
    four directions of the hinge are ideal (zcp) or parasitic modes (parasitic)."""
    (tmp_path / "hanging.yaml").write_text(PENDULUM)
    rep = modes_json(tmp_path / "hanging.yaml", "--method", method, "-o", str(tmp_path))
    io = I_G + M * D ** 2
    k = M * 9.81 * D
    [m] = [m for m in rep["modes"] if m["kind"] == "functional"]
    assert m["frequency_hz"] == pytest.approx(np.sqrt(k / io) / (2 * np.pi), rel=1e-5)
    assert m["damping_ratio"] == pytest.approx(C_H / (2 * np.sqrt(k * io)), rel=1e-4)
    assert m["bodies"] == [{"name": "rod", "share": 1.0}]
    # the shape turns the rod about the hinge (body x): its angle ax, G moving along x
    shape = m["shape"]["rod"]
    assert abs(complex(*shape["ax"])) > 0 and abs(complex(*shape["ay"])) < 1e-6
    assert complex(*shape["x"]) == pytest.approx(-D * complex(*shape["ax"]), rel=1e-4)
    kinds = {x["kind"] for x in rep["modes"]}
    assert kinds == ({"functional", "parasitic"} if method == "parasitic"
                     else {"functional"})


def test_a_state_not_at_rest_is_refused_in_one_line(compiled, gen_dir):
    """A preload the suspension's start does not hold: no equilibrium to linearize."""
    compiled(TUTORIAL_MODEL)
    r = CliRunner().invoke(main, ["modes", str(TUTORIAL_MODEL), "-p", "mount.preload=50",
                                  "-q", "-o", str(gen_dir)])
    assert r.exit_code == 2
    assert "not a static equilibrium" in r.output and "Traceback" not in r.output


@pytest.mark.slow
def test_sarib_modes_agree_across_methods_and_carry_its_resonances(compiled, gen_dir):
    """The SARIB about its static equilibrium: lagrange and zcp give the same functional
    modes in their constraint subspaces (1e-4 Hz), parasitic the same within its joints'
    compliance (0.3 %: 0.05 Hz on the 16.7 Hz mode) plus its parasitic modes; the
    pumping mode is carried by the four beaters alike; every resonance bgc frf finds
    under pumping is one of them to 0.01 Hz, while the peak of a_OF_z sits 0.09 Hz below
    it (the anti-resonance beside it)."""
    from helpers import MODELS
    reps = {}
    for method in ("zcp", "lagrange", "parasitic"):
        compiled("sarib", method)
        reps[method] = modes_json(MODELS / "sarib.yaml", "--method", method, "--f-max", "25",
                                  "-o", str(gen_dir))
    func = {k: [m for m in r["modes"] if m["kind"] == "functional"] for k, r in reps.items()}
    f = {k: np.array([m["frequency_hz"] for m in v]) for k, v in func.items()}
    assert len(f["zcp"]) == len(f["lagrange"]) == len(f["parasitic"]) == 6
    assert np.abs(f["zcp"] - f["lagrange"]).max() < 1e-4
    assert np.abs(f["zcp"] / f["parasitic"] - 1).max() < 4e-3
    assert [m["kind"] for m in reps["parasitic"]["modes"]].count("parasitic") >= 1
    pumping = min(func["zcp"], key=lambda m: abs(m["frequency_hz"] - 16.2))
    top = pumping["bodies"][:4]
    assert all("beater" in b["name"] for b in top)
    assert max(b["share"] for b in top) - min(b["share"] for b in top) < 1e-3
    for out in ("a_OF_z", "F_A1_z"):
        r = CliRunner().invoke(main, ["frf", str(MODELS / "sarib.yaml"), "--method", "zcp",
                                      "--input", "pumping", "--output", out, "--json", "-q",
                                      "-o", str(gen_dir)])
        rep = json.loads(r.output)
        assert rep["resonances_hz"]
        for fr in rep["resonances_hz"]:
            assert np.abs(f["zcp"] - fr).min() <= 0.01
        assert pumping["frequency_hz"] == pytest.approx(rep["resonances_hz"][-1], abs=0.01)
        if out == "a_OF_z":
            assert 0.05 < pumping["frequency_hz"] - rep["peaks_hz"][-1] < 0.15


def test_the_constraint_basis_ignores_the_differences_round_off():
    """A state no constraint reads, whose column of the constraints' Jacobian holds only
    round-off (1e-17, as exactly rotated frames give), stays in the subspace untouched:
    equilibration scaled such a column by 1e16 and bent the basis off the constraints
    (the SARIB as an assembly: spurious modes at 0 Hz, its modes 0.1 Hz off)."""
    from bgc.analysis.modes import constraint_basis

    class Module:
        CONSTRAINT_NAMES = ("a", "b")

        @staticmethod
        def constraints(t, x, p):     # x0 - x1 and x1 + 2 x2; x3 read only by round-off
            return np.array([x[0] - x[1], x[1] + 2.0 * x[2] + 1e-17 * np.sin(1e3 * x[3])])

    x = np.array([0.1, 0.1, -0.05, 0.3])
    Q, rank = constraint_basis(Module, x, np.zeros(0))
    assert rank == 2 and Q.shape == (4, 2)
    J = np.array([[1.0, -1.0, 0.0, 0.0], [0.0, 1.0, 2.0, 0.0]])
    assert np.abs(J @ Q).max() < 1e-12                      # on the constraints
    assert abs(abs(Q[3]).max() - 1.0) < 1e-12               # x3 free: one of its directions
