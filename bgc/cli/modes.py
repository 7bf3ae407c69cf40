"""``bgc modes``: the modes of a model linearized about its static equilibrium (the
linearization ``bgc frf`` makes): natural frequency, damping ratio, kind and the bodies
that carry each (``bgc.analysis.modes``)."""

from __future__ import annotations

import json
import math

import click

from bgc import progress
from bgc.cli.app import main, user_errors
from bgc.cli.options import (
    NUMBER,
    check_method_options,
    check_out_dir,
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
from bgc.errors import BgcError
from bgc.pipeline import ensure_module


@main.command()
@click.argument("model", type=click.Path())
@click.option("--f-min", type=NUMBER, default=0.0, show_default=True,
              help="band start [Hz] (natural frequencies)")
@click.option("--f-max", type=NUMBER, help="band end [Hz] (default: every mode)")
@params_option("override a parameter (no recompilation)")
@out_dir_option
@method_option
@parasitic_option
@loops_option
@json_option
@user_errors
@progress_option
def modes(model, f_min, f_max, params, out_dir, method, parasitic_mode, keep_loops, as_json):
    """Modes of MODEL about its static equilibrium: natural frequency, damping ratio,
    kind (functional; parasitic: the joints' stiff springs; overdamped; unstable) and the
    bodies with the largest share of each mode's kinetic energy; --json adds each shape
    over the bodies' pose coordinates."""
    from bgc.analysis import frf, mechanism
    from bgc.analysis import modes as bmodes
    f_max = math.inf if f_max is None else f_max
    if not 0 <= f_min < f_max:
        raise BgcError(f"need 0 <= --f-min < --f-max, got {f_min:g} and {f_max:g}",
                       key="--f-min", hint="give the band's start first")
    check_method_options(method, keep_loops, parasitic_mode, linearizes=True)
    check_out_dir(out_dir)

    constants, params = split_constants(model, params)

    def check(decl):            # against the model, before any compile
        check_params(decl, params)
        check_overrides(model, params, constants=constants)
    module, m, _ = ensure_module(model, out_dir, method, check=check, constants=constants)
    p, choice = run_parameters(module, m, method, params, parasitic_mode)
    with progress.stage("modes") as stage:
        lin = frf.linearize(module, m, None, p)
        mech = mechanism.of_model(m, module, lin.p)
        modal = bmodes.analyse(module, m, lin, mech)
        shown = modal.band(f_min, f_max)
        stage.done(f"{progress.count(len(shown), 'mode')} in the band of "
                   f"{len(modal.modes)}, {modal.rigid} rigid")
    report = {"model": m.name, "method": method, "f_min": f_min,
              "f_max": None if math.isinf(f_max) else f_max,
              "equilibrium_residual": lin.residual, "states": modal.states,
              "subspace": modal.states if modal.basis is None else modal.basis.shape[1],
              "constraint_rank": modal.constraints, "invariance": modal.invariance,
              "rigid_motions": modal.rigid,
              "modes": [md.to_dict(module.STATE_NAMES, bmodes.body_states(mech))
                        for md in shown],
              "parasitic": choice.to_dict() if choice else None}
    if as_json:
        click.echo(json.dumps(report, indent=2))
        return
    band = f"[{f_min:g}, {'inf' if math.isinf(f_max) else f'{f_max:g}'}] Hz"
    click.echo(f"{m.name} ({method}): {progress.count(len(shown), 'mode')} in {band}, "
               f"linearized about the equilibrium (|dx/dt| = {lin.residual:.2g})")
    if modal.basis is not None:
        click.echo(f"  in the constraint subspace: {report['subspace']} of {modal.states} "
                   f"states ({modal.constraints} independent constraint rows)")
    if modal.rigid:
        click.echo(f"  {modal.rigid} eigenvalues at zero (rigid motions: free or idle "
                   "coordinates), not listed")
    if choice:
        click.echo(choice.describe())
    click.echo(f"  {'#':>3} {'f [Hz]':>10} {'damping':>8}  {'kind':10} bodies (kinetic "
               "energy share)")
    for i, md in enumerate(shown, 1):
        bodies = ", ".join(f"{n} {s:.0%}" for n, s in md.bodies) or "-"
        click.echo(f"  {i:>3} {md.frequency_hz:>10.4f} {md.damping_ratio:>8.4f}  "
                   f"{md.kind:10} {bodies}")
