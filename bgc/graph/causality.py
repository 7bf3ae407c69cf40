"""Stage **causality**: BondGraph -> CausalGraph, by the Sequential Causality Assignment
Procedure (SCAP, Karnopp & Rosenberg).

Order: fixed-causality elements first (sources; by the vector rule C2 the EJS and the
cross-product TFs; one-way matrix transformers; the ports of bodies of negligible mass), then storage elements preferring integral causality,
then R elements (in the form their law is written in), then any bond still free. Each
choice is propagated through junctions, TF and GY before the next one; a free choice that
leads to a conflict is undone and the other one taken. A conflict between fixed causalities
(two effort sources on one 0-junction, ...) is an error naming the elements and bonds.

Representation: for every bond, ``effort_in[b]`` is the element that *receives* the effort
(the end carrying the causal stroke).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from bgc.errors import CausalityError
from bgc.graph.bondgraph import BondGraph


@dataclass
class CausalGraph:
    graph: BondGraph
    effort_in: list[str]
    storage: dict[str, str] = field(default_factory=dict)  # C/I -> integral | derivative
    r_form: dict[str, str] = field(default_factory=dict)   # R -> resistance | conductance
    choices: list[str] = field(default_factory=list)       # free choices, for the report

    def receives_effort(self, b: int, node: str) -> bool:
        return self.effort_in[b] == node

    def report(self) -> dict:
        g = self.graph
        return {
            "storage": {n: c for n, c in self.storage.items()},
            "resistors": dict(self.r_form),
            "bonds": [{"bond": bd.name, "from": bd.src, "to": bd.dst,
                       "effort_into": self.effort_in[i]} for i, bd in enumerate(g.bonds)],
            "free_choices": list(self.choices),
        }


class _Conflict(Exception):
    def __init__(self, node: str, bonds: list[int], rule: str):
        self.node, self.bonds, self.rule = node, bonds, rule


# What each kind requires of the bonds at a node, with 'in' = the node receives effort.
def _rule(kind: str) -> str:
    return {"0": "one_in", "1": "one_out", "TF": "one_in", "MTF": "one_in", "XTF": "one_in",
            "GY": "same", "MGY": "same"}.get(kind, "free")


_FIXED = {"Se": "out", "MSe": "out", "Sf": "in", "MSf": "in"}


def one_way(el) -> bool:
    """A two-port that only works flow-in at its input, flow-out at its output (rule C2):
    the cross-product TF, and a TF/MTF whose matrix ratio has no usable inverse (not
    square, or modulated and not a rotation)."""
    if el.kind == "XTF":
        return True
    ratio = el.fields.get("ratio")
    if el.kind in ("TF", "MTF") and hasattr(ratio, "shape"):
        if ratio.shape[0] != ratio.shape[1]:
            return True
        return el.kind == "MTF" and not el.orthogonal
    return False


def _fixed_ports(graph: BondGraph, name: str, el) -> list[tuple[int, bool]]:
    """(bond, element receives effort) for every port of a fixed-causality element."""
    if el.kind in _FIXED:
        return [(b, _FIXED[el.kind] == "in") for b in graph.ports[name]]
    if el.kind == "EJS":            # C2: flow in, effort out
        return [(b, False) for b in graph.ports[name]]
    if el.kind == "M0":             # its flow is the unknown twist: effort in
        return [(b, True) for b in graph.ports[name]]
    a, c = graph.two_port(name)     # one-way two-port: flow in at a, flow out at c
    return [(a, False), (c, True)]


class _Scap:
    def __init__(self, graph: BondGraph):
        self.g = graph
        self.effort_in: list[str | None] = [None] * len(graph.bonds)
        self.forced_by: list[str | None] = [None] * len(graph.bonds)  # whose rule set it
        self.queue: list[str] = []

    def assign(self, b: int, receiver: str, by: str):
        cur = self.effort_in[b]
        if cur is not None:
            if cur != receiver:
                raise self._clash(b, by)
            return
        self.effort_in[b] = receiver
        self.forced_by[b] = by
        bond = self.g.bonds[b]
        self.queue += [bond.src, bond.dst]

    def _clash(self, b: int, by: str) -> _Conflict:
        """A bond asked for the other causality: blame the junction (or two-port) whose
        rule decided it, naming the bonds that imposed that rule and the new one."""
        for node in (self.forced_by[b], by):
            rule = _rule(self.g.elements[node].kind) if node else "free"
            if rule in ("one_in", "one_out"):
                want = rule == "one_in"
                hits = [x for x in self.g.ports[node] if x != b and self.effort_in[x]
                        is not None and (self.effort_in[x] == node) is want]
                if not hits:   # b was this node's last chance to satisfy its rule
                    return _Conflict(node, list(self.g.ports[node]),
                                     "none_in" if want else "none_out")
                return _Conflict(node, hits + [b], rule)
            if rule == "same":
                return _Conflict(node, list(self.g.ports[node]), rule)
        return _Conflict(by, [b], "assigned")

    def set_port(self, node: str, b: int, receives: bool):
        self.assign(b, node if receives else self.g.other(b, node), node)

    def propagate(self):
        while self.queue:
            self.apply(self.queue.pop())

    def apply(self, node: str):
        rule = _rule(self.g.elements[node].kind)
        if rule == "free":
            return
        bonds = self.g.ports[node]
        state = {b: (None if self.effort_in[b] is None else self.effort_in[b] == node)
                 for b in bonds}
        if rule == "same":
            known = {v for v in state.values() if v is not None}
            if len(known) == 2:
                raise _Conflict(node, bonds, rule)
            if known:
                v = known.pop()
                for b in bonds:
                    self.set_port(node, b, v)
            return
        want = rule == "one_in"     # the value exactly one bond must have
        hits = [b for b in bonds if state[b] is want]
        free = [b for b in bonds if state[b] is None]
        if len(hits) > 1:
            raise _Conflict(node, hits, rule)
        if len(hits) == 1:
            for b in free:
                self.set_port(node, b, not want)
        elif len(free) == 1:
            self.set_port(node, free[0], want)
        elif not free:
            raise _Conflict(node, bonds, "none_in" if want else "none_out")

    def attempt(self, node: str, b: int, receives: bool) -> bool:
        """Try a free choice; undo it and return False if it leads to a conflict."""
        saved = list(self.effort_in), list(self.forced_by)
        try:
            self.set_port(node, b, receives)
            self.propagate()
            return True
        except _Conflict:
            (self.effort_in, self.forced_by), self.queue = saved, []
            return False


def _describe(g: BondGraph, b: int) -> str:
    bond = g.bonds[b]
    return (f"bond {bond.name} {g.label(bond.src)}->{g.label(bond.dst)} "
            f"(line {bond.loc.line})")


def _conflict_error(g: BondGraph, c: _Conflict, during: str) -> CausalityError:
    el = g.elements[c.node]
    bonds = "; ".join(_describe(g, b) for b in c.bonds)
    others = ", ".join(f"{g.elements[g.other(b, c.node)].kind} '{g.label(g.other(b, c.node))}'"
                       for b in c.bonds)
    what = {"one_in": f"receives effort from {len(c.bonds)} bonds, it takes exactly one",
            "one_out": f"has its flow imposed by {len(c.bonds)} bonds, it takes exactly one",
            "same": "needs both bonds effort-in or both effort-out",
            "none_in": "has no bond to take its effort from, it needs exactly one",
            "none_out": "has no bond to take its flow from, it needs exactly one",
            "assigned": "gets two causalities on one bond"}[c.rule]
    hint = {("0", "one_in"): "two effort sources (or an effort source and a C) cannot "
                             "share a 0-junction; put an R between them",
            ("1", "one_out"): "two flow sources (or a flow source and an I) cannot share a "
                              "1-junction; put an R or C between them",
            ("0", "none_in"): "nothing sets this junction's effort: add a C, an effort "
                              "source or an R to it",
            ("1", "none_out"): "nothing sets this junction's flow: add an I, a flow source "
                               "or an R to it"}.get((el.kind, c.rule),
                                                    "check the sources' placement")
    return CausalityError(f"causality conflict while assigning {during}: {el.kind} "
                          f"'{g.label(c.node)}' {what}: {bonds} (from {others})", loc=el.loc,
                          key=f"elements.{c.node}", hint=hint)


def _both_fixed(graph: BondGraph) -> None:
    """Refuse a bond whose causality both its ends fix (a source bonded straight to a
    source): whether or not the two agree, no equation relates its effort and flow, and
    each source's value is lost on the other (an Se on an Sf is a power meter of nothing).
    Named at the bond's file:line."""
    fixed: dict[int, list[str]] = {}
    for name, el in graph.elements.items():
        if el.kind in _FIXED:
            for b in graph.ports[name]:
                fixed.setdefault(b, []).append(name)
    for b, names in fixed.items():
        if len(names) > 1:
            bond = graph.bonds[b]
            kinds = [f"{graph.elements[n].kind} '{n}'" for n in names]
            raise CausalityError(f"bond {bond.name} joins {kinds[0]} straight to {kinds[1]}: "
                                 "each source fixes the bond's causality, so nothing "
                                 "relates its effort and flow", loc=bond.loc,
                                 key=f"bonds.{bond.name}",
                                 hint="put a junction (0 or 1) and the element the sources "
                                      "drive between them")


