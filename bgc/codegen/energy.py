"""Where the power goes: the energy variant of a module (``bgc energy``).

Every element that supplies, stores or dissipates power (sources, C, I, R, the bodies'
masses and inertias, gravity, a method's constraint elements, parasitic springs and
dampers) gets two quadrature states, integrated by the solver with the model's own
states, so inside its error control:

- ``energy[NAME]``, the work of its power P = s e.f in its column's sense: out of a
  source or a constraint element (supplied), into a C, I or R, into gravity's potential
  or a parasitic spring (stored: minus the power out of these sources of the bond
  graph), and
- ``activity[NAME]``, its activity A = int |P| dt (Louca, Stein, Hulbert and Sprague
  1997), the measure of model order reduction by element activity.

Where a storage element has an energy function of the states (a linear or polynomial C or
I law, a body's kinetic energy, gravity's potential, a parasitic spring on its joint's
deflection), it is an output ``stored[NAME]``: the energy stored is then that function at
the end minus at the start, so the balance supplied = stored + dissipated checks the
integration (its residual is the quadratures' and the states' error against each other,
plus any work a method's constraints do), not only the junction structure's power
conservation (Tellegen's theorem makes the sum of the powers zero at every instant).

The energy states exist only in the energy variant (``<name>_<method>_energy.py``): the
ordinary module is not slowed by them. ``ENERGY`` in the module lists the entries (name,
kind, column, body, joint) that ``bgc.analysis.energy`` reads after the run.

The junctions' variant (``<name>_<method>_junctions.py``, what a scene's ``activity:
{junctions: J}`` measures) adds the activity of every bond at a 0- or 1-junction, per
component of a multibond (a body's 3-dimensional junctions are three scalar ones), as
``activity[BOND]`` or ``activity[BOND.x]`` (``junction_terms``): the terms of each
junction's balance whose shares Rideout, Stein and Louca's junction inactivity compares.
A bond to a one-port element that supplies, stores or dissipates carries that element's
power, whose activity ``activity[NAME]`` is already there.
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from bgc.graph.expand import AXES, joint_param, position
from bgc.model import symbols

# an element's kind -> the column of the balance its work goes in
COLUMN = {"source": "supplied", "constraint": "supplied",
          "C": "stored", "I": "stored", "kinetic": "stored", "potential": "stored",
          "parasitic spring": "stored",
          "R": "dissipated", "parasitic damper": "dissipated"}
# kinds whose bond-graph element is a source: the work they store is minus their power out
_SOURCE_STORES = ("potential", "parasitic spring")


@dataclass(frozen=True)
class Entry:
    """An element the energy accounting follows: its graph name, its kind (a key of
    ``COLUMN``), the body or joint it belongs to ('' if none)."""
    element: str
    kind: str
    body: str = ""
    joint: str = ""

    @property
    def name(self) -> str:
        """As the model's states name it (``arm__m`` -> ``arm.m``)."""
        return self.element.replace("__", ".")


def entries(graph) -> list[Entry]:
    """The elements of a bond graph that supply, store or dissipate power, in graph
    order, classified: junctions, transformers, gyrators, the Eulerian junction structure
    (w . (w x Jw) = 0) and a massless body's port conserve power and are left out."""
    constraint = {c.element for c in graph.constraints}
    parasitic = {}
    for j, dirs in graph.joints.items():
        for d in dirs:
            zero = f"{j}__{d.label}"
            if d.blocked:
                parasitic[f"{zero}__L"] = "parasitic spring"
                parasitic[f"{zero}__Lc"] = "parasitic damper"
    owners = [(f"{n}__", n, "") for n in graph.bodies] + \
        [(f"{j}__", "", j) for j in graph.joints]
    owners.sort(key=lambda o: -len(o[0]))       # the longest prefix owns
    out = []
    for name, el in graph.elements.items():
        body = joint = ""
        for prefix, b, j in owners:
            if name.startswith(prefix):
                body, joint = b, j
                break
        if name in constraint:
            kind = "constraint"
        elif name in parasitic and el.kind in ("MSe", "C", "R"):
            kind = parasitic[name]
        elif body and name == f"{body}__g":
            kind = "potential"
        elif body and name in (f"{body}__m", f"{body}__J"):
            kind = "kinetic"
        elif el.kind in ("Se", "Sf", "MSe", "MSf"):
            kind = "source"
        elif el.kind in ("C", "I", "R"):
            kind = el.kind
        else:
            continue
        out.append(Entry(name, kind, body, joint))
    return out


def power(b, e: Entry) -> sp.Expr:
    """The element's power in its column's sense: into a C, I or R, out of a source (the
    sign of its port, ``Builder.port``), into what a source of the bond graph stores
    (``_SOURCE_STORES``); summed over a multibond's components."""
    _, s, E, F = b.port(e.element)
    if e.kind in _SOURCE_STORES:
        s = -s
    if isinstance(E, sp.MatrixBase):
        return s * sp.Add(*[E[k] * F[k] for k in range(len(E))])
    return s * E * F


