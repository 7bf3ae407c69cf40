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
    progress_option,
)
from bgc.codegen.module_file import stored_hash
from bgc.pipeline import compile_model


@main.command("compile")
@click.argument("model", type=click.Path())
@out_dir_option
@method_option
@loops_option
@json_option
@user_errors
@progress_option
def compile_cmd(model, out_dir, method, keep_loops, as_json):
    """Generate the numba simulation module for MODEL."""
    check_method_options(method, keep_loops)
    check_out_dir(out_dir)
    t0 = time.perf_counter()
    c, path = compile_model(model, out_dir, method, open_loops=not keep_loops)
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
