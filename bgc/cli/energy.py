"""``bgc energy MODEL``: where the power goes. The run ``bgc simulate`` makes with the same
options (method, excitation, ``-p`` without recompiling, solver, tolerances), on the
model's energy variant (``codegen.energy``: every element's work and activity integrated
by the solver), read as an energy balance (``analysis.energy``): per element and per
body, joint and component, the energy supplied, stored and dissipated, the activity and
its share, and the balance's residual."""

from __future__ import annotations

import functools
import json

import click

from bgc import progress
from bgc.cli import simulate as sim
from bgc.cli.app import main, user_errors
from bgc.cli.options import NUMBER, json_option, progress_option
from bgc.errors import BgcError, SimulationError
from bgc.fileio import atomic_write, check_writable

# simulate's options that are not this command's: its files, its JSON and --quiet (this
# command has its own), and MODEL (required here: no main job)
_NOT_RUN_OPTIONS = {"model", "out", "plot", "states", "zoom", "report", "as_json", "quiet"}


@main.command()
@click.argument("model", type=click.Path())
@click.option("--out", type=click.Path(dir_okay=False),
              help="also write the JSON (as --json prints it) to this file, for "
                   "bgc draw --energy")
@click.option("--sankey", type=click.Path(dir_okay=False),
              help="a Sankey chart of the mean power from the sources to where it is "
                   "stored and dissipated, per body, joint and component (.png or .svg)")
@click.option("--since", type=NUMBER, metavar="T",
              help="account from the first output time at or after T [s] to the end "
                   "(e.g. the steady state, past a transient; default: the whole run)")
@click.option("--top", type=click.IntRange(1), default=20, show_default=True,
              help="the text report's most active elements")
@json_option
@user_errors
@progress_option
def energy(out, sankey, since, top, as_json, **options):
    """Run MODEL as bgc simulate does (the same options) and say where the power goes:
    for every element that supplies, stores or dissipates energy, and summed per body,
    per joint and per component instance, the energy supplied (sources; a method's
    constraint elements, whose work ideal joints keep at zero), stored at the end minus
    the start (C, I, the bodies' kinetic and potential energy, parasitic springs),
    dissipated (R, parasitic dampers), the activity (the integral of |power|) and its
    share of the total; and the balance supplied = stored + dissipated with its
    residual. The power integrals are states of the model's energy variant
    (<name>_<method>_energy.py), integrated by the solver within its tolerances."""
    ctx = click.get_current_context()
    options.update(out=None, plot=None, states=True, zoom=None, report=None,
                   as_json=False)
    o = sim.resolve(options, ctx)
    sim._check_options(o)
    check_writable(out, "--out")
    if sankey:
        from bgc.draw.sankey import image_format
        image_format(sankey, "--sankey")
        check_writable(sankey, "--sankey")
    if since is not None and since < 0:
        raise BgcError(f"--since {since:g} is before the run's start (0)", key="--since",
                       hint="a time within the run, from 0 to its end")

    def check(decl):            # against what the model declares, before any compile
        sim._check_declared(o, decl)
        t_end = o.t_end or decl.settings.t_end
        if since is not None and since >= t_end:
            raise BgcError(f"--since {since:g} s is not before the run's end ({t_end:g} s)",
                           key="--since", hint="a time before the end, or a longer --t-end")
    run = sim._prepare(o, check, energy=True)
    sim._choose_parameters(o, run)
    from bgc.analysis import energy as accounting
    try:
        sim._integrate(o, run)
    except SimulationError as exc:      # the balance up to the failure, not a CSV
        res = exc.result
        if out and res is not None and len(res.t) > 1 and \
                accounting.is_energy_module(run.module) and (since or 0) < res.t[-1]:
            data = accounting.account(run.module, res, since).to_dict()
            atomic_write(out, json.dumps(data, indent=2) + "\n", "--out")
            click.echo(f"the balance up to t = {res.t[-1]:.6g} written to {out}", err=True)
        exc.result = None           # (the command's --out is JSON: no partial CSV there)
        raise
    if not accounting.is_energy_module(run.module):
        raise BgcError(f"{o.model}: the model has no element that supplies, stores or "
                       "dissipates energy", hint="add sources, storage or resistors")
    bal = accounting.account(run.module, run.result, since)
    data = bal.to_dict()
    files = {}
    if out:
        files["json"] = str(atomic_write(out, json.dumps(data, indent=2) + "\n", "--out"))
    if sankey:
        from bgc.draw import sankey as chart
        with progress.stage("sankey") as st:
            title = f"{run.module.MODEL_NAME} ({o.method}" + (
                f", {run.excitation['kind']} {run.excitation['direction']}"
                if run.excitation else "") + ")"
            files["sankey"] = str(chart.draw(bal, sankey, title))
            st.done(files["sankey"])
    if as_json:
        click.echo(json.dumps(data, indent=2))
        return
    for line in accounting.describe(bal, top):
        click.echo(line)
    for kind, f in files.items():
        click.echo(f"  {kind}: {f}")


energy.params[1:1] = [p for p in sim.simulate.params if p.name not in _NOT_RUN_OPTIONS]
