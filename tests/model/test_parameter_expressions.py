"""A joint's spring, damper and preload as expressions of the model's parameters (issue 26,
item 2): the generated code reads the expression, so ``-p`` retunes it without a
recompile, and it behaves exactly as the same numbers written out."""

from __future__ import annotations

import numpy as np
import pytest

from bgc.codegen.emit import import_module
from bgc.errors import ModelError
from bgc.model import symbols
from bgc.model.load import loads
from bgc.pipeline import compile_model
from bgc.simulate import simulate

SLIDER = """\
name: {name}
parameters:
  k_s: 400.0
  c_s: 2.0
  f0: 5.0
bodies:
  cart: {{mass: 2.0, com: [0, 0, 0], inertia: [0.1, 0.1, 0.1]}}
joints:
  rail: {{type: prismatic, between: [fixed_frame, cart], at: [0, 0, 0], axis: [1, 0, 0],
         spring: {{k: {k}, c: {c}, preload: {f}}}}}
outputs:
  x: cart.x
simulation: {{t_end: 0.5}}
"""


def _model(name="slider", k="2 * k_s", c="c_s", f="f0"):
    return loads(SLIDER.format(name=name, k=k, c=c, f=f), "slider.yaml")


def test_the_expression_is_kept_and_no_joint_parameter_made_for_it():
    m = _model()
    fun = m.joints["rail"].functional["tx"]
    P = symbols.param
    assert fun.k == 2 * P("k_s") and fun.c == P("c_s") and fun.preload == P("f0")
    assert not {"rail__tx_k", "rail__tx_c", "rail__tx_preload"} & set(m.parameters)
    lit = _model(k="800.0", c="2.0", f="5.0")       # numbers: joint parameters, as before
    assert lit.joints["rail"].functional["tx"].k == 800.0
    assert {"rail__tx_k", "rail__tx_c", "rail__tx_preload"} <= set(lit.parameters)


def step_response(t, m, k, c, f):
    """x(t) of m x'' + c x' + k x = f from rest at x = 0 (underdamped): the exact motion of
    a cart on a prismatic joint's spring, damper and preload, against which a run is
    checked (as the same model written with the numbers runs: tests/mechanics)."""
    wn, zeta = np.sqrt(k / m), c / (2 * np.sqrt(k * m))
    wd = wn * np.sqrt(1 - zeta ** 2)
    return f / k * (1 - np.exp(-zeta * wn * t) * (np.cos(wd * t)
                                                  + zeta * wn / wd * np.sin(wd * t)))


# a value -p gives (650) and the model's own (400: the number the expression takes
# unretuned, in make test-all), each against the exact motion with the numbers
@pytest.mark.parametrize("k_s", [650.0, pytest.param(400.0, marks=pytest.mark.slow)])
def test_minus_p_retunes_it_without_recompiling_and_matches_the_numbers(tmp_path, k_s):
    _, path = compile_model(_model(), tmp_path)
    mod = import_module(path)
    names = list(mod.PARAM_NAMES)
    p = mod.PARAMS.copy()
    p[names.index("k_s")] = k_s
    r = simulate(mod, t_end=0.5, rtol=1e-10, atol=1e-12, params=p, points=51)
    ref = step_response(r.t, 2.0, 2 * k_s, 2.0, 5.0)
    assert np.abs(r.column("x") - ref).max() < 1e-11       # measured 1e-13
    # it oscillates about the preload's deflection f0 / (2 k_s), at sqrt(2 k_s / m)
    assert np.mean(r.column("x")[10:]) == pytest.approx(5.0 / (2 * k_s), rel=0.2)


@pytest.mark.parametrize("k, c, f, msg", [
    ("k_s - 1000", "c_s", "f0", "k = k_s - 1000 is -600"),
    ("2 * k_s", "t", "f0", "unknown name 't'"),
    ("2 * k_s", "c_s", "x_cart", "unknown name 'x_cart'"),
    ("2 * k_s", "c_s", "1 / (k_s - 400)", "division by zero"),
])
def test_a_bad_expression_is_refused_at_its_line(k, c, f, msg):
    with pytest.raises(ModelError) as e:
        _model(k=k, c=c, f=f)
    assert e.value.loc is not None and e.value.loc.line == 10, e.value
    assert e.value.key.startswith("joints.rail.spring."), e.value.key
    assert msg in str(e.value), str(e.value)


