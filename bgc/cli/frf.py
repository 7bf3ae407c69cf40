"""``bgc frf``: the frequency response of a model output to an excitation direction,
linearized about the static equilibrium (``bgc.analysis.frf``)."""

from __future__ import annotations

import json

import click
import numpy as np

from bgc import progress
from bgc.cli.app import main, user_errors
from bgc.cli.options import (
    POSITIVE,
    check_direction,
    check_method_options,
    check_out_dir,
    check_output,
    check_overrides,
    check_params,
    json_option,
    loops_option,
    method_option,
    out_dir_option,
    parasitic_option,
    params_option,
    split_constants,
    progress_option,
    run_parameters,
)
from bgc.fileio import check_writable
from bgc.pipeline import ensure_module


@main.command()
@click.argument("model", type=click.Path())
@click.option("--input", "direction", required=True, metavar="NAME",
              help="the excitation direction driven (e.g. pumping, roll, pitch)")
@click.option("--output", "output", required=True, metavar="NAME", help="the model output")
@click.option("--f-min", type=POSITIVE, default=5.0, show_default=True, help="band start [Hz]")
@click.option("--f-max", type=POSITIVE, default=25.0, show_default=True, help="band end [Hz]")
@click.option("--out", type=click.Path(dir_okay=False),
              help="CSV of f, |H|, phase [deg] on a 0.01 Hz grid")
@params_option("override a parameter (no recompilation)")
@out_dir_option
@method_option
@parasitic_option
@loops_option
@json_option
@user_errors
@progress_option
def frf(model, direction, output, f_min, f_max, out, params, out_dir, method, parasitic_mode,
        keep_loops, as_json):
    """Frequency response of an output to an excitation direction, linearized about the
    static equilibrium; its anti-resonances and resonances in the band."""
    # twelve parameters, one per option as click passes them, each read once below: a
    # settings object would only rename them (simulate's 22 have one, SimulateOptions)
    from bgc.analysis import frf as bfrf
    from bgc.analysis import modes
    bfrf.check_band(f_min, f_max)
    check_method_options(method, keep_loops, parasitic_mode, linearizes=True)
    check_out_dir(out_dir)
    check_writable(out, "--out")
    constants, params = split_constants(model, params)

    def check(decl):            # against the model, before any compile
        check_output(decl, output)
        check_direction(decl, direction, "--input")
        check_params(decl, params)
        check_overrides(model, params, constants=constants)
    module, m, _ = ensure_module(model, out_dir, method, open_loops=not keep_loops,
                                 check=check, constants=constants)
    p, choice = run_parameters(module, m, method, params, parasitic_mode)
    with progress.stage("frequency response") as stage:
        lin = bfrf.linearize(module, m, direction, p)
        f, h = grid = bfrf.sweep(lin, output, f_min, f_max)
        anti, res, peaks = modes.resonances(module, m, lin, output, f_min, f_max,
                                            grid)
        stage.done(f"{progress.count(len(f), 'frequency', 'frequencies')}, "
                   f"{progress.count(len(anti), 'anti-resonance')}, "
                   f"{progress.count(len(res), 'resonance')}")
    report = {"model": m.name, "method": method, "input": direction, "output": output,
              "f_min": f_min, "f_max": f_max, "equilibrium_residual": lin.residual,
              "antiresonances_hz": [round(f, 2) for f in anti],
              "resonances_hz": [round(f, 2) for f in res],
              "peaks_hz": [round(f, 2) for f in peaks],
              "parasitic": choice.to_dict() if choice else None}
    if out:
        from bgc.analysis.results import write_table
        report["files"] = {"csv": str(write_table(out, ["f_hz", "abs_H", "phase_deg"],
                                                  [f, np.abs(h), np.degrees(np.angle(h))]))}
    if as_json:
        click.echo(json.dumps(report, indent=2))
        return
    click.echo(f"{m.name}: {output} / {direction} in [{f_min:g}, {f_max:g}] Hz, linearized "
               f"about the equilibrium (|dx/dt| = {lin.residual:.2g})")
    if choice:
        click.echo(choice.describe())
    click.echo(f"  anti-resonances: {', '.join(f'{f:.2f}' for f in anti) or 'none'} Hz")
    click.echo(f"  resonances: {', '.join(f'{f:.2f}' for f in res) or 'none'} Hz (natural "
               f"frequencies of the modes behind the peaks of |H|, at "
               f"{', '.join(f'{f:.2f}' for f in peaks) or 'none'} Hz)")
    if out:
        click.echo(f"  csv: {report['files']['csv']}")
