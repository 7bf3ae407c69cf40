"""``bgc draw``, last step: a ``Layout`` -> an SVG, PNG or PDF file (matplotlib).

Standard bond-graph notation (Karnopp, Margolis & Rosenberg, *System Dynamics: Modeling,
Simulation, and Control of Mechatronic Systems*, 5th ed., 2012, sec. 5.1, "Basic Causal
Considerations"):

- an element is its label, ``C:k``, ``I:m``, ``Se:g``, ``MTF:rx.w1``; a junction is ``0``
  or ``1`` (its name within its group, small, beside it);
- a bond is a line with a half-arrow at the end the power flows to (``Bond.dst``);
- the causal stroke is a short line across the bond at the end towards which the effort is
  directed, the end of the element that takes the effort as its input
  (``CausalGraph.effort_in[b]``; the other end imposes it and takes the flow back):
  ``Se --|`` has it away from the source, ``Sf |--`` at the source; an I in integral
  causality has it at the I (effort in, flow out), a C in integral causality away from the
  C (flow in, effort out), an R in resistance form away from the R;
- a multibond (dimension > 1, Breedveld's notation) is a double line with its dimension
  written beside it.

Marks: constraint elements L on an orange label, algebraic loops blue under their bonds
and labels, zero-order causal paths violet, a causality conflict red; elements outside
``--only`` grey. Each element's label, bond, stroke, half-arrow, multibond dimension and
frame is an SVG group with an id (``el-NAME``, ``bond-NAME``, ``stroke-NAME``,
``arrow-NAME``, ``dim-NAME``, ``group-NAME``) so that a test or a reader can find them; an
element's and a bond's group has a ``<title>`` (a tooltip: the full name, a bond's ends and
causality); the SVG keeps its text as text.
"""

from __future__ import annotations

import io
import math
import re
from pathlib import Path

from bgc.draw.layout import FONT, MARGIN, NOTE, Layout
from bgc.errors import BgcError
from bgc.fileio import atomic_write

FORMATS = ("svg", "png", "pdf")
STROKE = 5.0            # half the causal stroke's length (pt)
BARB = (8.0, 4.5)       # the half-arrow: back along the bond, to its side (pt)
MARK = {"loop": "#3b82c4", "zcp": "#8e44ad", "conflict": "#d62728"}
CONSTRAINT = ("#ffd9a0", "#d9822b")
OUTSIDE = "#8c8c8c"
FILL = "#f6f6f2"        # a group's frame
KEY = [("causal stroke |: at the end that receives the effort", None, None),
       ("half-arrow: power direction", None, None),
       ("double line N: multibond of dimension N", None, "multibond"),
       ("constraint element L", CONSTRAINT[1], "constraint"),
       ("algebraic loop", MARK["loop"], "loop"), ("zero-order causal path", MARK["zcp"], "zcp"),
       ("causality conflict", MARK["conflict"], "conflict"),
       ("outside --only", OUTSIDE, "outside")]


def image_format(path: str | Path) -> str:
    """The format a drawing's path names by its suffix; a one-line error otherwise."""
    fmt = Path(path).suffix[1:].lower()
    if fmt not in FORMATS:
        raise BgcError(f"cannot draw to {str(path)!r}: unknown suffix '{Path(path).suffix}'",
                       key="--out", hint="use " + ", ".join(f".{f}" for f in FORMATS))
    return fmt


def render(lay: Layout, path: str | Path) -> Path:
    """Draw ``lay`` into ``path`` (atomically), in the format of its suffix."""
    import matplotlib
    from matplotlib.figure import Figure
    fmt = image_format(path)
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "bgc",
                                "font.family": "DejaVu Sans"}):
        fig = Figure(figsize=(lay.width / 72, lay.height / 72))
        ax = fig.add_axes((0, 0, 1, 1))
        ax.set_xlim(0, lay.width)
        ax.set_ylim(0, lay.height)
        ax.set_axis_off()
        _frames(ax, lay)
        for e in lay.diagram.edges:
            _bond(ax, lay, e)
        for name in lay.diagram.nodes:
            _node(ax, lay, name)
        _header(ax, lay)
        if fmt == "svg":
            buf = io.StringIO()
            fig.savefig(buf, format="svg", metadata={"Date": None})
            return atomic_write(path, _titles(buf.getvalue(), lay.diagram), "drawing")
        dpi = min(150.0, 9000.0 / max(lay.width, lay.height) * 72)
        return atomic_write(path, lambda tmp: fig.savefig(tmp, format=fmt, dpi=dpi),
                            "drawing")


