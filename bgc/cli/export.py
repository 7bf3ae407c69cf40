"""``bgc export MODEL --fmu OUT.fmu``: the model as an FMU (FMI 2.0, Model Exchange and
Co-Simulation, a native library for linux64) that tools without Python import
(``bgc.export.fmu``)."""

from __future__ import annotations

import json

import click

from bgc.cli.app import main, user_errors
from bgc.cli.options import (
    NUMBER,
    check_method_options,
    check_out_dir,
    json_option,
    loops_option,
    method_option,
    out_dir_option,
    parasitic_option,
    params_option,
    progress_option,
)
from bgc.methods.parasitic import SEPARATION


@main.command("export")
@click.argument("model", type=click.Path())
@click.option("--fmu", "--out", "fmu_path", required=True, type=click.Path(dir_okay=False),
              metavar="OUT.fmu", help="the FMU to write (--out, as every command's output "
                                      "file)")
@click.option("--fmi", type=click.IntRange(2, 3), default=2, show_default=True,
              help="FMI version (2.0; 3.0 is not written yet)")
@params_option("a parameter's value in the FMU (its start value there)")
@parasitic_option
@click.option("--separation", type=NUMBER, default=SEPARATION, show_default=True,
              help="--parasitic auto: parasitic frequencies over the highest functional one")
@out_dir_option
@method_option
@loops_option
@json_option
@user_errors
@progress_option
def export_cmd(model, fmu_path, fmi, params, parasitic_mode, separation, out_dir, method,
               keep_loops, as_json):
    """Write MODEL as an FMU (FMI 2.0 Model Exchange and Co-Simulation, linux64).

    The FMU's library holds the model's kernels, bgc's Radau (for Co-Simulation) and the
    start of a run (static loads, the projection onto the constraints), and needs
    neither Python nor bgc. Linking needs a C compiler (gcc, cc, clang or $CC; else
    pip install ziglang). -o is where --parasitic auto keeps the generated module it
    linearizes. See docs/fmu.md.
    """
    from bgc.export import fmu
    check_method_options(method, keep_loops, parasitic_mode,
                         separation if parasitic_mode == "auto" else None)
    check_out_dir(out_dir)
    done = fmu.export(model, fmu_path, method, fmi, params, not keep_loops, parasitic_mode,
                      separation, out_dir)
    if as_json:
        click.echo(json.dumps(done.to_dict(), indent=2))
        return
    click.echo(f"wrote {done.fmu} (FMI {done.fmi}, {' and '.join(done.interfaces)}; "
               f"{done.states} states, {done.parameters} parameters, {done.outputs} outputs, "
               f"{done.event_indicators} event indicators; {done.bytes / 1e3:.0f} kB) in "
               f"{done.timings['total']:.1f} s")
    for note in done.notes:
        click.echo(f"  note: {note}")
