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
    check_overrides,
    json_option,
    method_option,
    out_dir_option,
    params_option,
    parse_params,
    split_constants,
    progress_option,
)
from bgc.errors import BgcError
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
@click.option("--parasitic", "parasitic_mode", type=click.Choice(["given", "auto"]),
              default="given", show_default=True,
              help="method parasitic: the joints' stiffness as the model gives it, or chosen "
                   "by bgc.methods.parasitic.auto (as bgc simulate --parasitic auto)")
@json_option
@user_errors
@progress_option
def frf(model, direction, output, f_min, f_max, out, params, out_dir, method, parasitic_mode,
        as_json):
    """Frequency response of an output to an excitation direction, linearized about the
    static equilibrium; its anti-resonances and resonances in the band."""
    # eleven parameters, one per option as click passes them, each read once below: a
    # settings object would only rename them (simulate's 22 have one, SimulateOptions)
    from bgc.analysis import frf as bfrf
    if not 0 < f_min < f_max:
        raise BgcError(f"need 0 < --f-min < --f-max, got {f_min} and {f_max}", key="--f-min")
    check_writable(out, "--out")
    constants, params = split_constants(model, params)
    module, m, _ = ensure_module(model, out_dir, method, constants=constants)
    if output not in module.OUTPUT_NAMES:
        raise BgcError(f"unknown output '{output}'", key="--output",
                       hint="outputs: " + ", ".join(module.OUTPUT_NAMES))
    check_overrides(model, params, constants)
    p, choice = _parameters(module, m, method, params, parasitic_mode)
    with progress.stage("frequency response") as stage:
        lin = bfrf.linearize(module, m, direction, p)
        f, h = grid = bfrf.sweep(lin, output, f_min, f_max)
        anti, res = bfrf.extrema(lin, output, f_min, f_max, grid)
        stage.done(f"{progress.count(len(f), 'frequency', 'frequencies')}, "
                   f"{progress.count(len(anti), 'anti-resonance')}, "
                   f"{progress.count(len(res), 'resonance')}")
    report = {"model": m.name, "method": method, "input": direction, "output": output,
              "f_min": f_min, "f_max": f_max, "equilibrium_residual": lin.residual,
              "antiresonances_hz": [round(f, 2) for f in anti],
              "resonances_hz": [round(f, 2) for f in res],
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
    click.echo(f"  resonances: {', '.join(f'{f:.2f}' for f in res) or 'none'} Hz")
    if out:
        click.echo(f"  csv: {report['files']['csv']}")


def _parameters(module, model, method, params, mode):
    """The module's parameters with ``-p`` applied; under ``--parasitic auto`` the joints'
    stiffness and damping chosen first (the explicit ``-p`` values still win)."""
    p = parse_params(module, params)
    if mode != "auto":
        return p, None
    from bgc import methods
    from bgc.methods import parasitic
    if methods.get(method).ideal:
        raise BgcError(f"--parasitic auto applies to --method parasitic, not {method}",
                       key="--parasitic", hint="drop --parasitic or use --method parasitic")
    p, choice = parasitic.auto(module, model, module.initial_state(p), p)
    return parse_params(module, params, base=p), choice
