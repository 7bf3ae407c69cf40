"""Method pass **zcp** (paper 11.2.5.1): the constraint element L of a blocked joint
direction is an ideal flow source, and the zero-order causal paths (ZCPs) it creates are
found, classified and resolved.

With flow sources on the blocked directions, the bodies' inertias can no longer all
integrate: the flow a joint imposes fixes some velocity components of the body it carries
(derivative causality on those components of its mass or inertia I). This is done at the
equation level, per component (the graphical vector rule C1 would forbid a revolute's two
blocked rotations on a three-component inertia):

- a **spanning tree** of the joints from the fixed frame; every tree joint's blocked
  directions are flow sources, and each fixes one velocity component of the joint's child
  body, chosen where the joint's rows are best conditioned at the initial pose (column-
  pivoted QR, translations first). Those components are *dependent*: not states, but
  solved at run time from the imposed flows ``dg/dt = -alpha g`` (``alpha = zcp__alpha``
  keeps the positions on the constraints; 0 gives the ideal source ``dg/dt = 0``). The
  class-1 ZCP between a dependent (derivative) component and the integral ones is the
  linear solve of the dependent momenta, and their derivative-causal efforts (the joint
  forces) meet the integral momenta's rates in the constraint block;
- a joint that closes a **kinematic loop** (a tree's chord) would impose a flow the tree
  already fixes: a class-4 ZCP, a causal cycle whose topological loop is closed, an index-2
  DAE. It is opened with break variables: its blocked directions become effort sources
  whose efforts are solved with the others at the acceleration level (Baumgarte), so the
  result stays an explicit ODE for any integrator. ``open_loops=False`` (``--keep-loops``)
  keeps it closed: the break variables become algebraic states with the velocity-level
  equations ``0 = dg/dt + alpha g``, an index-2 DAE ``M dx/dt = f(x)`` (M: zero rows
  there) that only an integrator built for index 2 takes (native Radau, which scales
  those states' errors by h as Hairer's RADAU5 does); bgc refuses the others, naming
  the loop. Bodies of negligible mass cannot be kept closed (their relays are refused).

Class-2 (algebraic loops of R-like elements, topologically flat) and class-3 ZCPs (causal
cycles through one element's port, topologically open) are the algebraic loops the
equations stage finds; ``paths`` classifies everything for ``bgc check --method zcp``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
import sympy as sp

from bgc.errors import EquationError
from bgc.graph.bondgraph import BondGraph
from bgc.graph.expand import AXES, initial_pose, twist_row
from bgc.methods.multipliers import MultiplierState, Multipliers
from bgc.model import symbols

ALPHA = "zcp__alpha"
FIXED = "fixed_frame"
_ROTATION_WEIGHT = 1e-3     # pivot on translations first: they are the physical choice


@dataclass
class TreeJoint:
    """A joint of the spanning tree: its flow sources fix ``dependent`` components
    ((I element, axis index)) of ``child``."""
    joint: str
    parent: str | None
    child: str
    dependent: list[tuple[str, int]]


@dataclass
class KinematicLoop:
    """A class-4 ZCP: the closed chain of bodies and joints that ``cut`` closes."""
    cut: str
    joints: list[str]
    bodies: list[str]

    def describe(self) -> str:
        chain = " - ".join(b or FIXED for b in self.bodies)
        return f"kinematic loop {chain} (joints {', '.join(self.joints)}), closed by '{self.cut}'"


@dataclass
class Plan:
    tree: list[TreeJoint] = field(default_factory=list)
    loops: list[KinematicLoop] = field(default_factory=list)
    # joints of bodies of negligible mass: break variables, not flow sources
    relays: list[str] = field(default_factory=list)
    # loops kept closed (``open_loops=False``): their break variables are the algebraic
    # states of an index-2 DAE, M dx/dt = f(x) with zero rows of M
    closed: bool = False

    @property
    def dependent(self) -> list[tuple[str, int]]:
        return [d for tj in self.tree for d in tj.dependent]

    def storage(self, element: str) -> str | None:
        """How a body inertia's components are split, e.g. 'derivative (y, z: joint
        guide), integral (x)'; None if all integrate."""
        for tj in self.tree:
            dep = [AXES[k] for el, k in tj.dependent if el == element]
            if dep:
                free = [a for a in AXES if a not in dep]
                return (f"derivative ({', '.join(dep)}: imposed by joint '{tj.joint}')"
                        + (f", integral ({', '.join(free)})" if free else ""))
        return None