def assign(graph: BondGraph) -> CausalGraph:
    """Run SCAP and return the causal graph, or raise CausalityError."""
    s = _Scap(graph)
    els = graph.elements
    # 1. sources: fixed causality. A conflicting source is set aside so that every
    #    conflict in the model is found and reported together.
    conflicts: list[CausalityError] = []
    # the mechanism's own fixed causalities first, so that a model element that
    # contradicts them (a flow source on a port) is the one reported
    user = graph.model.elements if graph.model is not None else els
    _both_fixed(graph)
    for name, el in sorted(els.items(), key=lambda item: item[0] in user):
        if el.kind in _FIXED or el.kind in ("EJS", "M0") or one_way(el):
            saved = list(s.effort_in), list(s.forced_by)
            try:
                for b, receives in _fixed_ports(graph, name, el):
                    s.set_port(name, b, receives)
                s.propagate()
            except _Conflict as c:
                what = (f"source '{name}'" if el.kind in _FIXED else
                        f"the fixed causality (rule C2) of {el.kind} '{name}'")
                conflicts.append(_conflict_error(graph, c, what))
                (s.effort_in, s.forced_by), s.queue = saved, []
    if conflicts:
        first = conflicts[0]
        also = "".join(f"; also: {e.loc}: {e.message}" for e in conflicts[1:])
        err = CausalityError(first.message + also, loc=first.loc, key=first.key,
                             hint=first.hint)
        err.conflicts = conflicts
        raise err
    choices: list[str] = []
    # 2. storage, preferring integral causality
    for name, el in els.items():
        if el.kind in ("C", "I"):
            b = graph.ports[name][0]
            if s.effort_in[b] is not None:
                continue
            integral_receives = el.kind == "I"
            if not s.attempt(name, b, integral_receives):
                if not s.attempt(name, b, not integral_receives):
                    raise CausalityError(f"no causality fits {el.kind} '{name}'",
                                         loc=el.loc, key=f"elements.{name}")
                choices.append(f"{el.kind} '{name}' takes derivative causality (integral "
                               "would conflict)")
    # 3. resistors, in the form their law is written in
    for name, el in els.items():
        if el.kind == "R":
            b = graph.ports[name][0]
            if s.effort_in[b] is not None:
                continue
            conductance = el.law == "flow"
            if s.attempt(name, b, conductance):
                form = "conductance" if conductance else "resistance"
            elif s.attempt(name, b, not conductance):
                form = "resistance" if conductance else "conductance"
            else:
                raise CausalityError(f"no causality fits R '{name}'", loc=el.loc,
                                     key=f"elements.{name}")
            choices.append(f"R '{name}' chosen in {form} form (free choice: an algebraic "
                           "loop may follow)")
    # 4. any bond still free (junction structures without elements)
    for b, bond in enumerate(graph.bonds):
        if s.effort_in[b] is None:
            if not (s.attempt(bond.dst, b, True) or s.attempt(bond.src, b, True)):
                raise CausalityError(f"no causality fits bond {bond.name}", loc=bond.loc,
                                     key=f"bonds.{bond.name}")
            choices.append(f"bond {bond.name} chosen freely (effort into "
                           f"'{s.effort_in[b]}')")
    # every rule must hold now that all bonds are assigned
    for name in els:
        try:
            s.apply(name)
        except _Conflict as c:
            raise _conflict_error(graph, c, "the remaining bonds") from None
    cg = CausalGraph(graph, [str(x) for x in s.effort_in], choices=choices)
    for name, el in els.items():
        if el.kind in ("C", "I"):
            receives = cg.receives_effort(graph.ports[name][0], name)
            integral = receives if el.kind == "I" else not receives
            cg.storage[name] = "integral" if integral else "derivative"
        elif el.kind == "R":
            receives = cg.receives_effort(graph.ports[name][0], name)
            cg.r_form[name] = "conductance" if receives else "resistance"
    return cg


