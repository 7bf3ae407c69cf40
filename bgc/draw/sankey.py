"""``bgc energy --sankey FILE``: where the power goes, as a Sankey-style chart of mean
power over the run (``analysis.energy.Balance``), PNG or SVG by the suffix.

Left, what fed the run: the sources' supply and the stores that gave energy back
(energy stored at the end less than at the start: a body that fell, a spring that
relaxed), each by the body, joint or component that owns it. Right, where it went: what
each group dissipated and the energy it holds more at the end. The two sides are equal
(the balance; its residual is stated). A band joins every feed to every destination in
proportion to both: the balance says how much each element took and gave, not which
path through the junction structure the power took, so the chart draws the split, not a
route. Groups under ``MIN_SHARE`` of the total are summed into one node per side.
"""

from __future__ import annotations

from pathlib import Path

from bgc.errors import BgcError
from bgc.fileio import atomic_write

FORMATS = ("png", "svg")
MIN_SHARE = 0.01
COLORS = {"supplied": "#d9822b", "released": "#8fb8de", "dissipated": "#c0392b",
          "stored": "#3b82c4"}


def image_format(path: str | Path, key: str = "--sankey") -> str:
    fmt = Path(path).suffix[1:].lower()
    if fmt not in FORMATS:
        raise BgcError(f"cannot draw a chart to {str(path)!r}: unknown suffix "
                       f"'{Path(path).suffix}'", key=key,
                       hint="use " + ", ".join(f".{f}" for f in FORMATS))
    return fmt


def sides(bal) -> tuple[list, list]:
    """(feeds, destinations): ``(label, column, mean power [W])`` lists, largest first,
    per owner (an element's body or joint, else itself), the small ones summed."""
    span = (bal.t1 - bal.t0) or 1.0
    acc: dict[tuple[str, str], float] = {}
    for ln in bal.elements:
        owner = bal.owner.get(ln.name, ln.name)
        for column, value in (("supplied", ln.supplied), ("stored", ln.stored),
                              ("dissipated", ln.dissipated)):
            if value:
                acc[owner, column] = acc.get((owner, column), 0.0) + value / span
    feeds, dests = [], []
    for (owner, column), p in acc.items():
        if column == "supplied":
            (feeds if p > 0 else dests).append((owner, "supplied" if p > 0 else "stored",
                                                abs(p)))
        elif column == "stored":
            (dests if p > 0 else feeds).append((owner, "stored" if p > 0 else "released",
                                                abs(p)))
        else:
            (dests if p > 0 else feeds).append((owner, "dissipated", abs(p)))
    return _merge(feeds), _merge(dests)


def _merge(items: list) -> list:
    total = sum(p for _, _, p in items) or 1.0
    items = sorted(items, key=lambda it: -it[2])
    big = [it for it in items if it[2] >= MIN_SHARE * total]
    small = [it for it in items if it[2] < MIN_SHARE * total]
    if small:
        big.append((f"{len(small)} others", small[0][1] if len({s[1] for s in small}) == 1
                    else "other", sum(p for _, _, p in small)))
    return big


