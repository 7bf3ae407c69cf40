"""Method zcp and --parasitic auto (issue 4).

zcp: the tree joints' blocked directions are ideal flow sources (derivative causality on
the velocity components they fix), kinematic loops (class-4 ZCPs) are opened with break
variables. It must agree with lagrange (both have ideal joints) and, within the parasitic
modelling error, with parasitic."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import ANDREWS_REF, MODELS, REFERENCE_SOLVERS, fd_jacobian, rel_err, slider_closure

from bgc.cli import main
from bgc.codegen.emit import import_module
from bgc.errors import SimulationError
from bgc.methods import parasitic
from bgc.pipeline import compile_model, ensure_module
from bgc.simulate import simulate


def _check(model, *extra):
    res = CliRunner().invoke(main, ["check", str(MODELS / f"{model}.yaml"), "--method",
                                    "zcp", "--json", *extra])
    return res, (json.loads(res.output) if res.exit_code == 0 else None)


def _rank_params(mod, run):
    p = mod.PARAMS.copy()
    p[list(mod.PARAM_NAMES).index("lagrange__rank")] = run.projection.rank
    return p


# the slider-crank's tree joints (class 1) and opened loop (class 4) in make test; the
# pendulum's single tree joint, a module no other fast test compiles, in make test-all
@pytest.mark.parametrize("name", [pytest.param("pendulum", marks=pytest.mark.slow),
                                  "slider_crank"])
def test_zcp_jacobian_matches_finite_differences(compiled, name):
    mod = compiled(name, "zcp")
    run = simulate(mod, t_end=0.2, rtol=1e-8, atol=1e-10, points=5)
    p = _rank_params(mod, run)
    rng = np.random.default_rng(5)
    for x0 in run.x[1:]:
        x = x0 + 1e-4 * rng.uniform(-1, 1, len(x0)) * np.maximum(np.abs(x0), 1e-2)
        J = mod.jac(0.1, x, p)
        fd = fd_jacobian(mod, 0.1, x, p)
        assert np.abs(J - fd).max() / np.abs(fd).max() < 1e-5   # measured 2e-7 at most


@pytest.mark.slow       # 9 s: zcp against lagrange stays in the four-bar and screw tests
def test_open_chain_needs_no_loop_opening_and_matches_lagrange(compiled):
    res, rep = _check("double_pendulum")
    assert res.exit_code == 0, res.output
    classes = sorted(z["class"] for z in rep["zcp_paths"])
    assert classes == [1, 1]                        # one per joint, no class 4
    shoulder = next(z for z in rep["zcp_paths"] if "'shoulder'" in z["what"])
    assert "rod1__m" in shoulder["elements"] and shoulder["lines"] and shoulder["bonds"]
    assert rep["storage"]["rod1__J"].startswith("derivative (y, z")
    # the 4 degrees of freedom (revolute + spherical) are the only momenta integrated
    momenta = [s for s in rep["states"] if ".p" in s]
    assert momenta == ["rod1.J.px", "rod2.J.px", "rod2.J.py", "rod2.J.pz"]
    kw = dict(t_end=2.0, rtol=1e-9, atol=1e-11, solver="radau")
    z = simulate(compiled("double_pendulum", "zcp"), **kw)
    lag = simulate(compiled("double_pendulum", "lagrange"), **kw)
    par = simulate(compiled("double_pendulum"), **kw)
    assert np.abs(z.column("y2") - lag.column("y2")).max() < 1e-8     # measured 1.6e-11
    assert 1e-7 < np.abs(par.column("y2") - z.column("y2")).max() < 3e-4  # 5.9e-5
    e = z.column("energy")
    assert np.abs(e - e[0]).max() < 1e-7 * abs(e[0])
    assert z.stats.drift_position < 1e-9 and z.stats.drift_velocity < 1e-8
    assert z.stats.steps < lag.stats.steps < par.stats.steps


@pytest.mark.parametrize("solver", REFERENCE_SOLVERS)
def test_slider_crank_loop_is_opened_with_break_variables(compiled, solver):
    res, rep = _check("slider_crank")
    assert res.exit_code == 0, res.output
    (loop,) = [z for z in rep["zcp_paths"] if z["class"] == 4]
    assert "closed by 'wrist_pin'" in loop["what"] and "wrist_pin.tx.break" in loop["what"]
    assert {33, 34, 35, 36} <= set(loop["lines"])        # the four joints' lines
    assert sum(z["class"] == 1 for z in rep["zcp_paths"]) == 3
    kw = dict(t_end=1.0, rtol=1e-9, atol=1e-11, solver=solver)
    z = simulate(compiled("slider_crank", "zcp"), **kw)
    lag = simulate(compiled("slider_crank", "lagrange"), **kw)
    assert np.abs(z.column("slider_x") - lag.column("slider_x")).max() < 1e-8  # 1.5e-10
    err, th = slider_closure(z)
    assert np.unwrap(th)[-1] - th[0] > 2 * np.pi and err < 1e-8
    # 15 flow sources + 5 break variables, the planar loop's 3 redundant among the latter
    assert (z.projection.n_constraints, z.projection.rank) == (20, 17)
    assert z.projection.redundant and all(n.startswith("wrist_pin.")
                                          for n in z.projection.redundant)
    assert len(z.state_names) == 21 and len(lag.state_names) == 36


def test_scalar_zero_order_causal_paths_are_classified():
    _, rep = _check("rr_loop")
    assert [z["class"] for z in rep["zcp_paths"]] == [2]
    assert {"r1", "r2", "r3"} <= set(rep["zcp_paths"][0]["elements"])
    _, rep = _check("geared_inertias")
    (z,) = rep["zcp_paths"]
    assert z["class"] == 1 and "J_l" in z["what"] and z["bonds"]


@pytest.mark.slow       # index-2 DAEs under native Radau stay in make test (test_native_closed_forms)
def test_class4_loop_kept_closed_is_an_index2_dae_for_native_radau_only(compiled, tmp_path):
    """--keep-loops: the four-bar's loop-closing joint keeps its break variables as
    algebraic states (0 = dg/dt + alpha g), an index-2 DAE. Native Radau (index-2 error
    scaling) matches the opened loops; a solver that does not take index 2 is refused
    naming the loop, and, let through, fails (IDA at t = 0; Radau without the scaling
    takes three times the steps); nothing is written. A planar loop in 3D (the slider-crank) repeats its
    constraints: refused, naming the dependent ones."""
    _, rep = _check("four_bar", "--keep-loops")
    (loop,) = [z for z in rep["zcp_paths"] if z["class"] == 4]
    assert "kept closed, an index-2 DAE" in loop["what"] and "ball_B.tx.lambda" in loop["what"]
    out = tmp_path / "r.csv"
    res = CliRunner().invoke(main, ["simulate", str(MODELS / "four_bar.yaml"), "--method",
                                    "zcp", "--keep-loops", "--solver", "bdf", "-o",
                                    str(tmp_path), "--out", str(out)])
    assert res.exit_code == 2 and "Traceback" not in res.output
    assert "index-2 DAE" in res.output and "'ball_B'" in res.output
    assert "--solver native" in res.output and not out.exists()
    closed, _, _ = ensure_module(MODELS / "four_bar.yaml", tmp_path, "zcp", open_loops=False)
    opened = compiled("four_bar", "zcp")
    assert list(closed.ALGEBRAIC) and not list(opened.ALGEBRAIC)
    ref = simulate(opened, t_end=0.5, rtol=1e-10, atol=1e-12, solver="native", points=51)
    dae = simulate(closed, t_end=0.5, rtol=1e-8, atol=1e-10, solver="native", points=51)
    assert rel_err(dae.column("rocker_angle"), ref.column("rocker_angle")) < 1e-6
    with pytest.raises(SimulationError, match="index 1 at most"):
        simulate(closed, t_end=0.5, solver="ida")
    with pytest.raises(SimulationError, match="ida failed at t = 0"):
        simulate(closed, t_end=0.5, solver="ida", check_index=False)
    # without the index-2 error scaling Radau's error estimate of the break variables is
    # an order too large: it gets there (the loop keeps its state across pauses; when
    # every pause restarted it, from a fresh step estimate, it collapsed) in 3x the steps
    scaled = simulate(closed, t_end=0.5, rtol=1e-6, atol=1e-8, solver="native", points=51)
    plain = simulate(closed, t_end=0.5, rtol=1e-6, atol=1e-8, solver="native",
                     check_index=False, points=51)
    assert plain.stats.steps > 2 * scaled.stats.steps
    assert rel_err(plain.column("rocker_angle"), ref.column("rocker_angle")) < 1e-6
    sc, _, _ = ensure_module(MODELS / "slider_crank.yaml", tmp_path, "zcp", open_loops=False)
    with pytest.raises(SimulationError, match="5 algebraic equations of rank 2") as err:
        simulate(sc, t_end=0.5, solver="native")
    assert "wrist_pin" in str(err.value) and "drop --keep-loops" in err.value.hint


_SPRUNG = """\
name: sprung
gravity: 0
bodies:
  block: {mass: 2.0, com: [0, 0, 0], inertia: [0.01, 0.02, 0.03], velocity: [0.1, 0, 0]}
