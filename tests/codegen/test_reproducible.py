"""Generated code is the same bytes on every machine, and exact values stay exact.

The committed modules' freshness test (test_codegen) compares bytes on the developers'
machine only: it passed there while another CPU vendor's last bits made it fail, because
frames, poses and offsets were computed in floating point (numpy, BLAS, LAPACK) and their
noise reached the emitted expressions. These tests reproduce another machine here: every
geometric number of a loaded model, and every result of numpy's linear algebra during the
build, is moved by one unit in the last place, and the generated source must not change.
"""

from __future__ import annotations

import math
import random
import re
import struct
import textwrap
from fractions import Fraction

import numpy as np
import pytest
import sympy as sp
from helpers import MODELS, rendered

from bgc.codegen import emit
from bgc.mechanics import exact
from bgc.model import load
from bgc.model.sections import bodies
from bgc.pipeline import build

# the shipped models with bodies and joints whose numbers are decimals of at most 15
# digits (andrews and four_bar give theirs to 17 digits: a nudged 17-digit number is
# another model, so they are checked against numpy's noise only), and a scalar one
DECIMAL_MODELS = ["bricard", "double_pendulum", "heavy_top", "isosceles_slider_crank",
                  "pendulum", "sarib_one_leg", "slider_crank", "tumbling_box", "rlc"]

LITERAL = re.compile(r"(?<![\w.])(\d+\.\d*(?:e[-+]?\d+)?|\d+e[-+]?\d+)")


def _nudge(v, rng: random.Random):
    """Every nonzero float in ``v`` (nested tuples) moved one unit in the last place, up or
    down at random: what another machine's rounding does to a computed value."""
    if isinstance(v, tuple):
        return tuple(_nudge(x, rng) for x in v)
    if isinstance(v, float) and v != 0.0:
        return math.nextafter(v, rng.choice((-math.inf, math.inf)))
    return v


def _nudged_inputs(monkeypatch, seed: int):
    """The loader's geometric inputs (com, points, frame axes, joint points and axes,
    inertias, velocities) each one ulp off as a float: what the inputs of a numerical
    computation look like after another machine's rounding."""
    rng = random.Random(seed)
    vector = bodies.vector      # every 3-vector of the geometry is read by it

    def nudged(v, loc, key):
        return tuple(_nudge(float(x), rng) for x in vector(v, loc, key))
    monkeypatch.setattr(bodies, "vector", nudged)


def _source(model) -> str:
    return emit.render(build(model).system)


@pytest.mark.parametrize("name", DECIMAL_MODELS)
def test_last_bit_of_the_geometry_does_not_reach_the_generated_code(name, monkeypatch,
                                                                    compiled):
    """The inputs of the geometry one ulp off give the same generated source, byte for
    byte: the geometry is computed exactly from the decimals they stand for, never in
    floating point (which amplified such differences to 1e-10 before). (The reference,
    this run's render of the model as written: ``helpers.rendered``.)"""
    reference = rendered(compiled, name).decode()
    for seed in (1, 2):
        with monkeypatch.context() as mp:
            _nudged_inputs(mp, seed)
            assert _source(load.load(MODELS / f"{name}.yaml")) == reference, f"seed {seed}"


def _noisy(fn):
    def wrapped(*args, **kwargs):
        out = fn(*args, **kwargs)
        if isinstance(out, tuple):      # eigh: (values, vectors)
            return type(out)(*(np.asarray(o) * (1 + 2.0 ** -52) for o in out))
        return np.asarray(out) * (1 + 2.0 ** -52)
    return wrapped


@pytest.mark.parametrize("name", ["andrews", "four_bar", "slider_crank", "sarib_one_leg"])
def test_numpy_linear_algebra_does_not_reach_the_generated_code(name, monkeypatch,
                                                                compiled):
    """numpy's norm, eigh, det, cross and dot give results one ulp off during the whole
    build (as another BLAS or CPU might): the generated source does not change."""
    reference = rendered(compiled, name).decode()
    for mod, fn in ((np.linalg, "norm"), (np.linalg, "eigh"), (np.linalg, "det"),
                    (np, "cross"), (np, "dot")):
        monkeypatch.setattr(mod, fn, _noisy(getattr(mod, fn)))
    assert _source(load.load(MODELS / f"{name}.yaml")) == reference


