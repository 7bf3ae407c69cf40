"""``bgc check``: what the front end makes of a model (causality, algebraic loops,
derivative causality, the mechanism's counts; with --method zcp the zero-order causal
paths), or of a scene (the state count before and after each reduction pass); with
``--stage STAGE``, the output of one compiler stage (``stages``)."""

from __future__ import annotations

import json

import click

from bgc.cli.app import main, user_errors
from bgc.cli.options import (
    check_method_options,
    check_out_dir,
    json_option,
    loops_option,
    method_option,
    params_option,
    progress_option,
    split_constants,
)
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
@params_option("set a compile-time constant of the model (its constants:, e.g. -p N=40)")
@method_option
@loops_option
@json_option
@user_errors
@progress_option
def check(model, stage, out_dir, params, method, keep_loops, as_json):
    """Assign causality and derive equations; report storage causality, algebraic loops,
    derivative causality and conflicts; with --method zcp, the zero-order causal paths.
    Given a scene file: the state count before and after each reduction pass."""
    from bgc.scene import scenes as bscene
    check_method_options(method, keep_loops)
    check_out_dir(out_dir)
    if bscene.is_scene(model):
        if stage is not None:
            raise BgcError(f"--stage applies to a model file, not the scene {model}",
                           key="--stage", hint="give the scene's model file to see its "
                                               "stages")
        _check_scene(bscene, model, as_json, out_dir)
        return
    if stage is not None:
        _show_stage(stage, model, method, not keep_loops, out_dir, as_json)
        return
    constants, rest = split_constants(model, params)
    if rest:
        raise BgcError(f"-p {rest[0][0]}: not a constant of the model", key="--param",
                       hint="bgc check takes -p for the model's constants: only")
    c = build(model, method, open_loops=not keep_loops, constants=constants)
    report, method_lines = _report(c, model, method)
    if as_json:
        click.echo(json.dumps(report, indent=2))
        return
    _print_report(c, report, method_lines, model, method)


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


SHOWN = 20      # the junctions pass's cuts listed one a line (all of them in --json)


def _check_scene(bscene, path, as_json: bool, out_dir: str = "generated") -> None:
    """A scene's reduction passes, each with the states and assignments before and after
    (a scene with ``activity`` runs its model's energy variant, in OUT_DIR/scenes)."""
    from pathlib import Path
    sc = bscene.load_scene(path)
    passes = bscene.check_scene(sc, Path(out_dir) / "scenes")
    if as_json:
        click.echo(json.dumps(passes, indent=2))
        return
    click.echo(f"scene {sc.name}: {sc.model.stem} ({sc.method}), outputs "
               f"{', '.join(sc.outputs)}")
    for r in passes:
        click.echo(f"  {r['pass']:16s} states {r['states_before']:4d} -> "
                   f"{r['states_after']:4d}, assignments {r['assignments_before']} -> "
                   f"{r['assignments_after']}: {r['note']}")
        if r["pass"] == "junctions":        # each cut: bond, junction, source, share
            for line in r["removed"][:SHOWN]:
                click.echo(f"    cut {line}")
            if len(r["removed"]) > SHOWN:
                click.echo(f"    ... {len(r['removed']) - SHOWN} more (--json: every cut)")


def _report(c, model: str, method: str) -> tuple[dict, list[str]]:
    """The report of a built model (``pipeline.Compiled``) as ``--json`` prints it, and
    the method's own findings as text lines (``ConstraintMethod.report``: zcp's zero-order
    causal paths, lagrange's multipliers)."""
    from bgc import methods
    from bgc.mechanics.joints import JOINT_KINDS
    s, m = c.system, methods.get(method)
    own, own_lines = m.report(c)
    rep = c.causal.report()
    report = {
        "model": c.model.name, "file": model, "method": method,
        "elements": len(c.causal.graph.elements), "bonds": len(c.causal.graph.bonds),
        "bodies": len(c.model.bodies),
        "states": [st.name for st in s.states],
        "storage": {n: m.storage(c.causal.graph, n) or v for n, v in rep["storage"].items()},
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
        # and what the constraints are at the initial configuration: their numerical
        # rank, the mobility it implies, a minimal redundant set (the simulator's too)
        from bgc.mechanics import mobility
        found = mobility.analyse(c.causal.graph, s)
        report.update(rank=found["rank"], mobility=found["mobility"],
                      redundant=found["redundant"])
    report["instances"] = [{"name": i.name, "component": i.component,
                            "file": i.loc.file, "line": i.loc.line,
                            "definition": f"{i.definition.file}:{i.definition.line}"}
                           for i in c.model.instances.values()]
    report.update(own)
    return report, own_lines


def _print_report(c, report: dict, method_lines: list[str], model: str, method: str) -> None:
    """The report as lines: counts, mechanism, each storage element's and resistor's
    causality, the algebraic loops, the constraints or ZCPs, the notes."""
    from bgc import methods
    s, m = c.system, methods.get(method)
    rep = c.causal.report()
    click.echo(f"{model}: {report['bodies']} bodies, {report['elements']} elements, "
               f"{report['bonds']} bonds, "
               f"{len(s.states)} states ({', '.join(report['states']) or 'none'})")
    if c.model.bodies:
        red = report["redundant"]
        click.echo(f"mechanism: {report['coordinates']} absolute coordinates, "
                   f"{report['constraints']} scalar constraints of rank {report['rank']} at "
                   f"the initial configuration: mobility {report['mobility']} (Gruebler "
                   f"count {report['dof']})" + (
                       f"; {len(red)} redundant: {', '.join(red)}" if red else
                       "; no redundant constraint"))
    by_component: dict = {}
    for i in c.model.instances.values():
        by_component.setdefault((i.component, f"{i.definition.file}:{i.definition.line}"),
                                []).append(i.name)
    for (comp, where), names in by_component.items():
        click.echo(f"instances of {comp} ({where}): {', '.join(names)}")
    click.echo("causality: no conflicts")
    for name, cz in rep["storage"].items():
        kind = c.causal.graph.elements[name].kind
        extra = f" (dependent state {s.dependent[name]})" if name in s.dependent else ""
        cz = m.storage(c.causal.graph, name) or cz
        click.echo(f"  {kind} {name}: {cz}{extra}")
    for name, form in rep["resistors"].items():
        click.echo(f"  R {name}: {form}")
    # a method may report some blocks under its own heading (zcp: as ZCPs, below)
    loops = [lp for lp in s.loops if not m.hides_loop(lp)]
    click.echo(f"algebraic loops: {len(loops) or 'none'}")
    for lp in loops:
        click.echo(f"  {lp.describe()}")
    for line in method_lines:
        click.echo(line)
    for note in rep["free_choices"] + s.notes:
        click.echo(f"note: {note}")
