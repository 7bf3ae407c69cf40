"""The interface of a constraint method: what the constraint element L of a blocked joint
direction becomes (paper 11.2.5), and what that adds to each stage.

A method is an object with a ``name`` and these hooks, each called by one stage:

- **graph** (``expand``): ``constraint_element`` puts the elements of L on the joint
  direction's 0-junction; ``restructure`` is a pass over the expanded bond graph before
  causality (zcp's spanning tree and flow sources), returning the graph;
- **equations** (``codegen.equations``): ``embed`` changes the causal equations before
  they are sorted (zcp: the dependent momenta leave the states); ``stabilisation`` names
  the parameter of the Baumgarte rate of the multipliers' equations, if any;
- **initial conditions and run-time monitoring**: declared, not run, here. The generated
  module carries what the method made of each constraint (``CONSTRAINT_NAMES``,
  ``IMPOSED``, ``ALGEBRAIC``, the ``<method>__alpha`` and rank parameters) and
  ``methods.consistent`` projects the start onto the constraints and watches drift and
  rank from that alone, so a run imports no method (nor sympy). ``ideal`` says whether
  there are such constraints at all;
- **reports** (``bgc check``): ``report`` adds the method's own findings.

Methods are registered by name in ``bgc.methods`` (``REGISTRY``) and looked up with
``bgc.methods.get``. Adding one (a penalty or an augmented-Lagrangian method, say) means a
module here with a subclass, and a line in ``REGISTRY``: nothing outside ``methods/``
branches on a method's name.
"""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from bgc.graph.bondgraph import BondGraph
    from bgc.mechanics.joints import Direction
    from bgc.model.model import Joint


class ConstraintMethod(abc.ABC):
    """One way of handling a blocked joint direction. A subclass must say what L becomes
    (``constraint_element``) and overrides the other hooks it needs; their defaults add
    nothing."""

    name: str = ""
    # True: blocked directions are kinematic constraints (multipliers, imposed flows), held
    # by the equations; False: they are compliant elements, part of the model's dynamics
    # (which then also owns the joints' static loads: ``static_loads``).
    ideal: bool = False
    # True: the method passes singular configurations (the constraints losing rank, a
    # mechanism's dead point) and keeps its accuracy there, so the rank monitor that stops
    # a run at one (``consistent.RankMonitor``) does not watch its runs
    passes_singular: bool = False

    # --- graph ------------------------------------------------------------------------
    @abc.abstractmethod
    def constraint_element(self, ex, joint: Joint, d: Direction, zero: str) -> list[str]:
        """Add the element(s) of L for blocked direction ``d`` of ``joint`` through the
        expander ``ex`` (``ex.add``, ``ex.constraints``); return their names, which
        ``expand`` bonds to the direction's 0-junction ``zero``."""

    def restructure(self, graph: BondGraph, open_loops: bool = True) -> BondGraph:
        """A pass over the expanded graph before causality. ``open_loops``: whether
        kinematic loops may be opened (a method that never closes them ignores it)."""
        return graph

    # --- equations --------------------------------------------------------------------
    def embed(self, builder) -> None:
        """Change the causal equations of ``builder`` (``codegen.equations``) before they
        are sorted."""

    def constraint_equations(self, builder) -> list:
        """Define the unknowns the method's constraint elements introduced (multipliers)
        in ``builder``; return ``(name, g, dg/dt)`` of every constraint, for the generated
        module's ``constraints``."""
        return []

    def constraint_block(self, builder, block) -> tuple:
        """The constraint block (``equations.LinearBlock`` of the multipliers) as the
        method solves it, with the assignments it adds before it and after the block's
        chain (method augmented: its regularization and the projection's block)."""
        return [], block, []

    def parameters(self, model, constraints) -> list[tuple[str, float]]:
        """Parameters the method adds to the module (name, default value)."""
        return []

    @property
    def stabilisation(self) -> str | None:
        """The parameter of the multipliers' Baumgarte rate (``<name>__alpha``), or None
        where the method makes no multipliers."""
        return f"{self.name}__alpha" if self.ideal else None

    def role(self, constraint) -> str:
        """What a constraint's unknown is called in reports: ``lambda`` (a multiplier)."""
        return "lambda"

    def static_loads(self) -> bool:
        """Whether the joints' static loads are parameters of the module (compliant
        joints start deflected under them)."""
        return not self.ideal

    # --- reports ------------------------------------------------------------------------
    def report(self, compiled) -> tuple[dict, list[str]]:
        """``bgc check``: the method's own findings about a compiled model, as JSON fields
        and text lines."""
        return {}, []

    def hides_loop(self, loop) -> bool:
        """Whether ``bgc check`` reports an algebraic loop under the method's own heading
        (zcp: its flow-source and constraint blocks are zero-order causal paths)."""
        return False

    def storage(self, graph: BondGraph, name: str) -> str | None:
        """What the method made of storage element ``name``'s causality, if it changed it
        (zcp: a body's momentum imposed by a flow source)."""
        return None

    def __repr__(self) -> str:
        return f"<constraint method {self.name}>"