def draw(bal, path: str | Path, title: str) -> Path:
    """The chart of ``bal`` into ``path`` (atomically)."""
    import matplotlib
    from matplotlib.figure import Figure
    from matplotlib.patches import PathPatch, Rectangle
    from matplotlib.path import Path as MPath
    fmt = image_format(path)
    feeds, dests = sides(bal)
    total_l = sum(p for *_, p in feeds) or 1.0
    total_r = sum(p for *_, p in dests) or 1.0
    n = max(len(feeds), len(dests), 1)
    height = max(4.0, 0.42 * n + 2.0)
    gap = 0.025                         # between nodes, as a fraction of the column
    with matplotlib.rc_context({"svg.fonttype": "none", "svg.hashsalt": "bgc",
                                "font.family": "DejaVu Sans"}):
        fig = Figure(figsize=(11, height))
        ax = fig.add_axes((0.02, 0.06, 0.96, 0.84))
        ax.set_xlim(-0.62, 1.62)
        ax.set_ylim(-0.02, 1.02)
        ax.set_axis_off()
        x0, x1, w = 0.0, 1.0, 0.035

        def column(items, total):
            room = 1.0 - gap * (len(items) - 1)
            y, out = 1.0, []
            for label, col, p in items:
                h = room * p / total
                out.append((label, col, p, y - h, y))
                y -= h + gap
            return out
        left, right = column(feeds, total_l), column(dests, total_r)
        # bands: feed i to destination j carries p_i p_j / total, stacked on both sides
        lcur = {i: top for i, (*_, bot, top) in enumerate(left)}
        rcur = {j: top for j, (*_, bot, top) in enumerate(right)}
        for i, (_, lcol, pl, lb, lt) in enumerate(left):
            for j, (_, rcol, pr, rb, rt) in enumerate(right):
                share = pr / total_r
                hl, hr = (lt - lb) * share, (rt - rb) * (pl / total_l)
                ya, yb = lcur[i], rcur[j]
                lcur[i] -= hl
                rcur[j] -= hr
                xa, xb, xm = x0 + w, x1, 0.5
                verts = [(xa, ya), (xm, ya), (xm, yb), (xb, yb), (xb, yb - hr),
                         (xm, yb - hr), (xm, ya - hl), (xa, ya - hl), (xa, ya)]
                codes = [MPath.MOVETO, MPath.CURVE4, MPath.CURVE4, MPath.CURVE4,
                         MPath.LINETO, MPath.CURVE4, MPath.CURVE4, MPath.CURVE4,
                         MPath.CLOSEPOLY]
                ax.add_patch(PathPatch(MPath(verts, codes), fc=COLORS.get(rcol, "#999999"),
                                       ec="none", alpha=0.35, zorder=1))
        for items, x, ha, dx in ((left, x0, "right", -0.015), (right, x1, "left", w + 0.015)):
            for label, col, p, bot, top in items:
                ax.add_patch(Rectangle((x, bot), w, top - bot,
                                       fc=COLORS.get(col, "#999999"), ec="none", zorder=2))
                ax.text(x + dx, (bot + top) / 2, f"{label} ({col}): {_watts(p)}",
                        ha=ha, va="center", fontsize=8.5, zorder=3)
        ax.text(x0 + w / 2, 1.015, "fed by", ha="center", va="bottom", fontsize=9,
                weight="bold")
        ax.text(x1 + w / 2, 1.015, "went to", ha="center", va="bottom", fontsize=9,
                weight="bold")
        fig.suptitle(f"{title}: mean power over t = {bal.t0:g} .. {bal.t1:g} s",
                     fontsize=11, weight="bold")
        span = (bal.t1 - bal.t0) or 1.0
        fig.text(0.02, 0.015,
                 f"supplied {_watts(bal.supplied / span)} = stored "
                 f"{_watts(bal.stored / span)} + dissipated "
                 f"{_watts(bal.dissipated / span)}; residual {bal.residual / span:.2g} W. "
                 "Bands split each feed over the destinations in proportion (not the "
                 "route through the junctions).", fontsize=8, color="#404040")
        if fmt == "svg":
            import io
            buf = io.StringIO()
            fig.savefig(buf, format="svg", metadata={"Date": None})
            return atomic_write(path, buf.getvalue(), "--sankey")
        return atomic_write(path, lambda tmp: fig.savefig(tmp, format=fmt, dpi=130),
                            "--sankey")


def _watts(p: float) -> str:
    a = abs(p)
    for scale, unit in ((1e6, "MW"), (1e3, "kW"), (1.0, "W"), (1e-3, "mW"), (1e-6, "uW")):
        if a >= scale:
            return f"{p / scale:.3g} {unit}"
    return f"{p:.2g} W"
