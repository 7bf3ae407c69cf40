"""``bgc draw``, second step: a ``Diagram`` -> a ``Layout``, where each element and each
group's frame sits (in points, y up).

Each group's elements are laid out on their own by igraph's Sugiyama layered layout
(``layout_sugiyama``: layers along the bonds' power direction, crossings reduced; compiled
C, 20 ms for the whole SARIB), from the bonds inside the group; then the groups' frames
are packed in rows, in depth-first order over the bonds between them, so that a body's
joints sit beside it and the SARIB's 738 elements read as 32 frames.
"""

from __future__ import annotations

import math
import textwrap
from dataclasses import dataclass

from bgc.draw.diagram import Diagram

FONT = 7.0              # label size (pt)
CHAR = 0.62 * FONT      # a label character's width (pt)
LAYER = 48.0            # between two layers of elements (pt)
PAD = 14.0              # inside a group's frame, around its elements (pt)
CAPTION = 14.0          # a frame's title band (pt)
GAP = 36.0              # between two frames (pt)
MARGIN = 20.0           # around the drawing; HEADER: the title and key above it
HEADER = 60.0
NOTE = 14.0             # a note's line in the header (a causality conflict)


@dataclass
class Layout:
    diagram: Diagram
    pos: dict[str, tuple[float, float]]        # element -> its label's centre
    half: dict[str, tuple[float, float]]       # element -> its label's half width, height
    frames: dict[str, tuple[float, float, float, float]]   # group -> x0, y0, x1, y1
    width: float
    height: float
    notes: list[str]                            # the diagram's notes, wrapped to the width


def layout(d: Diagram) -> Layout:
    """Where everything goes: each group laid out alone, then the groups in rows."""
    half = {n: (8.0, 8.5) if node.kind in ("0", "1") else
            (len(node.label) * CHAR / 2 + 3, FONT * 0.75) for n, node in d.nodes.items()}
    members: dict[str, list[str]] = {g: [] for g in d.groups}
    for n, node in d.nodes.items():
        members[node.group].append(n)
    local = {g: _group(g, names, d, half) for g, names in members.items()}
    origin = _arrange(d, {g: size for g, (_, size) in local.items()})
    pos, frames = {}, {}
    for g, (place, (w, h)) in local.items():
        x0, y0 = origin[g]
        frames[g] = (x0, y0, x0 + w, y0 + h)
        for n, (x, y) in place.items():
            pos[n] = (x0 + x, y0 + y)
    width = max((f[2] for f in frames.values()), default=0) + MARGIN
    width = max(width, 480.0)
    chars = int((width - 2 * MARGIN) / (0.6 * FONT))
    notes = [line for note in d.notes for line in textwrap.wrap(note, chars)]
    height = (max((f[3] for f in frames.values()), default=0) + MARGIN + HEADER
              + NOTE * len(notes))
    return Layout(d, pos, half, frames, width, height, notes)


def _sugiyama(n: int, edges: list[tuple[int, int]]) -> list[tuple[float, float]]:
    """(x, layer) of ``n`` vertices by igraph's Sugiyama layout of the directed
    ``edges`` (cycles broken by igraph's feedback arc set)."""
    import igraph
    g = igraph.Graph(n=n, edges=sorted(set(edges)), directed=True)
    return [(x, y) for x, y in g.layout_sugiyama(maxiter=200).coords[:n]]


def _group(group: str, names: list[str], d: Diagram, half) -> tuple[dict, tuple]:
    """A group's elements placed in its frame (frame-relative: each in the middle of its
    column, so that a chain of elements draws straight), and the frame's size."""
    idx = {n: i for i, n in enumerate(names)}
    edges = [(idx[e.src], idx[e.dst]) for e in d.edges
             if e.src in idx and e.dst in idx and e.src != e.dst]
    coords = _sugiyama(len(names), edges)
    left = min(x for x, _ in coords)
    widest = max(2 * half[n][0] for n in names)
    tallest = max(half[n][1] for n in names)
    layers = max(y for _, y in coords)
    place = {n: (PAD + widest / 2 + (x - left) * (widest + 16),
                 PAD + (layers - y) * LAYER + tallest) for n, (x, y) in zip(names, coords)}
    caption = d.groups[group]
    w = max(max(x + half[n][0] for n, (x, _) in place.items()) + PAD,
            len(caption) * (FONT + 0.5) * 0.6 + 12)
    h = layers * LAYER + 2 * tallest + 2 * PAD + CAPTION * bool(caption)
    return place, (w, h)


def _arrange(d: Diagram, size: dict[str, tuple[float, float]]) -> dict[str, tuple]:
    """Each group's frame's lower-left corner: the groups in depth-first order over the
    bonds between them (from the first group in file order: a body, then a joint of it,
    the body across it, ...), so that a body's joints sit beside it, packed in rows from
    left to right and top to bottom (the groups ``--only`` left out first, so that their
    bonds come from above), wrapped at a width that keeps the drawing about as
    wide as tall."""
    near: dict[str, list[str]] = {g: [] for g in size}
    for e in d.edges:
        a, b = d.nodes[e.src].group, d.nodes[e.dst].group
        if a != b:
            near[a].append(b)
            near[b].append(a)
    rank = {g: i for i, g in enumerate(size)}
    order: list[str] = []
    for start in size:
        stack = [start]
        while stack:
            g = stack.pop()
            if g in order:
                continue
            order.append(g)
            stack += sorted(set(near[g]) - set(order), key=rank.get, reverse=True)
    order = sorted(order, key=lambda g: g not in d.outside)   # --only's neighbours on top
    area = sum((w + GAP) * (h + GAP) for w, h in size.values())
    limit = max(max(w for w, _ in size.values()), 1.3 * math.sqrt(area))
    rows: list[list[str]] = [[]]
    for g in order:
        if rows[-1] and sum(size[h][0] + GAP for h in rows[-1]) + size[g][0] > limit:
            rows.append([])
        rows[-1].append(g)
    origin, top = {}, 0.0
    for r in rows:
        x, tall = MARGIN, max(size[g][1] for g in r)
        for g in r:
            origin[g] = (x, -top - size[g][1])
            x += size[g][0] + GAP
        top += tall + GAP
    return {g: (x, y + top + MARGIN - GAP) for g, (x, y) in origin.items()}
