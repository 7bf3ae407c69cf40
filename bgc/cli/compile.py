"""``bgc compile``: write a model's generated module and compile its machine code
(``pipeline.compile_model``)."""

from __future__ import annotations

import json
import time

import click

from bgc.cli.app import main, user_errors
from bgc.cli.options import (
    check_method_options,
    check_out_dir,
    json_option,
    loops_option,
    method_option,
    out_dir_option,
    params_option,
    progress_option,
    split_constants,
)
from bgc.codegen.module_file import stored_hash
from bgc.pipeline import compile_model


@main.command("compile")
@click.argument("model", type=click.Path())
@out_dir_option
@params_option("set a compile-time constant of the model (its constants:, e.g. -p N=40)")
@method_option
@loops_option
@json_option
@user_errors
@progress_option
def compile_cmd(model, out_dir, params, method, keep_loops, as_json):
    """Generate the numba simulation module for MODEL."""
    check_method_options(method, keep_loops)
    check_out_dir(out_dir)
    from bgc.errors import BgcError
    constants, rest = split_constants(model, params)
    if rest:
        raise BgcError(f"-p {rest[0][0]}: not a constant of the model; a parameter is set "
                       "at run time (bgc simulate -p), not compiled in", key="--param",
                       hint="bgc compile takes -p for the model's constants: only")
    t0 = time.perf_counter()
    c, path = compile_model(model, out_dir, method, open_loops=not keep_loops,
                            constants=constants)
    total = time.perf_counter() - t0
    text = path.read_text()
    info = {"module": str(path), "states": len(c.system.states),
            "assignments": len(c.system.assignments), "bytes": len(text.encode()),
            "model_hash": stored_hash(path), "timings": c.timings}
    if as_json:
        click.echo(json.dumps(info, indent=2))
    else:
        click.echo(f"wrote {path} ({info['states']} states, {info['assignments']} "
                   f"assignments, {info['bytes']} bytes) in {total:.3f} s")
