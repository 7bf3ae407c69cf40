"""A mechanism as the report draws it and ``bgc modes`` weighs it: each body's pose states
in a generated module, its mass and inertia at the run's parameters, and its drawn points
(centre of mass, named points, the joints' points on it).

A point at body-frame offset ``s`` from G sits at ``G + F0 Rx(a) Ry(b) Rz(c) s`` in R0
(docs/format.md: the Cardan angles are measured from the body's initial frame ``F0``, the
offsets are the model's ``points`` and the joints' ``at``). A small motion of the pose
(dG, da, db, dc) moves it by ``dG + F0 (dtheta x s)``, dtheta = (da, db, dc): the
first-order displacement a mode shape draws.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

POSE = ("x", "y", "z", "ax", "ay", "az")


@dataclass
class BodyPose:
    """One body: where its pose lives in the state vector, its inertia at the parameters
    (principal moments in its frame ``F0``), and its drawn points (body-frame offsets
    from G, the first one G itself)."""
    name: str
    states: list[int]               # indices of x, y, z, ax, ay, az
    mass: float
    inertia: np.ndarray             # (3,) principal moments
    F0: np.ndarray                  # (3, 3): columns = body axes in R0 at the start
    com: np.ndarray                 # G at the reference pose (R0)
    offsets: np.ndarray             # (k, 3) body-frame offsets of the drawn points
    labels: list[str]               # "G", point names, "joint:<name>"


@dataclass
class Mechanism:
    bodies: list[BodyPose]
    # joints drawn: name, kind, point at the reference pose (R0), the two bodies and where
    # the point sits in ``points()``'s order for each (None: the fixed frame)
    joints: list[dict] = field(default_factory=list)

    @property
    def point_count(self) -> int:
        return sum(len(b.offsets) for b in self.bodies)

    def points(self, X: np.ndarray) -> np.ndarray:
        """World positions (frames, points, 3) of every drawn point for the state rows
        ``X`` (frames, states), bodies in order."""
        X = np.atleast_2d(X)
        out = np.empty((len(X), self.point_count, 3))
        k = 0
        for b in self.bodies:
            q = X[:, b.states]
            R = np.einsum("ij,fjk->fik", b.F0, _rotations(q[:, 3], q[:, 4], q[:, 5]))
            out[:, k:k + len(b.offsets)] = q[:, None, :3] + np.einsum("fij,pj->fpi", R,
                                                                     b.offsets)
            k += len(b.offsets)
        return out

    def displacement(self, dx: np.ndarray) -> np.ndarray:
        """First-order displacement (points, 3) of every drawn point for a (complex)
        change ``dx`` of the states about the reference angles (zero)."""
        out = []
        for b in self.bodies:
            d = dx[b.states]
            out.append(d[None, :3] + np.cross(d[3:], b.offsets) @ b.F0.T)
        return np.concatenate(out) if out else np.zeros((0, 3), dtype=dx.dtype)

    def energy(self, dx: np.ndarray) -> dict[str, float]:
        """Each body's kinetic-energy weight m |dG|^2 + sum J_i |dtheta_i|^2 in a motion
        ``dx`` of the states (a mode shape: its kinetic energy up to the common
        omega^2 / 2), bodies of negligible mass none."""
        out = {}
        for b in self.bodies:
            d = dx[b.states]
            out[b.name] = float(b.mass * np.sum(np.abs(d[:3]) ** 2)
                                + np.sum(b.inertia * np.abs(d[3:]) ** 2))
        return out

    def size(self) -> float:
        """The largest extent of the drawn points at the reference pose (at least 1e-3)."""
        P = np.concatenate([b.com + b.offsets @ b.F0.T for b in self.bodies]) \
            if self.bodies else np.zeros((1, 3))
        return max(float(np.ptp(P, axis=0).max()), 1e-3)


def _rotations(a, b, c) -> np.ndarray:
    """Rx(a) Ry(b) Rz(c) for arrays of angles: (frames, 3, 3)."""
    ca, sa, cb, sb, cc, sc = np.cos(a), np.sin(a), np.cos(b), np.sin(b), np.cos(c), np.sin(c)
    return np.stack([
        np.stack([cb * cc, -cb * sc, sb], -1),
        np.stack([ca * sc + sa * sb * cc, ca * cc - sa * sb * sc, -sa * cb], -1),
        np.stack([sa * sc - ca * sb * cc, sa * cc + ca * sb * sc, ca * cb], -1),
    ], -2)


def _value(expr, default, names, p) -> float:
    """A body's mass or moment: its expression of parameters at ``p``, else ``default``."""
    if expr is None or not hasattr(expr, "free_symbols"):
        return float(default if expr is None else expr)
    from bgc.model import symbols
    return float(expr.xreplace({symbols.param(n): float(v) for n, v in zip(names, p)}))


def of_model(model, module, p=None) -> Mechanism:
    """The Mechanism of a Model whose generated module is ``module`` (its bodies' pose
    states by name), masses and moments at the parameters ``p`` (default the module's)."""
    names = list(module.PARAM_NAMES)
    p = np.asarray(module.PARAMS if p is None else p, dtype=np.float64)
    index = {n: i for i, n in enumerate(module.STATE_NAMES)}
    on_body: dict[str, list[tuple[str, np.ndarray]]] = {n: [] for n in model.bodies}
    joints = []
    for jn, j in model.joints.items():
        at = np.asarray(j.at, dtype=float)
        ends = {}
        for side, n in (("body1", j.body1), ("body2", j.body2)):
            if n is None or n not in model.bodies:
                ends[side] = None
                continue
            b = model.bodies[n]
            on_body[n].append((f"joint:{jn}", np.asarray(b.frame, dtype=float).T
                               @ (at - np.asarray(b.com, dtype=float))))
            ends[side] = (n, len(on_body[n]))      # 1 + its index after G
        joints.append({"name": jn, "kind": j.kind, "at": at, **ends})
    bodies = []
    for n, b in model.bodies.items():
        states = [index.get(f"{n}.{s}") for s in POSE]
        if None in states:
            continue                # a body the module does not carry (a scene's reduction)
        inertia = b.inertia_expr or b.inertia
        labels = ["G"] + list(b.points) + [lab for lab, _ in on_body[n]]
        offsets = [np.zeros(3)] + [np.asarray(v, dtype=float) for v in b.points.values()] \
            + [off for _, off in on_body[n]]
        bodies.append(BodyPose(
            n, states, _value(b.mass_expr, b.mass, names, p),
            np.array([_value(e, v, names, p) for e, v in zip(inertia, b.inertia)]),
            np.asarray(b.frame, dtype=float), np.asarray(b.com, dtype=float),
            np.array(offsets), labels))
    start = {}
    k = 0
    for b in bodies:
        start[b.name] = k
        k += len(b.offsets)
    for j in joints:        # each end as the index of its point in points()
        for side in ("body1", "body2"):
            end = j[side]
            j[side] = None if end is None or end[0] not in start else \
                (end[0], start[end[0]] + len(model.bodies[end[0]].points) + end[1])
    return Mechanism(bodies, joints)