@dataclass
class Path:
    """One zero-order causal path of the report."""
    cls: int
    what: str
    elements: list[str]
    bonds: list[str]
    lines: list[int]
    key: list[str] = field(default_factory=list)   # its sources and storages, for a summary

    def to_dict(self) -> dict:
        return {"class": self.cls, "what": self.what, "elements": self.elements,
                "bonds": self.bonds, "lines": self.lines}

    def summary(self) -> str:
        """Lines, the path's sources and storages, and its bonds (abridged)."""
        key = self.key or self.elements
        bonds = ", ".join(self.bonds[:6]) + (f" and {len(self.bonds) - 6} more"
                                              if len(self.bonds) > 6 else "")
        return (f"lines {', '.join(map(str, self.lines))}; elements {', '.join(key)}"
                + (f" ({len(self.elements)} with the junction structure)"
                   if len(self.elements) > len(key) else "") + f"; bonds {bonds or 'none'}")


def _spanning_tree(graph: BondGraph):
    """(tree edges (joint, parent, child), chords, relays) by breadth-first search from
    the fixed frame, then from any body no joint connects to it; joints in file order.
    A body of negligible mass has no inertia to take derivative causality, so it stays
    out of the tree: its joints are *relays*, opened with break variables like chords,
    and its twist is a state (as under lagrange)."""
    bodies = graph.model.bodies
    massless = {n for n, b in bodies.items() if b.mass == 0}
    edges = [(name, graph.model.joints[name]) for name, dirs in graph.joints.items()
             if any(d.blocked for d in dirs)]
    seen, tree, chords, used = {None}, [], [], set()
    for root in [None] + [n for n in bodies if n not in massless]:
        if root is not None:
            if root in seen:
                continue
            seen.add(root)
        queue = [root]
        while queue:
            node = queue.pop(0)
            for name, j in edges:
                if name in used or node not in (j.body1, j.body2):
                    continue
                other = j.body2 if j.body1 == node else j.body1
                if other in massless:
                    continue
                used.add(name)
                if other in seen:
                    chords.append(name)
                else:
                    seen.add(other)
                    tree.append((name, node, other))
                    queue.append(other)
    relays = [name for name, _ in edges if name not in used]
    return tree, chords, relays


def _loop(cut: str, graph: BondGraph, parent: dict) -> KinematicLoop:
    """The tree path between the cut joint's bodies, closed by the cut joint."""
    j = graph.model.joints[cut]

    def up(n):
        out = [(n, None)]
        while n in parent:
            jn, n = parent[n]
            out[-1] = (out[-1][0], jn)
            out.append((n, None))
        return out
    a, b = up(j.body1), up(j.body2)
    common = next(n for n, _ in a if n in {m for m, _ in b})
    pa = a[:[n for n, _ in a].index(common) + 1]
    pb = b[:[n for n, _ in b].index(common)]
    bodies = [n for n, _ in pa] + [n for n, _ in reversed(pb)]
    joints = [jn for _, jn in pa[:-1]] + [jn for _, jn in reversed(pb)] + [cut]
    return KinematicLoop(cut, joints, bodies)


def _pivot_columns(A: np.ndarray, k: int) -> list[int]:
    """``k`` independent columns of ``A``, as QR with column pivoting picks them (the
    largest residual norm first), but with ties (within 1e-9) going to the lowest index
    and in Python's correctly rounded arithmetic: the choice, and so the generated code,
    is the same on every machine (LAPACK's pivoting broke ties of a symmetric mechanism
    by the last bits of its own rounding)."""
    cols = [[float(x) for x in A[:, j]] for j in range(A.shape[1])]
    chosen, basis = [], []
    for _ in range(k):
        residual = {}
        for j, col in enumerate(cols):
            if j in chosen:
                continue
            r = col
            for q in basis:
                d = math.fsum(a * b for a, b in zip(r, q))
                r = [a - d * b for a, b in zip(r, q)]
            residual[j] = (math.sqrt(math.fsum(a * a for a in r)), r)
        top = max(n for n, _ in residual.values())
        j = min(j for j, (n, _) in residual.items() if n >= top * (1 - 1e-9))
        n, r = residual[j]
        chosen.append(j)
        basis.append([a / n for a in r] if n > 0 else r)
    return sorted(chosen)