CART = """\
name: {name}
parameters:
  m_c: 2.0
bodies:
  cart: {{mass: {m}, com: [0, 0, 0], inertia: [0.1, {i}, 0.1]}}
joints:
  rail: {{type: prismatic, between: [fixed_frame, cart], at: [0, 0, 0], axis: [1, 0, 0],
         spring: {{k: 800.0, c: 2.0, preload: 5.0}}}}
outputs:
  x: cart.x
simulation: {{t_end: 0.5}}
"""


# a value -p gives (3) and the model's own (2, in make test-all), each against the exact
# motion with the numbers
@pytest.mark.parametrize("m_c", [3.0, pytest.param(2.0, marks=pytest.mark.slow)])
def test_a_mass_and_moments_given_by_parameters_retune_without_recompiling(tmp_path, m_c):
    m = loads(CART.format(name="cart", m="m_c", i='"0.05 * m_c"'), "cart.yaml")
    cart = m.bodies["cart"]
    assert cart.mass == 2.0 and cart.mass_expr == symbols.param("m_c")
    assert cart.inertia == (0.1, 0.1, 0.1) and cart.inertia_expr[1] == 0.05 * symbols.param("m_c")
    _, path = compile_model(m, tmp_path)
    mod = import_module(path)
    p = mod.PARAMS.copy()
    p[list(mod.PARAM_NAMES).index("m_c")] = m_c
    r = simulate(mod, t_end=0.5, rtol=1e-10, atol=1e-12, params=p, points=51)
    ref = step_response(r.t, m_c, 800.0, 2.0, 5.0)
    assert np.abs(r.column("x") - ref).max() < 1e-11       # measured 1e-13


@pytest.mark.parametrize("m, i, msg", [
    ('"m_c - 2"', "0.1", "mass = m_c - 2 is 0"),
    ("m_c", '"0.2 * m_c"', "triangle inequality"),        # 0.1, 0.4, 0.1 at m_c = 2
    ('"m_c * t"', "0.1", "unknown name 't'"),
])
def test_a_bad_mass_or_moment_is_refused_at_its_line(m, i, msg):
    with pytest.raises(ModelError) as e:
        loads(CART.format(name="cart", m=m, i=i), "cart.yaml")
    assert e.value.loc is not None and e.value.loc.line == 5, e.value
    assert e.value.key.startswith("bodies.cart."), e.value.key
    assert msg in str(e.value), str(e.value)


SPIN = """\
name: {name}
parameters:
  w0: 5.0
  v0: 0.5
  m_b: 2.0
bodies:
  box: {{mass: {m}, com: [0, 0, 0], inertia: [0.1, 0.2, {i}], velocity: [{v}, 0, 0],
        omega: [{w}, 0.05, 0.1]}}
outputs:
  x: box.x
  wx: box.wx_R0
  wz: box.wz_R0
simulation: {{t_end: 0.5}}
"""


@pytest.mark.slow       # parameters in masses and moments stay in make test
def test_initial_velocities_by_parameters_and_a_spinning_body_of_parametric_inertia(tmp_path):
    """The free body's initial velocity and spin, its mass and a moment as expressions
    (the spin's momentum J w then is one too): the same run as the numbers written out,
    for the defaults and for values given at run time."""
    m = loads(SPIN.format(name="spin", m="m_b", i='"0.1 * m_b"', v="v0", w="w0"),
              "spin.yaml")
    assert m.bodies["box"].velocity == (0.5, 0.0, 0.0)
    assert m.bodies["box"].omega_expr[0] == symbols.param("w0")
    _, path = compile_model(m, tmp_path)
    mod = import_module(path)
    names = list(mod.PARAM_NAMES)
    for w0, v0, m_b in ((5.0, 0.5, 2.0), (8.0, 1.0, 2.5)):
        p = mod.PARAMS.copy()
        for n, val in (("w0", w0), ("v0", v0), ("m_b", m_b)):
            p[names.index(n)] = val
        r = simulate(mod, t_end=0.5, rtol=1e-10, atol=1e-12, params=p, points=51)
        _, lit = compile_model(loads(SPIN.format(name=f"spin_{int(w0)}", m=m_b,
                                                 i=0.1 * m_b, v=v0, w=w0), "spin.yaml"),
                               tmp_path)
        ref = simulate(import_module(lit), t_end=0.5, rtol=1e-10, atol=1e-12, points=51)
        assert r.column("x")[-1] == pytest.approx(0.5 * v0, rel=1e-9)   # free flight
        assert r.column("wx")[0] == pytest.approx(w0, rel=1e-12)
        for out in ("x", "wx", "wz"):
            assert np.abs(r.column(out) - ref.column(out)).max() < 1e-9 * max(1.0, w0)


