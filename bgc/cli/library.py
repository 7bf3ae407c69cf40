"""``bgc library``: the components bgc ships (``library/``, ``bgc.data.library``), each
with its ports and parameters; ``--json``: ``{"components": [{"name", "description",
"ports", "parameters", "constants", "file", "line"}]}``. A model instances one by its name
(``component: dc_motor``; docs/format.md, Components)."""

from __future__ import annotations

import json
import textwrap

import click

from bgc.cli.app import main, user_errors
from bgc.cli.options import json_option


@main.command()
@click.argument("name", required=False)
@json_option
@user_errors
def library(name, as_json):
    """List the library's components (NAME: one of them) with their ports and
    parameters; a model uses one as `instances: {NAME: {component: dc_motor, ...}}`."""
    from bgc.errors import BgcError
    from bgc.model import library as lib
    comps = lib.listing()
    if name is not None:
        comps = [c for c in comps if c["name"] == name]
        if not comps:
            raise BgcError(f"the library has no component '{name}'", key="NAME",
                           hint="its components: " + ", ".join(lib.library_names()))
    if as_json:
        click.echo(json.dumps({"components": comps}, indent=2))
        return
    for c in comps:
        click.echo(f"{c['name']} ({c['file']}:{c['line']})")
        if c["description"] and name is not None:
            click.echo(textwrap.fill(c["description"], 88, initial_indent="  ",
                                     subsequent_indent="  "))
        elif c["description"]:
            click.echo("  " + c["description"].split(". ")[0].rstrip(".") + ".")
        ports = ", ".join(f"{p['name']} ({p['kind']}"
                          + (f" {p['target']}" if p["target"] else "")
                          + (f", power {p['power']}" if p.get("power") else "") + ")"
                          for p in c["ports"])
        click.echo(f"  ports: {ports or 'none'}")
        params = ", ".join(f"{p['name']} = {p['value']}" + (f" {p['unit']}" if p["unit"]
                                                             else "")
                           for p in c["parameters"])
        click.echo(f"  parameters: {params or 'none'}")
        if c["constants"]:
            click.echo("  constants (compile-time): " + ", ".join(
                f"{k['name']} = {k['value']}" for k in c["constants"]))