def assign(graph: BondGraph, open_loops: bool = True) -> BondGraph:
    """Choose the flow-source (tree) and break-variable (loop-closing) directions and the
    dependent velocity components; return a copy of the graph with its plan (``method_plan``) and
    its constraints marked ``imposed`` where L is a flow source (``graph`` unchanged)."""
    model = graph.model
    tree, chords, relays = _spanning_tree(graph)
    parent = {child: (name, par) for name, par, child in tree}
    plan = Plan(loops=[_loop(c, graph, parent) for c in chords], relays=relays)
    plan.closed = not open_loops
    if plan.relays and not open_loops:
        j = model.joints[plan.relays[0]]
        light = [n for n in (j.body1, j.body2) if n and model.bodies[n].mass == 0]
        raise EquationError(
            f"class-4 zero-order causal path: joint '{j.name}' meets body '{light[0]}' of "
            "negligible mass, where flow sources from its joints would impose one twist "
            "twice; bgc keeps only kinematic loops between bodies with mass closed (the "
            "massless body's twist has no rate to take), so nothing was run (t = 0)",
            loc=j.loc, key=f"joints.{j.name}",
            hint="let zcp open it with break variables (the default), or use --method "
                 "lagrange or parasitic")
    pose = initial_pose(model)
    for name, par, child in tree:
        j = model.joints[name]
        rows = np.array([twist_row(model, j, d, {child: 0}, pose, 6)
                         for d in graph.joints[name] if d.blocked])
        weights = np.array([1.0] * 3 + [_ROTATION_WEIGHT] * 3)
        cols = _pivot_columns(rows * weights, len(rows))
        block = rows[:, cols]
        if np.linalg.cond(block) > 1e10:
            raise EquationError(
                f"method zcp: the blocked directions of joint '{name}' do not fix "
                f"{len(rows)} independent velocity components of body '{child}'",
                loc=j.loc, key=f"joints.{name}", hint="use --method lagrange")
        dep = [(f"{child}__m", c) if c < 3 else (f"{child}__J", c - 3) for c in cols]
        plan.tree.append(TreeJoint(name, par, child, dep))
    imposed = {tj.joint for tj in plan.tree}
    closed = {lp.cut for lp in plan.loops} if plan.closed else set()
    return replace(graph, method_plan=plan, constraints=[
        replace(c, imposed=c.joint in imposed, closed=c.joint in closed)
        for c in graph.constraints])


def dependent_states(graph: BondGraph) -> list[tuple[sp.Symbol, sp.Symbol, str]]:
    """(momentum symbol, its rate's symbol, display name) of every dependent component."""
    out = []
    for el, k in graph.method_plan.dependent:
        label = f"{el.replace('__', '.')}.p{AXES[k]}"
        out.append((symbols.state(el, f"p{AXES[k]}"), symbols.dstate(el, f"p{AXES[k]}"),
                    label))
    return out


def embed(b) -> set:
    """In an equations builder: the dependent momenta stop being states; each gets the
    equation ``p = p + (dg/dt + alpha g)`` of a flow source of its tree joint, so that they
    form one linear loop (solved numerically, ``equations``) whose solution imposes the
    flows. Returns the dependent momenta."""
    g = b.g
    dep = dependent_states(g)
    syms = {s for s, _, _ in dep}
    b.states = [st for st in b.states if st.sym not in syms]
    state: MultiplierState = b.method_state
    state.dependent = dep
    alpha = symbols.param(ALPHA)
    imposed = [c for c in g.constraints if c.imposed]
    by_joint: dict[str, list] = {}
    for c in imposed:
        by_joint.setdefault(c.joint, []).append(c)
    plan: Plan = g.method_plan
    sources = [c for tj in plan.tree for c in by_joint[tj.joint]]   # as plan.dependent
    for c, (el, _), (p, _, label) in zip(sources, plan.dependent, dep):
        bond, s, E, F = b.port(c.element)
        gap = c.g if c.g is not None else sp.S.Zero
        b.eqs[p] = p - s * F + alpha * gap         # -s F: the direction's rate dg/dt
        b.origin[p] = (el, None)
        b.display[p] = f"{label} (dependent)"
    return syms


