"""``bgc check``: what the front end makes of a model (causality, algebraic loops,
derivative causality, the mechanism's counts; with --method zcp the zero-order causal
paths), or of a scene (the state count before and after each reduction pass); with
``--stage STAGE``, the output of one compiler stage (``stages``)."""

from __future__ import annotations

import json

import click

from bgc.cli.app import main, user_errors
from bgc.cli.options import json_option, loops_option, method_option, progress_option
from bgc.cli.stages import STAGES
from bgc.errors import BgcError
from bgc.pipeline import build


@main.command()
@click.argument("model", type=click.Path())
@click.option("--stage", type=click.Choice(STAGES),
              help="show one stage's output instead: load (the Model), expand (the bond "
                   "graph), causality (the causal strokes), equations (the equation "
                   "system), emit (the generated module's source, not written)")
@click.option("-o", "--out-dir", default="generated", show_default=True,
              help="--stage emit: where bgc compile would write the module")
@method_option
@loops_option
@json_option
@user_errors
@progress_option
def check(model, stage, out_dir, method, keep_loops, as_json):
    """Assign causality and derive equations; report storage causality, algebraic loops,
    derivative causality and conflicts; with --method zcp, the zero-order causal paths.
    Given a scene file: the state count before and after each reduction pass."""
    from bgc.scene import scenes as bscene
    if bscene.is_scene(model):
        if stage is not None:
            raise BgcError(f"--stage applies to a model file, not the scene {model}",
                           key="--stage", hint="give the scene's model file to see its "
                                               "stages")
        _check_scene(bscene, model, as_json)
        return
    if stage is not None:
        _show_stage(stage, model, method, not keep_loops, out_dir, as_json)
        return
    c = build(model, method, open_loops=not keep_loops)
    report, zcps = _report(c, model, method)
    if as_json:
        click.echo(json.dumps(report, indent=2))
        return
    _print_report(c, report, zcps, model, method)


def _show_stage(stage: str, model: str, method: str, open_loops: bool, out_dir: str,
                as_json: bool) -> None:
    """One stage's output (``stages.report``), as JSON or text."""
    from bgc.cli import stages
    rep = stages.report(stage, model, method, open_loops, out_dir)
    if as_json:
        click.echo(json.dumps(rep, indent=2))
        return
    for line in stages.lines(rep):
        click.echo(line)


def _check_scene(bscene, path, as_json: bool) -> None:
    """A scene's reduction passes, each with the states and assignments before and after."""
    sc = bscene.load_scene(path)
    passes = bscene.check_scene(sc)
    if as_json:
        click.echo(json.dumps(passes, indent=2))
        return
    click.echo(f"scene {sc.name}: {sc.model.stem} ({sc.method}), outputs "
               f"{', '.join(sc.outputs)}")
    for r in passes:
        click.echo(f"  {r['pass']:16s} states {r['states_before']:4d} -> "
                   f"{r['states_after']:4d}, assignments {r['assignments_before']} -> "
                   f"{r['assignments_after']}: {r['note']}")


def _report(c, model: str, method: str) -> tuple[dict, list]:
    """The report of a built model (``pipeline.Compiled``) as ``--json`` prints it, and
    its zero-order causal paths (method zcp)."""
    from bgc.mechanics.joints import JOINT_KINDS
    from bgc.methods.zcp import paths
    s = c.system
    zcps = paths(c.causal.graph, s) if method == "zcp" else []
    rep = c.causal.report()
    report = {
        "model": c.model.name, "file": model, "method": method,
        "elements": len(c.causal.graph.elements), "bonds": len(c.causal.graph.bonds),
        "bodies": len(c.model.bodies),
        "states": [st.name for st in s.states],
        "storage": {n: (c.causal.graph.zcp.storage(n) if c.causal.graph.zcp else None) or v
                    for n, v in rep["storage"].items()},
        "resistors": rep["resistors"],
        "derivative_causality": dict(s.dependent),
        "algebraic_loops": [lp.__dict__ for lp in s.loops],
        "free_choices": rep["free_choices"], "strokes": rep["bonds"],
        "notes": s.notes, "conflicts": [],
        "constraint_multipliers": [name for name, _, _ in s.constraints],
    }
    if c.model.bodies:      # Table 11.1: absolute coordinates, scalar constraints, Gruebler
        report["coordinates"] = 6 * len(c.model.bodies)
        report["constraints"] = sum(len(JOINT_KINDS[j.kind].blocked)
                                    for j in c.model.joints.values())
        report["dof"] = report["coordinates"] - report["constraints"]
    if method == "zcp":
        report["zcp_paths"] = [z.to_dict() for z in zcps]
    return report, zcps


def _print_report(c, report: dict, zcps: list, model: str, method: str) -> None:
    """The report as lines: counts, mechanism, each storage element's and resistor's
    causality, the algebraic loops, the constraints or ZCPs, the notes."""
    s = c.system
    rep = c.causal.report()
    click.echo(f"{model}: {report['bodies']} bodies, {report['elements']} elements, "
               f"{report['bonds']} bonds, "
               f"{len(s.states)} states ({', '.join(report['states']) or 'none'})")
    if c.model.bodies:
        click.echo(f"mechanism: {report['coordinates']} absolute coordinates, "
                   f"{report['constraints']} scalar constraints, {report['dof']} degrees of "
                   f"freedom (Gruebler count: redundant constraints make the real mobility "
                   f"larger)")
    click.echo("causality: no conflicts")
    plan = c.causal.graph.zcp
    for name, cz in rep["storage"].items():
        kind = c.causal.graph.elements[name].kind
        extra = f" (dependent state {s.dependent[name]})" if name in s.dependent else ""
        if plan is not None:
            cz = plan.storage(name) or cz
        click.echo(f"  {kind} {name}: {cz}{extra}")
    for name, form in rep["resistors"].items():
        click.echo(f"  R {name}: {form}")
    # under zcp the flow-source and constraint blocks are reported as ZCPs below
    loops = [lp for lp in s.loops if method != "zcp" or lp.kind not in ("imposed-flow",
                                                                       "constraint")]
    click.echo(f"algebraic loops: {len(loops) or 'none'}")
    for lp in loops:
        click.echo(f"  {lp.describe()}")
    if s.constraints and method == "lagrange":
        click.echo(f"constraints (method {method}): {len(s.constraints)} multipliers, "
                   f"solved at the acceleration level with Baumgarte stabilisation")
    if method == "zcp":
        n_imp = len(s.imposed)
        click.echo(f"zero-order causal paths: {len(zcps) or 'none'} ({n_imp} flow sources, "
                   f"{len(s.constraints) - n_imp} break variables)")
        for z in zcps:
            click.echo(f"  class {z.cls}: {z.what}")
            click.echo(f"    {z.summary()}")
    for note in rep["free_choices"] + s.notes:
        click.echo(f"note: {note}")