def _titles(svg: str, d) -> str:
    """The SVG with a ``<title>`` (a tooltip in a browser) in each element's and bond's
    group: the element's kind and full name; the bond's ends, dimension and the end that
    receives the effort."""
    from xml.sax.saxutils import escape
    tips = {f"el-{n}": f"{node.kind} {n}" for n, node in d.nodes.items()}
    for e in d.edges:
        tips[f"bond-{e.name}"] = (
            f"bond {e.name}: {e.src} -> {e.dst}" + (f", dimension {e.dim}" if e.dim > 1
                                                    else "")
            + (f", effort into {e.effort_in}" if e.effort_in else ", no causality"))

    def add(m):
        tip = tips.get(m.group(1))
        return m.group(0) + (f"\n    <title>{escape(tip)}</title>" if tip else "")
    return re.sub(r'<g id="([^"]+)">', add, svg)


def _frames(ax, lay: Layout) -> None:
    """Each group's frame and caption (none for a model's lone network)."""
    from matplotlib.patches import Rectangle
    for g, (x0, y0, x1, y1) in lay.frames.items():
        caption = lay.diagram.groups[g]
        if not caption:
            continue
        outside = g in lay.diagram.outside
        ax.add_patch(Rectangle((x0, y0), x1 - x0, y1 - y0, facecolor=FILL,
                               edgecolor=OUTSIDE if outside else "#9a9a90", lw=0.8,
                               ls="--" if outside else "-", zorder=0, gid=f"group-{g}"))
        ax.text(x0 + 5, y1 - 4, caption, fontsize=FONT + 0.5, va="top", ha="left",
                color=OUTSIDE if outside else "#404040", style="italic", zorder=1)


def ends(lay: Layout, src: str, dst: str):
    """The bond's two ends, at the edges of its elements' labels (plus 2 pt), and its unit
    direction and normal (the normal to the left of src -> dst)."""
    (x0, y0), (x1, y1) = lay.pos[src], lay.pos[dst]
    dx, dy = x1 - x0, y1 - y0
    length = math.hypot(dx, dy) or 1.0
    ux, uy = dx / length, dy / length

    def clip(name):
        hw, hh = lay.half[name]
        hw, hh = hw + 2, hh + 2
        return min(hw / abs(ux) if ux else math.inf, hh / abs(uy) if uy else math.inf)
    a, b = clip(src), clip(dst)
    if a + b >= length:          # labels touching: the bond is their centres' segment
        a = b = length / 3
    p0 = (x0 + ux * a, y0 + uy * a)
    p1 = (x1 - ux * b, y1 - uy * b)
    return p0, p1, (ux, uy), (-uy, ux)


def _bond(ax, lay: Layout, e) -> None:
    """A bond: its marks under it, the line (a double line for a multibond, with its
    dimension), the half-arrow at dst, the causal stroke at the end receiving effort."""
    from matplotlib import patheffects
    p0, p1, (ux, uy), (nx, ny) = ends(lay, e.src, e.dst)
    xs, ys = (p0[0], p1[0]), (p0[1], p1[1])
    for m in sorted(e.marks):
        _line(ax, xs, ys, color=MARK[m], lw=6, alpha=0.35, solid_capstyle="round", zorder=2)
    outside = "outside" in lay.diagram.nodes[e.src].marks | lay.diagram.nodes[e.dst].marks
    color = OUTSIDE if outside else "black"
    act = lay.diagram.activity
    share = act.get(e.src, act.get(e.dst))
    if share is not None:       # --energy: the element's share of the run's activity
        from bgc.draw.activity import style
        width, shade = style(share)
        _line(ax, xs, ys, color=shade, lw=width + 2.6 * (e.dim > 1), solid_capstyle="butt",
              zorder=2.5,
              gid=f"activity-{e.name}")
    line = _line(ax, xs, ys, color=color, lw=0.8, zorder=3, gid=f"bond-{e.name}")
    if e.dim > 1:
        line.set_linewidth(2.6)
        line.set_path_effects([patheffects.Stroke(linewidth=2.6, foreground=color),
                               patheffects.Stroke(linewidth=1.0, foreground="white")])
        mx, my = (p0[0] + p1[0]) / 2, (p0[1] + p1[1]) / 2
        ax.text(mx + 6 * nx, my + 6 * ny, str(e.dim), fontsize=FONT - 1.5, color=color,
                ha="center", va="center", zorder=3, gid=f"dim-{e.name}")
    back, side = BARB
    _line(ax, (p1[0], p1[0] - back * ux + side * nx), (p1[1], p1[1] - back * uy + side * ny),
          color=color, lw=0.8, zorder=3, gid=f"arrow-{e.name}")
    if e.effort_in is not None:
        cx, cy = p1 if e.effort_in == e.dst else p0
        _line(ax, (cx - STROKE * nx, cx + STROKE * nx), (cy - STROKE * ny, cy + STROKE * ny),
              color=color, lw=1.3, zorder=3, gid=f"stroke-{e.name}")


