"""What the benchmarks run: scenarios (a model, an excitation, a time window, the outputs
whose error counts), the generated modules they need, and their reference solutions.

Every run of a scenario goes through ``Bench.run`` so that all integrators and methods are
timed on the same generated code, with the same parameters and the same start: a window
that begins inside a long excitation (the SARIB chirp around its anti-resonance) starts
from the state a tight run reached there (``Bench.start``, one per method and parameter
set), so the window's runs cost only the window.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from bgc.errors import SimulationError
from bgc.model import load
from bgc.pipeline import ensure_module
from bgc.simulate import Result, prepare, simulate

MODELS = Path(__file__).resolve().parents[2] / "models"
# the references' tolerance (a scenario may ask for less: see Scenario.ref_tol)
TIGHT = 1e-10
# the run to a window's start: every run of the window starts from the same state, so its
# accuracy does not enter any error; it only has to be a state the excitation reaches
START_TOL = 1e-8


@dataclass(frozen=True)
class Scenario:
    """One question a benchmark asks of a model."""
    name: str
    title: str
    model: Path
    t_end: float
    outputs: tuple[str, ...]           # whose error is measured
    t_start: float = 0.0
    excitation: tuple[str, str, float | None] | None = None   # kind, direction, frequency
    points: int = 1001
    published: dict | None = None      # output -> value at t_end (a published reference)
    reference_method: str = "lagrange"  # the ideal-constraint reference
    note: str = ""
    ref_tol: float = TIGHT             # the reference's rtol = atol


def sarib(name: str) -> Scenario:
    """The SARIB scenarios: the paper's pumping chirp (5 -> 25 Hz over 5..25 s, 28 s), a
    3 s window of it around the anti-resonance (16.5..19.5 s: 16.5 -> 19.5 Hz, the
    hinge forces' minimum at 17.96 Hz), and a 2 s sine dwell at 18 Hz from rest."""
    forces = ("a_OF_z", "F_A1_x", "F_A1_z", "F_A2_x", "F_A2_z")
    model = MODELS / "sarib.yaml"
    if name == "sarib_chirp":
        # peers only (errors of 1e-3 .. 1e-2 at rtol 1e-5): a reference at 1e-8 is 1e4
        # times finer and costs minutes, where 1e-10 costs half an hour
        return Scenario(name, "SARIB pumping chirp 5 -> 25 Hz, 28 s", model, 28.0, forces,
                        excitation=("chirp", "pumping", None), points=28001, ref_tol=1e-8)
    if name == "sarib_chirp_window":
        return Scenario(name, "SARIB pumping chirp, window 16.5..19.5 s (anti-resonance)",
                        model, 19.5, forces, t_start=16.5,
                        excitation=("chirp", "pumping", None), points=3001)
    if name == "sarib_sine":
        return Scenario(name, "SARIB pumping sine dwell at 18 Hz, 2 s from rest", model,
                        2.0, forces, excitation=("sine", "pumping", 18.0), points=2001)
    raise KeyError(name)


# Andrews' squeezer at t = 0.03: the IVP test set's reference (PSIDE at tol 1e-14)
ANDREWS_REF = {"beta": 15.81077119629904, "Theta": -15.75637105984298,
               "gamma": 0.04082224013073101, "Phi": -0.5347301163226948,
               "delta": 0.5244099658805304, "Omega": 0.5347301163226948,
               "epsilon": 1.048080741042263}
ANDREWS = Scenario("andrews", "Andrews' squeezer to t = 0.03 s (IVP test set)",
                   MODELS / "andrews.yaml", 0.03, tuple(ANDREWS_REF), points=31,
                   published=ANDREWS_REF,
                   note="error: largest relative deviation of the seven angles at t = 0.03 "
                        "from the IVP test set's reference")

# the small scale of every part (``bgc bench --quick``, the tests): a slider-crank
SLIDER = Scenario("slider_crank", "slider-crank falling from rest, 0.2 s",
                  MODELS / "slider_crank.yaml", 0.2, ("A_x", "A_z", "slider_x"), points=101)


@dataclass
class Bench:
    """Generated modules (in ``build``, not the repository's generated/), window starts
    and references, each made once per benchmark run."""
    build: Path
    log: object = print
    _starts: dict = field(default_factory=dict)
    _refs: dict = field(default_factory=dict)

    def module(self, scn: Scenario, method: str):
        """The scenario's module under ``method`` (``zcp_closed``: zcp, loops kept closed)."""
        closed = method == "zcp_closed"
        mod, _, _ = ensure_module(scn.model, self.build, "zcp" if closed else method,
                                  open_loops=not closed)
        return mod

    def model(self, scn: Scenario):
        return load.load(scn.model)

    def params(self, scn: Scenario, mod, overrides: dict | None = None) -> np.ndarray:
        """The module's parameters with the scenario's excitation and ``overrides``."""
        p = np.array(mod.PARAMS, dtype=np.float64)
        names = list(mod.PARAM_NAMES)
        if scn.excitation is not None:
            kind, direction, freq = scn.excitation
            for name, value in self.model(scn).excitation.select(kind, direction, None,
                                                                 freq).items():
                p[names.index(name)] = value
        for name, value in (overrides or {}).items():
            p[names.index(name)] = value
        return p

    def start(self, scn: Scenario, method: str, mod, p) -> tuple[np.ndarray | None, np.ndarray]:
        """State and parameters at ``scn.t_start``: a tight native run from t = 0 (None,
        ``p``: the window starts at 0)."""
        if scn.t_start == 0:
            return None, p
        key = (scn.name, method, p.tobytes())
        if key not in self._starts:
            self.log(f"  [{scn.name}] {method}: run to the window's start t = "
                     f"{scn.t_start:g} s at rtol = atol = {START_TOL:g}")
            r = simulate(mod, t_end=scn.t_start, rtol=START_TOL, atol=START_TOL,
                         solver="native",
                         params=p, points=2)
            self._starts[key] = (r.x[-1].copy(), r.params.copy())
        return self._starts[key]

    def initial(self, scn: Scenario, method: str, overrides: dict | None = None):
        """(module, state, parameters) at the scenario's start, prepared as a run would
        (loads, projection, rank): what the stability limits are computed at."""
        mod = self.module(scn, method)
        p = self.params(scn, mod, overrides)
        x0, p = self.start(scn, method, mod, p)
        x, p, _ = prepare(mod, mod.initial_state(p) if x0 is None else x0, p, scn.t_start)
        return mod, x, p

    def run(self, scn: Scenario, method: str, solver: str, rtol: float,
            atol: float | None = None, overrides: dict | None = None, x0=None,
            **kw) -> Result:
        """One run of the scenario (from ``x0`` if given; ``kw`` go to ``simulate``:
        step, check_stability, ...)."""
        mod = self.module(scn, method)
        p = self.params(scn, mod, overrides)
        start, p = self.start(scn, method, mod, p)
        x0 = start if x0 is None else x0
        return simulate(mod, t_start=scn.t_start, t_end=scn.t_end, rtol=rtol,
                        atol=rtol if atol is None else atol, solver=solver, params=p,
                        x0=x0, points=scn.points, **kw)

    def reference(self, scn: Scenario, method: str | None = None) -> tuple:
        """The scenario's reference outputs and how they were made: published values, or
        ``method``'s model (default: the ideal-constraint one) at rtol = atol =
        ``scn.ref_tol`` (1e-10) with native Radau, with its own accuracy: the same model and tolerance under
        CVODE (variable-order BDF, another integrator family)."""
        if scn.published is not None:
            return scn.published, "published (IVP test set)"
        method = method or scn.reference_method
        if (scn.name, method) not in self._refs:
            tol = scn.ref_tol
            self.log(f"  [{scn.name}] reference: {method}, native, rtol = atol = {tol:g}")
            ref = self.run(scn, method, "native", tol)
            note = f"{method} model, native Radau IIA, rtol = atol = {tol:g}"
            try:
                check = self.run(scn, method, "cvode", tol)
                spread = self.error(scn, check, ref.y)
                note += f"; CVODE at the same tolerance differs by {spread:.2g}"
            except SimulationError as exc:
                note += f"; CVODE at the same tolerance failed ({exc})"
            self._refs[scn.name, method] = (ref.y, note)
        return self._refs[scn.name, method]

    def error(self, scn: Scenario, result: Result, ref) -> float:
        """Largest error over the scenario's outputs, each relative to its reference's
        largest magnitude over the window, but at least 1e-3 of the largest output's (an
        output that stays zero by symmetry measures nothing); published values: at
        t_end, each relative to itself."""
        if isinstance(ref, dict):
            return max(abs(result.column(k)[-1] - v) / abs(v) for k, v in ref.items())
        cols = [result.output_names.index(k) for k in scn.outputs]
        y, r = result.y[:, cols], ref[:, cols]
        if len(y) != len(r):
            return float("nan")
        size = np.abs(r).max(axis=0)
        size = np.maximum(size, 1e-3 * size.max())
        return float((np.abs(y - r).max(axis=0) / size).max())


FOUR_BAR = Scenario("four_bar", "spatial RSSR four-bar, 1 s", MODELS / "four_bar.yaml", 1.0,
                    ("crank_angle", "rocker_angle"), points=101)
BRICARD = Scenario("bricard", "Bricard's overconstrained mechanism, 1 s",
                   MODELS / "bricard.yaml", 1.0, ("tip_x", "tip_y", "tip_z", "P3_x",
                                                  "P3_y", "P3_z"), points=101)
