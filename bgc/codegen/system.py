"""The data structure of stage **equations**: the ``EquationSystem`` (states, parameters,
assignments in causal order, outputs, what the constraint method adds) and the algebraic
``Loop``s found on the way."""

from __future__ import annotations

from dataclasses import dataclass, field

import sympy as sp

from bgc import methods
from bgc.codegen.builder import State
from bgc.model.model import Model, Table


@dataclass
class Loop:
    """An algebraic loop (a strongly connected block of equations) and how it was solved."""
    kind: str            # "algebraic" | "derivative" (through a derivative-causal storage)
    variables: list[str]
    bonds: list[str]
    elements: list[str]
    tearing: list[str]

    def describe(self) -> str:
        return (f"{self.kind} loop through {', '.join(self.elements)} (bonds "
                f"{', '.join(self.bonds)}), {len(self.variables)} equations, solved for "
                f"{', '.join(self.tearing)}")


@dataclass
class EquationSystem:
    model: Model
    method: str
    states: list[State]
    params: list[tuple[sp.Symbol, str, float]]   # (symbol, name, default)
    assignments: list  # causal order: (symbol, expr) pairs and LinearBlocks
    outputs: list[tuple[str, sp.Expr]]
    loops: list[Loop] = field(default_factory=list)
    dependent: dict[str, str] = field(default_factory=dict)  # storage -> dependent state
    display: dict[sp.Symbol, str] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    # (what, margin expression): the run stops where a margin reaches GUARD_TOLERANCE
    guards: list[tuple[str, sp.Expr]] = field(default_factory=list)
    # lagrange: (joint.direction, deflection g or None, rate dg/dt) per multiplier
    constraints: list[tuple[str, sp.Expr | None, sp.Expr]] = field(default_factory=list)
    # zcp: the constraints whose flow is imposed (tree joints), not break variables
    imposed: set[str] = field(default_factory=set)
    # a DAE M dx/dt = rhs: the states whose row of M is zero (index 2: zcp, loops kept
    # closed); empty for an ODE
    algebraic: list[int] = field(default_factory=list)
    # method augmented: the projection onto the constraints after a step, as (state
    # index, its correction) (``methods.augmented``)
    projection: list[tuple[int, sp.Expr]] = field(default_factory=list)
    loops_closed: bool = False      # zcp: kinematic loops kept closed (--keep-loops)
    scene: str = ""                 # reduced for a scene (bgc/scene.py): its name
    # the energy variant (``codegen.energy``): (name, kind, column, body, joint) per
    # element whose energy and activity are quadrature states; None: the ordinary module
    energy: list | None = None
    # the junctions' variant: every junction bond's activity too (``codegen.energy``)
    junctions: bool = False
    # the states no equation reads (the energy variant's quadratures): left out where the
    # run-time side solves for the rates (static loads)
    quadrature: list[int] = field(default_factory=list)
    # the variables inlined as copies of others or numbers (``_drop_aliases``): a pass
    # that reads a bond's variable by name finds where it went
    aliases: dict = field(default_factory=dict)
    # parameters folded into constants (a scene's ``fold_parameters``): symbol -> value,
    # for what reads the model's parameters outside the equations (a signal's frequency)
    folded: dict = field(default_factory=dict)

    @property
    def variant(self) -> str:
        """What the generated module is named and hashed by: the method, for zcp whether
        its loops were kept closed (``zcp_closed``), the scene it was reduced for, and the
        energy variant (``_energy``, or ``_junctions`` with the junction bonds' activities)."""
        v = methods.variant(self.method, not self.loops_closed)
        v = f"{v}_{self.scene}" if self.scene else v
        if self.energy is None:
            return v
        return f"{v}_junctions" if self.junctions else f"{v}_energy"

    @property
    def tables(self) -> list[Table]:
        return self.model.tables

    @property
    def breakpoints(self) -> list[float]:
        return sorted({bp for s in self.model.signals.values() for bp in s.breakpoints})