def _line(ax, xs, ys, **style):
    """A line in data coordinates (``Line2D`` added as it is: ``ax.plot``'s argument
    parsing and autoscaling took a third of the SARIB's drawing time)."""
    from matplotlib.lines import Line2D
    return ax.add_artist(Line2D(xs, ys, **style))


def _node(ax, lay: Layout, name: str) -> None:
    """An element's label (a junction's name small beside it), on its mark's colour."""
    node = lay.diagram.nodes[name]
    x, y = lay.pos[name]
    fill = FILL if lay.diagram.groups[node.group] else "white"
    box = dict(boxstyle="square,pad=0.1", fc=fill, ec="none")     # hides the bonds behind
    if "conflict" in node.marks:
        box = dict(boxstyle="round,pad=0.2", fc="#ffd0d0", ec=MARK["conflict"], lw=1)
    elif "constraint" in node.marks:
        box = dict(boxstyle="round,pad=0.2", fc=CONSTRAINT[0], ec=CONSTRAINT[1], lw=0.6)
    elif "loop" in node.marks or "zcp" in node.marks:
        mark = "loop" if "loop" in node.marks else "zcp"
        box = dict(boxstyle="round,pad=0.2", fc="white", ec=MARK[mark], lw=0.9)
    junction = node.kind in ("0", "1")
    color = OUTSIDE if "outside" in node.marks else "black"
    ax.text(x, y, node.label, fontsize=FONT + 1.5 * junction, ha="center", va="center",
            weight="bold" if junction else "normal", color=color, bbox=box, zorder=4,
            gid=f"el-{name}")
    if node.sub:
        ax.text(x + lay.half[name][0] + 1, y - FONT * 0.6, node.sub, fontsize=FONT - 2.5,
                ha="left", va="center", color=OUTSIDE, zorder=4)


def _header(ax, lay: Layout) -> None:
    """The title, any note (a causality conflict), and the key: the notation, and the
    marks the drawing has, wrapped to its width."""
    d = lay.diagram
    top = lay.height - MARGIN / 2
    ax.text(MARGIN, top, d.title, fontsize=FONT + 3, va="top", ha="left", weight="bold")
    for i, note in enumerate(lay.notes):
        ax.text(MARGIN, top - 16 - NOTE * i, note, fontsize=FONT, va="top", ha="left",
                color=MARK["conflict"])
    marks = {m for n in d.nodes.values() for m in n.marks}
    marks |= {m for e in d.edges for m in e.marks} | {"multibond" for e in d.edges
                                                       if e.dim > 1}
    x, y = MARGIN, top - 26 - NOTE * len(lay.notes)
    if d.activity:
        x = _activity_key(ax, x, y)
    for text, color, mark in KEY:
        if mark and mark not in marks:
            continue
        size = len(text) * (FONT - 0.5) * 0.55 + 14 + 13 * bool(color)
        if x > MARGIN and x + size > lay.width - MARGIN:
            x, y = MARGIN, y - 12
        if color:
            _line(ax, (x, x + 10), (y, y), color=color, lw=5, alpha=0.6)
            x += 13
        ax.text(x, y, text, fontsize=FONT - 0.5, va="center", ha="left", color="#404040")
        x += size - 13 * bool(color)


def _activity_key(ax, x: float, y: float) -> float:
    """--energy's key: bonds at shares 1e-4 .. 1 of the activity; returns the x after."""
    from bgc.draw.activity import style
    ax.text(x, y, "activity share:", fontsize=FONT - 0.5, va="center", ha="left",
            color="#404040")
    x += 70
    for share, label in ((1e-4, "1e-4"), (1e-3, "1e-3"), (1e-2, "1 %"), (1e-1, "10 %"),
                         (1.0, "100 %")):
        width, shade = style(share)
        _line(ax, (x, x + 14), (y, y), color=shade, lw=width, solid_capstyle="butt")
        ax.text(x + 16, y, label, fontsize=FONT - 1.5, va="center", ha="left",
                color="#404040")
        x += 46
    return x + 10
