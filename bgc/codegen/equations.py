"""Stage **equations**: CausalGraph -> EquationSystem.

Every bond variable, storage rate and signal gets exactly one defining equation, read off
the causal strokes. The equations are sorted into causal order (block lower triangular,
Tarjan's SCCs) and kept as a list of assignments; they are never substituted into one
expression. Two things need more than sorting:

- **derivative causality**: a C or I whose causality is derivative has a dependent state
  g(x, t); its output is the total derivative sum(dg/dx_i * dx_i/dt) + dg/dt, which ties
  it to the integral states' rates in a *linear* loop;
- **algebraic loops** (R-R networks, derivative causality): each strongly connected block
  is torn (a small set of tearing variables is kept, the rest substituted), checked to be
  linear in the tearing variables and solved; a nonlinear loop is refused with the
  elements and bonds it runs through.
"""

from __future__ import annotations

import gc
from contextlib import contextmanager

import sympy as sp

from bgc import methods
from bgc.codegen import blocks, elements, shapes
from bgc.codegen.builder import Builder, State
from bgc.codegen.loops import MAX_SYMBOLIC_LOOP, dependencies, solve_loop
from bgc.codegen.system import EquationSystem, Loop
from bgc.graph.causality import CausalGraph
from bgc.graph.expand import AXES
from bgc.model import symbols
from bgc.symbolic.algorithms import is_cyclic, strongly_connected, substitute
from bgc.symbolic.forward_mode import trivial
from bgc.symbolic.linear import LinearBlock, Regularized

__all__ = ["Builder", "EquationSystem", "LinearBlock", "Loop", "MAX_SYMBOLIC_LOOP",
           "Regularized", "State", "derive"]


def build(b: Builder):
    """The causal equations of ``b``'s graph: the signals, every element by its kind's
    rule (``elements.RULES``; the elements of one shape derived once), the bodies'
    kinematics and the control blocks (``blocks.build``)."""
    for name, sig in b.m.signals.items():
        var = symbols.signal(name)
        b.define(var, sig.expr, name)
        b.display[var] = name
    for i, bond in enumerate(b.g.bonds):
        for var, tag in ((b.E(i), "e"), (b.F(i), "f")):
            if bond.dim == 1:
                b.display[var] = f"{bond.name}.{tag}"
            else:
                for k, v in enumerate(var):
                    b.display[v] = f"{bond.name}.{tag}{AXES[k]}"
    memo = shapes.RuleMemo(b)         # elements of one shape: derived once
    for name, el in b.g.elements.items():
        memo.apply(name, el, elements.RULES[el.kind])
    b.kinematics()
    blocks.build(b)


def derive(cg: CausalGraph, max_symbolic_loop: int = MAX_SYMBOLIC_LOOP,
           energy: bool = False, junctions: bool = False, cut=()) -> EquationSystem:
    """Build, sort and solve the causal equations of a causal graph. Loops with more
    than ``max_symbolic_loop`` tearing variables are solved numerically at run time.
    The method (what L became) was chosen by ``expand``; its hooks add its own
    equations and solve its own loops (``methods.base``). ``energy``: the energy
    variant, every element's work and activity as quadrature states (``codegen.energy``);
    ``junctions``: that and every junction bond's activity. ``cut``: (junction, bond,
    component or None) terms the junctions' sums leave out (a scene's junction-activity
    pass, ``scene.reduce.junctions``)."""
    with gc_paused():
        return _derive(cg, max_symbolic_loop, energy or junctions, junctions, cut)


@contextmanager
def gc_paused():
    """Python's cyclic garbage collector off for a while: building expressions allocates
    millions of acyclic sympy objects, and each full collection walks all that are alive,
    so the collections cost more than linearly with the model's size (about a fifth of
    the equations of a 40-link chain; half the emit stage of A02 with 160 windows, which
    ``pipeline.build`` and ``compile_model`` run paused too). What the pause allocated
    and kept is then frozen (``gc.freeze``): it never was in a collection, and the first
    one after the pause would walk all of it (0.6 s after A02 with 40 windows); acyclic
    sympy nodes are still freed by their reference counts."""
    was = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was:
            gc.freeze()
            gc.enable()


def _derive(cg: CausalGraph, max_symbolic_loop: int, energy: bool = False,
            junctions: bool = False, cut=()) -> EquationSystem:
    b = Builder(cg)
    b.cut = frozenset(cut)
    method = methods.get(cg.graph.method)
    b.method_state = method.new_state(b)
    build(b)
    b.resolve_refs()
    b.resolve_derivatives()
    method.embed(b)
    constraints = method.constraint_equations(b)
    deps = dependencies(b.eqs)
    assignments, loops, blocks = [], [], 0
    for comp in strongly_connected(list(b.eqs), deps):
        if is_cyclic(comp, deps):
            solved, loop = solve_loop(b, comp, deps, max_symbolic_loop, blocks)
            blocks += sum(isinstance(a, LinearBlock) for a in solved)
            assignments += solved
            loops.append(loop)
        else:
            assignments.append((comp[0], b.eqs[comp[0]]))
    assignments, aliases = _drop_aliases(assignments)
    outputs = [(o.name, o.expr.xreplace(b.refs).xreplace(aliases)) for o in b.m.outputs]
    params = [(symbols.param(p.name), p.name, p.value) for p in b.m.parameters.values()]
    if constraints:
        params += [(symbols.param(n), n, v) for n, v in method.parameters(b.m, constraints)]
        constraints = [(n, g if g is None else g.xreplace(aliases), r.xreplace(aliases))
                       for n, g, r in constraints]
    system = EquationSystem(b.m, method.name, b.states, params, assignments, outputs, loops,
                            {n: b.display[v] for n, v in b.dependent.items()}, b.display,
                            guards=b.guards, constraints=constraints,
                            imposed={c.name for c in cg.graph.constraints if c.imposed},
                            algebraic=[i for i, st in enumerate(b.states)
                                       if st.sym in set(b.algebraic)],
                            projection=[(i, b.projection[st.sym].xreplace(aliases))
                                        for i, st in enumerate(b.states)
                                        if st.sym in b.projection],
                            loops_closed=method.loops_closed(cg.graph), aliases=aliases)
    if energy:
        from bgc.codegen import energy as accounting
        accounting.account(b, system, aliases, junctions)
    for name in b.dependent:
        el = b.g.elements[name]
        if el.initial != 0:
            system.notes.append(f"{el.kind} '{name}' has derivative causality: its initial "
                                f"value {el.initial} is ignored (its state follows the "
                                "others)")
    return system


def _drop_aliases(assignments):
    """Inline assignments that only copy a variable (``e2 = e1``, ``f3 = -f1``) or a number;
    state derivatives stay, since the right-hand side returns them. Blocks get the final
    alias map (their chains name loop variables assigned after them)."""
    aliases: dict = {}
    kept = []
    for item in assignments:
        if isinstance(item, LinearBlock):
            kept.append(item)
            continue
        v, e = item
        e = substitute(e, aliases, {})    # (a memo of its own: the map grows)
        if trivial(e) and symbols.kind(v) != "rate":
            aliases[v] = e
        else:
            kept.append((v, e))
    kept = [it.xreplace(aliases) if isinstance(it, LinearBlock) else it for it in kept]
    return kept, aliases
