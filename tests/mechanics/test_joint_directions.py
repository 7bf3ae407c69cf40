"""Joint models on their own (``joints.directions``): for every joint kind, between the
fixed frame and a body in a generic pose, the blocked directions' deflections g vanish at
assembly, each direction's rate rows are the time derivative of its g (central differences
along a rigid motion of the body), and the directions a kind lists are independent."""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from scipy.linalg import expm

from bgc.mechanics.joints import JOINT_KINDS, Geometry, directions

# the joint frame: x = the axis, y = the second axis (universal, line), z = x cross y;
# rational so that the pose at assembly is exact
FRAME = sp.Matrix([[sp.Rational(3, 5), 0, sp.Rational(-4, 5)],
                   [sp.Rational(4, 5), 0, sp.Rational(3, 5)],
                   [0, -1, 0]])
AT = sp.Matrix([sp.Rational(1, 2), -1, 2])             # the joint point (R0)
R0 = sp.Matrix([[0, -1, 0], [1, 0, 0], [0, 0, 1]])      # the body's orientation at assembly
V = np.array([0.3, -0.7, 0.2])                          # the joint point's velocity (R0)
W = np.array([-0.4, 0.5, 0.9])                          # the body's angular velocity (R0)


def _skew(w):
    return np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])


def _directions(kind, h=0.0):
    """The joint's directions with the body moved for time h along the rigid motion
    (V at the joint point, W), body 1 being the fixed frame."""
    rot = sp.Matrix(expm(_skew(W) * h)) * R0 if h else R0
    pos = AT + sp.Matrix(V * h) if h else AT
    geo = Geometry(None, (rot, R0), AT, pos)
    return directions(kind, geo, FRAME.tolist(), pitch=0.05)


@pytest.mark.parametrize("kind", sorted(JOINT_KINDS))
def test_rows_are_the_rate_of_the_deflection_and_directions_are_independent(kind):
    spec = JOINT_KINDS[kind]
    dirs = _directions(kind)
    assert [d.label for d in dirs if d.blocked] == list(spec.blocked)
    assert [d.label for d in dirs if not d.blocked] == list(spec.free)
    h = 1e-6
    ahead, behind = _directions(kind, h), _directions(kind, -h)
    rows = []       # the body's rows (the fixed frame's, v1 and w1, meet no motion)
    for d, a, b in zip(dirs, ahead, behind):
        v2 = np.array(d.rows.get("v2", sp.zeros(3, 1)), dtype=float).ravel()
        w2 = np.array(d.rows.get("w2", sp.zeros(3, 1)), dtype=float).ravel()
        rows.append(np.concatenate([v2, w2]))
        if d.g is None:                             # a free or integrated direction
            continue
        assert sp.nsimplify(d.g) == 0, (d.label, d.g)
        rate = (float(a.g) - float(b.g)) / (2 * h)
        assert rate == pytest.approx(v2 @ V + w2 @ W, abs=1e-8), d.label
    assert np.linalg.matrix_rank(np.array(rows)) == len(dirs)
