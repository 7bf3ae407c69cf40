"""``bgc draw``, first step: a model's causal bond graph -> a ``Diagram``, what is drawn.

A Diagram holds every element to draw (its kind, label, group and marks) and every bond
(its ends, power direction, dimension, the end that receives the effort and its marks),
in plain names: the layout (``layout.py``) and the rendering (``render.py``) read nothing
else. It is made from the pipeline's own stages (``pipeline.build``: the method's graph
pass and SCAP, then the equations for the algebraic loops), so that it shows what a compile
assigns.

Groups: ``expand`` names the elements of a body ``<body>__...`` and those of a joint
``<joint>__...`` (``bgc/graph/expand.py``); an element belongs to the longest body or joint
name its own starts with (followed by ``__``): a body's points belong to the body, a joint's
directions, transformers and constraint elements to the joint. The model's own elements
(an electric network, ports' elements) form the group ``network``, but for those of an
instance of a component (``leg_1.motor.coil``), which form the instance's group.

``--only NAME[,NAME...]`` keeps some groups: a body brings the joints it takes part in, a
joint comes alone, ``network`` is the model's own elements, and a NAME with ``*``, ``?`` or
``[`` is a shell pattern over the body and joint names (a body it matches brings its joints
too), and an instance's name keeps all of its parts (its bodies, joints and own elements,
those of the instances in it too). The SARIB's leg i is the instance ``leg_i``: ``--only
leg_1`` draws ``leg_1.beater``, ``leg_1.bar``, ``leg_1.hinge``, ``leg_1.bar_bottom`` and
``leg_1.bar_top``. The elements of
other groups that a kept element is bonded to are drawn too, marked ``outside``, so that
every bond of a kept element is drawn with its stroke.

Marks: ``constraint`` on the constraint elements L of the blocked joint directions (the
method's: spring and damper under parasitic, the multiplier's source under lagrange, the
flow source under zcp); ``loop`` on the elements and bonds of the algebraic loops that
``bgc check`` reports; ``zcp`` on those of the method's zero-order causal paths (zcp);
``conflict`` on the elements and bonds a causality conflict names (no stroke is drawn
then: SCAP stops at the conflict).
"""

from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass, field

from bgc.errors import BgcError, CausalityError

NETWORK = "network"


@dataclass
class Node:
    name: str
    kind: str
    label: str                 # standard notation: '0', '1', 'C:k', 'MTF:rx.w1'
    sub: str                   # a junction's name within its group ('' for other kinds)
    group: str
    marks: set[str] = field(default_factory=set)


@dataclass
class Edge:
    name: str
    src: str                   # power flows from src to dst (the half-arrow at dst)
    dst: str
    dim: int                   # > 1: a multibond
    effort_in: str | None      # the end that receives the effort (the stroke); None: none
    marks: set[str] = field(default_factory=set)


@dataclass
class Diagram:
    title: str
    nodes: dict[str, Node]
    edges: list[Edge]
    groups: dict[str, str]     # group -> its caption ('' for the network: no frame)
    outside: set[str] = field(default_factory=set)    # groups --only left out
    notes: list[str] = field(default_factory=list)
    # bgc draw --energy: an element's share of a run's activity (draw/activity.py)
    activity: dict[str, float] = field(default_factory=dict)


def of_model(path: str, method: str, only: str | None = None,
             open_loops: bool = True) -> tuple[Diagram, CausalityError | None]:
    """The Diagram of a model file under ``method``; with a causality conflict, the graph
    with the conflict marked and no strokes, and the error (the caller reports it)."""
    from bgc import methods
    from bgc.pipeline import build
    try:
        c = build(path, method, open_loops=open_loops)
    except CausalityError as err:
        return _of_conflict(path, method, err, only, open_loops), err
    m = methods.get(method)
    graph = c.causal.graph
    marks: dict[str, tuple[set, set]] = {"loop": (set(), set()), "zcp": (set(), set())}
    for lp in c.system.loops:
        if not m.hides_loop(lp):
            marks["loop"][0].update(lp.elements)
            marks["loop"][1].update(lp.bonds)
    own, _ = m.report(c)
    for paths in own.values():       # zcp: its zero-order causal paths
        for p in paths if isinstance(paths, list) else []:
            if isinstance(p, dict) and "bonds" in p:
                marks["zcp"][0].update(p["elements"])
                marks["zcp"][1].update(p["bonds"])
    title = f"{graph.model.name} ({method})"
    return build_diagram(graph, c.causal.effort_in, marks, only, title), None


def _of_conflict(path, method, err: CausalityError, only, open_loops) -> Diagram:
    """The graph SCAP refused: the elements and bonds the conflict names (its keys,
    ``elements.NAME`` or ``bonds.NAME``, and the bonds its messages name), marked
    ``conflict``; no strokes."""
    from bgc import methods
    from bgc.graph import expand
    from bgc.model import load
    model = load.load(path)
    graph = methods.get(method).restructure(expand.expand(model, method), open_loops)
    errors = err.conflicts or [err]
    keys = [e.key.split(".", 1) for e in errors if e.key and "." in e.key]
    els = {name for section, name in keys if section == "elements"}
    text = " ".join(e.message for e in errors)
    bonds = {bd.name for bd in graph.bonds if ["bonds", bd.name] in keys
             or re.search(rf"\bbond {re.escape(bd.name)}\b", text)}
    d = build_diagram(graph, [None] * len(graph.bonds), {"conflict": (els, bonds)}, only,
                      f"{model.name} ({method}): causality conflict")
    d.notes.append(f"causality conflict, no strokes drawn: {err.message}")
    return d


