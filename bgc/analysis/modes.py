"""Modal analysis of the linearization about the static equilibrium (``bgc modes``): the
eigenvalues and eigenvectors of the Jacobian that ``frf.linearize`` makes, read as modes
(natural frequency, damping ratio, shape, the bodies that carry it).

- **Constraint subspace.** Under lagrange and zcp the state holds more than the
  mechanism's motions: the constraint rows g and dg/dt (``constraints``) are held by
  Baumgarte terms or imposed flows whose eigenvalues (-alpha, ...) are no modes of the
  structure. The motions that keep every constraint, the null space of the constraint
  rows' Jacobian (rows and columns equilibrated, rank as ``consistent`` judges it), is an
  invariant subspace of A (the constraint rows evolve by themselves); the modes are those
  of A restricted to it (the residual of that invariance is reported).
- **Rigid motions.** An idle spin or a free translation is a zero eigenvalue, defective
  (angle and rate), that round-off splits into a pair of size sqrt(eps ||A||); an
  eigenvalue within its own perturbation bound of zero (``RIGID`` times its condition
  number times eps ||A||) is such a motion, counted, not listed.
- **Parasitic modes.** Under parasitic, a mode whose eigenvalue follows the joints' stiff
  springs (``d ln|lambda| / d ln k`` above ``PARASITIC_RATE`` when every joint stiffness is
  scaled by k and its damping by sqrt(k), as ``methods.parasitic`` tells functional from
  parasitic modes) is of kind ``parasitic``: the joints' compliance, not the design.
- **Participation.** Each mode's bodies are weighted by their kinetic energy in its shape
  (m |dG|^2 + sum J |dtheta|^2, ``mechanism.Mechanism.energy``), the field's habit.
- **Resonances.** A peak of |H| (``frf.extrema``) is the resonance of the mode whose
  modal term C v w^H B / (w^H v) / (s - lambda) is largest there (``Modal.behind``); its
  frequency is that mode's natural frequency, whatever the output (a displacement's peak
  sits below it by damping, an acceleration's above it, a neighbouring zero pulls it).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from threadpoolctl import threadpool_limits

from bgc.analysis.frf import Linearization, central_differences

RIGID = 100.0           # an eigenvalue within RIGID kappa eps ||A|| of zero: a rigid motion
PARASITIC_RATE = 0.1    # d ln|lambda| / d ln k above this: a parasitic mode
SHARE = 0.05            # bodies listed: those with at least this share of a mode's energy
MAX_BODIES = 6
CLUSTER = 1e-6          # relative distance of eigenvalues treated as one (repeated) value


@dataclass
class Mode:
    eigenvalue: complex
    kind: str                                   # functional | parasitic | overdamped
    shape: np.ndarray                           # right eigenvector, full state (complex)
    bodies: list[tuple[str, float]] = field(default_factory=list)   # (body, energy share)
    index: int = 0                              # in the restricted eigenproblem

    @property
    def frequency_hz(self) -> float:
        """Natural frequency |lambda| / 2 pi."""
        return float(abs(self.eigenvalue) / (2 * np.pi))

    @property
    def damped_hz(self) -> float:
        """Damped natural frequency Im(lambda) / 2 pi (0: overdamped)."""
        return float(abs(self.eigenvalue.imag) / (2 * np.pi))

    @property
    def damping_ratio(self) -> float:
        return float(-self.eigenvalue.real / abs(self.eigenvalue))

    def to_dict(self, state_names=None, body_states: dict | None = None) -> dict:
        """The JSON form: frequency, damping, kind, bodies; the shape over the body pose
        coordinates (``body_states``: body -> {coordinate: state index}) as [re, im], or
        over every state (``state_names``) for a model without bodies."""
        sig = lambda v: float(f"{v:.9g}")  # noqa: E731
        out = {"frequency_hz": sig(self.frequency_hz),
               "damping_ratio": sig(self.damping_ratio),
               "damped_hz": sig(self.damped_hz), "kind": self.kind,
               "eigenvalue": [float(self.eigenvalue.real), float(self.eigenvalue.imag)],
               "bodies": [{"name": n, "share": round(s, 4)} for n, s in self.bodies]}
        pair = lambda z: [float(f"{z.real:.6g}"), float(f"{z.imag:.6g}")]  # noqa: E731
        if body_states:
            out["shape"] = {b: {c: pair(self.shape[i]) for c, i in coords.items()}
                            for b, coords in body_states.items()}
        elif state_names is not None:
            out["shape"] = {n: pair(v) for n, v in zip(state_names, self.shape)}
        return out


@dataclass
class Modal:
    """The modes of one linearization: every mode of the restricted A (rigid motions
    apart), lowest first, and what ``behind`` needs to attribute an FRF peak to one."""
    lin: Linearization
    modes: list[Mode]
    basis: np.ndarray | None        # the constraint subspace (None: the whole state)
    rigid: int                      # rigid motions (eigenvalues at zero)
    constraints: int                # rank of the constraint rows (0: none)
    invariance: float               # ||A N - N A_r|| / ||A||: how well N is invariant
    eig: tuple = ()                 # (lambda, left, right) of the restricted A
    states: int = 0

    def band(self, f_min: float = 0.0, f_max: float = np.inf) -> list[Mode]:
        return [m for m in self.modes if f_min <= m.frequency_hz <= f_max]

    def behind(self, output: str, peaks) -> list[Mode | None]:
        """The mode behind each peak frequency of ``output``'s |H|: the one whose modal
        term is largest there (None where no oscillatory mode reaches the output)."""
        lam, W, V = self.eig
        lin = self.lin
        k = list(lin.output_names).index(output)
        C, B = lin.C[k], lin.B
        if self.basis is not None:
            C, B = C @ self.basis, self.basis.T @ B
        norm = np.einsum("ij,ij->j", W.conj(), V)
        by_index = {m.index: m for m in self.modes if m.eigenvalue.imag > 0}
        cand = [i for i in by_index if abs(norm[i]) > 1e-12]
        res = {i: (C @ V[:, i]) * (W[:, i].conj() @ B) / norm[i] for i in cand}
        out = []
        for f in peaks:
            s = 2j * np.pi * f
            terms = {i: abs(r / (s - lam[i])) for i, r in res.items()}
            best = max(terms, key=terms.get, default=None)
            out.append(by_index[best] if best is not None and terms[best] > 0 else None)
        return out


def constraint_basis(module, x, p) -> tuple[np.ndarray | None, int]:
    """An orthonormal basis of the state motions that keep every constraint row (g and
    dg/dt of ``module.constraints``) to first order, and the rows' rank; (None, 0) for a
    module without constraints."""
    if not len(getattr(module, "CONSTRAINT_NAMES", ())):
        return None, 0
    from bgc.solvers.consistent import RANK_TOL, equilibration
    x = np.asarray(x, dtype=np.float64)
    J = central_differences(lambda y: module.constraints(0.0, y, p), x, rel=1e-7)
    # differences' round-off below the rank's tolerance is zero: equilibration would
    # scale a column of such noise up to the others (by 1e16 on the SARIB's legs, whose
    # frames are rotated exactly: its own zeros come out as 1e-16) and the basis with it
    J[np.abs(J) <= RANK_TOL * max(float(np.abs(J).max()), 1e-300)] = 0.0
    r, c = equilibration(J)
    _, s, vt = np.linalg.svd(J * r[:, None] * c[None, :])
    rank = int(np.sum(s > RANK_TOL * max(s[0] if len(s) else 0.0, 1e-300)))
    N = c[:, None] * vt[rank:].T            # back to the states' own units
    Q, _ = np.linalg.qr(N)
    return Q, rank


def analyse(module, model, lin: Linearization, mechanism=None, kinds: bool = True) -> Modal:
    """The modes of ``lin`` (``frf.linearize`` of ``module``): restricted to the constraint
    subspace, rigid motions set apart, parasitic modes marked (unless not ``kinds``: every
    damped one is then "functional"), bodies weighted by ``mechanism``
    (``mechanism.of_model``; none: no bodies listed)."""
    with threadpool_limits(1):      # as frf.Linearization.responses: faster on one
        return _analyse(module, model, lin, mechanism, kinds)


def _analyse(module, model, lin, mechanism, kinds) -> Modal:
    import scipy.linalg
    A = lin.A
    N, rank = constraint_basis(module, lin.x, lin.p)
    Ar = A if N is None else N.T @ A @ N
    scale = max(float(np.linalg.norm(A)), 1e-300)
    invariance = 0.0 if N is None else float(np.linalg.norm(A @ N - N @ Ar)) / scale
    lam, W, V = scipy.linalg.eig(Ar, left=True, right=True)
    kappa = 1.0 / np.maximum(np.abs(np.einsum("ij,ij->j", W.conj(), V)), 1e-300)
    rigid = np.abs(lam) <= RIGID * np.maximum(kappa, 1.0) * np.finfo(float).eps * \
        max(float(np.linalg.norm(Ar)), 1e-300)
    parasitic = _parasitic(module, model, lin, N, Ar, lam, W, V) \
        if model is not None and kinds else np.zeros(len(lam), dtype=bool)
    modes = []
    for i in np.argsort(np.abs(lam)):
        if rigid[i] or lam[i].imag < 0:
            continue
        if lam[i].imag == 0 and lam[i].real >= 0:
            kind = "unstable"
        else:
            kind = "parasitic" if parasitic[i] else (
                "overdamped" if lam[i].imag == 0 else "functional")
        shape = V[:, i] if N is None else N @ V[:, i]
        modes.append(_mode(lam[i], kind, shape, mechanism, i))
    return Modal(lin, modes, N, int(rigid.sum()), rank, invariance, (lam, W, V), len(A))


def _mode(lam, kind, shape, mechanism, index) -> Mode:
    """A Mode with its shape normalised (unit kinetic-energy weight, or unit largest
    component, its largest component real) and its bodies' energy shares."""
    bodies = []
    if mechanism is not None and mechanism.bodies:
        e = mechanism.energy(shape)
        total = sum(e.values())
        if total > 0:
            shape = shape / np.sqrt(total)
            ranked = sorted(((n, v / total) for n, v in e.items()), key=lambda t: -t[1])
            bodies = [(n, float(s)) for n, s in ranked if s >= SHARE][:MAX_BODIES]
            pose = np.concatenate([b.states for b in mechanism.bodies])
            j = pose[int(np.argmax(np.abs(shape[pose])))]
        else:
            j = int(np.argmax(np.abs(shape)))
    else:
        j = int(np.argmax(np.abs(shape)))
    if abs(shape[j]) > 0:
        shape = shape * (abs(shape[j]) / shape[j])
        if not bodies:
            shape = shape / abs(shape[j])
    return Mode(complex(lam), kind, shape, bodies, int(index))


