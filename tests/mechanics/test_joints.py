"""Joints closed with parasitic elements, against closed forms and invariants: a revolute
pendulum's period, a heavy top's precession, a 3D double pendulum's energy, a body of
negligible mass between two revolutes against a universal joint, and for every joint
kind a constraint violation that falls as the parasitic stiffness grows."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import REFERENCE_SOLVERS, fd_jacobian
from scipy.special import ellipk

from bgc.codegen.emit import import_module
from bgc.errors import ModelError
from bgc.mechanics.joints import JOINT_KINDS, NEEDS_AXIS2
from bgc.model.load import loads
from bgc.pipeline import compile_model
from bgc.simulate import simulate


def crossings(t, x):
    """Times where x crosses zero upwards (linear interpolation)."""
    i = np.where((x[:-1] < 0) & (x[1:] >= 0))[0]
    return t[i] - x[i] * (t[i + 1] - t[i]) / (x[i + 1] - x[i])


@pytest.mark.parametrize("solver", REFERENCE_SOLVERS)
def test_revolute_pendulum_period_energy_and_hinge_force(compiled, solver):
    mod = compiled("pendulum")
    r = simulate(mod, t_end=4.0, rtol=1e-9, atol=1e-11, solver=solver, points=4001)
    m, d, g, theta0 = 2.0, 0.5, 9.81, np.radians(2.0)
    I_O = 0.2 + m * d ** 2
    # exact period of the (finite-amplitude) physical pendulum; 2 pi sqrt(I/(m g d)) for
    # small amplitude, 2 deg changes it by 8e-5
    T = 4 * np.sqrt(I_O / (m * g * d)) * ellipk(np.sin(theta0 / 2) ** 2)
    periods = np.diff(crossings(r.t, r.column("x")))
    assert len(periods) >= 1
    assert np.abs(periods / T - 1).max() < 1e-5
    assert abs(T / (2 * np.pi * np.sqrt(I_O / (m * g * d))) - 1) < 1e-4
    E = r.column("energy")
    assert np.abs(E - E[0]).max() < 1e-5 * m * g * d * 2     # what parasitic damping takes
    assert r.column("gap").max() < 1e-5                        # m g / k with k = 1e7
    # the hinge carries the weight (plus the small centripetal part) upwards
    Fz = r.column("force_z")[r.t > 0.1]
    assert abs(Fz.mean() / (m * g) - 1) < 2e-3
    # the tip's acceleration output is the derivative of its velocity output (after the
    # parasitic springs' first 0.1 s of settling under the load)
    v, a = r.column("tip_vx"), r.column("tip_accx")
    late = (r.t > 0.1) & (r.t < r.t[-1] - 0.01)
    assert np.abs(np.gradient(v, r.t) - a)[late].max() < 5e-3 * np.abs(a[late]).max()


@pytest.mark.slow       # the spherical pendulum stays in make test
def test_heavy_top_precesses_at_the_closed_form_rate(compiled):
    mod = compiled("heavy_top")
    r = simulate(mod, t_end=3.0, rtol=1e-9, atol=1e-11, solver="radau")
    azimuth = np.unwrap(np.arctan2(r.column("y"), r.column("x")))
    rate = np.polyfit(r.t, azimuth, 1)[0]
    I1, I3, m, g, d, th, w3 = 0.02 + 0.01, 0.04, 1.0, 9.81, 0.1, np.radians(30), 60.0
    a, b, c = I1 * np.cos(th), -I3 * w3, m * g * d
    omega = (-b - np.sqrt(b * b - 4 * a * c)) / (2 * a)      # slow steady precession
    assert abs(rate / omega - 1) < 1e-5
    z = r.column("z")
    assert z.max() - z.min() < 1e-5                           # no nutation to speak of
    assert r.column("gap").max() < 1e-5


@pytest.mark.slow       # the spherical pendulum and the revolute one stay in make test
def test_3d_double_pendulum_conserves_energy(compiled):
    mod = compiled("double_pendulum")
    r = simulate(mod, t_end=2.0, rtol=1e-9, atol=1e-11, solver="radau")
    E = r.column("energy")
    assert np.abs(E - E[0]).max() < 5e-5 * abs(E[0])
    y2 = r.column("y2")
    assert y2.max() - y2.min() > 0.1                          # it moves out of the plane
    assert r.column("gap").max() < 1e-5


SPHERICAL_PENDULUM = """
name: spherical_pendulum
gravity: 9.81
bodies:
  bob:        # a small ball (isotropic inertia) 0.6 m from the pivot, 40 deg out, moving sideways
    mass: 1.5
    com: [0.3856725658, 0.0, -0.4596266659]
    inertia: [0.01, 0.01, 0.01]
    velocity: [0.0, 1.2, 0.0]
    omega: [1.5320888862, 0.0, 1.2855752194]      # v_G = omega x r_G: the pivot stays put
