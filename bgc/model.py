"""The Model: what a model file says, checked and parsed, before any graph is built.

Element kinds are described by ``KINDS``: how many bonds they take, which keys they accept,
which constitutive-law keys are alternatives, and whether they may be modulated by the
state of the graph (the M- elements).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp

from .errors import Loc


@dataclass(frozen=True)
class KindSpec:
    ports: int | None          # number of bonds; None = any number >= 2 (junctions)
    laws: tuple[str, ...]      # exactly one of these keys is required (empty: none)
    initial: str | None = None  # key of the initial condition (storage elements)
    modulated: bool = False    # law may read states and bond variables
    local: tuple[str, ...] = ()  # local variables the law may use
    doc: str = ""


KINDS: dict[str, KindSpec] = {
    "Se": KindSpec(1, ("effort",), doc="effort source"),
    "Sf": KindSpec(1, ("flow",), doc="flow source"),
    "MSe": KindSpec(1, ("effort",), modulated=True, doc="modulated effort source"),
    "MSf": KindSpec(1, ("flow",), modulated=True, doc="modulated flow source"),
    "C": KindSpec(1, ("C", "k", "effort"), initial="q0", local=("q",),
                  doc="capacitor / spring: e = q/C, e = k*q, or effort(q)"),
    "I": KindSpec(1, ("I", "flow"), initial="p0", local=("p",),
                  doc="inertia / inductor: f = p/I or flow(p)"),
    "R": KindSpec(1, ("R", "effort", "flow"), local=("e", "f"),
                  doc="resistor: e = R*f, effort(f) or flow(e)"),
    "TF": KindSpec(2, ("ratio",), doc="transformer: e1 = ratio*e2, f2 = ratio*f1"),
    "MTF": KindSpec(2, ("ratio",), modulated=True, doc="modulated transformer"),
    "GY": KindSpec(2, ("r",), doc="gyrator: e1 = r*f2, e2 = r*f1"),
    "MGY": KindSpec(2, ("r",), modulated=True, doc="modulated gyrator"),
    "0": KindSpec(None, (), doc="common-effort junction"),
    "1": KindSpec(None, (), doc="common-flow junction"),
}

SOURCES = ("Se", "Sf", "MSe", "MSf")
STORAGE = ("C", "I")
TWO_PORTS = ("TF", "MTF", "GY", "MGY")
JUNCTIONS = ("0", "1")
# Standard power direction of a one-port: into C, I, R; out of a source.
POWER_IN = ("C", "I", "R")


@dataclass(frozen=True)
class Parameter:
    name: str
    value: float
    loc: Loc
    unit: str | None = None


@dataclass(frozen=True)
class Table:
    """Points of a table signal, interpolated linearly and held constant outside."""
    index: int
    t: tuple[float, ...]
    y: tuple[float, ...]


@dataclass(frozen=True)
class Signal:
    name: str
    kind: str
    expr: sp.Expr               # a function of t (tables through the ``table`` function)
    loc: Loc
    breakpoints: tuple[float, ...] = ()


@dataclass
class Element:
    name: str
    kind: str
    loc: Loc
    fields: dict[str, sp.Expr] = field(default_factory=dict)
    field_locs: dict[str, Loc] = field(default_factory=dict)
    initial: sp.Expr | None = None      # in terms of parameters
    description: str | None = None

    @property
    def law(self) -> str | None:
        """The constitutive-law key this element was given (e.g. 'C', 'k', 'effort')."""
        for key in KINDS[self.kind].laws:
            if key in self.fields:
                return key
        return None


@dataclass(frozen=True)
class Bond:
    name: str
    src: str        # power flows from src ...
    dst: str        # ... to dst (the half arrow points at dst)
    loc: Loc
    dim: int = 1


@dataclass(frozen=True)
class Output:
    name: str
    expr: sp.Expr
    loc: Loc


@dataclass(frozen=True)
class Settings:
    """Default run settings a model file may carry (``simulation:``)."""
    t_end: float = 1.0
    rtol: float = 1e-6
    atol: float = 1e-8
    solver: str = "bdf"
    points: int = 1001


@dataclass
class Model:
    name: str
    file: str
    digest: str                      # hash of the model's content (not of its comments)
    parameters: dict[str, Parameter]
    signals: dict[str, Signal]
    tables: list[Table]
    elements: dict[str, Element]
    bonds: list[Bond]
    outputs: list[Output]
    settings: Settings
    description: str | None = None

    def param_values(self) -> dict[sp.Symbol, float]:
        from . import symbols
        return {symbols.param(p.name): p.value for p in self.parameters.values()}
