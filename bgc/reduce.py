"""Stage **reduce** (EquationSystem -> EquationSystem): model no more than a scene needs.

A scene asks for some outputs under one excitation; each pass below removes what cannot
change those outputs and reports what it did (``PassReport``), in this order:

- ``fold_parameters``: parameters the scene does not expose become constants, and the
  assignments they make constant are propagated (a zero damper, a zero preload vanish);
  the parameters bgc itself sets at run time (joint loads, the excitation's selectors,
  the constraint rank) stay parameters.
- ``idle_dofs``: the spin of a body about its own axis when no force can act on it (every
  joint of the body a spherical joint on that axis, the two other principal moments
  equal, at rest about it): its momentum stays zero, so it is no state (the MGB bars).
- ``prune``: outputs the scene does not ask for, and states that cannot reach the asked
  ones through the equations, are removed.

Every pass is exact: what it removes is identically zero or cannot influence the outputs
(``idle_dofs`` drops the moments of joint forces whose lever arm across the axis is round-
off of the model's coordinates, below 1e-9 m).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import sympy as sp

from .emit import _cone
from .equations import EquationSystem, LinearBlock

# parameters bgc writes at run time: never folded
RUNTIME_PARAMS = ("_load", "excitation__", "lagrange__rank")
# geometry and inertia closer than this (relative) are taken as equal
TOLERANCE = 1e-9


@dataclass
class PassReport:
    name: str
    states_before: int
    states_after: int
    assignments_before: int
    assignments_after: int
    removed: list[str] = field(default_factory=list)   # what the pass took out
    note: str = ""

    def to_dict(self) -> dict:
        return {"pass": self.name, "states_before": self.states_before,
                "states_after": self.states_after,
                "assignments_before": self.assignments_before,
                "assignments_after": self.assignments_after,
                "removed": self.removed, "note": self.note}


def _substitute(system: EquationSystem, mapping: dict) -> EquationSystem:
    """``mapping`` (symbol -> constant) substituted everywhere, and every assignment that
    becomes constant propagated forward (kept where it defines a state's rate)."""
    rates = {st.dsym for st in system.states}
    mapping = dict(mapping)
    assignments = []
    for item in system.assignments:
        if isinstance(item, LinearBlock):
            assignments.append(item.xreplace(mapping))
            continue
        v, e = item
        e = e.xreplace(mapping)
        if e.is_Number and v not in rates:
            mapping[v] = e
            continue
        assignments.append((v, e))
    return replace(
        system, assignments=assignments,
        outputs=[(n, e.xreplace(mapping)) for n, e in system.outputs],
        states=[replace(st, initial=st.initial.xreplace(mapping)) for st in system.states],
        guards=[(w, e.xreplace(mapping)) for w, e in system.guards],
        constraints=[(n, None if g is None else g.xreplace(mapping), r.xreplace(mapping))
                     for n, g, r in system.constraints])


def _keep_states(system: EquationSystem, keep: list) -> EquationSystem:
    """Only the states in ``keep`` (State objects, in order); algebraic indices follow."""
    old = {id(st): i for i, st in enumerate(system.states)}
    algebraic = {i for i in system.algebraic}
    return replace(system, states=keep,
                   algebraic=[k for k, st in enumerate(keep) if old[id(st)] in algebraic])


def _report(name, before: EquationSystem, after: EquationSystem, removed, note=""):
    return PassReport(name, len(before.states), len(after.states), len(before.assignments),
                      len(after.assignments), removed, note)


# --- passes ---------------------------------------------------------------------------
def fold_parameters(system: EquationSystem, values: dict, expose=()) -> tuple:
    """Parameters not in ``expose`` (nor set by bgc at run time) become constants at
    ``values`` (name -> value; default: the model's)."""
    keep, mapping = [], {}
    for sym, name, default in system.params:
        if name in expose or any(k in name for k in RUNTIME_PARAMS):
            keep.append((sym, name, values.get(name, default)))
        else:
            v = float(values.get(name, default))
            mapping[sym] = sp.Integer(int(v)) if v.is_integer() else sp.Float(v)
    out = replace(_substitute(system, mapping), params=keep)
    folded = sorted(name for sym, name, _ in system.params if sym in mapping)
    return out, _report("fold_parameters", system, out, folded,
                        f"{len(mapping)} of {len(system.params)} parameters folded, "
                        f"{len(keep)} kept")


def idle_dofs(system: EquationSystem, outputs=None) -> tuple:
    """Drop the momentum of each body's idle spin (see the module's docstring), unless
    one of ``outputs`` (default: all) reads it."""
    m = system.model
    if system.method != "parasitic":
        return system, _report("idle_dofs", system, system, [],
                               f"method {system.method}: the spin's rate is an unknown of "
                               "the constraint block, left as it is")
    by_name = {st.name: st for st in system.states}
    zero, notes = {}, []
    for body in m.bodies.values():
        axis = _idle_axis(m, body)
        if axis is None:
            continue
        st = by_name.get(f"{body.name}.J.p{'xyz'[axis]}")
        if st is None or sp.sympify(st.initial).is_zero is not True:
            continue
        zero[st.sym] = sp.Integer(0)
        notes.append(st.name)
    read = [n for n, e in system.outputs if (outputs is None or n in outputs)
            and _cone(system.assignments, [e])[1] & set(zero)]
    if read:     # an output reads a spin: it is not idle for this scene
        return system, _report("idle_dofs", system, system, [],
                               f"outputs {', '.join(read)} read a spin: kept")
    out = _substitute(system, zero)
    out = _keep_states(out, [st for st in out.states if st.sym not in zero])
    return out, _report("idle_dofs", system, out, notes,
                        f"{len(notes)} bodies spin freely about their own axis")


def _idle_axis(m, body) -> int | None:
    """The body-frame axis about which nothing can turn ``body``: every joint on it is
    spherical with its centre on that axis through G, nothing else is bonded to it, the
    other two principal moments are equal, and it starts at rest about it."""
    if body.mass <= 0:
        return None
    joints = [j for j in m.joints.values() if body.name in (j.body1, j.body2)]
    if not joints or any(j.kind != "spherical" for j in joints):
        return None
    if any(end.split(".")[0] == body.name for b in m.bonds for end in (b.src, b.dst)):
        return None
    R = np.array(body.frame, dtype=float)            # columns: body axes in R0
    arms = [R.T @ (np.array(j.at) - np.array(body.com)) for j in joints]
    scale = max([1.0] + [float(np.abs(a).max()) for a in arms])
    inertia = np.array(body.inertia, dtype=float)
    for axis in range(3):
        a, b = (k for k in range(3) if k != axis)
        if abs(inertia[a] - inertia[b]) > TOLERANCE * max(inertia[a], inertia[b]):
            continue
        if any(abs(r[a]) > TOLERANCE * scale or abs(r[b]) > TOLERANCE * scale for r in arms):
            continue
        if abs(float(np.dot(np.array(body.omega), R[:, axis]))) > 0:
            continue
        return axis
    return None


def prune(system: EquationSystem, outputs) -> tuple:
    """Only the ``outputs`` asked for, and the states they depend on through the rates."""
    kept_outputs = [(n, e) for n, e in system.outputs if n in set(outputs)]
    states = {st.sym: st for st in system.states}
    seeds = [e for _, e in kept_outputs]
    seeds += [e for _, g, r in system.constraints for e in (r, g) if e is not None]
    need: set = set()
    frontier = seeds
    while frontier:
        _, used = _cone(system.assignments, frontier)
        new = {s for s in used if s in states} - need
        need |= new
        frontier = [states[s].dsym for s in new]
    keep = [st for st in system.states if st.sym in need]
    removed = [st.name for st in system.states if st not in keep]
    gone = {st.sym for st in system.states if st not in keep}
    out = _keep_states(replace(system, outputs=kept_outputs,
                               guards=[(w, e) for w, e in system.guards
                                       if not e.free_symbols & gone]), keep)
    dropped = [n for n, _ in system.outputs if n not in set(outputs)]
    return out, _report("prune", system, out, removed + [f"output {n}" for n in dropped],
                        f"{len(removed)} states and {len(dropped)} outputs cannot reach "
                        "the outputs asked for")


def reduce(system: EquationSystem, outputs, values: dict, expose=()) -> tuple:
    """All passes in order; returns the reduced system and one PassReport per pass."""
    reports = []
    for step in (lambda s: fold_parameters(s, values, expose),
                 lambda s: idle_dofs(s, outputs), lambda s: prune(s, outputs)):
        system, rep = step(system)
        reports.append(rep)
    return system, reports