joints:
  pivot: {type: spherical, between: [fixed_frame, bob], at: [0, 0, 0]}
outputs:
  z: bob.z
  gap: pivot.gap
  energy: "0.5 * 1.5 * (bob.vx**2 + bob.vy**2 + bob.vz**2) + 0.5 * 0.01 * (bob.wx**2 + bob.wy**2 + bob.wz**2) + 1.5 * 9.81 * bob.z"
  Lz: "1.5 * (bob.x * bob.vy - bob.y * bob.vx) + 0.01 * bob.wz_R0"
"""


@pytest.mark.parametrize("solver", REFERENCE_SOLVERS)
def test_spherical_pendulum_conserves_energy_and_vertical_angular_momentum(tmp_path, solver):
    """Gravity and the pivot force have no moment about the vertical through the pivot, so
    L_z is conserved; with no functional damping, so is the energy (up to what the
    parasitic dampers dissipate)."""
    f = tmp_path / "spherical_pendulum.yaml"
    f.write_text(SPHERICAL_PENDULUM)
    _, path = compile_model(f, tmp_path / "gen")
    r = simulate(import_module(path), t_end=3.0, rtol=1e-9, atol=1e-11, solver=solver)
    E, Lz = r.column("energy"), r.column("Lz")
    assert abs(Lz[0] - 1.5 * 0.3856725658 * 1.2 - 0.01 * 1.2855752194) < 1e-9
    # the pivot load (~15 N) deflects the parasitic spring by F/k: F^2/(2k) ~ 1e-5 J
    assert np.abs(E - E[0]).max() < 1e-5 * abs(E[0]), np.abs(E - E[0]).max() / abs(E[0])
    assert np.abs(Lz - Lz[0]).max() < 1e-6 * abs(Lz[0]), np.abs(Lz - Lz[0]).max() / Lz[0]
    z = r.column("z")
    assert z.max() - z.min() > 0.05                          # it nutates, not a cone
    assert r.column("gap").max() < 1e-5


CHAIN = """
name: {name}
gravity: 9.81
bodies:
{massless}  rod:
    mass: 2.0
    com: [0.1, 0.05, -0.5]
    inertia: [0.2, 0.2, 0.01]
joints:
{joints}
outputs:
  x: rod.x
  y: rod.y
  z: rod.z
"""


@pytest.mark.parametrize("solver", REFERENCE_SOLVERS)
def test_body_of_negligible_mass_between_two_revolutes_is_a_universal_joint(tmp_path, solver):
    """Int1 (mass 0) between a revolute about x and a revolute about y behaves as a
    universal joint: its twist is solved from the balance of its joints' forces. (The
    chain's rod and the universal joint's, side by side in one model: one module.)"""
    rod = CHAIN.split("  rod:\n", 1)[1].split("joints:")[0]
    f = tmp_path / "chain_univ.yaml"
    f.write_text(f"""
name: chain_univ
gravity: 9.81
bodies:
  int1: {{mass: 0, com: [0, 0, 0]}}
  rod:
{rod}  rod_u:
{rod}joints:
  j1: {{type: revolute, between: [fixed_frame, int1], at: [0, 0, 0], axis: [1, 0, 0]}}
  j2: {{type: revolute, between: [int1, rod], at: [0, 0, 0], axis: [0, 1, 0]}}
  u: {{type: universal, between: [fixed_frame, rod_u], at: [0, 0, 0], axis: [1, 0, 0],
      axis2: [0, 1, 0]}}