EXACT_MODEL = """\
name: exact_geometry
gravity: 9.81
bodies:
  arm:                       # turned by pi/2 about z
    mass: 0.5
    com: [0.05, 0, 0]
    frame: {x: [0, 1, 0], y: [-1, 0, 0], z: [0, 0, 1]}
    inertia: [0.001, 0.002, 0.0025]
    points: {tip: [0.1, 0, 0], side: [0.05, 0.03, 0]}
  link:                      # at 45 deg, axes not of unit length
    mass: 0.25
    com: [0.15, 0.05, 0]
    frame: {x: [2, 2, 0], y: [-1, 1, 0], z: [0, 0, 3]}
    inertia: [0.0002, 0.0003, 0.0004]
    points: {end: [0.2, 0.1, 0]}
  box:                       # its inertia given as a tensor in a rotated frame
    mass: 1.0
    com: [0.3, 0.1, 0]
    frame: {x: [0, 0, 1], y: [1, 0, 0], z: [0, 1, 0]}
    inertia: [[0.3, 0, 0], [0, 0.1, 0], [0, 0, 0.2]]
joints:
  pivot: {type: revolute, between: [fixed_frame, arm], at: [0, 0, 0], axis: [0, 0, 1],
          spring: {k: 2.0, c: 0.1}}
  pin: {type: revolute, between: [arm, link], at: arm.tip, axis: [0, 0, 1]}
  slide: {type: prismatic, between: [link, box], at: link.end, axis: [1, 1, 0]}
outputs:
  tip_x: arm.tip.x
  side_y: arm.side.y
  slide_force: slide.Fx
"""


def _literals(source: str) -> list[float]:
    """The numbers of the generated code: decimal literals of its Python, and the exact
    doubles (hexadecimal bit patterns) of its LLVM IR."""
    body = source.split("def initial_state", 1)[1]
    ir = re.findall(r"\b0x([0-9A-F]{16})\b", body)
    return [float(s) for s in LITERAL.findall(body)] + [
        struct.unpack("<d", struct.pack("<Q", int(h, 16)))[0] for h in ir]


def _short(x: float, digits: int = 6) -> bool:
    return float(f"{x:.{digits - 1}e}") == x


def test_exact_geometry_stays_exact(tmp_path):
    """Right angles, pi/2 and 45 deg turns, 0.05 offsets and axes that are not of unit
    length: every constant of the generated code is either a short decimal of the model
    (0.05, 0.1 ...), a ratio of them (1/0.3), or a short decimal times or over sqrt(2) (a
    45 deg axis), rounded correctly or, for a product with the rounded 1/sqrt(2), within 2
    ulp; no unproven zero (1e-17) and no value a few ulps off a short one."""
    path = tmp_path / "exact_geometry.yaml"
    path.write_text(EXACT_MODEL)
    source = _source(load.load(path))
    values = sorted(set(_literals(source)))
    assert values, "no constants found"
    for v in values:
        assert v == 0 or abs(v) > 1e-9, f"unproven zero {v!r}"
        if _short(v, 12):
            continue
        # not short: then a short decimal times or over sqrt(2) (45 deg), rounded correctly
        # (within 2 ulp: a product of the canonical 1/sqrt(2) and a model decimal is
        # rounded once more)
        ok = abs(float(Fraction(v).limit_denominator(10 ** 9)) - v) <= math.ulp(v)  # 1/0.3
        for f in (sp.sqrt(2), 1 / sp.sqrt(2)):
            short = float(f"{float(sp.N(sp.Rational(repr(v)) * f, 30)):.7e}")
            back = float(sp.N(sp.Rational(repr(short)) / f, 30))
            ok = ok or abs(back - v) <= 2 * math.ulp(v)
        assert ok, f"{v!r} is neither exact in the model nor a 45 deg projection"
    assert 0.7071067811865476 in values              # 1/sqrt(2), correctly rounded
    for wrong in ("0.7071067811865475", "0.7071067811865477", "1.0000000000000002",
                  "0.9999999999999999", "0.04999999999999999", "0.05000000000000001"):
        assert float(wrong) not in values, wrong


def test_exact_geometry_output_is_stable_under_noise(tmp_path, monkeypatch):
    path = tmp_path / "exact_geometry.yaml"
    path.write_text(EXACT_MODEL)
    reference = _source(load.load(path))
    monkeypatch.setattr(np.linalg, "eigh", _noisy(np.linalg.eigh))
    monkeypatch.setattr(np.linalg, "norm", _noisy(np.linalg.norm))
    _nudged_inputs(monkeypatch, 3)
    assert _source(load.load(path)) == reference


