"""Method parasitic (paper 11.2.5.2): choose the joints' parasitic stiffness and damping,
per joint and per kind (translational, rotational), from the functional modes.

The paper's first rule: the stiff springs must be stiff enough not to change the
system's own dynamics, and no stiffer, or the problem only gets stiffer. Two measures of
"not changing" are kept, each a floor:

1. **separation**: the functional eigenfrequencies are those of the linearised model (the
   generated analytic Jacobian at the initial state) that do not move when every
   parasitic stiffness is scaled (three probes, x100, x370, x1900, the dampers scaled
   with the square root, which moves a parasitic mode with it, a joint between bodies of
   negligible mass included; one matching another by chance in all three is unlikely).
   The undeflected start misses what only the joints' load gives when the model has no
   static loads, and a mechanism moving without restoring forces has no mode at all: the
   fastest initial body rotation and the pendulum rate ``sqrt(g / l)`` of the shortest
   lever (body centre to joint point) are floors. Each blocked direction's **effective
   mass** ``1 / (J M^-1 J^T)`` (its constraint row over the bodies' twists, at the
   initial pose) gives its parasitic frequency ``sqrt(k / m_eff)``; a joint's stiffness
   of each kind puts its slowest blocked direction ``separation`` times faster than the
   fastest functional mode.
2. **accuracy**: a compliance in series with a functional spring (the SARIB membrane's
   2000 N m/rad behind a 1e5 N m/rad joint) or a lever (a 700 N m/rad hinge seen through
   a 4 cm arm is 4.4e5 N/m at the bar's joint) shifts the functional modes far more than
   the separation tells. The shift of a functional eigenfrequency ``w`` falls as ``1/k``,
   so ``k dln(w)/dk`` (the first-order eigenvalue sensitivity, from the left and right
   eigenvectors of the Jacobian at the static loads) is the part of its relative shift
   that this stiffness causes. Every functional mode's shifts summed must stay under
   ``accuracy``: the stiffnesses whose part is above an equal share are raised to it
   (the others keep theirs), and that is checked again until it holds.

The damping makes each raised direction critically damped (``DAMPING_RATIO``), as Rayman
recommends, so the parasitic modes do not ring; a joint between bodies of negligible mass
(no mass to ring) gets ``c = k / w_target``, its first-order mode ``k / c`` at the
separation's frequency. A stiffness already above both floors is kept with its damping:
never softer than the model gave it, since the compliance is the modelling error.

The values are parameters of the generated module: nothing is recompiled.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from bgc.errors import SimulationError
from bgc.methods.base import ConstraintMethod

SEPARATION = 100.0       # parasitic frequencies >= this x the highest functional one
ACCURACY = 1e-4          # largest relative shift of a functional eigenfrequency, all joints
DAMPING_RATIO = 1.0      # of the slowest blocked direction of each joint
_MATCH = 0.02            # an eigenvalue that moves less than this (relative) is functional
_PARASITIC = 0.1         # dln|lambda| / dln(all k) above this: a parasitic mode (0.5: a
#                          mass on a stiff spring; 1: a massless joint's k / c)
_ROUNDS = 4              # accuracy checks: the shift falls as 1/k, two nearly always do


@dataclass
class Role:
    """One stiffness parameter of a joint: its translational or rotational directions."""
    joint: str
    kind: str                       # "stiffness" | "rot_stiffness"
    k: int                          # index of the stiffness parameter
    c: int                          # index of its damping parameter
    masses: dict[str, float]        # blocked direction -> effective mass (kg or kg m^2)

    @property
    def mass(self) -> float:
        """The largest effective mass: the slowest direction (0 between massless bodies)."""
        return max(self.masses.values(), default=0.0)


@dataclass
class Choice:
    separation: float
    functional_hz: float                  # highest functional eigenfrequency
    accuracy: float = ACCURACY
    values: dict[str, float] = field(default_factory=dict)     # parameter -> value
    parasitic_hz: dict[str, float] = field(default_factory=dict)  # joint -> slowest mode
    # stiffness parameter -> blocked direction -> its parasitic frequency sqrt(k / m_eff)
    # [Hz] (none between bodies of negligible mass)
    directions: dict[str, dict[str, float]] = field(default_factory=dict)
    # stiffness parameter -> what set it: "separation", "accuracy" or "given" (kept)
    reasons: dict[str, str] = field(default_factory=dict)
    # stiffness parameter -> its part of the largest functional shift (k dln(w)/dk)
    shares: dict[str, float] = field(default_factory=dict)
    shift: float | None = None            # largest relative functional shift, estimated
    modes: int = 0                        # functional modes checked
    # min chosen / max functional joint stiffness of the same kind (N/m, N m/rad)
    stiffness_ratio: float | None = None
    # the stiffnesses left as the model gave them (stiffer than both floors ask)
    kept: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return dict(self.__dict__)

    def describe(self) -> str:
        lo = min(self.parasitic_hz.values(), default=float("nan"))
        why = {r: sum(v == r for v in self.reasons.values())
               for r in ("separation", "accuracy", "given")}
        out = (f"parasitic auto: highest functional eigenfrequency {self.functional_hz:.4g} "
               f"Hz; {len(self.parasitic_hz)} joints set to parasitic modes >= {lo:.4g} Hz "
               f"(separation {self.separation:g}); stiffnesses set by separation "
               f"{why['separation']}, by accuracy {why['accuracy']}")
        if self.shift is not None:
            out += (f"; {self.modes} functional modes shifted <= {self.shift:.2g} by the "
                    f"joints' compliance (accuracy {self.accuracy:g})")
        if self.stiffness_ratio is not None:
            out += f"; stiffness ratio parasitic/functional {self.stiffness_ratio:.3g}"
        if self.kept:
            out += (f"; {len(self.kept)} stiffness(es) kept as given, already stiffer "
                    "(never made softer: the compliance is the modelling error)")
        return out + "\n" + self.table()

    def table(self) -> str:
        """One line per stiffness: value, what set it, its part of the largest functional
        shift, and the parasitic frequency of each blocked direction it acts on."""
        lines = []
        for name, why in self.reasons.items():
            dirs = ", ".join(f"{d} {hz:.4g}" for d, hz in self.directions[name].items())
            lines.append(f"  {name:32s} {self.values[name]:10.4g}  {why:10s} "
                         f"shift {self.shares.get(name, 0.0):8.2g}"
                         + (f"  [Hz] {dirs}" if dirs else ""))
        return "\n".join(lines)


def _roles(model, names: list[str]) -> list[Role]:
    """Every joint's stiffness parameters with the effective mass of each blocked
    direction they act on (a direction between bodies of negligible mass has none)."""
    from bgc.graph.expand import expand, initial_pose, joint_param, twist_row
    graph = expand(model)
    pose = initial_pose(model)
    massive = [n for n, b in model.bodies.items() if b.mass > 0]
    col = {n: 6 * i for i, n in enumerate(massive)}
    minv = np.concatenate([[1 / model.bodies[n].mass] * 3
                           + [1 / v for v in model.bodies[n].inertia] for n in massive])
    roles = []
    for jn, dirs in graph.joints.items():
        j = model.joints[jn]
        for kind in ("stiffness", "rot_stiffness"):
            blocked = [d for d in dirs if d.blocked and d.rotational == (kind != "stiffness")]
            if not blocked or joint_param(jn, kind) not in names:
                continue
            masses = {}
            for d in blocked:
                row = twist_row(model, j, d, col, pose, 6 * len(massive))
                w = float(row @ (minv * row))
                if w > 0:
                    masses[d.label] = 1 / w
            roles.append(Role(jn, kind, names.index(joint_param(jn, kind)),
                              names.index(joint_param(jn, kind.replace("stiffness",
                                                                        "damping"))), masses))
    return roles


def _jacobian(module, x, p) -> np.ndarray:
    """The Jacobian at ``x`` with the joints' static loads where the model starts loaded
    (their geometric stiffness, a pendulum's restoring moment, is part of the modes)."""
    if getattr(module, "STATIC_LOADS", False):
        from bgc.solvers.consistent import static_loads
        p = static_loads(module, x, p)
    return module.jac(0.0, x, p)


def _functional_rate(module, x, p, stiff: list[int], damp: list[int]) -> float:
    """Largest |eigenvalue| of the Jacobian that does not follow the parasitic stiffness
    (the dampers scaled with its square root: a parasitic mode's eigenvalue scales so,
    the first-order mode ``k / c`` of a joint between massless bodies too)."""
    def spectrum(factor):
        q = p.copy()
        q[stiff] *= factor
        q[damp] *= np.sqrt(factor)
        return np.linalg.eigvals(_jacobian(module, x, q))
    a, others = spectrum(1e2), [spectrum(f) for f in (3.7e2, 1.9e3)]
    noise = 1e-7 * max(np.abs(a).max(initial=0.0), 1e-300)   # rigid-body modes: ~0
    fixed = [abs(z) for z in a if abs(z) > noise and
             all(np.min(np.abs(b - z)) <= _MATCH * abs(z) for b in others)]
    return max(fixed, default=0.0)


def _floor_rate(model) -> float:
    """What the undeflected start may not show: the fastest initial body rotation and the
    pendulum rate ``sqrt(g / l)`` of the shortest lever from a body's centre to a joint."""
    spin = max((float(np.linalg.norm(b.omega)) for b in model.bodies.values()), default=0.0)
    levers = [float(np.linalg.norm(np.subtract(j.at, model.bodies[n].com)))
              for j in model.joints.values() for n in (j.body1, j.body2)
              if n in model.bodies and model.bodies[n].mass > 0]
    levers = [v for v in levers if v > 1e-9]
    g = float(np.linalg.norm(model.gravity))
    return max(spin, np.sqrt(g / min(levers)) if g and levers else 0.0)


def _sensitivity(module, x, p, stiff: list[int], damp: list[int]) -> np.ndarray:
    """``k_j dln|lambda_i| / dk_j`` for each functional mode i (rows) and stiffness j:
    the part of the mode's relative shift that the joint's compliance causes (first
    order, from the left and right eigenvectors; the Jacobian is affine in each k). A
    mode is functional where scaling every k by f and every c by sqrt(f) leaves it
    (``_PARASITIC``): an overdamped parasitic mode ``-c / m`` follows the dampers only."""
    import scipy.linalg
    if getattr(module, "STATIC_LOADS", False):     # the loads do not depend on k
        from bgc.solvers.consistent import static_loads
        p = static_loads(module, x, p)
    A = module.jac(0.0, x, p)
    lam, left, right = scipy.linalg.eig(A, left=True, right=True)
    norm = np.einsum("ij,ij->j", left.conj(), right)
    keep = (np.abs(lam) > 1e-7 * np.abs(lam).max(initial=0.0)) & (np.abs(norm) > 1e-300)
    lam, left, right, norm = lam[keep], left[:, keep], right[:, keep], norm[keep]

    def log_rate(q, h):     # dln|lambda| of every mode for the step q - p (relative h)
        dA = (module.jac(0.0, x, q) - A) / h
        dlam = np.einsum("ij,ij->j", left.conj(), dA @ right) / norm
        return np.real(np.conj(lam) * dlam) / np.abs(lam) ** 2
    q = p.copy()
    q[stiff] *= 1.001
    q[damp] *= np.sqrt(1.001)
    functional = np.abs(log_rate(q, 1e-3)) < _PARASITIC
    E = np.zeros((int(functional.sum()), len(stiff)))
    for c, j in enumerate(stiff):
        if p[j] > 0:
            q = p.copy()
            q[j] *= 1.001
            E[:, c] = np.abs(log_rate(q, 1e-3)[functional])
    return E


def _shares(e: np.ndarray, budget: float) -> np.ndarray:
    """Each stiffness's share of a mode's shift budget: a part under an equal share keeps
    it, the others split what is left equally (the fewest, smallest raises)."""
    order, share, left = np.argsort(e), e.copy(), budget
    for pos, i in enumerate(order):
        fair = left / (len(e) - pos)
        if e[i] > fair:
            share[order[pos:]] = fair
            break
        left -= e[i]
    return share


def auto(module, model, x, p, separation: float = SEPARATION,
         accuracy: float = ACCURACY) -> tuple[np.ndarray, Choice]:
    """Parameters ``p`` with every joint's parasitic stiffness and damping chosen, and
    the Choice made (reported by ``bgc simulate --parasitic auto``)."""
    names = list(module.PARAM_NAMES)
    roles = _roles(model, names)
    if not roles:
        raise SimulationError("--parasitic auto: the model has no blocked joint direction",
                              hint="it applies to models with joints (method parasitic)")
    x = np.asarray(x, dtype=np.float64)
    given = np.array(p, dtype=np.float64)
    stiff = [r.k for r in roles]
    rate = max(_functional_rate(module, x, given, stiff, [r.c for r in roles]),
               _floor_rate(model))
    if rate <= 0:
        raise SimulationError("--parasitic auto: no functional eigenfrequency found at the "
                              "initial state (the linearised model has no dynamics apart "
                              "from the parasitic modes)",
                              hint="give the joints' stiffness explicitly (-p NAME=VALUE)")
    target = separation * rate          # rad/s
    choice = Choice(separation, rate / (2 * np.pi), accuracy)
    out = given.copy()
    # separation; a joint between massless bodies as stiff as the stiffest of its kind
    floor = {r.kind: max(target ** 2 * s.mass for s in roles if s.kind == r.kind)
             for r in roles}
    for r in roles:
        k = target ** 2 * r.mass if r.mass > 0 else floor[r.kind]
        choice.reasons[names[r.k]] = "given" if out[r.k] >= k else "separation"
        if out[r.k] < k:
            out[r.k], out[r.c] = k, _damping(r, k, target)
    _refine(module, x, out, roles, target, choice)
    for r in roles:
        n = names[r.k]
        if choice.reasons[n] == "given":
            choice.kept.append(n)
        choice.values[n], choice.values[names[r.c]] = out[r.k], out[r.c]
        choice.directions[n] = {d: float(np.sqrt(out[r.k] / m) / (2 * np.pi))
                                for d, m in r.masses.items()}
        if r.masses:
            hz = min(choice.directions[n].values())
            choice.parasitic_hz[r.joint] = min(choice.parasitic_hz.get(r.joint, hz), hz)
    choice.stiffness_ratio = _stiffness_ratio(model, names, given, out, roles)
    return out, choice


def _damping(role: Role, k: float, target: float) -> float:
    """Critical damping of the slowest blocked direction; between massless bodies,
    ``k / target``: the joint's first-order mode at the separation's frequency."""
    if role.mass > 0:
        return 2 * DAMPING_RATIO * np.sqrt(k * role.mass)
    return k / target


def _refine(module, x, out, roles, target, choice) -> None:
    """Raise the stiffnesses whose part of a functional mode's shift is above its share
    of ``choice.accuracy`` (in place), until every mode's shifts sum under it."""
    names = list(module.PARAM_NAMES)
    stiff = [r.k for r in roles]
    for _ in range(_ROUNDS):
        E = _sensitivity(module, x, out, stiff, [r.c for r in roles])
        choice.modes = len(E)
        total = E.sum(axis=1)
        worst = int(np.argmax(total)) if len(E) else None
        choice.shift = float(total[worst]) if worst is not None else None
        if worst is not None:
            choice.shares = {names[j]: float(e) for j, e in zip(stiff, E[worst])}
        if choice.shift is None or choice.shift <= choice.accuracy:
            return
        raise_by = np.ones(len(roles))
        for e, t in zip(E, total):
            if t > choice.accuracy:     # 0.9: the shift is 1/k only asymptotically
                share = _shares(e, 0.9 * choice.accuracy)
                raise_by = np.maximum(raise_by, np.divide(e, share, out=np.ones_like(e),
                                                          where=share > 0))
        for r, f in zip(roles, raise_by):
            if f > 1:
                out[r.k] *= f
                out[r.c] = _damping(r, out[r.k], target)
                choice.reasons[names[r.k]] = "accuracy"


def _stiffness_ratio(model, names, given, out, roles) -> float | None:
    """Min chosen / max functional joint stiffness of the same kind."""
    ratios = []
    for rot in (False, True):
        functional = [abs(k) for j in model.joints.values()
                      for label, f in j.functional.items()
                      if f is not None and (k := _at(f.k, names, given))
                      and label.startswith("r") == rot]
        chosen = [out[r.k] for r in roles if r.kind.startswith("rot") == rot]
        if functional and chosen:
            ratios.append(min(chosen) / max(functional))
    return min(ratios) if ratios else None


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