def build_diagram(graph, effort_in: list, marks: dict[str, tuple[set, set]],
                  only: str | None, title: str) -> Diagram:
    """The Diagram of a BondGraph with ``effort_in[b]`` (None: unassigned), marks as
    ``{mark: (element names, bond names)}``, restricted to ``only`` (module doc)."""
    group = groups_of(graph)
    keep = select(graph, only)
    kept = {n for n, g in group.items() if g in keep}
    shown = set(kept)
    for bd in graph.bonds:
        if bd.src in kept or bd.dst in kept:
            shown.update((bd.src, bd.dst))
    constraint = constraint_elements(graph)
    nodes = {}
    for name in graph.elements:
        if name not in shown:
            continue
        kind = graph.elements[name].kind
        label, sub = _label(name, kind, group[name])
        node = Node(name, kind, label, sub, group[name])
        node.marks.update(m for m, (els, _) in marks.items() if name in els)
        if name in constraint:
            node.marks.add("constraint")
        if name not in kept:
            node.marks.add("outside")
        nodes[name] = node
    edges = [Edge(bd.name, bd.src, bd.dst, bd.dim, effort_in[b],
                  {m for m, (_, bonds) in marks.items() if bd.name in bonds})
             for b, bd in enumerate(graph.bonds) if bd.src in kept or bd.dst in kept]
    used = {n.group for n in nodes.values()}
    captions = {g: _caption(graph, g, g in keep) for g in _ordered(graph) if g in used}
    return Diagram(f"{title}: {len(nodes)} elements, {len(edges)} bonds", nodes, edges,
                   captions, used - keep)


def _ordered(graph) -> list[str]:
    """The groups in file order: bodies, joints, the instances (their own network
    elements), the network."""
    if not graph.model:
        return [NETWORK]
    return [*graph.model.bodies, *graph.model.joints, *graph.model.instances, NETWORK]


def groups_of(graph) -> dict[str, str]:
    """element -> its group: the longest body or joint name that prefixes it (module
    doc), else the longest instance name (``leg_1.motor`` for ``leg_1.motor.coil``),
    else ``network``."""
    model = graph.model
    parts = sorted([*model.bodies, *model.joints] if model else [], key=len, reverse=True)
    insts = sorted(model.instances if model else [], key=len, reverse=True)
    return {el: next((g for g in parts if el.startswith(g + "__")), None)
            or next((g for g in insts if el.startswith(g + ".")), NETWORK)
            for el in graph.elements}


def select(graph, only: str | None) -> set[str]:
    """The groups ``--only`` keeps (all without it); an unknown name is a one-line error
    listing the valid ones."""
    groups = _ordered(graph)
    if not only:
        return set(groups)
    model = graph.model
    joints_of = {b: [j.name for j in model.joints.values() if b in (j.body1, j.body2)]
                 for b in model.bodies} if model else {}
    keep: set[str] = set()
    for name in (s.strip() for s in only.split(",")):
        hits = ([g for g in groups if fnmatch.fnmatchcase(g, name)]
                if any(c in name for c in "*?[") else [name] if name in groups else [])
        if model and name in model.instances:       # an instance: all of its parts
            hits = [g for g in groups if g == name or g.startswith(name + ".")]
        if not hits:
            raise BgcError(f"no body, joint, instance or group named '{name}'",
                           key="--only", hint="give bodies (with their joints), joints, "
                           "instances, 'network' or a pattern such as 'leg_*': "
                           + ", ".join(groups))
        for g in hits:
            keep.add(g)
            keep.update(joints_of.get(g, ()))
    return keep


def constraint_elements(graph) -> set[str]:
    """The constraint elements L: the method's constraint sources (``graph.constraints``)
    and the one-port elements on each blocked direction's 0-junction (``<joint>__<label>``,
    as expand names it), directly or through its 1-junction."""
    out = {c.element for c in graph.constraints}
    els, ports = graph.elements, graph.ports
    for joint, dirs in graph.joints.items():
        for d in dirs:
            zero = f"{joint}__{d.label}"
            if not d.blocked or zero not in els:
                continue
            near = [graph.other(b, zero) for b in ports[zero]]
            near += [graph.other(b, n) for n in near if els[n].kind == "1"
                     for b in ports[n]]
            out.update(n for n in near if len(ports[n]) == 1)
    return out


def _label(name: str, kind: str, group: str) -> tuple[str, str]:
    """(label, junction subscript): the kind and the name within its group."""
    short = name[len(group) + 2:] if group != NETWORK else name
    short = short.replace("__", ".")
    if kind in ("0", "1"):
        return kind, short
    return (f"{kind}:{short}" if short and short != kind else kind), ""


def _caption(graph, group: str, kept: bool) -> str:
    """A group's frame title ('' for the network of a model without bodies)."""
    model = graph.model
    if group == NETWORK:
        return "network" if model and (model.bodies or model.joints) else ""
    what = (f"body {group}" if group in model.bodies
            else f"joint {group} ({model.joints[group].kind})" if group in model.joints
            else f"instance {group} ({model.instances[group].component})")
    return what if kept else f"{what}: outside --only"
