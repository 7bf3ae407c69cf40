"""Pass **merge_relays** of stage reduce (``bgc.scene.reduce``; Model -> Model, before the
equations are derived): a chain of bodies of negligible mass that only relay forces
between two bodies (two revolutes with perpendicular, intersecting axes; a slider and
such a pair) becomes the one joint it is (``universal``, ``prismatic_universal``), its
springs, dampers and actuators moved onto the joint's free directions. Exact for ideal
joints; under parasitic the chain's compliance becomes one joint's (scenes ask).
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass, replace

import numpy as np
import sympy as sp

from bgc.mechanics import exact
from bgc.mechanics.joints import JOINT_KINDS
from bgc.model import symbols
from bgc.model.load import joint_params
from bgc.model.model import Functional, Joint, Model


AXIS_TOLERANCE = 1e-6       # perpendicular / parallel axes, as the loader checks axis2


@dataclass
class _Link:
    """One joint of a relay chain, walked from end 1 to end 2 (``forward``: the joint's
    body 1 is on end 1's side)."""
    joint: Joint
    forward: bool

    @property
    def axis(self) -> np.ndarray:
        """The joint's axis, turned so that its coordinate counts from end 1 to end 2."""
        return np.array(self.joint.frame, dtype=float)[:, 0] * (1 if self.forward else -1)

    @property
    def functional(self):
        free = JOINT_KINDS[self.joint.kind].free[0]
        return self.joint.functional.get(free)


def end_owner(end: str, model: Model) -> str:
    """The body, joint or element a bond's end names: itself, or the joint of a port
    ``joint.tx`` or the body of ``body.P.z`` (names of instances' parts hold dots)."""
    name = end
    while name not in model.elements and name not in model.joints \
            and name not in model.bodies and "." in name:
        name = name.rpartition(".")[0]
    return name


def _references(model: Model) -> dict[str, set[tuple[str, str]]]:
    """Body or joint name -> who reads it: ``("element", E)``, ``("bond", B)``,
    ``("joint", J)`` (its actuator), ``("output", O)``."""
    read: dict[str, set] = {}

    def scan(e, who):
        for s in getattr(e, "free_symbols", ()):
            if symbols.is_ref(s):       # body, body__point, joint, joint__direction, ...
                read.setdefault(symbols.split_ref(s)[0].split("__")[0], set()).add(who)
    for el in model.elements.values():
        for e in list(el.fields.values()) + [el.initial]:
            scan(e, ("element", el.name))
    for b in model.bonds:
        for end in (b.src, b.dst):
            read.setdefault(end_owner(end, model), set()).add(("bond", b.name))
    for j in model.joints.values():
        for f in j.functional.values():
            scan(f.actuator, ("joint", j.name))
    for o in model.outputs:
        scan(o.expr, ("output", o.name))
    return read


def _chains(model: Model) -> list[tuple[str | None, list[str], list[_Link], str | None]]:
    """Maximal chains end1 -joint- relay -joint- relay ... -joint- end2, where each relay
    is a body of negligible mass with exactly two joints."""
    touching: dict = {}
    for j in model.joints.values():
        for b in (j.body1, j.body2):
            touching.setdefault(b, []).append(j)
    relays = {n for n, b in model.bodies.items()
              if b.mass == 0 and len(touching.get(n, ())) == 2}

    def across(j, body):
        return j.body2 if j.body1 == body else j.body1

    def onward(relay, came_by):
        return next(j for j in touching[relay] if j is not came_by)

    seen, out = set(), []
    for start in sorted(relays):
        if start in seen:
            continue
        link, body = None, start          # walk to one end ...
        while True:
            link = onward(body, link)
            body = across(link, body)
            if body not in relays or body == start:
                break
        if body == start:                 # a ring of relays: nothing to merge into
            seen.add(start)
            continue
        end1, here, bodies, links = body, body, [], []
        while True:                       # ... and collect the chain from there
            links.append(_Link(link, link.body1 == here))
            here = across(link, here)
            if here not in relays:
                break
            bodies.append(here)
            link = onward(here, link)
        seen.update(bodies)
        out.append((end1, bodies, links, here))
    return out


def _universal_centre(ra: _Link, rb: _Link) -> tuple[np.ndarray | None, str]:
    """The point where two revolute axes meet at right angles, or why they do not."""
    a, b = ra.axis, rb.axis
    if abs(a @ b) > AXIS_TOLERANCE:
        return None, f"the axes of {ra.joint.name} and {rb.joint.name} are not perpendicular"
    pa, pb = np.array(ra.joint.at), np.array(rb.joint.at)
    qa, qb = pa + ((pb - pa) @ a) * a, pb + ((pa - pb) @ b) * b
    scale = max(1.0, float(np.abs(pa).max()), float(np.abs(pb).max()))
    if np.linalg.norm(qa - qb) > AXIS_TOLERANCE * scale:
        return None, f"the axes of {ra.joint.name} and {rb.joint.name} do not meet"
    pa, pb, a, b = (exact.vector(v) for v in (pa, pb, a, b))    # the centre, exactly
    qa, qb = pa + (pb - pa).dot(a) * a, pb + (pa - pb).dot(b) * b
    return (qa + qb) / 2, ""


def _merged_joint(name, end1, end2, links: list[_Link]) -> tuple[Joint | None, str]:
    """The one joint a chain is (or None and why not). Its axes keep the old joints'
    senses where they can, so that most springs keep the sign of their preload."""
    kinds = [lk.joint.kind for lk in links]
    if kinds == ["revolute", "revolute"]:
        slider, (ra, rb), kind = None, links, "universal"
    elif kinds == ["prismatic", "revolute", "revolute"]:
        slider, ra, rb = links
        kind = "prismatic_universal"
    else:
        return None, "its joints (" + ", ".join(kinds) + ") are no universal joint"
    if len({lk.joint.parasitic for lk in links}) > 1:
        return None, "its joints have different parasitic settings"
    centre, why = _universal_centre(ra, rb)
    if centre is None:
        return None, why
    x, y = ra.axis, rb.axis
    if slider is not None:
        p = slider.axis
        z = np.cross(x, y)
        if abs(abs(z @ p) - 1) > AXIS_TOLERANCE:
            return None, (f"{slider.joint.name} does not slide at right angles to both "
                          f"axes of {ra.joint.name} and {rb.joint.name}")
        if z @ p < 0:
            y = -y
    X = exact.vector(x)                          # the frame, exactly (``exact``)
    Y = exact.unit(exact.vector(y) - exact.vector(y).dot(X) * X)
    frame = sp.Matrix.hstack(X, Y, X.cross(Y))
    x, y, z = (np.array(exact.floats(frame[:, k])) for k in range(3))
    frame = exact.floats(frame)
    labels = {id(ra): ("rx", x), id(rb): ("ry", y)}
    if slider is not None:
        labels[id(slider)] = ("tz", z)
    functional = {}
    for lk in links:
        f = lk.functional
        if f is None:
            continue
        label, new = labels[id(lk)]
        s = int(np.sign(new @ lk.axis))
        functional[label] = Functional(f.k, f.c, s * f.preload + 0.0,
                                       None if f.actuator is None else s * f.actuator, f.loc)
    first = links[0].joint
    return Joint(name, first.loc, kind, end1, end2, exact.floats(centre), frame,
                 first.parasitic, functional), ""


def _merged_name(model: Model, joints: list[str]) -> str:
    """The chain's joints' common prefix (attach_pumping, attach_roll -> attach), else
    their names joined."""
    prefix = os.path.commonprefix(joints).rstrip("_")
    taken = set(model.joints) | set(model.bodies) | set(model.elements)
    if prefix.isidentifier() and "__" not in prefix and prefix not in taken:
        return prefix
    return "_".join(joints)


def merge_relays(model: Model, outputs=None, keep_params=()) -> tuple[Model, list, str]:
    """The model with every mergeable relay chain replaced by its joint (see the module's
    docstring). A chain stays when an expression, a bond or one of ``outputs`` (default
    all; the others that read a chain are dropped) reads its bodies or joints, or when
    it holds one of ``keep_params`` (a scene's exposed or set parameters). Returns the
    model, what was removed, and a note that says what was merged and what was left, why."""
    read = _references(model)
    kept_outputs = None if outputs is None else set(outputs)
    merged, notes, removed = [], [], []
    for end1, relays, links, end2 in _chains(model):
        names = [lk.joint.name for lk in links]
        if links[-1].joint.kind == "prismatic":     # the slider sits on end 1's side
            end1, end2 = end2, end1
            links = [_Link(lk.joint, not lk.forward) for lk in reversed(links)]
        readers = {f"{kind} {who}" for n in relays + names for kind, who in read.get(n, ())
                   if kind != "output" or kept_outputs is None or who in kept_outputs}
        held = sorted(p for p in keep_params if p.split("__")[0] in names)
        chain = " - ".join(names)
        if end1 == end2:
            notes.append(f"{chain} left: it begins and ends on {end1 or 'the fixed frame'}")
            continue
        if readers or held:
            notes.append(f"{chain} left: " + ", ".join(sorted(readers) + held) + " read it")
            continue
        joint, why = _merged_joint(_merged_name(model, names), end1, end2, links)
        if joint is None:
            notes.append(f"{chain} left: {why}")
            continue
        merged.append((joint, relays, names))
        removed += relays + names
        notes.append(f"{chain} -> {joint.name} ({joint.kind})")
    if not merged:
        return model, [], "; ".join(notes) or "no bodies of negligible mass relay forces"
    gone_joints = {n for _, _, names in merged for n in names}
    gone_bodies = {b for _, relays, _ in merged for b in relays}
    joints = {n: j for n, j in model.joints.items() if n not in gone_joints}
    params = {n: p for n, p in model.parameters.items()
              if n.split("__")[0] not in gone_joints}
    renamed = {}
    for joint, _, names in merged:
        joints[joint.name] = joint
        joint_params(joint, params)
        renamed.update({n: joint.name for n in names})
    excitation = model.excitation
    if excitation is not None:
        excitation = replace(excitation, directions={
            d: (renamed.get(j, j), amp) for d, (j, amp) in excitation.directions.items()})
    gone = gone_joints | gone_bodies
    dropped = [o.name for o in model.outputs
               if any(("output", o.name) in read.get(n, ()) for n in gone)]
    removed += [f"output {n}" for n in dropped]
    digest = hashlib.sha256((model.digest + repr(notes)).encode()).hexdigest()
    out = replace(model, digest=digest, joints=joints, parameters=params,
                  bodies={n: b for n, b in model.bodies.items() if n not in gone_bodies},
                  outputs=[o for o in model.outputs if o.name not in dropped],
                  excitation=excitation)
    return out, removed, "; ".join(notes)