PENDULUM = """\
name: {name}
parameters:
  g_acc: 9.81
gravity: {g}
bodies:
  rod: {{mass: 2.0, com: [0.3, 0, -0.4], inertia: [0.2, 0.2, 0.01]}}
joints:
  hinge: {{type: revolute, between: [fixed_frame, rod], at: [0, 0, 0], axis: [0, 1, 0]}}
outputs:
  x: rod.x
simulation: {{t_end: 0.5}}
"""


@pytest.mark.slow       # -p retuning without recompiling stays in make test
def test_gravity_by_a_parameter_swings_the_pendulum_as_the_number_does(tmp_path):
    for form in ("g_acc", "[0, 0, -g_acc]", "[0, 0, -0.5 * g_acc]"):
        g = loads(PENDULUM.format(name="pend", g=form), "pend.yaml")
        assert g.gravity[:2] == (0.0, 0.0) and g.gravity_expr[:2] == (0, 0)
        assert g.gravity_expr[2] == -symbols.param("g_acc") * (0.5 if "0.5" in form else 1)
    m = loads(PENDULUM.format(name="pend", g="g_acc"), "pend.yaml")
    assert m.gravity == (0.0, 0.0, -9.81)
    _, path = compile_model(m, tmp_path)
    mod = import_module(path)
    for g in (9.81, 1.62):                                  # the Earth, the Moon
        p = mod.PARAMS.copy()
        p[list(mod.PARAM_NAMES).index("g_acc")] = g
        r = simulate(mod, t_end=0.5, rtol=1e-10, atol=1e-12, params=p, points=51)
        _, lit = compile_model(loads(PENDULUM.format(name=f"pend_{int(g * 100)}", g=g),
                                     "pend.yaml"), tmp_path)
        ref = simulate(import_module(lit), t_end=0.5, rtol=1e-10, atol=1e-12, points=51)
        assert np.abs(r.column("x") - ref.column("x")).max() < 1e-9
        assert abs(r.column("x")[-1] - 0.3) > 1e-3            # it swings


def test_a_negative_gravity_by_parameters_is_refused():
    with pytest.raises(ModelError, match="gravity = -g_acc is -9.81"):
        loads(PENDULUM.format(name="pend", g="-g_acc"), "pend.yaml")


INITIAL = """\
name: {name}
parameters: {{x0: 0.01}}
bodies:
  cart: {{mass: 2.0, com: [0, 0, 0], inertia: [1, 1, 1]}}
  {extra}
joints:
  rail: {{type: prismatic, between: [fixed_frame, cart], at: [0, 0, 0], axis: [0.6, 0.8, 0],
         spring: {{k: 50, c: 0}}, initial: {initial}}}
  {joint}
outputs:
  xs: rail.tx.q
simulation: {{t_end: 1.0}}
"""


def _initial(initial="{tx: x0}", extra="", joint="", name="rail_start"):
    return loads(INITIAL.format(name=name, initial=initial, extra=extra, joint=joint),
                 "rail.yaml")


def test_a_joint_starts_displaced_by_a_parameter(tmp_path):
    """initial: {tx: x0} starts body 2 at x0 along the axis with the spring stretched by
    it: x = x0 cos(5 t) (k 50, m 2), and -p x0 moves the start without recompiling."""
    _, path = compile_model(_initial(), tmp_path)
    mod = import_module(path)
    for x0 in (0.01, -0.03):
        p = mod.PARAMS.copy()
        p[list(mod.PARAM_NAMES).index("x0")] = x0
        r = simulate(mod, t_end=1.0, rtol=1e-11, atol=1e-13, params=p, points=101)
        t = r.t
        assert np.abs(r.column("xs") - x0 * np.cos(5 * t)).max() < 1e-10
        # the body moved along the axis (0.6, 0.8, 0): cart.x is 0.6 of it
        assert np.abs(r.column("cart.x") - 0.6 * r.column("xs")).max() < 1e-12


@pytest.mark.parametrize("initial, extra, joint, msg", [
    ("{ty: x0}", "", "", "'ty' is not a free translation of a prismatic joint"),
    ("{tx: t}", "", "", "unknown name 't'"),
    ("{tx: x0}", "other: {mass: 1, com: [1, 0, 0], inertia: [1, 1, 1]}",
     "tie: {type: spherical, between: [cart, other], at: [0.5, 0, 0]}",
     "body 'cart' is also held by joint tie"),
])
def test_a_start_that_cannot_be_is_refused(initial, extra, joint, msg):
    with pytest.raises(ModelError, match=msg):
        _initial(initial, extra, joint)
