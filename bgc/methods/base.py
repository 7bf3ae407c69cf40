"""The interface of a constraint method: what the constraint element L of a blocked joint
direction becomes (paper 11.2.5), and what that adds to each stage.

A method is an object with a ``name`` and these hooks, each called by one stage:

- **graph** (``expand``): ``constraint_element`` puts the elements of L on the joint
  direction's 0-junction; ``restructure`` is a pass over the expanded bond graph before
  causality (zcp's spanning tree and flow sources), returning the graph;
- **equations** (``codegen.equations``): the builder keeps one slot for the method's own
  state (``new_state``, in ``Equations.method_state``); ``massless_body`` may write a body
  of negligible mass's balance its own way; ``embed`` changes the causal equations before
  they are sorted (zcp: the dependent momenta leave the states); ``constraint_equations``
  defines the method's unknowns; for each algebraic loop, ``tear_first`` names the
  variables torn first and ``loop_block`` may solve the loop its own way (a
  ``LoopSolution``: a constraint block of its own, ``constraint_block``); ``loops_closed``
  says whether a module is an index-2 DAE; ``stabilisation`` names the parameter of the
  Baumgarte rate of the multipliers' equations, if any;
- **initial conditions and run-time monitoring**: declared, not run, here. The generated
  module carries what the method made of each constraint (``CONSTRAINT_NAMES``,
  ``IMPOSED``, ``ALGEBRAIC``, the ``<method>__alpha`` and rank parameters) and
  ``solvers.consistent`` projects the start onto the constraints and watches drift and
  rank from that alone, so a run imports no method (nor sympy). ``ideal`` says whether
  there are such constraints at all;
- **reports** (``bgc check``): ``report`` adds the method's own findings.

The hooks take public surfaces, declared here as protocols (``Expander``, ``Equations``,
``TornLoop``): a method reads and writes the stages through them and imports no stage's
code generator (``tests/test_layers.py``). Methods are registered by name in ``bgc.methods`` (``REGISTRY``) and looked up with
``bgc.methods.get``. Adding one (a penalty or an augmented-Lagrangian method, say) means a
module here with a subclass, and a line in ``REGISTRY``: nothing outside ``methods/``
branches on a method's name.
"""

from __future__ import annotations

import abc
from typing import TYPE_CHECKING, NamedTuple, Protocol

if TYPE_CHECKING:
    from bgc.graph.bondgraph import BondGraph
    from bgc.mechanics.joints import Direction
    from bgc.model.model import Joint
    from bgc.symbolic.linear import LinearBlock


class Expander(Protocol):
    """What ``constraint_element`` may do to the graph being expanded
    (``graph.expand.Expander``): add an element, record a constraint."""
    constraints: list

    def add(self, name: str, kind: str, loc, initial=None, orthogonal: bool = False,
            **fields) -> str: ...


class Equations(Protocol):
    """The causal equations as a method extends them (``codegen.builder.Builder``): the
    graph and model, the tables of equations, their origins and display names, the
    states, the states' corrections after a step (``projection``), and the method's own
    state (``method_state``, made by ``new_state``)."""
    g: BondGraph
    m: object
    eqs: dict
    origin: dict
    display: dict
    states: list
    projection: dict
    method_state: object

    def define(self, var, expr, element: str, bond: int | None = None) -> None: ...

    def port(self, name: str) -> tuple: ...

    def add_state(self, label: str, sym, dsym, initial, element: str) -> None: ...

    def algebraic_state(self, label: str, sym, dsym, residual, element: str) -> None: ...


class TornLoop(Protocol):
    """An algebraic loop as the equations stage tore it (``codegen.loops.Torn``): its
    variables (``comp``), tearing variables (``tears``, the method's ``tear_first``
    first), the others in causal order (``order``), the index its first block gets, its
    kind as ``bgc check`` reports it (``kind``: a method that solves it names it first);
    the loop's assignments after its tears (``chain``), the block reduced to its tears
    that the stage builds (``reduced_block``) and the error that names the loop
    (``refuse``)."""
    comp: list
    tears: list
    order: list
    index: int
    kind: str

    def chain(self) -> list: ...

    def reduced_block(self, rank=None, numeric_rhs: bool = False) -> LinearBlock: ...

    def refuse(self, why: str, hint: str) -> Exception: ...


class LoopSolution(NamedTuple):
    """A loop as a method solves it: how it was torn (for ``bgc check``) and its
    assignments (pairs and ``LinearBlock``s, in causal order)."""
    tearing: list[str]
    items: list


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
    def constraint_element(self, ex: Expander, joint: Joint, d: Direction,
                           zero: str) -> list[str]:
        """Add the element(s) of L for blocked direction ``d`` of ``joint`` through the
        expander ``ex`` (``ex.add``, ``ex.constraints``); return their names, which
        ``expand`` bonds to the direction's 0-junction ``zero``."""

    def restructure(self, graph: BondGraph, open_loops: bool = True) -> BondGraph:
        """A pass over the expanded graph before causality. ``open_loops``: whether
        kinematic loops may be opened (a method that never closes them ignores it)."""
        return graph

    def loops_closed(self, graph: BondGraph) -> bool:
        """Whether the method kept kinematic loops closed in ``graph`` (an index-2 DAE: a
        variant of its own, ``methods.variant``)."""
        return False

    # --- equations --------------------------------------------------------------------
    def new_state(self, builder: Equations) -> object:
        """The method's own state while the equations are built (``builder.method_state``:
        what its hooks learn and read again), or None."""
        return None

    def massless_body(self, builder: Equations, name: str, bond: int, sign: int, E,
                      F) -> bool:
        """Write the equations of a body of negligible mass (element ``name``: M0, on bond
        ``bond`` with power sign ``sign``, effort and flow columns ``E`` and ``F``) the
        method's way and return True, or return False for the element rule's own (the
        twist an algebraic unknown, defined by the balance of forces)."""
        return False

    def embed(self, builder: Equations) -> None:
        """Change the causal equations of ``builder`` (``codegen.equations``) before they
        are sorted."""

    def constraint_equations(self, builder: Equations) -> list:
        """Define the unknowns the method's constraint elements introduced (multipliers)
        in ``builder``; return ``(name, g, dg/dt)`` of every constraint, for the generated
        module's ``constraints``."""
        return []

    def tear_first(self, builder: Equations, comp: list) -> list:
        """The variables of algebraic loop ``comp`` to tear first (multipliers, dependent
        momenta): the loop's unknowns the method solves for."""
        return []

    def loop_block(self, builder: Equations, loop: TornLoop) -> LoopSolution | None:
        """Solve algebraic loop ``loop`` the method's way (a constraint block), or None for
        the equations stage's own ways (symbolically, or a numeric block)."""
        return None

    def constraint_block(self, builder: Equations, block: LinearBlock) -> tuple:
        """The method's constraint block (a ``LinearBlock`` its ``loop_block`` built) as
        the method solves it, with the assignments it adds before it and after the block's
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
