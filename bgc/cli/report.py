"""``bgc report``: the run ``bgc simulate`` makes with the same options, written as one
self-contained HTML page (``bgc.analysis.report``) instead of CSV and PNG files."""

from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import click

from bgc.cli import simulate as sim
from bgc.cli.app import main, user_errors
from bgc.cli.options import json_option, progress_option
from bgc.fileio import check_writable

# simulate's options that choose its files (the report is the one file here), its JSON
# and --quiet (this command has its own)
_NOT_RUN_OPTIONS = {"out", "plot", "states", "zoom", "report", "as_json", "quiet"}


@main.command()
@click.option("--out", type=click.Path(dir_okay=False),
              help="the HTML file (default: report.html; without MODEL: the main job's, "
                   "results/sarib_<direction>_<kind>.html)")
@json_option
@user_errors
@progress_option
def report(out, as_json, **options):
    """Run MODEL as bgc simulate does (the same options) and write one self-contained
    HTML page: zoomable time histories, each chirp envelope with its minima and the
    frequency response's anti-resonances, the FRF's magnitude and phase, the modes, and
    the mechanism in 3D playing the run and each mode shape. Works offline: plotly.js is
    inside the page. Without MODEL: the main job (make run's SARIB chirp)."""
    ctx = click.get_current_context()
    options.update(out=None, plot=None, states=True, zoom=None, report=out, as_json=False)
    o = sim.resolve(options, ctx)
    o = replace(o, out=None, plot=None, zoom=None,
                report=o.report if options["model"] is None or out else "report.html")
    check_writable(o.report, "--out")
    run = sim.run_for(o)
    path = Path(run.files["report"])
    if as_json:
        click.echo(json.dumps({"model": run.module.MODEL_NAME, "report": str(path),
                               "bytes": path.stat().st_size,
                               "modes": len(run.linear.modal.modes) if run.linear else 0,
                               "linear_error": run.linear_error,
                               "t_end": float(run.result.t[-1])}, indent=2))
        return
    click.echo(f"{run.module.MODEL_NAME}: report {path} ({path.stat().st_size / 1e6:.1f} MB)")
    if run.linear_error:
        click.echo(f"  no frequency response or modes: {run.linear_error}")


report.params[:0] = [p for p in sim.simulate.params if p.name not in _NOT_RUN_OPTIONS]