def paths(graph: BondGraph, system) -> list[Path]:
    """Every zero-order causal path of the compiled model, classified 1-4: flow sources of
    tree joints and dependent storage (1), algebraic loops (2-4), and what the plan
    opened or kept closed (4)."""
    plan = graph.method_plan
    out = _tree_paths(graph, plan) if plan is not None else []
    out += _dependent_paths(graph, system) + _algebraic_paths(graph, system)
    if plan is not None:
        out += _plan_loop_paths(graph, plan)
    return out


def _bonds_among(graph: BondGraph, names: set) -> list[str]:
    return [bd.name for bd in graph.bonds if bd.src in names and bd.dst in names]


def _lines(graph: BondGraph, names) -> list[int]:
    els = graph.elements
    return sorted({els[n].loc.line for n in names if n in els and els[n].loc})


def _tree_paths(graph: BondGraph, plan: Plan) -> list[Path]:
    """Class 1: each tree joint's flow sources imposing its child's velocity."""
    els, out = graph.elements, []
    for tj in plan.tree:
        srcs = [c.element for c in graph.constraints if c.joint == tj.joint]
        zeros = {f"{tj.joint}__{c.label}" for c in graph.constraints if c.joint == tj.joint}
        proj = {n for n in els if any(n.startswith(z + "__") for z in zeros)
                and els[n].kind == "MTF"}
        child = tj.child
        body = {n for n in els if n.startswith(f"{child}__") and els[n].kind != "Se"}
        names = set(srcs) | zeros | proj | body
        parts = {}
        for el, k in tj.dependent:
            parts.setdefault(el.replace("__", "."), []).append(AXES[k])
        fixed = ", ".join(f"{n} ({''.join(a)})" for n, a in parts.items())
        free = [f"{child}.{part}.p{a}" for part, el in (("m", f"{child}__m"),
                                                         ("J", f"{child}__J"))
                for k, a in enumerate(AXES) if (el, k) not in tj.dependent]
        labels = ", ".join(c.label for c in graph.constraints if c.joint == tj.joint)
        what = (f"joint '{tj.joint}': flow sources on {labels} "
                f"impose the velocity of {fixed}: derivative causality, the dependent "
                "momenta follow the integral ones" + (f" ({', '.join(free)}" if free
                                                      else " (of the parent bodies")
                + (f" and of '{tj.parent}')" if tj.parent and free else ")"))
        key = srcs + sorted({el for el, _ in tj.dependent})
        out.append(Path(1, what, sorted(names), _bonds_among(graph, names),
                        _lines(graph, names), key))
    return out


def _dependent_paths(graph: BondGraph, system) -> list[Path]:
    """Class 1: storage elements in derivative causality."""
    out = []
    for name, dep in system.dependent.items():
        lp = next((lp for lp in system.loops if name in lp.elements), None)
        names = set(lp.elements) if lp else {name}
        out.append(Path(1, f"{graph.elements[name].kind} '{name}' in derivative causality "
                           f"(dependent state {dep})", sorted(names),
                        lp.bonds if lp else [], _lines(graph, names)))
    return out


def _algebraic_paths(graph: BondGraph, system) -> list[Path]:
    """Classes 2-4: algebraic loops, by what closes them."""
    out = []
    for lp in system.loops:
        if lp.kind != "algebraic":
            continue
        ends = [(bd.src, bd.dst) for bd in graph.bonds if bd.name in lp.bonds]
        nodes = {n for e in ends for n in e}
        closed = bool(ends) and len(ends) > len(nodes) - _components(nodes, ends)
        if any(graph.elements[n].kind == "R" for n in lp.elements):
            cls, what = 2, "algebraic loop between resistors"
        elif closed:
            cls, what = 4, "causal cycle around a closed junction-structure loop"
        else:
            cls, what = 3, "causal cycle back to its own port (topologically open)"
        out.append(Path(cls, f"{what}: {lp.describe()}", lp.elements, lp.bonds,
                        _lines(graph, lp.elements)))
    return out


