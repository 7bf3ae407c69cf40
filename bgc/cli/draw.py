"""``bgc draw MODEL --out FILE``: the model's bond graph as the causality stage assigned it, in
standard notation (``bgc.draw``), to an SVG, PNG or PDF file chosen by its suffix."""

from __future__ import annotations

import time

import click

from bgc.cli.app import main, user_errors
from bgc.cli.options import (
    check_method_options,
    loops_option,
    method_option,
    progress_option,
    retired_option,
)


@main.command()
@click.argument("model", type=click.Path())
@click.option("--out", required=True, metavar="FILE",
              help="the drawing: .svg, .png or .pdf")
@retired_option("-o", "--out FILE for the drawing (-o names the directory of generated "
                      "modules, which bgc draw does not write)")
@click.option("--only", metavar="NAME[,NAME...]",
              help="draw some groups: a body (with its joints), a joint, an instance of a "
                   "component (all its parts), 'network' (the model's own elements) or a "
                   "pattern such as 'leg_*'; the SARIB's leg 1: --only leg_1")
@click.option("--energy", "energy", type=click.Path(dir_okay=False), metavar="RUN.json",
              help="a run's activities (bgc energy --out RUN.json): each element's bond "
                   "drawn as wide and dark as its share of the run's activity")
@method_option
@loops_option
@user_errors
@progress_option
def draw(model, out, only, energy, method, keep_loops):
    """Draw the bond graph: elements, 0- and 1-junctions, half-arrows for the power
    direction, causal strokes (at the end that receives the effort), multibonds with their
    dimension; constraint elements, zero-order causal paths and algebraic loops marked,
    grouped by body and joint. A causality conflict is drawn (no strokes, the conflicting
    elements marked), then reported as an error. With --energy RUN.json (bgc energy
    --out), each element's bond is as wide and dark as its share of the run's activity."""
    from bgc import progress
    from bgc.draw import diagram, layout, render
    from bgc.fileio import check_writable
    check_method_options(method, keep_loops)
    render.image_format(out)
    check_writable(out, "drawing")
    run = None
    if energy is not None:
        from bgc.draw import activity
        run = activity.load(energy)
    d, conflict = diagram.of_model(model, method, only, open_loops=not keep_loops)
    if run is not None:
        activity.apply(d, run, energy)
    with progress.stage("draw") as st:
        t = time.perf_counter()
        lay = layout.layout(d)
        laid = time.perf_counter() - t
        path = render.render(lay, out)
        st.done(f"{path}: {progress.count(len(d.nodes), 'element')}, "
                f"{progress.count(len(d.edges), 'bond')} (layout {laid:.2f} s)")
    if conflict is not None:
        raise conflict
