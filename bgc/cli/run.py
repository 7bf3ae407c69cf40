"""``bgc run``: run a scene (``bgc.scene.scenes``): its reduced module built once, then
simulated; CSV, PNG and a JSON summary written."""

from __future__ import annotations

import json

import click

from bgc.cli.app import main, user_errors
from bgc.cli.options import (
    check_out_dir,
    json_option,
    params_option,
    progress_option,
    retired_option,
)
from bgc.errors import BgcError
from bgc.fileio import check_writable


@main.command("run")
@click.argument("scene", type=click.Path())
@click.option("--results", "out_dir", default="results/scenes", show_default=True,
              type=click.Path(file_okay=False),
              help="the directory the CSV, PNG and JSON summary go to")
@click.option("-o", "--out-dir", "gen_dir", default="generated/scenes", show_default=True,
              help="where the scene's reduced module is kept")
@retired_option("--out", "--results DIR for the directory of the scene's files (--out "
                         "names one output file in bgc's commands)")
@retired_option("--gen-dir", "-o/--out-dir DIR")
@params_option("set a parameter the scene exposes (repeatable)")
@json_option
@user_errors
@progress_option
def run_cmd(scene, out_dir, gen_dir, params, as_json):
    """Run a scene: build its reduced model (once), simulate, write CSV, PNG and a JSON
    summary. SCENE: a scene file, or the name of a scene bgc ships (pumping_chirp,
    roll_sine, ...: the repository's scenes/) where no such file is."""
    from bgc import data
    from bgc.scene import scenes as bscene
    sc = bscene.load_scene(data.find("scenes", scene))
    values = {}
    for name, value in params:
        if name not in sc.expose:
            raise BgcError(f"parameter '{name}' is not exposed by scene {sc.name}",
                           key="-p", hint="exposed: " + (", ".join(sc.expose) or "none; "
                                                       "add it to the scene's expose list"))
        values[name] = value
    check_writable(out_dir, "--results", directory=True)
    check_out_dir(gen_dir)
    summary = bscene.run_scene(sc, out_dir, gen_dir, values)
    if as_json:
        click.echo(json.dumps(summary, indent=2, default=str))
    else:
        _print_summary(sc, summary)
    if not summary["ok"]:
        raise click.ClickException(f"{sc.name}: {summary['error']} (results up to there "
                                   f"in {summary['files']['csv']})")


def _print_summary(sc, summary: dict) -> None:
    """A scene run's summary as lines: its states and statistics, the reduction passes,
    the envelope minima and the files written."""
    st = summary["stats"]
    click.echo(f"scene {sc.name}: {summary['states']} states, {summary['solver']} to "
               f"t = {summary['t_end']:g} s: {st['steps']} steps, "
               f"{st['wall_time']:.3f} s")
    for r in summary["passes"]:
        click.echo(f"  {r['pass']:16s} states {r['states_before']} -> "
                   f"{r['states_after']}")
    for name, peak in summary["noise_outputs"].items():
        click.echo(f"  {name}: numerical noise (peak {peak:.2g}), no minima, stated in "
                   f"the plot")
    for name, fs in (summary["envelope_minima_hz"] or {}).items():
        if name not in summary["noise_outputs"]:
            click.echo(f"  envelope minima of {name}: "
                       f"{', '.join(f'{f:.2f}' for f in fs[:3]) or 'none'} Hz")
    for kind, f in summary["files"].items():
        click.echo(f"  {kind}: {f}")
