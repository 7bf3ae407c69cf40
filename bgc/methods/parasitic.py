"""Method parasitic (paper 11.2.5.2): choose the joints' parasitic stiffness and damping
by separating the parasitic eigenfrequencies from the functional ones.

The paper's first rule: the stiff springs must be stiff enough not to change the
system's own dynamics, and no stiffer, or the problem only gets stiffer. Here:

1. the **functional** eigenfrequencies are those of the linearised model (the generated
   analytic Jacobian at the initial state) that do not move when every parasitic
   stiffness is scaled (three probes, x100, x370, x1900, dampers off: a parasitic mode
   moves with the square root, so one matching another by chance in all three is
   unlikely);
   The start is linearised with the parasitic springs undeflected, so what only their
   load gives (a pendulum's restoring moment from the joint's tension) is missing, and a
   mechanism moving without restoring forces has no mode at all: the fastest initial
   body rotation and the pendulum rate ``sqrt(g / l)`` of the shortest lever (body centre
   to joint point) are floors;
2. each blocked direction's **effective mass** ``1 / (J M^-1 J^T)`` (its constraint row
   over the bodies' twists, at the initial pose) gives its parasitic frequency
   ``sqrt(k / m_eff)``; a joint's stiffness is set so that its slowest blocked direction
   vibrates ``separation`` times faster than the fastest functional mode;
3. the damping makes that direction critically damped (``DAMPING_RATIO``), as Rayman
   recommends, so the parasitic modes do not ring.

The values are parameters of the generated module: nothing is recompiled.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bgc.errors import SimulationError
from bgc.methods.base import ConstraintMethod

SEPARATION = 100.0       # parasitic frequencies >= this x the highest functional one
DAMPING_RATIO = 1.0      # of the slowest blocked direction of each joint
_MATCH = 0.02            # an eigenvalue that moves less than this (relative) is functional


@dataclass
class Choice:
    separation: float
    functional_hz: float                  # highest functional eigenfrequency
    values: dict[str, float] = field(default_factory=dict)     # parameter -> value
    parasitic_hz: dict[str, float] = field(default_factory=dict)  # joint -> slowest mode
    # min chosen / max functional joint stiffness of the same kind (N/m, N m/rad)
    stiffness_ratio: float | None = None
    # the stiffnesses left as the model gave them (stiffer than the separation asks)
    kept: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return dict(self.__dict__)

    def describe(self) -> str:
        lo = min(self.parasitic_hz.values(), default=float("nan"))
        out = (f"parasitic auto: highest functional eigenfrequency {self.functional_hz:.4g} "
               f"Hz; {len(self.parasitic_hz)} joints set to parasitic modes >= {lo:.4g} Hz "
               f"(separation {self.separation:g})")
        if self.stiffness_ratio is not None:
            out += f"; stiffness ratio parasitic/functional {self.stiffness_ratio:.3g}"
        if self.kept:
            out += (f"; {len(self.kept)} stiffness(es) kept as given, already stiffer "
                    "(never made softer: the compliance is the modelling error)")
        return out


def _functional_rate(module, x, p, stiff: list[int], damp: list[int]) -> float:
    """Largest |eigenvalue| of the Jacobian that does not follow the parasitic stiffness."""
    def spectrum(factor):
        q = p.copy()
        q[stiff] *= factor
        q[damp] = 0.0
        return np.linalg.eigvals(module.jac(0.0, x, q))
    a, others = spectrum(1e2), [spectrum(f) for f in (3.7e2, 1.9e3)]
    noise = 1e-7 * max(np.abs(a).max(initial=0.0), 1e-300)   # rigid-body modes: ~0
    fixed = [abs(z) for z in a if abs(z) > noise and
             all(np.min(np.abs(b - z)) <= _MATCH * abs(z) for b in others)]
    return max(fixed, default=0.0)


def auto(module, model, x, p, separation: float = SEPARATION) -> tuple[np.ndarray, Choice]:
    """Parameters ``p`` with every joint's parasitic stiffness and damping chosen, and
    the Choice made (reported by ``bgc simulate --parasitic auto``)."""
    from bgc.graph.expand import expand, initial_pose, joint_param, twist_row
    names = list(module.PARAM_NAMES)
    graph = expand(model)
    pose = initial_pose(model)
    massive = [n for n, b in model.bodies.items() if b.mass > 0]
    col = {n: 6 * i for i, n in enumerate(massive)}
    minv = np.concatenate([[1 / model.bodies[n].mass] * 3
                           + [1 / v for v in model.bodies[n].inertia] for n in massive])
    roles = []   # (joint, 'stiffness' | 'rot_stiffness', largest effective mass)
    for jn, dirs in graph.joints.items():
        j = model.joints[jn]
        for rot in (False, True):
            meff = []
            for d in dirs:
                if d.blocked and d.rotational == rot:
                    row = twist_row(model, j, d, col, pose, 6 * len(massive))
                    w = float(row @ (minv * row))
                    if w > 0:
                        meff.append(1 / w)
            role = "rot_stiffness" if rot else "stiffness"
            if meff and joint_param(jn, role) in names:
                roles.append((jn, role, max(meff)))
    if not roles:
        raise SimulationError("--parasitic auto: the model has no blocked joint direction",
                              hint="it applies to models with joints (method parasitic)")
    stiff = [names.index(joint_param(jn, r)) for jn, r, _ in roles]
    damp = [names.index(joint_param(jn, r.replace("stiffness", "damping")))
            for jn, r, _ in roles]
    linear = _functional_rate(module, np.asarray(x, float), np.array(p, float), stiff, damp)
    # the linearisation misses what the undeflected parasitic springs do not carry yet
    # at the start: the motion's own rate (the fastest initial body rotation) and the
    # pendulum rate sqrt(g / l) of the shortest lever from a body's centre to its joints
    spin = max((float(np.linalg.norm(b.omega)) for b in model.bodies.values()), default=0.0)
    levers = [float(np.linalg.norm(np.subtract(j.at, model.bodies[n].com)))
              for j in model.joints.values() for n in (j.body1, j.body2) if n in massive]
    levers = [v for v in levers if v > 1e-9]
    g = float(np.linalg.norm(model.gravity))
    pendulum = np.sqrt(g / min(levers)) if g and levers else 0.0
    rate = max(linear, spin, pendulum)
    if rate <= 0:
        raise SimulationError("--parasitic auto: no functional eigenfrequency found at the "
                              "initial state (the linearised model has no dynamics apart "
                              "from the parasitic modes)",
                              hint="give the joints' stiffness explicitly (-p NAME=VALUE)")
    target = separation * rate          # rad/s
    choice = Choice(separation, rate / (2 * np.pi))
    out = np.array(p, dtype=np.float64)
    for (jn, _, m), ks, cs in zip(roles, stiff, damp):
        k = target ** 2 * m
        c = 2 * DAMPING_RATIO * np.sqrt(k * m)
        if out[ks] >= k:    # the model's joint is stiffer already: never made softer (the
            choice.kept.append(names[ks])    # compliance is the modelling error), as given
            k, c = out[ks], out[cs]
        out[ks], out[cs] = k, c
        choice.values[names[ks]], choice.values[names[cs]] = k, c
        hz = np.sqrt(k / m) / (2 * np.pi)
        choice.parasitic_hz[jn] = min(choice.parasitic_hz.get(jn, hz), hz)
    ratios = []
    for rot in (False, True):
        functional = [abs(k) for j in model.joints.values()
                      for label, f in j.functional.items()
                      if f is not None and (k := _at(f.k, names, p))
                      and label.startswith("r") == rot]
        chosen = [out[ks] for (_, role, _), ks in zip(roles, stiff)
                  if role.startswith("rot") == rot]
        if functional and chosen:
            ratios.append(min(chosen) / max(functional))
    choice.stiffness_ratio = min(ratios) if ratios else None
    return out, choice


def _at(value, names, p) -> float:
    """A functional spring's value: a number, or an expression of parameters at ``p``."""
    if not hasattr(value, "free_symbols"):
        return float(value)
    from bgc.model import symbols
    return float(value.xreplace({symbols.param(n): float(v) for n, v in zip(names, p)}))


class Parasitic(ConstraintMethod):
    """L is a stiff spring in parallel with a damper (paper 11.2.5.2): the joint is
    compliant, its stiffness and damping parameters of the module (``auto`` chooses them),
    and a direction whose gap ``g`` is known starts deflected under its static load."""

    name = "parasitic"
    ideal = False

    def constraint_element(self, ex, joint, d, zero):
        import sympy as sp

        from bgc.graph.expand import joint_param
        from bgc.model import symbols
        kind = "rot_" if d.rotational else ""
        k = symbols.param(joint_param(joint.name, kind + "stiffness"))
        c = symbols.param(joint_param(joint.name, kind + "damping"))
        if d.g is not None:     # load: the static joint load it starts with
            load = symbols.param(joint_param(joint.name, f"{d.label}_load"))
            spring = ex.add(f"{zero}__L", "MSe", joint.loc, effort=k * d.g - load)
        else:
            spring = ex.add(f"{zero}__L", "C", joint.loc, k=k, initial=sp.S.Zero)
        return [spring, ex.add(f"{zero}__Lc", "R", joint.loc, R=c)]
