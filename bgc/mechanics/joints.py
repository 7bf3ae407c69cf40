"""Joint models (paper 11.2.3, Figs 11.7-11.9): what each joint kind blocks and leaves free.

A joint compares two bodies at a point, in a joint frame fixed on body 1 (x = the axis).
Every direction it acts in is a scalar *direction* with

- a **rate** ``dg/dt = r_v1.v_P1 + r_w1.w1 + r_v2.v_P2 + r_w2.w2`` (point velocities and
  angular velocities in R0): the rows become modulated transformers from the bodies'
  point and angular-velocity junctions to the direction's 0-junction, so the direction's
  effort (the joint force along it) reaches each body as ``r^T * effort``, power-consistent
  by construction;
- for a **blocked** direction, its geometric deflection ``g`` (zero when the joint is
  assembled). The constraint element L of the parasitic method is a stiff spring on ``g``
  in parallel with a damper on ``dg/dt``. Using the geometric ``g`` instead of an integrated
  relative velocity keeps the deflection exact: it cannot drift when a joint turns or slides
  far (an integrated deflection of a spinning revolute's tilt grows without bound);
- for a **free** direction, the rate of its joint coordinate, where functional elements
  (spring with preload, damper, actuator) sit.

Two kinds of deflection measure everything:
``dist(u1)``: ``g = (x_P2 - x_P1).u1`` with ``u1`` fixed on body 1 (where all three
translations are blocked, ``u1`` is simply an R0 axis: same span, constant rows); and
``perp(u2, w1)``: ``g = u2.w1`` with ``u2`` on body 2, ``w1`` on body 1 (perpendicular at
assembly). Labels: ``tx ty tz`` translations along, ``rx ry rz`` rotations about the
joint-frame axes (``ry`` of a universal joint is about its second axis). A
``prismatic_universal`` is the chain slider - universal joint with the intermediate bodies'
mass neglected (the SARIB's attach and membrane joints): one joint instead of two bodies
of negligible mass, whose poses would be states and whose twists an algebraic loop.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from bgc.mechanics import exact


@dataclass(frozen=True)
class JointKind:
    blocked: tuple[str, ...]
    free: tuple[str, ...]          # free directions that may carry functional elements
    dof: int
    doc: str


JOINT_KINDS: dict[str, JointKind] = {
    "revolute": JointKind(("tx", "ty", "tz", "ry", "rz"), ("rx",), 1,
                          "rotation about the axis"),
    "prismatic": JointKind(("ty", "tz", "rx", "ry", "rz"), ("tx",), 1,
                           "translation along the axis"),
    "cylindrical": JointKind(("ty", "tz", "ry", "rz"), ("tx", "rx"), 2,
                             "translation along and rotation about the axis"),
    "spherical": JointKind(("tx", "ty", "tz"), (), 3, "any rotation about the point"),
    "screw": JointKind(("ty", "tz", "ry", "rz", "screw"), ("rx",), 1,
                       "rotation about the axis with translation pitch/(2 pi) per radian"),
    "sphere_cylinder": JointKind(("ty", "tz"), ("tx",), 4,
                                 "a sphere (body 2) in a cylinder (body 1) along the axis"),
    "point": JointKind(("tx",), ("ty", "tz"), 5,
                       "a sphere (body 2) on a plane (body 1) whose normal is the axis"),
    "line": JointKind(("tx", "rz"), ("ty", "tz", "rx"), 4,
                      "a cylinder (body 2, along axis2) on a plane (body 1, normal axis)"),
    "universal": JointKind(("tx", "ty", "tz", "rz"), ("rx", "ry"), 2,
                           "two revolutes: about the axis (body 1) and axis2 (body 2)"),
    "prismatic_universal": JointKind(("tx", "ty", "rz"), ("tz", "rx", "ry"), 3,
                                     "a universal joint on a slider: slides along "
                                     "axis x axis2 (body 1), turns about the axis and "
                                     "axis2 (body 2)"),
    "planar": JointKind(("tx", "ry", "rz"), ("ty", "tz", "rx"), 3,
                        "motion in the plane whose normal is the axis"),
    "fixed": JointKind(("tx", "ty", "tz", "rx", "ry", "rz"), (), 0, "a weld"),
}

# joint kinds that need a second axis (joint-frame y), body 2's
NEEDS_AXIS2 = ("universal", "prismatic_universal", "line")
# kinds whose second rotation (ry) is about body 2's axis2: a universal joint's
UNIVERSAL = ("universal", "prismatic_universal")


@dataclass
class Direction:
    label: str
    blocked: bool
    rotational: bool
    rows: dict          # "v1" | "w1" | "v2" | "w2" -> 3x1 Matrix (R0), absent = zero
    # geometric deflection of a blocked direction, displacement of a free translation
    # (None: integrate its rate)
    g: sp.Expr | None


class Geometry:
    """Body-fixed vectors and points of one joint, in R0, as functions of the states.

    ``vec(side, u)`` is the vector that equals ``u`` (R0) at the initial pose and turns
    with body ``side`` (1 or 2); ``point(side)`` is the joint point fixed on that body."""

    def __init__(self, rot1, rot2, pos1, pos2):
        self.rot = {1: rot1, 2: rot2}     # (R(t), R(0)) or None for the fixed frame
        self.pos = {1: pos1, 2: pos2}     # x_P as a 3x1 Matrix

    def vec(self, side: int, u) -> sp.Matrix:
        u = exact.vector(u)
        rot = self.rot[side]
        if rot is None:
            return u
        R, R0 = rot
        return R * exact.canonical(R0.T * u)


def _dist(geo, label, u, blocked=True, in_r0=False):
    """Separation of the joint points along ``u``: fixed on body 1, or (``in_r0``, for
    joints that block all three translations: same span) an R0 axis with constant rows."""
    u1 = exact.vector(u) if in_r0 else geo.vec(1, u)
    d = geo.pos[2] - geo.pos[1]
    rows = {"v1": -u1, "v2": u1} if in_r0 else {"v1": -u1, "v2": u1, "w1": u1.cross(d)}
    return Direction(label, blocked, False, rows, u1.dot(d))


def _perp(geo, label, u2, w1, sign=1):
    a, b = geo.vec(2, u2), geo.vec(1, w1)
    rows = {"w1": sign * b.cross(a), "w2": sign * a.cross(b)}
    return Direction(label, True, True, rows, sign * a.dot(b))


def _turn(geo, label, side, u, blocked=False):
    """Rotation rate about an axis fixed on body ``side``: (w2 - w1).u."""
    v = geo.vec(side, u)
    return Direction(label, blocked, True, {"w1": -v, "w2": v}, None)


def directions(kind: str, geo: Geometry, frame, pitch: float = 0.0) -> list[Direction]:
    """The blocked and free directions of a joint; ``frame`` = columns x, y, z (R0)."""
    x, y, z = ([frame[i][k] for i in range(3)] for k in range(3))
    spec = JOINT_KINDS[kind]
    out = []
    trans = {"tx": x, "ty": y, "tz": z}
    rotation_measure = {           # small rotation about x, y, z of body 2 w.r.t. body 1
        "rx": lambda: _perp(geo, "rx", y, z),
        "ry": lambda: _perp(geo, "ry", x, z, -1),
        "rz": lambda: _perp(geo, "rz", x, y),
    }
    point = all(t in spec.blocked for t in trans)
    for label in spec.blocked:
        if label in trans and point:
            k = "xyz".index(label[1])
            out.append(_dist(geo, label, [int(i == k) for i in range(3)], in_r0=True))
        elif label in trans:
            out.append(_dist(geo, label, trans[label]))
        elif kind in NEEDS_AXIS2 and label == "rz":  # body 2's axis2 stays perpendicular
            out.append(_perp(geo, "rz", y, x, -1))  # to the axis (line: in the plane)
        elif label == "screw":                       # tx - pitch/(2 pi) * rx, integrated
            t, r = _dist(geo, "tx", x, blocked=False), _turn(geo, "rx", 1, x)
            k = exact.rational(pitch) / (2 * sp.pi)
            rows = {key: t.rows.get(key, sp.zeros(3, 1)) - k * r.rows.get(key, sp.zeros(3, 1))
                    for key in ("v1", "w1", "v2", "w2")}
            rows = {key: v for key, v in rows.items() if any(e != 0 for e in v)}
            out.append(Direction("screw", True, False, rows, None))
        else:
            out.append(rotation_measure[label]())
    for label in spec.free:
        if label in trans:
            out.append(_dist(geo, label, trans[label], blocked=False))
        elif kind in UNIVERSAL and label == "ry":
            out.append(_turn(geo, "ry", 2, y))
        else:
            out.append(_turn(geo, label, 1, {"rx": x, "ry": y, "rz": z}[label]))
    return out