outputs: {{x: rod.x, y: rod.y, x_u: rod_u.x, y_u: rod_u.y}}
""")
    c, path = compile_model(f, tmp_path / "gen")
    assert any(loop.kind == "negligible-mass" for loop in c.system.loops)
    assert not any(st.element.startswith("int1__") and ".p" in st.name
                   for st in c.system.states)      # no made-up inertia
    r = simulate(import_module(path), t_end=1.5, rtol=1e-9, atol=1e-11, solver=solver)
    swing = np.ptp(r.column("x_u"))
    assert swing > 0.15                                       # it swings through -0.1..0.1
    for out in ("x", "y"):
        assert np.abs(r.column(out) - r.column(f"{out}_u")).max() < 1e-4 * swing


@pytest.mark.slow       # the revolute pair of negligible mass stays in make test
def test_prismatic_universal_is_a_slider_and_two_revolutes_on_bodies_of_negligible_mass(
        tmp_path):
    """The SARIB's attach joint written out (paper 11.3: a slider along z, then revolutes
    about x and y, on two bodies of negligible mass) against one prismatic_universal
    joint with the same spring, damper and torsion springs on its three free directions:
    the same motion (bouncing on the slide and swinging both ways) without the two
    bodies' twelve pose states."""
    springs = ("{k: 200.0, c: 2.0}", "{k: 5.0, c: 0.1}", "{k: 3.0}")
    runs, states = {}, {}
    for name, massless, joints in (
            ("chain", "  s1: {mass: 0, com: [0, 0, 0]}\n  s2: {mass: 0, com: [0, 0, 0]}\n",
             f"  slide: {{type: prismatic, between: [fixed_frame, s1], at: [0, 0, 0], "
             f"axis: [0, 0, 1], spring: {springs[0]}}}\n"
             f"  r1: {{type: revolute, between: [s1, s2], at: [0, 0, 0], axis: [1, 0, 0], "
             f"spring: {springs[1]}}}\n"
             f"  r2: {{type: revolute, between: [s2, rod], at: [0, 0, 0], axis: [0, 1, 0], "
             f"spring: {springs[2]}}}"),
            ("compound", "",
             f"  pu: {{type: prismatic_universal, between: [fixed_frame, rod], "
             f"at: [0, 0, 0], axis: [1, 0, 0], axis2: [0, 1, 0], directions: "
             f"{{tz: {springs[0]}, rx: {springs[1]}, ry: {springs[2]}}}}}")):
        f = tmp_path / f"{name}.yaml"
        f.write_text(CHAIN.format(name=name, massless=massless, joints=joints))
        c, path = compile_model(f, tmp_path / "gen")
        states[name] = len(c.system.states)
        runs[name] = simulate(import_module(path), t_end=1.5, rtol=1e-9, atol=1e-11,
                              solver="native", points=301)
    assert states["chain"] - states["compound"] == 12
    a, b = runs["chain"], runs["compound"]
    for out in ("x", "y", "z"):
        swing = np.ptp(b.column(out))
        assert swing > 0.01, (out, swing)                    # it moves in every direction
        assert np.abs(a.column(out) - b.column(out)).max() < 1e-4 * swing, out