def _parasitic(module, model, lin, N, Ar, lam, W, V) -> np.ndarray:
    """Which eigenvalues follow the joints' parasitic springs: every joint stiffness
    scaled by (1 + h) and its damping by sqrt(1 + h) (the loads kept: they do not depend
    on k), the first-order shift of each eigenvalue (of each cluster of equal ones
    together) from the left and right eigenvectors."""
    names = list(module.PARAM_NAMES)
    stiff, damp = [], []
    for jn in model.joints:
        for k, c in (("stiffness", "damping"), ("rot_stiffness", "rot_damping")):
            if f"{jn}__{k}" in names and f"{jn}__{c}" in names:
                stiff.append(names.index(f"{jn}__{k}"))
                damp.append(names.index(f"{jn}__{c}"))
    out = np.zeros(len(lam), dtype=bool)
    if not stiff:
        return out
    h = 1e-3
    q = lin.p.copy()
    q[stiff] *= 1 + h
    q[damp] *= np.sqrt(1 + h)
    dA = (module.jac(0.0, lin.x, q) - lin.A) / h
    if N is not None:
        dA = N.T @ dA @ N
    done = np.zeros(len(lam), dtype=bool)
    for i in range(len(lam)):
        if done[i]:
            continue
        cl = np.flatnonzero(~done & (np.abs(lam - lam[i])
                                     <= CLUSTER * max(abs(lam[i]), 1e-300)))
        done[cl] = True
        Wc, Vc = W[:, cl].conj().T, V[:, cl]
        try:
            d = np.linalg.eigvals(np.linalg.solve(Wc @ Vc, Wc @ dA @ Vc))
        except np.linalg.LinAlgError:
            continue            # a defective cluster (rigid motions): no first order
        if abs(lam[i]) > 0:
            rate = np.real(np.conj(lam[i]) * d) / abs(lam[i]) ** 2
            out[cl] = np.max(np.abs(rate)) > PARASITIC_RATE
    return out


def resonances(module, model, lin: Linearization, output: str, f_min: float, f_max: float,
               grid=None) -> tuple[list[float], list[float], list[float]]:
    """(anti-resonances, resonances, peaks) of ``output`` in the band: the minima of |H|,
    the natural frequencies of the modes behind its maxima (``Modal.behind``, in order,
    each once) and those maxima. What ``bgc frf`` and ``bgc sweep --frf`` report."""
    from bgc.analysis import frf
    anti, peaks = frf.extrema(lin, output, f_min, f_max, grid)
    behind = analyse(module, model, lin, kinds=False).behind(output, peaks) \
        if peaks else []
    return anti, natural(behind, peaks), peaks


def natural(behind: list, peaks) -> list[float]:
    """The resonances of peaks whose modes are ``behind`` (``Modal.behind``): each mode's
    natural frequency once, a peak no mode explains at its own frequency."""
    return sorted({md.frequency_hz if md is not None else f for md, f in zip(behind, peaks)})


def body_states(mechanism) -> dict:
    """body -> {pose coordinate: state index}, for ``Mode.to_dict``."""
    from bgc.analysis.mechanism import POSE
    return {b.name: dict(zip(POSE, b.states)) for b in mechanism.bodies} \
        if mechanism is not None else {}