joints:
  rail: {type: prismatic, between: [fixed_frame, block], at: [0, 0, 0], axis: [1, 0, 0],
         spring: {k: 200.0}}
outputs:
  x: block.x
  gap: rail.gap
simulation: {t_end: 1.0}
"""


def test_parasitic_auto_separates_the_frequencies_and_reports_the_ratio(tmp_path):
    path = tmp_path / "sprung.yaml"
    path.write_text(_SPRUNG)
    c, mod_path = compile_model(path, tmp_path)
    mod = import_module(mod_path)
    names = list(mod.PARAM_NAMES)
    soft = _soft(mod)
    p, choice = parasitic.auto(mod, c.model, mod.X0, soft, separation=30.0)
    # the functional mode is the block on its spring, sqrt(k/m) = 10 rad/s
    assert choice.functional_hz == pytest.approx(10 / (2 * np.pi), rel=1e-3)
    assert not choice.kept
    k = p[names.index("rail__stiffness")]
    assert k == pytest.approx((30 * 10) ** 2 * 2.0, rel=1e-3)     # m_eff = the mass
    assert p[names.index("rail__damping")] == pytest.approx(2 * np.sqrt(k * 2.0), rel=1e-6)
    assert choice.stiffness_ratio == pytest.approx(k / 200.0, rel=1e-9)   # 900
    assert choice.parasitic_hz["rail"] == pytest.approx(300 / (2 * np.pi), rel=1e-3)
    # the chosen parasitic modes are where they were asked to be
    lam = np.linalg.eigvals(mod.jac(0.0, mod.X0, p))
    assert np.abs(lam).max() > 0.5 * 300
    # never softer than the model's joints: the default 1e7 N/m is stiffer than the
    # 1.8e5 the separation asks, so it stays, with its damping, and the report says so
    # (the rotational one too)
    given = np.array(mod.PARAMS)
    p, choice = parasitic.auto(mod, c.model, mod.X0, given, separation=30.0)
    for role in ("stiffness", "damping"):
        i = names.index(f"rail__{role}")
        assert p[i] == given[i]
    assert "rail__stiffness" in choice.kept and "kept as given" in choice.describe()
    assert choice.parasitic_hz["rail"] > 300 / (2 * np.pi)    # above the separation asked


def _soft(mod) -> np.ndarray:
    """The module's parameters with every joint's parasitic stiffness at 1 (N/m, N m/rad):
    softer than any choice of ``parasitic.auto``, so that it decides them all."""
    p = np.array(mod.PARAMS)
    for i, n in enumerate(mod.PARAM_NAMES):
        if n.endswith("__stiffness") or n.endswith("__rot_stiffness"):
            p[i] = 1.0
    return p


@pytest.mark.slow       # five runs; parasitic auto itself stays in make test
def test_parasitic_auto_error_falls_with_the_separation(compiled, gen_dir):
    ref = simulate(compiled("double_pendulum", "zcp"), t_end=2.0, rtol=1e-9, atol=1e-11,
                   solver="radau")
    mod = compiled("double_pendulum")
    from bgc.model import load
    model = load.load(MODELS / "double_pendulum.yaml")
    errs = []
    for sep in (100.0, 1000.0):
        p, choice = parasitic.auto(mod, model, mod.X0, _soft(mod), sep)
        assert set(choice.parasitic_hz) == {"shoulder", "elbow"}
        r = simulate(mod, t_end=2.0, rtol=1e-9, atol=1e-11, solver="radau", params=p)
        errs.append(np.abs(r.column("y2") - ref.column("y2")).max())
    # measured 7.2e-3 and 6.7e-5 m: about 1/sep^2, i.e. 1/k
    assert errs[1] < 2e-4 and errs[0] / errs[1] > 30, errs
    res = CliRunner().invoke(main, ["simulate", str(MODELS / "double_pendulum.yaml"),
                                    "--parasitic", "auto", "--separation", "1000",
                                    "--t-end", "0.1", "-o", str(gen_dir), "--json"])
    assert res.exit_code == 0, res.output
    rep = json.loads(res.output)["parasitic"]
    assert rep["separation"] == 1000 and "elbow__stiffness" in rep["values"]
    res = CliRunner().invoke(main, ["simulate", str(MODELS / "double_pendulum.yaml"),
                                    "--parasitic", "auto", "--method", "lagrange",
                                    "-o", str(gen_dir)])
    assert res.exit_code == 2 and "--parasitic auto applies to --method parasitic" in \
        res.output


@pytest.mark.slow      # numba's cold compile of Andrews under zcp takes about 4 minutes
def test_andrews_under_zcp_matches_the_published_reference(gen_dir, tmp_path, compiled):
    """Andrews' squeezer (two kinematic loops, opened by break variables) against the IVP
    test set's reference at t = 0.03: measured 2e-9 .. 9.1e-7 relative (6 digits)."""
    import csv

    compiled("andrews", "zcp")
    out = tmp_path / "F.csv"
    res = CliRunner().invoke(main, ["simulate", str(MODELS / "andrews.yaml"), "--method",
                                    "zcp", "--t-end", "0.03", "--rtol", "1e-10", "--atol",
                                    "1e-10", "--out", str(out), "-o", str(gen_dir)])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(out.open()))
    for name, ref in ANDREWS_REF.items():
        assert abs(float(rows[-1][name]) - ref) <= 1e-6 * abs(ref), name
