"""Multibonds in the text format: bonds of dimension 3, matrix-valued I, C, R, vector
sources, the cross-product TF, and the vector causality rules C1 and C2."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.linalg import expm

from bgc.codegen.emit import import_module
from bgc.errors import BgcError, CausalityError, ModelError
from bgc.model.load import loads
from bgc.pipeline import build, compile_model
from bgc.simulate import simulate

MSD3 = """
name: msd3
elements:
  force: {type: Se, effort: [1.0, -0.5, 0.25]}
  v: {type: "1"}
  mass: {type: I, I: [[2.0, 0, 0], [0, 3.0, 0], [0, 0, 4.0]], p0: [0.1, 0, -0.2]}
  spring: {type: C, k: [[100.0, 20.0, 0], [20.0, 150.0, 10.0], [0, 10.0, 80.0]]}
  damper: {type: R, R: [[1.0, 0.2, 0], [0.2, 2.0, 0], [0, 0, 0.5]]}
bonds:
  - {from: force, to: v, dim: 3}
  - {from: v, to: mass, dim: 3}
  - {from: v, to: spring, dim: 3}
  - {from: v, to: damper, dim: 3}
outputs:
  fx: spring.ex
  qy: spring.qy
"""


def compile_text(tmp_path, text, name):
    f = tmp_path / f"{name}.yaml"
    f.write_text(text)
    _, path = compile_model(f, tmp_path / "gen")
    return import_module(path)


def test_3d_mass_spring_damper_matches_the_matrix_exponential(tmp_path):
    mod = compile_text(tmp_path, MSD3, "msd3")
    M = np.diag([2.0, 3.0, 4.0])
    K = np.array([[100.0, 20, 0], [20, 150, 10], [0, 10, 80]])
    R = np.array([[1.0, 0.2, 0], [0.2, 2, 0], [0, 0, 0.5]])
    F = np.array([1.0, -0.5, 0.25])
    Mi = np.linalg.inv(M)
    # x = [p, q]: p' = F - K q - R M^-1 p, q' = M^-1 p; forced by the augmented constant
    A = np.zeros((7, 7))
    A[:3, :3], A[:3, 3:6], A[:3, 6] = -R @ Mi, -K, F
    A[3:6, :3] = Mi
    x0 = np.array([0.1, 0, -0.2, 0, 0, 0, 1.0])
    r = simulate(mod, t_end=2.0, rtol=1e-11, atol=1e-13, solver="radau", points=201)
    exact = np.array([expm(A * t) @ x0 for t in r.t])
    names = ["mass.px", "mass.py", "mass.pz", "spring.qx", "spring.qy", "spring.qz"]
    got = np.column_stack([r.column(n) for n in names])
    assert np.abs(got - exact[:, :6]).max() < 1e-8 * np.abs(exact[:, :6]).max()
    assert np.allclose(r.column("fx"), (K @ exact[:, 3:6].T)[0], atol=1e-7)
    assert np.allclose(r.column("qy"), exact[:, 4], atol=1e-10)


LEVER = """
name: lever
elements:
  spin: {type: Sf, flow: [0.0, 0.0, 2.0]}
  arm: {type: XTF, r: [0.5, 0.0, 0.0]}
  spring: {type: C, k: 10.0}
bonds:
  - {from: spin, to: arm, dim: 3}
  - {from: arm, to: spring, dim: 3}
outputs:
  qy: spring.qy
  torque_z: spin.ez
"""


def test_cross_product_tf_gives_omega_x_r_and_r_x_force(tmp_path):
    """omega = 2 e_z at r = 0.5 e_x: the spring end moves at omega x r = 1 e_y; the
    source feels the moment r x (k q) = 0.5 * 10 * t about z."""
    mod = compile_text(tmp_path, LEVER, "lever")
    r = simulate(mod, t_end=1.0, rtol=1e-10, atol=1e-12)
    assert np.allclose(r.column("qy"), r.t, atol=1e-9)
    assert np.allclose(r.column("torque_z"), 5.0 * r.t, atol=1e-8)


def test_rule_c2_cross_product_tf_cannot_take_its_flow_from_the_output_side():
    text = LEVER.replace("spring: {type: C, k: 10.0}", "drive: {type: Sf, flow: [1, 0, 0]}") \
        .replace("{from: arm, to: spring, dim: 3}", "{from: arm, to: drive, dim: 3}") \
        .replace("  qy: spring.qy\n", "")
    with pytest.raises(CausalityError) as exc:
        build(loads(text, "c2.yaml"))
    msg = str(exc.value)
    assert msg.startswith("c2.yaml:") and "arm" in msg and "line" in msg
    assert "C2" in msg or "XTF" in msg


def test_rule_c1_junction_bonds_share_one_dimension():
    text = MSD3.replace("- {from: v, to: damper, dim: 3}", "- {from: v, to: damper}") \
        .replace("damper: {type: R, R: [[1.0, 0.2, 0], [0.2, 2.0, 0], [0, 0, 0.5]]}",
                 "damper: {type: R, R: 1.0}")
    with pytest.raises(ModelError) as exc:
        build(loads(text, "c1.yaml"))
    msg = str(exc.value)
    assert "rule C1" in msg and "b4 (dim 1" in msg and msg.startswith("c1.yaml:")


@pytest.mark.parametrize("old, new, words", [
    ("k: [[100.0, 20.0, 0], [20.0, 150.0, 10.0], [0, 10.0, 80.0]]",
     "k: [[100.0, 20.0, 0], [0, 150.0, 10.0], [0, 10.0, 80.0]]", "not symmetric"),
    ("I: [[2.0, 0, 0], [0, 3.0, 0], [0, 0, 4.0]]", "I: [[2.0, 0, 0], [0, -3.0, 0], [0, 0, 4.0]]",
     "not positive definite"),
    ("I: [[2.0, 0, 0], [0, 3.0, 0], [0, 0, 4.0]]", "I: [[2.0, 0], [0, 3.0]]",
     "must be a 3x3 matrix"),
    ("effort: [1.0, -0.5, 0.25]", "effort: [1.0, -0.5]", "must be a vector of 3"),
    ("k: [[100.0, 20.0, 0], [20.0, 150.0, 10.0], [0, 10.0, 80.0]]", "effort: 100*q",
     "must be a matrix"),
    ("{from: force, to: v, dim: 3}", "{from: force, to: v, dim: 2}", "dimension 2"),
])
def test_bad_multibond_elements_are_refused_with_their_line(old, new, words):
    assert old in MSD3
    with pytest.raises(BgcError) as exc:
        build(loads(MSD3.replace(old, new), "mb.yaml"))
    msg = str(exc.value)
    assert msg.startswith("mb.yaml:") and words in msg, msg