# ----------------------------------------------------------------------- the exact module
def test_rational_reads_a_double_as_the_decimal_it_stands_for():
    assert exact.rational(0.05) == sp.Rational(1, 20)
    assert exact.rational(0.1 + 0.2) == sp.Rational(3, 10)
    assert exact.rational(math.nextafter(0.05, 1)) == sp.Rational(1, 20)
    assert exact.rational(math.nextafter(0.05, 0)) == sp.Rational(1, 20)
    assert exact.rational(3) == 3 and exact.rational(-2.5) == sp.Rational(-5, 2)
    assert exact.rational(0.0) == 0
    assert exact.rational(1e-300) == sp.Rational(1, 10 ** 300)
    # a double that is no short decimal keeps all its digits
    x = 0.1234567890123456
    assert float(exact.rational(x)) == x
    with pytest.raises(ValueError):
        exact.rational(float("nan"))


def test_to_float_rounds_exact_values_correctly():
    assert exact.to_float(sp.sqrt(2) / 2) == 0.7071067811865476
    assert exact.to_float(sp.Rational(1, 3)) == 1 / 3
    assert exact.to_float(sp.sqrt(3) / 2) == math.sqrt(3) / 2
    # a zero sympy cannot prove structurally is still zero
    unproven = (sp.sqrt(2) + sp.sqrt(3)) ** 2 - 5 - 2 * sp.sqrt(6)
    assert exact.floats(sp.Matrix([unproven, 1, 2])) == (0.0, 1.0, 2.0)


def test_unit_axes_are_exact():
    u = exact.unit(exact.vector([0.7071067812, 0.7071067812, 0.0]))
    assert u == sp.Matrix([1, 1, 0]) / sp.sqrt(2)
    assert exact.floats(u) == (0.7071067811865476, 0.7071067811865476, 0.0)
    F = sp.Matrix.hstack(u, exact.unit(sp.Matrix([-1, 1, 0])), sp.Matrix([0, 0, 1]))
    assert sp.simplify(F.T * F) == sp.eye(3)


def test_principal_axes_of_a_rotated_tensor():
    """A tensor diagonal in its own frame: exact moments (ascending) and axes; a general
    tensor: the same bits however numpy's eigh rounds (mpmath, software arithmetic)."""
    moments, axes = exact.principal_axes(sp.diag(sp.Rational(3, 10), sp.Rational(1, 10),
                                                 sp.Rational(1, 5)))
    assert list(moments) == [sp.Rational(1, 10), sp.Rational(1, 5), sp.Rational(3, 10)]
    assert axes.det() == 1 and all(e in (-1, 0, 1) for e in axes)
    M = sp.Matrix([[2, 1, 0], [1, 2, 0], [0, 0, 5]]) / 10
    moments, axes = exact.principal_axes(M)
    assert exact.floats(moments) == (0.1, 0.3, 0.5)
    A = np.array(exact.floats(axes))
    assert np.allclose(A.T @ A, np.eye(3), atol=1e-15) and np.linalg.det(A) > 0
    assert np.allclose(A.T @ np.array(exact.floats(M)) @ A, np.diag([0.1, 0.3, 0.5]),
                       atol=1e-15)


def test_model_text_sets_the_exact_values(tmp_path):
    """Frames written with 10 digits (as the SARIB's are) are normalized exactly: an axis
    [0.7071067812, 0.7071067812, 0] is exactly the 45 deg one."""
    path = tmp_path / "m.yaml"
    path.write_text(textwrap.dedent("""\
        name: m
        bodies:
          b:
            mass: 1.0
            com: [0, 0, 0]
            frame: {x: [0.7071067812, 0.7071067812, 0.0], y: [-0.7071067812, 0.7071067812, 0.0], z: [0, 0, 1]}
            inertia: [1, 2, 3]
        joints:
          j: {type: revolute, between: [fixed_frame, b], at: [0, 0, 0], axis: [1, 1, 0]}
        """))
    m = load.load(path)
    r = 0.7071067811865476
    assert m.bodies["b"].frame == ((r, -r, 0.0), (r, r, 0.0), (0.0, 0.0, 1.0))
    # joint frame: x the axis, y the R0 axis most nearly perpendicular to it (z), z = x ^ y
    assert m.joints["j"].frame == ((r, 0.0, r), (r, 0.0, -r), (0.0, 1.0, 0.0))