def stored_function(b, e: Entry) -> sp.Expr | None:
    """The energy stored in ``e`` as a function of the states (None: none known, the
    stored energy is then its power integrated)."""
    g, el = b.g, b.g.elements[e.element]
    if e.kind == "potential":           # a constant weight W: V = -W . r_G
        W = el.fields["effort"]
        return -sum((W[k] * position(e.body)[k] for k in range(3)), sp.S.Zero)
    if e.kind == "parasitic spring" and el.kind == "MSe":   # effort k g - load on g
        joint, label = e.element.rsplit("__", 2)[:2]
        d = next(d for d in g.joints[joint] if d.label == label)
        rot = "rot_" if d.rotational else ""
        k = symbols.param(joint_param(joint, rot + "stiffness"))
        load = symbols.param(joint_param(joint, f"{label}_load"))
        return k * d.g ** 2 / 2 - load * d.g
    if el.kind not in ("C", "I"):
        return None
    qname = "q" if el.kind == "C" else "p"
    law = el.fields.get(el.law)
    if isinstance(law, sp.MatrixBase) or e.kind == "kinetic":    # multibond: p^T M^-1 p
        M = law if isinstance(law, sp.MatrixBase) else law * sp.eye(3)
        if el.law != el.kind or not M.is_diagonal():
            return None
        x = [symbols.state(e.element, f"{qname}{a}") for a in "xyz"]
        return sp.Add(*[x[k] ** 2 / (2 * M[k, k]) for k in range(M.rows)])
    x = b.dependent.get(e.element, symbols.state(e.element, qname))
    if el.law == el.kind:               # e = q/C, f = p/I
        return x ** 2 / (2 * law)
    if el.law == "k":
        return law * x ** 2 / 2
    if el.law not in ("effort", "flow"):
        return None
    u = sp.Dummy(qname, real=True)
    value = b.law(el, el.law, **{qname: u})
    if any(symbols.kind(s) != "parameter" for s in value.free_symbols - {u}):
        return None                     # modulated: not a function of its state alone
    if not value.is_polynomial(u):
        return None
    return sp.integrate(value, (u, 0, x))


@dataclass(frozen=True)
class Term:
    """One bond's term (one component's, on a multibond) in a 0- or 1-junction's balance:
    the junction, the bond's index, its component (None on a scalar bond) and the state
    that integrates its activity, int |e f| dt (``junction_terms``)."""
    junction: str
    bond: int
    component: int | None
    state: str


def junction_terms(graph) -> list[Term]:
    """Every bond's term at every 0- and 1-junction, in graph order: a scalar bond to an
    element of ``entries`` (one port) by that element's activity, any other by its own
    (``activity[BOND]``, a multibond's components ``activity[BOND.x]`` ...)."""
    one_port = {e.element: e.name for e in entries(graph)
                if len(graph.ports[e.element]) == 1}
    out = []
    for name, el in graph.elements.items():
        if el.kind not in ("0", "1"):
            continue
        for b in graph.ports[name]:
            bond, far = graph.bonds[b], graph.other(b, name)
            if bond.dim == 1:
                state = (f"activity[{one_port[far]}]" if far in one_port
                         else f"activity[{bond.name}]")
                out.append(Term(name, b, None, state))
                continue
            out += [Term(name, b, k, f"activity[{bond.name}.{AXES[k]}]")
                    for k in range(bond.dim)]
    return out


def _bond_activities(b, system, aliases: dict) -> None:
    """The junctions' variant: a quadrature state for every bond term of
    ``junction_terms`` that no element's activity gives, its rate |e f|; none where that
    is zero by construction (the term's activity is then zero: ``junction_activity``)."""
    from bgc.codegen.builder import State
    have = {st.name for st in system.states}
    for term in junction_terms(b.g):
        if term.state in have:
            continue
        have.add(term.state)
        bond = b.g.bonds[term.bond]
        E, F = b.E(term.bond), b.F(term.bond)
        tag = bond.name
        if term.component is not None:
            E, F, tag = E[term.component], F[term.component], \
                f"{bond.name}__{AXES[term.component]}"
        P = (E * F).xreplace(aliases)
        if P == 0:          # no power by construction (a zero effort or flow): no state
            continue
        x, dx = symbols.state(tag, "activity"), symbols.dstate(tag, "activity")
        system.assignments.append((dx, sp.Abs(P)))
        system.quadrature.append(len(system.states))
        system.states.append(State(term.state, x, dx, sp.S.Zero, bond.src))
        system.display[x] = term.state


def account(b, system, aliases: dict, junctions: bool = False) -> None:
    """Add the quadrature states (energy and activity of every entry), the stored
    energies' outputs and the ``energy`` table to an equation system built by ``b``;
    ``junctions``: also every junction bond's activity (``junction_terms``)."""
    from bgc.codegen.builder import State
    table = []
    for e in entries(b.g):
        P = power(b, e).xreplace(aliases)
        for tag, rate in (("energy", P), ("activity", sp.Abs(P))):
            x, dx = symbols.state(e.element, tag), symbols.dstate(e.element, tag)
            system.assignments.append((dx, rate))
            system.quadrature.append(len(system.states))
            system.states.append(State(f"{tag}[{e.name}]", x, dx, sp.S.Zero, e.element))
            system.display[x] = f"{tag}[{e.name}]"
        H = stored_function(b, e) if COLUMN[e.kind] == "stored" else None
        if H is not None:
            system.outputs.append((f"stored[{e.name}]", H.xreplace(aliases)))
        table.append((e.name, e.kind, COLUMN[e.kind], e.body, e.joint))
    system.energy = table
    if junctions:
        _bond_activities(b, system, aliases)
        system.junctions = True
