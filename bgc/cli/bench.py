"""``bgc bench``: the benchmarks (``bgc.bench``): speed against accuracy, CSV + PNG +
summary.md."""

from __future__ import annotations

import json

import click

from bgc.cli.app import main, user_errors
from bgc.cli.options import POSITIVE, json_option, retired_option
from bgc.errors import BgcError
from bgc.fileio import check_writable


@main.command()
@click.option("--results", "out", default="bench/results", show_default=True,
              type=click.Path(file_okay=False),
              help="the directory CSV, PNG and summary.md go to")
@retired_option("--out", "--results DIR for the directory of the benchmarks' files (--out "
                         "names one output file in bgc's commands)")
@click.option("--part", "parts", multiple=True,
              type=click.Choice(["peers", "precision", "stiffness", "stability", "compile",
                                 "startup", "symmetry", "scenes", "activity", "iftomm",
                                 "components"]),
              help="run only this part (repeatable; default: all)")
@click.option("--quick", is_flag=True,
              help="every part at small scale (a slider-crank, a pendulum): minutes")
@click.option("--repeats", type=int, default=3, show_default=True,
              help="peers: runs per integrator (the median is reported)")
@click.option("--budget", type=POSITIVE, default=60.0, show_default=True,
              help="work-precision: a series stops after a run longer than this [s]")
@click.option("--build", type=click.Path(file_okay=False),
              help="where the benchmarks' generated modules go (default: build/ beside the "
                   "--results directory, bench/build; --quick: build/ inside it)")
@json_option
@user_errors
def bench(out, parts, quick, repeats, budget, build, as_json):
    """Measure speed against accuracy: peers, work-precision, parasitic stiffness,
    stability maps, compile cost (CSV + PNG + summary.md in --results)."""
    from bgc import bench as bbench
    if repeats < 1:
        raise BgcError(f"--repeats must be >= 1, got {repeats}", key="--repeats")
    check_writable(out, "--results", directory=True)
    report = bbench.run(out, parts or bbench.PARTS, quick, repeats, budget,
                        log=lambda m: click.echo(m, err=True), build=build)
    if as_json:
        click.echo(json.dumps({"summary": report["summary"], "targets": report["targets"]},
                              indent=2))
        return
    for t in report["targets"]:
        click.echo(f"target: {t}")
    click.echo(f"summary: {report['summary']}")
