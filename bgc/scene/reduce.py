"""Stage **reduce**: model no more than a scene needs.

A scene asks for some outputs under one excitation; each pass below removes what cannot
change those outputs and reports what it did (``PassReport``), in this order:

- ``merge_relays`` (``bgc.scene.merge_relays``; Model -> Model, before the equations
  are derived): a chain of bodies of negligible mass that only relay forces between two
  bodies (two revolutes with perpendicular, intersecting axes; a slider and such a pair)
  becomes the one joint it is (``universal``, ``prismatic_universal``), its springs, dampers and actuators moved
  onto the joint's free directions. The relays' poses and twists are no states and their
  balance no algebraic loop. Exact for ideal joints (methods lagrange, zcp); under
  parasitic the chain's three joints' compliance becomes one joint's, which changes
  the model by its parasitic error, so there the pass runs only where the scene asks
  (``merge_relays: true``).
- ``fold_parameters``: parameters the scene does not expose become constants, and the
  assignments they make constant are propagated (a zero damper, a zero preload vanish);
  the parameters bgc itself sets at run time (joint loads, the excitation's selectors,
  the constraint rank) stay parameters.
- ``idle_dofs``: the spin of a body about its own axis when no force can act on it (every
  joint of the body a spherical joint on that axis, the two other principal moments
  equal, at rest about it): its momentum stays zero, so it is no state (the MGB bars).
- ``activity`` (only where a scene asks, ``activity: {keep: 0.999}``): the least active
  elements over the scene's run (Louca et al.'s activity, int |P| dt, measured by the
  full model's energy variant, ``bgc energy``) whose shares sum to at most 1 - keep
  leave the model: a spring, mass or damper that only adds its effort to a 1-junction's
  balance (or its flow to a 0-junction's) has that contribution set to zero, and its
  state, read by nothing else then, goes. Not exact: the scene's report gives the
  outputs' error against the full model.
- ``prune``: outputs the scene does not ask for, and states that cannot reach the asked
  ones through the equations, are removed.

Before them all (only where a scene asks, ``activity: {junctions: 0.99}``), ``junctions``:
Rideout, Stein and Louca's junction inactivity. At each 0- or 1-junction (each
component of a body's 3-dimensional ones) every bond's activity over the scene's run
is compared with the sum of its bonds'; the least active bonds that bring the summed
variable in (an effort into a 1-junction, a flow into a 0-junction), whose shares add
up to at most 1 - junctions, are cut there: the junction no longer feels them (their
term of its sum is zero), while the bond still carries the junction's common flow or
effort to the other side, a modulated source there (MSf, MSe). The equations are
derived again with those terms left out (``equations.derive(cut=...)``): causality and
every state stay as they were. Where the cuts leave a part of the model reading
another without being read by it, the model has split into a driving and a driven
part; ``prune`` then removes a driven part no output needs. Not exact either.

The passes after ``merge_relays`` work on the EquationSystem and, but ``activity``, are
exact: what they remove is identically zero or cannot influence the outputs
(``idle_dofs`` drops the moments of joint forces whose lever arm across the axis is
round-off of the model's coordinates, below 1e-9 m).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import sympy as sp

from bgc import methods
from bgc.codegen.emit import _defines, _free, cone
from bgc.codegen.equations import EquationSystem, LinearBlock
from bgc.mechanics import exact
from bgc.graph.expand import AXES
from bgc.model import symbols
from bgc.scene.merge_relays import end_owner

# parameters bgc writes at run time: never folded
RUNTIME_PARAMS = ("_load", "excitation__", "lagrange__rank")
# geometry and inertia closer than this (relative) are taken as equal
TOLERANCE = 1e-9


@dataclass
class PassReport:
    name: str
    states_before: int
    states_after: int
    assignments_before: int
    assignments_after: int
    removed: list[str] = field(default_factory=list)   # what the pass took out
    note: str = ""
    # activity: the full model's run (a simulate.Result, not written) and the reduced
    # module's outputs' largest difference from it, relative to each output's peak
    reference: object = field(default=None, repr=False)
    error: dict | None = None
    # junctions: the terms cut (``Cut.to_dict``) and the parts the model split into
    cuts: list | None = None
    parts: list | None = None

    def to_dict(self) -> dict:
        out = {"pass": self.name, "states_before": self.states_before,
               "states_after": self.states_after,
               "assignments_before": self.assignments_before,
               "assignments_after": self.assignments_after,
               "removed": self.removed, "note": self.note}
        if self.cuts is not None:
            out["cuts"] = self.cuts
            out["parts"] = self.parts
        if self.error is not None:
            out["output_error"] = self.error
        return out


def _substitute(system: EquationSystem, mapping: dict) -> EquationSystem:
    """``mapping`` (symbol -> constant) substituted everywhere, and every assignment that
    becomes constant propagated forward (kept where it defines a state's rate)."""
    rates = {st.dsym for st in system.states}
    mapping = dict(mapping)
    assignments = []
    for item in system.assignments:
        if isinstance(item, LinearBlock):
            assignments.append(item.xreplace(mapping))
            continue
        v, e = item
        e = e.xreplace(mapping)
        if e.is_Number and v not in rates:
            mapping[v] = e
            continue
        assignments.append((v, e))
    return replace(
        system, assignments=assignments,
        outputs=[(n, e.xreplace(mapping)) for n, e in system.outputs],
        states=[replace(st, initial=st.initial.xreplace(mapping)) for st in system.states],
        guards=[(w, e.xreplace(mapping)) for w, e in system.guards],
        constraints=[(n, None if g is None else g.xreplace(mapping), r.xreplace(mapping))
                     for n, g, r in system.constraints])


def _keep_states(system: EquationSystem, keep: list) -> EquationSystem:
    """Only the states in ``keep`` (State objects, in order); algebraic indices follow."""
    old = {id(st): i for i, st in enumerate(system.states)}
    algebraic = {i for i in system.algebraic}
    return replace(system, states=keep,
                   algebraic=[k for k, st in enumerate(keep) if old[id(st)] in algebraic])


def report(name, before: EquationSystem, after: EquationSystem, removed, note=""):
    """The PassReport of a pass that took ``before`` to ``after``."""
    return PassReport(name, len(before.states), len(after.states), len(before.assignments),
                      len(after.assignments), removed, note)


# --- passes ---------------------------------------------------------------------------
def fold_parameters(system: EquationSystem, values: dict, expose=()) -> tuple:
    """Parameters not in ``expose`` (nor set by bgc at run time) become constants at
    ``values`` (name -> value; default: the model's)."""
    keep, mapping = [], {}
    for sym, name, default in system.params:
        if name in expose or any(k in name for k in RUNTIME_PARAMS):
            keep.append((sym, name, values.get(name, default)))
        else:
            v = float(values.get(name, default))
            mapping[sym] = exact.rational(v)
    out = replace(_substitute(system, mapping), params=keep,
                  folded={**system.folded, **mapping})
    folded = sorted(name for sym, name, _ in system.params if sym in mapping)
    return out, report("fold_parameters", system, out, folded,
                        f"{len(mapping)} of {len(system.params)} parameters folded, "
                        f"{len(keep)} kept")


def idle_dofs(system: EquationSystem, outputs=None) -> tuple:
    """Drop the momentum of each body's idle spin (see the module's docstring), unless
    one of ``outputs`` (default: all) reads it."""
    m = system.model
    if methods.get(system.method).ideal:
        return system, report("idle_dofs", system, system, [],
                               f"method {system.method}: the spin's rate is an unknown of "
                               "the constraint block, left as it is")
    by_name = {st.name: st for st in system.states}
    zero, notes = {}, []
    for body in m.bodies.values():
        axis = _idle_axis(m, body)
        if axis is None:
            continue
        st = by_name.get(f"{body.name}.J.p{'xyz'[axis]}")
        if st is None or sp.sympify(st.initial).is_zero is not True:
            continue
        zero[st.sym] = sp.Integer(0)
        notes.append(st.name)
    read = [n for n, e in system.outputs if (outputs is None or n in outputs)
            and cone(system.assignments, [e])[1] & set(zero)]
    if read:     # an output reads a spin: it is not idle for this scene
        return system, report("idle_dofs", system, system, [],
                               f"outputs {', '.join(read)} read a spin: kept")
    out = _substitute(system, zero)
    out = _keep_states(out, [st for st in out.states if st.sym not in zero])
    return out, report("idle_dofs", system, out, notes,
                        f"{len(notes)} bodies spin freely about their own axis")


def _idle_axis(m, body) -> int | None:
    """The body-frame axis about which nothing can turn ``body``: every joint on it is
    spherical with its centre on that axis through G, nothing else is bonded to it, the
    other two principal moments are equal, and it starts at rest about it. Moments
    given by parameters may be changed by ``-p``: no axis is idle for sure then."""
    if body.mass <= 0 or body.inertia_expr is not None or body.omega_expr is not None:
        return None
    joints = [j for j in m.joints.values() if body.name in (j.body1, j.body2)]
    if not joints or any(j.kind != "spherical" for j in joints):
        return None
    if any(end_owner(end, m) == body.name for b in m.bonds for end in (b.src, b.dst)):
        return None
    R = np.array(body.frame, dtype=float)            # columns: body axes in R0
    arms = [R.T @ (np.array(j.at) - np.array(body.com)) for j in joints]
    scale = max([1.0] + [float(np.abs(a).max()) for a in arms])
    inertia = np.array(body.inertia, dtype=float)
    for axis in range(3):
        a, b = (k for k in range(3) if k != axis)
        if abs(inertia[a] - inertia[b]) > TOLERANCE * max(inertia[a], inertia[b]):
            continue
        if any(abs(r[a]) > TOLERANCE * scale or abs(r[b]) > TOLERANCE * scale for r in arms):
            continue
        if abs(float(np.dot(np.array(body.omega), R[:, axis]))) > 0:
            continue
        return axis
    return None


def removable(cg, name: str) -> tuple[str | None, str]:
    """Whether an element can leave the model by activity (``activity``): ('effort' or
    'flow', the variable it puts into its junction's sum, which becomes zero) or (None,
    why not). A C, I or R on one scalar bond to a 1-junction that it gives its effort (a
    force or voltage added in the junction's balance: the element becomes a short, a
    spring or mass taken out) or to a 0-junction that it gives its flow (an open branch).
    An element that sets its junction's common flow or effort (a mass carrying its
    junction's velocity, a spring holding its junction's force) cannot go without
    changing the others' causality and states, and stays; so does one acting on a body
    of negligible mass (its balance may need it), and the constraint elements of a
    method (parasitic's stiff springs and dampers are how it holds a joint: their
    little activity is that of a joint that holds, not of a part the scene can spare)."""
    g = cg.graph
    el = g.elements[name]
    if el.kind not in ("C", "I", "R") or len(g.ports[name]) != 1:
        return None, f"a {el.kind}"
    if any(d.blocked and name.startswith(f"{j}__{d.label}__L")
           for j, dirs in g.joints.items() for d in dirs):
        return None, "the method's constraint element"
    b = g.ports[name][0]
    if g.bonds[b].dim != 1:
        return None, "on a multibond (a body's mass or inertia)"
    j = g.other(b, name)
    kind = g.elements[j].kind
    light = _on_massless_body(g, j)
    if light:
        return None, f"it acts on {light}, of negligible mass, whose balance needs it"
    if kind == "1" and cg.receives_effort(b, j):
        return "effort", ""
    if kind == "0" and not cg.receives_effort(b, j):
        return "flow", ""
    if kind in ("0", "1"):
        return None, (f"it sets its {kind}-junction's common "
                      f"{'flow' if kind == '1' else 'effort'}")
    return None, f"bonded to a {kind}"


def _on_massless_body(g, junction: str) -> str | None:
    """The body of negligible mass a junction's element acts on (a free direction of one
    of its joints, ``<joint>__<dir>__1`` or the direction's 0-junction, or a port at one
    of its points), else None: such a body's velocity is fixed by the balance of what
    acts on it, which taking an element out can leave singular."""
    m = g.model
    bodies = []
    port = g.port_junctions.get(junction)
    if port is not None and port in m.ports:
        p = m.ports[port]
        bodies = [p.body] if p.body else [m.joints[p.joint].body1, m.joints[p.joint].body2]
    else:
        for jn in sorted(g.joints, key=len, reverse=True):
            if junction.startswith(f"{jn}__"):
                bodies = [m.joints[jn].body1, m.joints[jn].body2]
                break
    return next((b for b in bodies if b is not None and m.bodies[b].mass == 0), None)


def activity(system: EquationSystem, cg, shares: dict[str, float], keep: float) -> tuple:
    """Model order reduction by element activity (MORA; Louca, Stein, Hulbert and
    Sprague 1997): ``shares`` are the elements' shares of the total activity int |P| dt
    over the scene's run (``analysis.energy``, by the names ``bgc energy`` gives them);
    the least active removable elements (``removable``) whose shares add up to at most
    ``1 - keep`` are taken out, their junction variable set to zero and propagated, and
    the states nothing reads any more with them. The other states keep their names.
    Not exact: the scene's report gives the outputs' error against the full model."""
    g = cg.graph
    defined = {item[0]: k for k, item in enumerate(system.assignments)
               if not isinstance(item, LinearBlock)}
    ranked = sorted((share, name) for name, share in shares.items())
    by_name = {n.replace("__", "."): n for n in g.elements}
    budget, spent = 1.0 - keep, 0.0
    assignments, removed, kept_why = list(system.assignments), [], []
    for share, shown in ranked:
        name = by_name.get(shown)
        if name is None:
            continue
        if spent + share > budget:
            break
        what, why = removable(cg, name)
        if what is None:
            kept_why.append(f"{shown} ({why})")
            continue
        bond = g.bonds[g.ports[name][0]].name
        var = symbols.effort(bond) if what == "effort" else symbols.flow(bond)
        if var not in defined:      # a copy of another variable (a law of 1), or in a loop
            where = (f"a copy of {system.aliases[var]}" if var in system.aliases
                     else "in an algebraic loop")
            kept_why.append(f"{shown} (its {what} is {where})")
            continue
        assignments[defined[var]] = (var, sp.Integer(0))
        spent += share
        removed.append(shown)
    if not removed:
        return system, report("activity", system, system, [],
                               f"nothing removable within {budget:.3g} of the activity" +
                               (f"; kept: {', '.join(kept_why[:6])}" if kept_why else ""))
    out = _substitute(replace(system, assignments=assignments), {})
    read: set = set()
    rate_of = {st.dsym: st.sym for st in out.states}
    for item in out.assignments:
        syms = _free(item) if isinstance(item, LinearBlock) else item[1].free_symbols
        own = {rate_of[item[0]]} if not isinstance(item, LinearBlock) and \
            item[0] in rate_of else set()
        read |= syms - own
    for e in [e for _, e in out.outputs] + [e for _, e in out.guards] + \
            [e for _, g_, r in out.constraints for e in (g_, r) if e is not None] + \
            [e for _, e in out.projection]:
        read |= e.free_symbols
    dead = [st for st in out.states if st.sym not in read and st.element in
            {by_name[n] for n in removed}]
    out = _keep_states(out, [st for st in out.states if st not in dead])
    return out, report("activity", system, out, removed + [st.name for st in dead],
                        f"{len(removed)} elements, {100 * spent:.3g} % of the activity "
                        f"(keep {keep:g}), and their {len(dead)} states" +
                        (f"; kept below the threshold: {', '.join(kept_why[:6])}"
                         if kept_why else ""))


# --- junctions: Rideout, Stein and Louca's junction inactivity ---------------------------
# a junction (component) whose activity is below this share of the most active one's is
# idle over the run: its bonds' shares are round-off, and nothing is cut there
IDLE = 1e-9
_ELEMENTS = ("C", "I", "R", "Se", "Sf", "MSe", "MSf")
_ELEMENT = "an element's own bond (the element pass, keep, decides)"


@dataclass(frozen=True)
class Cut:
    """A bond's term left out of a junction's sum (``junctions``), and its share of the
    junction's activity over the scene's run."""
    junction: str
    bond: int
    component: int | None
    share: float

    def to_dict(self, g) -> dict:
        one = g.elements[self.junction].kind == "1"
        return {"junction": self.junction.replace("__", "."),
                "bond": g.bonds[self.bond].name,
                "component": None if self.component is None else AXES[self.component],
                "cut": "effort" if one else "flow",
                "into": g.other(self.bond, self.junction).replace("__", "."),
                "source": "MSf" if one else "MSe", "share": self.share}

    def describe(self, g) -> str:
        d = self.to_dict(g)
        comp = f".{d['component']}" if d["component"] else ""
        common = "flow" if d["cut"] == "effort" else "effort"
        return (f"{d['bond']}{comp} at {d['junction']} ({100 * self.share:.2g} %): its "
                f"{d['cut']} left out; {d['into']} takes the junction's {common} "
                f"({d['source']})")


def _owner_body(g, node: str) -> str | None:
    """The body a junction-structure node belongs to (the longest body name it starts
    with), else None."""
    best = None
    for n in g.bodies:
        if node.startswith(f"{n}__") and (best is None or len(n) > len(best)):
            best = n
    return best


def _variable(system: EquationSystem, var) -> set:
    """The symbols a bond variable stands for once aliases are inlined."""
    return set(sp.sympify(system.aliases.get(var, var)).free_symbols)


def _joints_held(system: EquationSystem, g) -> tuple[set, set]:
    """What the joints' constraints hold: (the symbols whose value carries a constraint
    force: the efforts at the blocked directions' junctions and whatever is computed from
    them; the symbols the constraints read: the flows there, their g and dg/dt, and
    whatever those are computed from)."""
    forces, rates = set(), set()
    for j, dirs in g.joints.items():
        for d in dirs:
            zero = f"{j}__{d.label}"
            if not d.blocked or zero not in g.ports:
                continue
            for b in g.ports[zero]:
                name = g.bonds[b].name     # a direction's bonds are scalar
                forces |= _variable(system, symbols.effort(name))
                rates |= _variable(system, symbols.flow(name))
    for _, gap, rate in system.constraints:
        for e in (gap, rate):
            if e is not None:
                rates |= e.free_symbols
    carry = set(forces)
    for item in system.assignments:
        if _free(item) & carry:
            carry.update(_defines(item))
    _, read = cone(system.assignments, sorted(rates, key=str))
    return carry, read | rates


def cuttable(cg, junction: str, b: int, system: EquationSystem | None = None,
             held: tuple[set, set] | None = None) -> str:
    """'' if the junctions pass may cut bond ``b``'s term at ``junction``, else why not:
    the bond must bring the summed variable in (a junction's common flow or effort comes
    from its one strong bond, which no cut can replace without changing the causality);
    an element's own bond is the element pass's (``activity``); a body of negligible mass
    needs every force on it (its balance fixes its velocity); and a joint's constraint
    is never cut into: not its own junctions, not a junction's sum of flows that a
    constraint reads (a point's velocity a blocked direction measures: the joint would
    no longer follow the bodies), and under an ideal method (lagrange, zcp, augmented)
    not a force that carries a constraint force (the multipliers, zcp's joint forces are
    solved so that the bodies' balances hold the joints: a balance without one of them
    no longer does). A parasitic joint's stiff spring is a force like any other: a
    light body's joint force on a heavy one may be cut, the joint still following the
    heavy body's point. ``held``: ``_joints_held(system)``."""
    g = cg.graph
    kind = g.elements[junction].kind
    far = g.other(b, junction)
    if cg.receives_effort(b, junction) != (kind == "1"):
        return (f"it sets the {kind}-junction's common "
                f"{'flow' if kind == '1' else 'effort'}")
    if g.elements[far].kind in _ELEMENTS and len(g.ports[far]) == 1:
        return _ELEMENT
    for j, dirs in g.joints.items():
        for d in dirs:
            zero = f"{j}__{d.label}"
            if d.blocked and any(n == zero or n.startswith(f"{zero}__")
                                 for n in (junction, far)):
                return "a joint's constraint structure"
    for n in (junction, far):
        body = _owner_body(g, n) or _on_massless_body(g, n)
        if body is not None and g.bodies[body].mass == 0:
            return "on a body of negligible mass"
    if system is None:
        return ""
    carry, read = held if held is not None else _joints_held(system, g)
    bond = g.bonds[b]
    comps = [None] if bond.dim == 1 else range(bond.dim)
    if kind == "1" and methods.get(system.method).ideal and \
            any(_variable(system, symbols.effort(bond.name, k)) & carry for k in comps):
        return "it carries an ideal joint's constraint force"
    if kind == "0":
        strong = next(s for s in g.ports[junction] if cg.receives_effort(s, junction))
        name = g.bonds[strong].name
        if any(_variable(system, symbols.flow(name, k)) & read for k in comps):
            return "a joint's constraint reads the junction's flow"
    return ""


def junction_cuts(cg, activity: dict[str, float], keep: float,
                  system: EquationSystem | None = None) -> tuple[list, list, int]:
    """The terms to cut: at each junction (component), the least active bonds whose
    shares of the junction's activity (``activity``: each term's state of the junctions'
    variant, ``codegen.energy.junction_terms``; a term without one has none) add up to
    at most ``1 - keep`` and that ``cuttable`` allows. Returns the cuts, the terms within
    the budget kept and why, and the count of idle junction components."""
    from bgc.codegen.energy import junction_terms
    groups: dict = {}
    for t in junction_terms(cg.graph):
        groups.setdefault((t.junction, t.component), []).append(t)
    totals = {key: sum(activity.get(t.state, 0.0) for t in ts) for key, ts in groups.items()}
    top = max(totals.values(), default=0.0)
    held = _joints_held(system, cg.graph) if system is not None else None
    cuts, kept, idle = [], [], 0
    for key, ts in groups.items():
        total = totals[key]
        if total <= IDLE * top:
            idle += 1
            continue
        spent = 0.0
        ranked = sorted(range(len(ts)), key=lambda i: (activity.get(ts[i].state, 0.0), i))
        for t in (ts[i] for i in ranked):
            if t.state not in activity:     # no power by construction: nothing to cut
                continue
            share = activity[t.state] / total
            if spent + share > 1.0 - keep:
                break
            why = cuttable(cg, t.junction, t.bond, system, held)
            if why:
                if why != _ELEMENT:
                    kept.append((t, share, why))
                continue
            cuts.append(Cut(t.junction, t.bond, t.component, share))
            spent += share
    return cuts, kept, idle


def _coupling(system: EquationSystem) -> dict:
    """State symbol -> the states its rate reads (through the assignments), as a bit mask
    over ``system.states``."""
    bit = {st.sym: 1 << i for i, st in enumerate(system.states)}
    dep = dict(bit)
    for item in system.assignments:
        syms = _free(item)
        mask = 0
        for s in syms:
            mask |= dep.get(s, 0)
        for v in _defines(item):
            dep[v] = dep.get(v, 0) | mask
    return dep


def _parts(before: EquationSystem, after: EquationSystem, outputs) -> list[dict]:
    """Where the cuts split a coupled part of the model (states that read each other
    before) into parts that no longer do: each part's states, the parts it reads (it is
    driven by them; none: a driving part) and whether the scene's outputs need it (what
    ``prune`` would keep of it)."""
    from bgc.symbolic.algorithms import strongly_connected
    names = [st.name for st in after.states]

    def sccs(system):
        dep = _coupling(system)
        n = len(system.states)
        reads = {i: [j for j in range(n) if dep.get(system.states[i].dsym, 0) >> j & 1]
                 for i in range(n)}
        return strongly_connected(range(n), reads), reads
    old, _ = sccs(before)
    new, reads = sccs(after)
    kept = {st.name for st in (after.states if outputs is None
                               else prune(after, outputs)[0].states)}
    index = {st.name: i for i, st in enumerate(after.states)}
    piece = {i: k for k, comp in enumerate(new) for i in comp}
    out = []
    for comp in old:
        members = [index[before.states[i].name] for i in comp
                   if before.states[i].name in index]
        pieces = sorted({piece[i] for i in members})
        if len(pieces) < 2:
            continue
        start = len(out)
        number = {k: start + n for n, k in enumerate(pieces)}
        for k in pieces:
            states = [i for i in new[k] if i in members]
            driven_by = sorted({number[piece[j]] for i in states for j in reads[i]
                                if piece[j] != k and piece[j] in number})
            out.append({"states": [names[i] for i in states], "driven_by": driven_by,
                        "needed": any(names[i] in kept for i in states)})
    return out


def _describe_parts(parts: list[dict]) -> str:
    if not parts:
        return ("no coupled part of the model splits (what a cut leaves out still comes "
                "back another way)")
    out = []
    for k, p in enumerate(parts):
        head = ", ".join(p["states"][:4]) + (f" and {len(p['states']) - 4} more"
                                             if len(p["states"]) > 4 else "")
        role = ("driving" if not p["driven_by"] else
                "driven by part " + ", ".join(str(d + 1) for d in p["driven_by"]))
        fate = "" if not p["driven_by"] else (
            ": the outputs need it, it stays, fed one-way" if p["needed"] else
            ": no output needs it, prune removes it")
        out.append(f"part {k + 1} ({len(p['states'])} states: {head}) {role}{fate}")
    return "; ".join(out)


def junctions(system: EquationSystem, cg, activity: dict[str, float], keep: float,
              outputs=None) -> tuple:
    """Junction inactivity (Rideout, Stein and Louca 2007; the module's docstring): the
    terms ``junction_cuts`` chooses are left out of their junctions' sums and the
    equations of ``cg`` derived again (``equations.derive(cut=...)``); every state keeps
    its name. The report lists each cut (bond, junction, the variable left out, the
    modulated source the other side becomes, its share) and the parts the model split
    into, driving and driven, and which of them the scene's ``outputs`` need."""
    from bgc import progress
    from bgc.codegen import equations
    g = cg.graph
    cuts, kept, idle = junction_cuts(cg, activity, keep, system)
    reasons: dict = {}
    for t, _, w in kept:
        reasons.setdefault(w, []).append(t)
    why = [f"{len(ts)} ({w}; e.g. {g.bonds[ts[0].bond].name} at "
           f"{ts[0].junction.replace('__', '.')})"
           for w, ts in sorted(reasons.items(), key=lambda r: -len(r[1]))]
    tail = (f"; {idle} idle junction components (no power to compare) left alone"
            if idle else "") + (f"; terms within the budget kept: {', '.join(why)}"
                                if why else "")
    if not cuts:
        rep = report("junctions", system, system, [],
                     f"no junction term within {1 - keep:.3g} of its junction's activity "
                     f"may be cut" + tail)
        rep.cuts, rep.parts = [], []
        return system, rep
    with progress.stage("junctions") as st:
        out = equations.derive(cg, cut=[(c.junction, c.bond, c.component) for c in cuts])
        parts = _parts(system, out, outputs)
        st.done(f"{len(cuts)} junction terms cut, {len(parts)} parts")
    out = replace(out, model=system.model)
    quiet = sum(c.share < IDLE for c in cuts)
    head = (f"{len(cuts)} bond terms cut at {len({c.junction for c in cuts})} junctions "
            f"(junctions {keep:g}, the largest {100 * max(c.share for c in cuts):.3g} % of "
            "its junction's activity" +
            (f"; {quiet} of them below {IDLE:g} of it, no power in this run" if quiet
             else "") + "); ")
    rep = report("junctions", system, out, [c.describe(g) for c in cuts],
                 head + _describe_parts(parts) + tail)
    rep.cuts, rep.parts = [c.to_dict(g) for c in cuts], parts
    return out, rep


def prune(system: EquationSystem, outputs) -> tuple:
    """Only the ``outputs`` asked for, and the states they depend on through the rates."""
    kept_outputs = [(n, e) for n, e in system.outputs if n in set(outputs)]
    states = {st.sym: st for st in system.states}
    seeds = [e for _, e in kept_outputs]
    seeds += [e for _, g, r in system.constraints for e in (r, g) if e is not None]
    need: set = set()
    frontier = seeds
    while frontier:
        _, used = cone(system.assignments, frontier)
        new = {s for s in used if s in states} - need
        need |= new
        frontier = [states[s].dsym for s in new]
    keep = [st for st in system.states if st.sym in need]
    removed = [st.name for st in system.states if st not in keep]
    gone = {st.sym for st in system.states if st not in keep}
    out = _keep_states(replace(system, outputs=kept_outputs,
                               guards=[(w, e) for w, e in system.guards
                                       if not e.free_symbols & gone]), keep)
    dropped = [n for n, _ in system.outputs if n not in set(outputs)]
    return out, report("prune", system, out, removed + [f"output {n}" for n in dropped],
                        f"{len(removed)} states and {len(dropped)} outputs cannot reach "
                        "the outputs asked for")


def reduce(system: EquationSystem, outputs, values: dict, expose=(),
           activity_of=None, junctions_of=None) -> tuple:
    """All passes in order; returns the reduced system and one PassReport per pass.
    ``activity_of``: (CausalGraph, shares, keep) for the ``activity`` pass and
    ``junctions_of``: (CausalGraph, each junction term's activity, keep) for the
    ``junctions`` pass, which run only where a scene asks for them."""
    reports = []
    steps = [lambda s: fold_parameters(s, values, expose), lambda s: idle_dofs(s, outputs)]
    if junctions_of is not None:
        steps.insert(0, lambda s: junctions(s, *junctions_of, outputs))
    if activity_of is not None:
        steps.append(lambda s: activity(s, *activity_of))
    for step in steps + [lambda s: prune(s, outputs)]:
        system, rep = step(system)
        reports.append(rep)
    return system, reports