def _plan_loop_paths(graph: BondGraph, plan: Plan) -> list[Path]:
    """Class 4: the joints of massless bodies and the kinematic loops, opened with break
    variables or kept closed."""
    els, out = graph.elements, []
    for name in plan.relays:
        j = graph.model.joints[name]
        light = [n for n in (j.body1, j.body2) if n and graph.model.bodies[n].mass == 0]
        cut = [c for c in graph.constraints if c.joint == name]
        names = {c.element for c in cut}
        names |= {n for n in els if any(n.startswith(f"{b}__M0") for b in light)}
        what = (f"joint '{name}' of the bod{'ies' if len(light) > 1 else 'y'} of "
                f"negligible mass {', '.join(light)}: flow sources would meet at a "
                f"junction with no inertia; opened with {len(cut)} break variable(s) "
                f"({', '.join(c.name + '.break' for c in cut)}) solved with the "
                "body's twist rates")
        out.append(Path(4, what, sorted(names), _bonds_among(graph, names),
                        sorted(set(_lines(graph, names)) | {j.loc.line}),
                        [c.element for c in cut]))
    for kl in plan.loops:
        names = {c.element for c in graph.constraints if c.joint in kl.joints}
        names |= {n for n in els if any(n.startswith(f"{b}__") for b in kl.bodies if b)}
        cut = [c for c in graph.constraints if c.joint == kl.cut]
        what = (f"{kl.describe()}: kept closed, an index-2 DAE: {len(cut)} algebraic "
                f"state(s) ({', '.join(c.name + '.lambda' for c in cut)}) with "
                "0 = dg/dt + alpha g" if plan.closed else
                f"{kl.describe()}: opened with {len(cut)} break variable(s) "
                f"({', '.join(c.name + '.break' for c in cut)})")
        joints = [graph.model.joints[j] for j in kl.joints]
        out.append(Path(4, what, sorted(names), _bonds_among(graph, names),
                        sorted(set(_lines(graph, names)) | {j.loc.line for j in joints}),
                        [c.element for c in cut]))
    return out


def _components(nodes: set, edges) -> int:
    parent = {n: n for n in nodes}

    def find(n):
        while parent[n] != n:
            parent[n] = parent[parent[n]]
            n = parent[n]
        return n
    for a, c in edges:
        parent[find(a)] = find(c)
    return len({find(n) for n in nodes})


class Zcp(Multipliers):
    """Zero-order causal paths (paper 11.2.5.1): starts from lagrange's effort sources and
    turns the blocked directions of a spanning tree's joints into flow sources
    (``assign``), whose imposed flows make the children's momenta dependent (``embed``);
    the joints that close kinematic loops keep multipliers (break variables), or stay
    closed as an index-2 DAE with ``open_loops`` False."""

    name = "zcp"

    def restructure(self, graph, open_loops=True):
        return assign(graph, open_loops)

    def embed(self, builder):
        embed(builder)

    def role(self, constraint) -> str:
        return "e" if constraint.imposed else "break"

    def hides_loop(self, loop) -> bool:
        return loop.kind in ("imposed-flow", "constraint")

    def loops_closed(self, graph) -> bool:
        return graph.method_plan is not None and graph.method_plan.closed

    def storage(self, graph, name):
        plan = graph.method_plan
        return plan.storage(name) if plan is not None else None

    def report(self, compiled):
        s = compiled.system
        found = paths(compiled.causal.graph, s)
        n_imp = len(s.imposed)
        lines = [f"zero-order causal paths: {len(found) or 'none'} ({n_imp} flow sources, "
                 f"{len(s.constraints) - n_imp} break variables)"]
        for z in found:
            lines += [f"  class {z.cls}: {z.what}", f"    {z.summary()}"]
        return {"zcp_paths": [z.to_dict() for z in found]}, lines
