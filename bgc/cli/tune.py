"""``bgc tune``: the value of a parameter that puts an anti-resonance of an output on a
target frequency, and dF/dparam there (``bgc.analysis.tune``)."""

from __future__ import annotations

import json

import click

from bgc import progress
from bgc.cli.app import main, user_errors
from bgc.cli.options import (
    NUMBER,
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
    param_items,
    parasitic_option,
    progress_option,
    retired_option,
    run_parameters,
    split_constants,
)
from bgc.errors import BgcError
from bgc.pipeline import ensure_module


def bracket_option(ctx, param, value):
    """``LO:HI``, two finite numbers, LO < HI."""
    if value is None:
        return None
    lo, colon, hi = value.partition(":")
    try:
        if not colon:
            raise click.BadParameter("")
        lo, hi = NUMBER.convert(lo, param, ctx), NUMBER.convert(hi, param, ctx)
    except click.BadParameter:
        raise click.BadParameter(f"expected LO:HI (two numbers), got {value!r}", ctx,
                                 param) from None
    if not lo < hi:
        raise click.BadParameter(f"expected LO < HI, got {value!r}", ctx, param)
    return lo, hi


def tune_params(ctx, param, items):
    """``-p NAME=VALUE`` as everywhere; a bare ``--param NAME`` is the form that named the
    tuned parameter before ``--tune``, told so."""
    for item in items:
        if "=" not in item:
            raise click.BadParameter(f"'{item}' is not NAME=VALUE: -p/--param sets a "
                                     f"parameter in every command; the parameter to tune "
                                     f"is --tune {item}", ctx, param)
    return param_items(ctx, param, items)


@main.command()
@click.argument("model", type=click.Path())
@click.option("--target-frequency", "target", type=POSITIVE, required=True, metavar="F",
              help="where the anti-resonance must sit [Hz]")
@click.option("--tune", "name", required=True, metavar="NAME",
              help="the parameter tuned (a module parameter: no recompilation)")
@click.option("--input", "direction", required=True, metavar="NAME",
              help="the excitation direction driven (e.g. pumping, roll, pitch)")
@click.option("--output", "output", required=True, metavar="NAME", help="the model output")
@click.option("--bracket", callback=bracket_option, metavar="LO:HI",
              help="where the value is looked for (default: half to twice the start)")
@click.option("--f-min", type=POSITIVE, help="the band where the anti-resonance nearest F "
              "is picked at the start [Hz] (default: F/2)")
@click.option("--f-max", type=POSITIVE, help="... and its end (default: 2 F)")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE",
              callback=tune_params,
              help="override a parameter (the tuned one: its start value)")
@retired_option("--set", "-p NAME=VALUE")
@out_dir_option
@method_option
@parasitic_option
@loops_option
@json_option
@user_errors
@progress_option
def tune(model, target, name, direction, output, bracket, f_min, f_max, params, out_dir,
         method, parasitic_mode, keep_loops, as_json):
    """Tune a parameter so that the anti-resonance of an output, for an excitation
    direction, sits on a target frequency: root finding on the linearization about the
    static equilibrium. Reports the value and the sensitivity dF/dparam there."""
    # one value per option as click passes them, each read once below
    from bgc.analysis import frf as bfrf
    from bgc.analysis import tune as btune
    band = (f_min or target / 2, f_max or 2 * target)
    if not band[0] < target < band[1]:
        raise BgcError(f"need --f-min < F < --f-max, got {band[0]:g}, {target:g}, "
                       f"{band[1]:g}", key="--f-min")
    bfrf.check_band(*band)
    check_method_options(method, keep_loops, parasitic_mode, linearizes=True)
    check_out_dir(out_dir)

    constants, params = split_constants(model, params)
    if split_constants(model, [(name, 0.0)])[0]:
        raise BgcError(f"'{name}' is a compile-time constant of the model: another value is "
                       "another mechanism, which cannot be tuned", key="--tune",
                       hint="tune a parameter; set the constant with -p")

    def check(decl):            # against the model, before any compile
        check_output(decl, output)
        check_direction(decl, direction, "--input")
        if name not in decl.params or name.startswith("excitation__"):
            raise BgcError(f"'{name}' is not a parameter that can be tuned", key="--tune",
                           hint="parameters: " + ", ".join(
                               n for n in decl.params if "__" not in n) + " (and the "
                                "joints' values bgc adds, <joint>__<value>)")
        check_params(decl, params)
        check_overrides(model, params, constants=constants)
        if bracket is not None:
            _check_ends(model, params, name, bracket, constants)
    module, m, _ = ensure_module(model, out_dir, method, open_loops=not keep_loops,
                                 check=check, constants=constants)
    p, _ = run_parameters(module, m, method, params, parasitic_mode)
    if bracket is None:
        bracket = btune.default_bracket(p[module.PARAM_NAMES.index(name)], name)
        _check_ends(model, params, name, bracket, constants)
    with progress.stage("tuning") as stage:
        r = btune.tune(module, m, direction, output, name, target, p, bracket, band)
        stage.done(f"{progress.count(r.linearizations, 'linearization')}")
    unit = m.parameters[name].unit if name in m.parameters else None
    report = {"model": m.name, "method": method, "input": direction, "output": output,
              "param": name, "unit": unit, "target_hz": target, "value": r.value,
              "frequency": r.frequency, "sensitivity": r.sensitivity,
              "sensitivity_unit": f"Hz/{unit}" if unit else "Hz per unit",
              "start": r.start, "start_frequency": r.start_frequency,
              "bracket": list(r.bracket), "reachable_hz": list(r.reachable),
              "linearizations": r.linearizations}
    if as_json:
        click.echo(json.dumps(report, indent=2))
        return
    u = f" {unit}" if unit else ""
    click.echo(f"{m.name}: {name} = {r.value:.6g}{u} puts the anti-resonance of {output} / "
               f"{direction} on {r.frequency:.6f} Hz")
    click.echo(f"  sensitivity: {r.sensitivity:.5g} {report['sensitivity_unit']}")
    click.echo(f"  from {r.start_frequency:.4f} Hz at {name} = {r.start:g}{u}; over "
               f"[{r.bracket[0]:g}, {r.bracket[1]:g}]{u} it spans {r.reachable[0]:.4g} .. "
               f"{r.reachable[1]:.4g} Hz ({r.linearizations} linearizations, method "
               f"{method})")


def _check_ends(model, params, name, bracket, constants=None):
    """The model's own checks for the bracket's ends (a mass or an inertia > 0, ...),
    before any work."""
    for end in bracket:
        try:
            check_overrides(model, [*params, (name, end)], constants=constants)
        except BgcError as exc:
            raise BgcError(exc.message, key="--bracket", hint=exc.hint) from None