@pytest.mark.slow       # the revolute pair of negligible mass stays in make test
def test_body_of_negligible_mass_under_ideal_constraints(tmp_path):
    """The same chain under lagrange and zcp: int1's twist is a state and its rate an
    unknown of the constraint block (the saddle point [J M^-1 J^T, J_U; J_U^T, 0]); both
    ideal, so the chain matches the universal joint (lagrange) to the integration error
    (measured 1.4e-11), and the Jacobian through the saddle point matches finite
    differences."""
    runs, mods = {}, {}
    for name, method, massless, joints in (
            ("univ", "lagrange", "", "  u: {type: universal, between: [fixed_frame, rod], "
             "at: [0, 0, 0], axis: [1, 0, 0], axis2: [0, 1, 0]}"),
            ("chain", "lagrange", "  int1: {mass: 0, com: [0, 0, 0]}\n",
             "  j1: {type: revolute, between: [fixed_frame, int1], at: [0, 0, 0], "
             "axis: [1, 0, 0]}\n  j2: {type: revolute, between: [int1, rod], at: [0, 0, 0], "
             "axis: [0, 1, 0]}")):
        f = tmp_path / f"{name}.yaml"
        f.write_text(CHAIN.format(name=name, massless=massless, joints=joints))
        for m in (("lagrange", "zcp") if name == "chain" else (method,)):
            c, path = compile_model(f, tmp_path / "gen", method=m)
            mods[name, m] = import_module(path)
            runs[name, m] = simulate(mods[name, m], t_end=1.5, rtol=1e-9, atol=1e-11,
                                     solver="radau")
    b = runs["univ", "lagrange"]
    assert np.ptp(b.column("x")) > 0.15
    for method in ("lagrange", "zcp"):
        mod, run = mods["chain", method], runs["chain", method]
        assert sum(n.startswith("int1.M0") for n in mod.STATE_NAMES) == 6   # its twist
        assert run.projection.rank == 10
        for out in ("x", "y"):
            assert np.abs(run.column(out) - b.column(out)).max() < 1e-8, (method, out)
        p = mod.PARAMS.copy()
        p[list(mod.PARAM_NAMES).index("lagrange__rank")] = run.projection.rank
        rng = np.random.default_rng(5)
        for x0 in run.x[1::len(run.t) // 4]:
            x = x0 + 1e-4 * rng.uniform(-1, 1, len(x0)) * np.maximum(np.abs(x0), 1e-2)
            J, fd = mod.jac(0.7, x, p), fd_jacobian(mod, 0.7, x, p)
            assert np.abs(J - fd).max() / np.abs(fd).max() < 1e-5


def _axis_text(kind):
    extra = ", axis2: [0.7071067812, -0.7071067812, 0]" if kind in NEEDS_AXIS2 else ""
    pitch = ", pitch: 0.05" if kind == "screw" else ""
    return f"axis: [0.5773502692, 0.5773502692, 0.5773502692]{extra}{pitch}"


# every kind's Jacobian and equations are checked in make test; the convergence of one
# kind there (the revolute: translations and rotations blocked, both checked; the
# spherical joint's motion keeps its own fast test), of every kind in make test-all
@pytest.mark.parametrize("kind", [k if k == "revolute" else
                                  pytest.param(k, marks=pytest.mark.slow)
                                  for k in sorted(JOINT_KINDS)])
def test_constraint_violation_falls_as_parasitic_stiffness_grows(tmp_path, kind):
    """A body hanging from the fixed frame by one joint (tilted axis, centre of mass off
    the joint) under gravity: the blocked deflection scales like 1/k. Stiffness x10,
    damping x sqrt(10) keeps the parasitic damping ratio."""
    text = f"""
name: k_{kind}
gravity: 9.81
bodies:
  b:
    mass: 1.0
    com: [0.1, 0.05, -0.2]
    inertia: [0.02, 0.03, 0.04]
joints:
  j: {{type: {kind}, between: [fixed_frame, b], at: [0, 0, 0], {_axis_text(kind)}}}
outputs:
  gap: j.gap
  tilt: j.tilt
  x: b.x
"""
    f = tmp_path / f"k_{kind}.yaml"
    f.write_text(text)
    _, path = compile_model(f, tmp_path / "gen")
    mod = import_module(path)
    names = list(mod.PARAM_NAMES)
    worst = []
    for scale in (1.0, 10.0):
        p = np.array(mod.PARAMS, dtype=float)
        for role, factor in (("stiffness", scale), ("rot_stiffness", scale),
                             ("damping", np.sqrt(scale)), ("rot_damping", np.sqrt(scale))):
            p[names.index(f"j__{role}")] *= factor
        r = simulate(mod, t_end=0.3, rtol=1e-8, atol=1e-11, solver="radau", params=p)
        worst.append((r.column("gap").max(), r.column("tilt").max()))
    (gap1, tilt1), (gap2, tilt2) = worst
    blocked = JOINT_KINDS[kind].blocked
    if any(lab in blocked for lab in ("tx", "ty", "tz")):
        assert 0 < gap1 < 1e-4 and gap2 < gap1 / 5, (gap1, gap2)
    if any(lab in blocked for lab in ("rx", "ry", "rz")):
        assert 0 < tilt1 < 1e-3 and tilt2 < tilt1 / 5, (tilt1, tilt2)


JOINT_BASE = """name: bad
bodies:
  a: {mass: 1, com: [0, 0, 0], inertia: [1, 1, 1], points: {p: [0, 0, 1]}}
  b: {mass: 1, com: [0, 0, 2], inertia: [1, 1, 1], points: {p: [0, 0, 1]}}
joints:
  j: JOINT
"""


@pytest.mark.parametrize("joint, key, words", [
    ("{type: hinge, between: [a, b], at: [0, 0, 1]}", "joints.j.type", "unknown joint type"),
    ("{type: revolute, between: [a, c], at: [0, 0, 1]}", "joints.j.between[1]",
     "unknown body 'c'"),
    ("{type: revolute, between: [a, b], at: q}", "joints.j.at", "names no point"),
    ("{type: revolute, between: [a, b], at: p}", "joints.j.at", "several bodies"),
    ("{type: revolute, between: [a, b], at: a.p, axis: [0, 0, 0]}", "joints.j.axis",
     "zero length"),
    ("{type: universal, between: [a, b], at: [0, 0, 1], axis: [1, 0, 0]}", "joints.j",
     "needs 'axis2'"),
    ("{type: universal, between: [a, b], at: [0, 0, 1], axis: [1, 0, 0], axis2: [1, 1, 0]}",
     "joints.j.axis2", "perpendicular"),
    ("{type: spherical, between: [a, b], at: [0, 0, 1], spring: {k: 1}}", "joints.j.spring",
     "no free direction"),
    ("{type: revolute, between: [a, b], at: [0, 0, 1], directions: {tx: {k: 1}}}",
     "joints.j.directions", "not a free direction"),
    ("{type: revolute, between: [a, a], at: [0, 0, 1]}", "joints.j.between",
     "two different bodies"),
    ("{type: revolute, between: [a, b], at: [0, 0, 1], spring: {k: -5}}",
     "joints.j.spring.k", "must be >= 0"),
    ("{type: screw, between: [a, b], at: [0, 0, 1]}", "joints.j", "needs 'pitch'"),
    ("{type: revolute, between: [a, b], at: [0, 0, 1], parasitic: {stiffnes: 1}}",
     "joints.j.parasitic", "stiffnes"),
])
def test_bad_joints_are_refused_with_their_line(joint, key, words):
    with pytest.raises(ModelError) as exc:
        loads(JOINT_BASE.replace("JOINT", joint), "bad.yaml")
    msg = str(exc.value)
    assert msg.startswith("bad.yaml:") and key in msg and words in msg, msg


def test_functional_element_on_a_direction_another_joint_blocks_is_refused():
    """A revolute's spring about z in parallel with a weld of the same bodies: the weld's
    parasitic spring would take the load, so the spring means nothing. A redundant but
    consistent pair (two spherical joints on one axis = a revolute) is accepted."""
    from bgc.pipeline import build
    welded = JOINT_BASE.replace("JOINT", "{type: revolute, between: [a, b], at: [0, 0, 1], "
                                "axis: [0, 0, 1], spring: {k: 50, c: 1}}\n"
                                "  w: {type: fixed, between: [a, b], at: [0, 0, 1]}")
    with pytest.raises(ModelError) as exc:
        build(loads(welded, "bad.yaml"))
    msg = str(exc.value)
    assert msg.startswith("bad.yaml:") and "joints.j" in msg and "'w'" not in msg, msg
    assert "rx of joint 'j'" in msg and "joint w blocks" in msg, msg
    fine = JOINT_BASE.replace("JOINT", "{type: revolute, between: [a, b], at: [0, 0, 1], "
                              "axis: [0, 0, 1], spring: {k: 50}}\n"
                              "  s: {type: spherical, between: [a, b], at: [0, 0, 1]}")
    build(loads(fine, "ok.yaml"))


def test_massless_body_left_free_is_refused():
    """A body of negligible mass with no joint (no path to the fixed frame), and one
    whose joints leave a direction free without damping, cannot be solved."""
    from bgc.pipeline import build
    lonely = "name: m\nbodies:\n  int1: {mass: 0, com: [0, 0, 0]}\n"
    with pytest.raises(ModelError, match="no joint") as exc:
        build(loads(lonely, "m.yaml"))
    assert str(exc.value).startswith("m.yaml:3:")
    loose = ("name: m\ngravity: 9.81\nbodies:\n  int1: {mass: 0, com: [0, 0, 0]}\n"
             "  rod: {mass: 1, com: [0, 0, -1], inertia: [1, 1, 1]}\njoints:\n"
             "  j1: {type: spherical, between: [fixed_frame, int1], at: [0, 0, 0]}\n"
             "  j2: {type: spherical, between: [int1, rod], at: [0, 0, 0]}\n")
    with pytest.raises(ModelError, match="undetermined in 3 direction") as exc:
        build(loads(loose, "m.yaml"))
    assert "j1, j2" in str(exc.value)
