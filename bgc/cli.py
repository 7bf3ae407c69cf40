"""The ``bgc`` command line: check, compile, simulate.

User mistakes (BgcError) are printed as one line and exit with status 2; with ``--json``
the same error is printed as a JSON object. The long stages report their progress on
stderr (``bgc.progress``: a live display on a terminal, else one ``bgc: ...`` line per
stage; nothing with ``--quiet``); stdout holds only the command's own output.
"""

from __future__ import annotations

import functools
import json
import math
import sys
import time
from pathlib import Path

import click
import numpy as np

from bgc import __version__, progress
from bgc.codegen.module_file import stored_hash
from bgc.errors import BgcError, SimulationError
from bgc.fileio import check_writable
from bgc.methods.parasitic import SEPARATION
from bgc.model.model import MAX_POINTS, Settings
from bgc.pipeline import METHODS, build, compile_model, ensure_module
from bgc.simulate import SOLVERS, Interrupted

_json_opt = click.option("--json", "as_json", is_flag=True, help="print the report as JSON")
_method_opt = click.option("--method", type=click.Choice(METHODS), default="parasitic",
                           show_default=True, help="how constraint elements are handled")
_loops_opt = click.option("--keep-loops", is_flag=True,
                          help="method zcp: keep kinematic loops (class-4 ZCPs) closed, an "
                               "index-2 DAE that --solver native integrates, instead of "
                               "opening them with break variables")


def _progress_opt(fn):
    """``--quiet``, and the command run with its progress reporter (``progress.for_stderr``);
    placed under ``_user_errors``, so that a live display is closed before an error line."""
    @click.option("-q", "--quiet", is_flag=True,
                  help="no progress report on stderr (errors are still reported)")
    @functools.wraps(fn)
    def wrapper(*args, quiet, **kwargs):
        with progress.use(progress.for_stderr(quiet, kwargs.get("as_json", False))):
            return fn(*args, **kwargs)
    return wrapper


# exit status of a run stopped by Ctrl-C (128 + SIGINT, as a shell reports it)
EXIT_INTERRUPTED = 130


def _points(st, t_end: float | None) -> int:
    """The model's output times over ``t_end``: its spacing (``st.points`` over its own
    t_end) kept, so that ``--t-end 0.01`` on the 28 s SARIB (28001 points, 1 ms) gives 11
    output times, not 28001 within 10 ms."""
    if t_end is None or t_end == st.t_end or not st.t_end > 0:
        return st.points
    return min(max(round((st.points - 1) * t_end / st.t_end) + 1, 2), MAX_POINTS)


class _Number(click.ParamType):
    """A finite number (click's float takes nan and inf); ``positive``: > 0."""

    name = "number"

    def __init__(self, positive: bool = False):
        self.positive = positive

    def convert(self, value, param, ctx):
        want = "a finite number" + (" > 0" if self.positive else "")
        try:
            v = float(value)
        except (TypeError, ValueError):
            v = math.nan
        if not math.isfinite(v) or (self.positive and not v > 0):
            self.fail(f"expected {want}, got {value!r}", param, ctx)
        return v


NUMBER, POSITIVE = _Number(), _Number(positive=True)
POINTS = click.IntRange(2, MAX_POINTS)


class _Bgc(click.Group):
    """The bgc group; click's own usage errors (a bad option value, an unknown option, a
    missing argument) are shown as one line in bgc's form, ``error: OPTION: message
    (hint: ...)``, with exit status 2, instead of click's usage block."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True,
             **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, False, **extra)
        try:
            rv = super().main(args, prog_name, complete_var, False, **extra)
        except click.UsageError as exc:
            click.echo(_usage_line(exc), err=True)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            exc.show()
            sys.exit(exc.exit_code)
        except click.Abort:         # Ctrl-C outside a command's own handling
            click.echo("interrupted (Ctrl-C)", err=True)
            sys.exit(EXIT_INTERRUPTED)
        sys.exit(rv if isinstance(rv, int) else 0)


def _usage_line(exc: click.UsageError) -> str:
    """One line for a click usage error, naming the option or argument."""
    param = getattr(exc, "param", None)
    if isinstance(param, click.Option):
        key = max(param.opts, key=len)
    elif isinstance(param, click.Argument):
        key = param.human_readable_name
    elif getattr(exc, "option_name", None):
        key = exc.option_name
    else:
        key = "COMMAND"
    where = exc.ctx.command_path if exc.ctx is not None else "bgc"
    text = f"error: {key}: {exc.message or exc.format_message()} (hint: see '{where} --help')"
    return "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)


def _user_errors(fn):
    """BgcError: one line (and the JSON object with --json), partial results of a failed
    run saved, exit 2. Ctrl-C: a note on stderr (the results so far saved if the
    integration was under way), exit 130, no traceback."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except BgcError as exc:
            if kwargs.get("as_json"):
                click.echo(json.dumps(exc.to_dict()))
            interrupted = isinstance(exc, Interrupted)
            click.echo(f"{'interrupted' if interrupted else 'error'}: {exc}", err=True)
            if isinstance(exc, SimulationError) and exc.result is not None:
                _save_partial(exc.result, kwargs)
            sys.exit(EXIT_INTERRUPTED if interrupted else 2)
        except KeyboardInterrupt:
            click.echo("interrupted (Ctrl-C): nothing was written", err=True)
            sys.exit(EXIT_INTERRUPTED)
    return wrapper


def _save_partial(result, kwargs):
    from bgc.analysis.results import write_csv
    out = kwargs.get("out")
    if out and len(result.t):
        write_csv(result, out, kwargs.get("states", True))
        click.echo(f"partial results up to t = {result.t[-1]:.6g} written to {out}",
                   err=True)


@click.group(cls=_Bgc)
@click.version_option(__version__, prog_name="bgc")
def main():
    """bgc: compile bond-graph models to fast simulation code."""


@main.command()
@click.argument("model", type=click.Path())
@_method_opt
@_loops_opt
@_json_opt
@_user_errors
@_progress_opt
def check(model, method, keep_loops, as_json):
    """Assign causality and derive equations; report storage causality, algebraic loops,
    derivative causality and conflicts; with --method zcp, the zero-order causal paths.
    Given a scene file: the state count before and after each reduction pass."""
    from bgc.mechanics.joints import JOINT_KINDS
    from bgc.methods.zcp import paths
    from bgc.scene import scenes as bscene
    if bscene.is_scene(model):
        sc = bscene.load_scene(model)
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
        return
    c = build(model, method, open_loops=not keep_loops)
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
    if as_json:
        click.echo(json.dumps(report, indent=2))
        return
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


@main.command("compile")
@click.argument("model", type=click.Path())
@click.option("-o", "--out-dir", default="generated", show_default=True,
              help="directory for <model>.py")
@_method_opt
@_loops_opt
@_json_opt
@_user_errors
@_progress_opt
def compile_cmd(model, out_dir, method, keep_loops, as_json):
    """Generate the numba simulation module for MODEL."""
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


def _param_items(ctx, param, items) -> tuple[tuple[str, float], ...]:
    """``-p NAME=VALUE`` options as (name, value) pairs, checked before any work: VALUE
    a finite number (the names are checked against the module's)."""
    out = []
    for item in items:
        name, eq, value = item.partition("=")
        if not eq or not name:
            raise click.BadParameter(f"{item!r} is not NAME=VALUE", ctx, param)
        try:
            out.append((name, NUMBER.convert(value, param, ctx)))
        except click.BadParameter as exc:
            raise click.BadParameter(f"{name}={value}: {exc.message}", ctx, param) from None
    return tuple(out)


def _parse_params(module, items, base=None):
    p = np.array(module.PARAMS if base is None else base, dtype=np.float64)
    for name, value in items:
        if name not in module.PARAM_NAMES:
            raise BgcError(f"unknown parameter '{name}'", key="--param",
                           hint="parameters: " + ", ".join(module.PARAM_NAMES))
        p[module.PARAM_NAMES.index(name)] = value
    return p


def _check_overrides(model, items) -> None:
    """Refuse ``-p`` values that the model's own checks refuse (a capacitance, inertance
    or mass not > 0, a constant that becomes infinite or complex): the model is read
    again with them, and its error is told as the option's."""
    if not items:
        return
    from bgc.model import load
    try:
        load.load(model, overrides=dict(items))
    except BgcError as exc:
        given = ", ".join(f"{n}={v:g}" for n, v in items)
        where = f" ({exc.key} at {exc.loc})" if exc.loc else ""
        raise BgcError(f"{given}: {exc.message}{where}", key="--param",
                       hint=exc.hint) from None


def _check_plan(module, p, t_end, step, key):
    """Refuse a run whose step plan alone exceeds ``limits.MAX_PLANNED_STEPS``: a fixed
    ``--step`` or the fastest input signal's period (``max_step``) over ``t_end``;
    ``key``: the option the error names when the signal is too fast."""
    from bgc.model.limits import MAX_PLANNED_STEPS, STEPS_PER_PERIOD, too_fast
    if step is not None and t_end / step > MAX_PLANNED_STEPS:
        raise BgcError(f"--t-end {t_end:g} s in steps of {step:g} s is {t_end / step:.3g} "
                       f"steps, more than bgc's limit of {MAX_PLANNED_STEPS:.0e}",
                       key="--step", hint="a larger --step or a shorter --t-end")
    h = float(module.max_step(p)) if hasattr(module, "max_step") else math.inf
    why = too_fast(1.0 / (STEPS_PER_PERIOD * h), t_end) if h > 0 else "no step is possible"
    if why:
        raise BgcError(f"the fastest input signal: {why}",
                       key=key,
                       hint="a lower frequency (--frequency, -p) or a shorter --t-end")


def _excitation(module, m, p, kind, direction, amplitude, frequency) -> dict | None:
    """Set the parameters of the excitation the options choose (in place); what was chosen."""
    if kind is None and direction is None:
        for opt, val in (("--amplitude", amplitude), ("--frequency", frequency)):
            if val is not None:
                raise BgcError(f"{opt} needs --excitation KIND --direction NAME", key=opt)
        return None
    exc = m.excitation
    if exc is None:
        raise BgcError(f"{m.file} has no 'excitation' section", key="--excitation",
                       hint="declare excitation: {directions: ..., kinds: ...} in the model")
    if kind is None or direction is None:
        raise BgcError("--excitation and --direction go together", key="--excitation",
                       hint=f"kinds: {', '.join(exc.kinds)}; directions: "
                            f"{', '.join(exc.directions)}")
    for name, value in exc.select(kind, direction, amplitude, frequency).items():
        p[module.PARAM_NAMES.index(name)] = value
    return {"kind": kind, "direction": direction,
            "amplitude": float(p[module.PARAM_NAMES.index(exc.param(direction))]),
            "frequency": (float(p[module.PARAM_NAMES.index(exc.FREQUENCY)])
                          if exc.kinds[kind].kind == "sine" else None)}


@main.command()
@click.argument("model", type=click.Path())
@click.option("--t-end", type=POSITIVE, help="end time [s] (default: the model's)")
@click.option("--rtol", type=POSITIVE, help="relative tolerance (default: the model's or 1e-6)")
@click.option("--atol", type=POSITIVE, help="absolute tolerance (default: the model's or 1e-8)")
@click.option("--solver", help="integrator (default: the model's, else bdf): "
              + "; ".join(f"{name}: {s.description}" for name, s in SOLVERS.items()))
@click.option("--step", type=POSITIVE, help="fixed-step solvers (rk4): the step [s]")
@click.option("--points", type=POINTS,
              help="number of output times (default: the model's simulation.points, or "
                   "1001, over its t_end; a --t-end keeps that spacing)")
@click.option("--max-steps", type=click.IntRange(1), help="stop the run after this many "
              "steps, keeping its results (default: 10^6; rk4: its planned steps)")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE",
              callback=_param_items, help="override a parameter (no recompilation)")
@click.option("--out", type=click.Path(dir_okay=False), help="CSV of t, states, outputs")
@click.option("--plot", type=click.Path(dir_okay=False), help="PNG of the outputs")
@click.option("--states/--no-states", default=True, show_default=True,
              help="whether the CSV holds the states besides t and the outputs")
@click.option("-o", "--out-dir", default="generated", show_default=True,
              help="where the generated module is kept")
@click.option("--parasitic", "parasitic_mode", type=click.Choice(["given", "auto"]),
              default="given", show_default=True,
              help="method parasitic: the joints' stiffness and damping as the model gives "
                   "them, or chosen from the eigenfrequencies")
@click.option("--separation", type=NUMBER, default=SEPARATION, show_default=True,
              help="--parasitic auto: parasitic frequencies over the highest functional one")
@click.option("--excitation", "exc_kind", metavar="KIND",
              help="the model's excitation g(t) (e.g. constant, sine, chirp)")
@click.option("--direction", "exc_dir", metavar="NAME",
              help="where the excitation acts (e.g. pumping, roll, pitch)")
@click.option("--amplitude", type=NUMBER, help="excitation amplitude (default: the model's)")
@click.option("--frequency", type=POSITIVE, help="sine excitation frequency [Hz]")
@click.option("--zoom", type=(NUMBER, NUMBER), metavar="T0 T1",
              help="with --plot: also <plot>_zoom.png over [T0, T1], outputs that differ "
                   "only by a number (F_A1_z, F_A2_z) in one panel")
@_method_opt
@_loops_opt
@_json_opt
@_user_errors
@_progress_opt
def simulate(model, t_end, rtol, atol, solver, step, points, max_steps, params, out, plot,
             states, out_dir,
             parasitic_mode, separation, exc_kind, exc_dir, amplitude, frequency, zoom,
             method, keep_loops, as_json):
    """Compile MODEL if needed and integrate it; print solver statistics."""
    from bgc.analysis.results import plot as plot_png
    from bgc.analysis.results import write_csv
    from bgc.simulate import simulate as run
    if solver is not None and solver not in SOLVERS:
        raise BgcError(f"unknown solver '{solver}'", key="--solver",
                       hint="valid solvers: " + ", ".join(SOLVERS))
    check_writable(out, "--out")       # before the run: a bad path fails at once
    check_writable(plot, "--plot")
    if plot:
        from bgc.analysis.results import plot_format
        plot_format(plot, "--plot")
    from bgc.simulate import precompile_loop

    def loop_beside(settings):          # the native loop compiles beside the model's build
        precompile_loop(solver or settings.solver)
    # the Model only for what reads it (an excitation, --parasitic auto): else a fresh
    # module is found from the model file's YAML, without sympy (pipeline.ensure_module)
    need_model = exc_kind is not None or exc_dir is not None or parasitic_mode == "auto"
    with progress.record() as stages:       # what this run paid before integrating
        module, m, compiled = ensure_module(model, out_dir, method,
                                            open_loops=not keep_loops, on_load=loop_beside,
                                            need_model=need_model)
    st = Settings(**module.SETTINGS)        # the model's, as the module was written
    _check_overrides(model, params)
    p, choice = _parse_params(module, params), None
    exc = _excitation(module, m, p, exc_kind, exc_dir, amplitude, frequency)
    if exc:
        p = _parse_params(module, params, base=p)     # explicit -p values still win
    if parasitic_mode == "auto":
        from bgc.methods import parasitic
        if method != "parasitic":
            raise BgcError(f"--parasitic auto applies to --method parasitic, not {method}",
                           key="--parasitic", hint="drop --parasitic or use --method "
                                                    "parasitic")
        if not separation > 1:
            raise BgcError(f"--separation must be > 1, got {separation}", key="--separation")
        p, choice = parasitic.auto(module, m, module.initial_state(p), p, separation)
        p = _parse_params(module, params, base=p)     # explicit -p values still win
    _check_plan(module, p, t_end or st.t_end, step,
                "--frequency" if frequency is not None else "--param" if params else "--t-end")
    with progress.stage("integrate") as stage:
        result = run(module, t_end=t_end or st.t_end, rtol=rtol or st.rtol,
                     atol=atol or st.atol, solver=solver or st.solver,
                     points=points or _points(st, t_end), params=p, step=step,
                     max_steps=max_steps)
        stage.done(f"{result.solver}, {progress.count(result.stats.steps, 'step')} to "
                   f"t = {result.t[-1]:g} s, "
                   f"{progress.seconds(result.stats.compile_time)} of it JIT/cache load")
    files = {}
    if out:
        files["csv"] = str(write_csv(result, out, states))
    title = f"{module.MODEL_NAME} ({result.solver}" + (
        f", {exc['kind']} {exc['direction']}" if exc else "") + ")"
    if plot:
        files["png"] = str(plot_png(result, plot, title=title))
    minima = None
    if exc:         # the Model is loaded (need_model)
        from bgc.analysis.envelope import chirp_sweep, minima_hz
        from bgc.analysis.results import plot_envelopes
        curves = chirp_sweep(m.excitation, exc, result)
        minima = minima_hz(curves, 2)
        if curves is not None and plot:
            path = Path(plot).with_name(Path(plot).stem + "_envelope.png")
            files["envelope_png"] = str(plot_envelopes(curves, path, title))
    if zoom and plot:
        t0, t1 = zoom
        path = Path(plot).with_name(Path(plot).stem + "_zoom.png")
        files["zoom_png"] = str(plot_png(result, path, title=title, window=(t0, t1),
                                         overlay=True))
    stats = result.stats.to_dict()
    proj = result.projection
    if as_json:
        click.echo(json.dumps({"model": module.MODEL_NAME, "method": method,
                               "solver": result.solver,
                               "t_end": float(result.t[-1]), "stats": stats,
                               "projection": proj.to_dict() if proj else None,
                               "parasitic": choice.to_dict() if choice else None,
                               "excitation": exc, "envelope_minima_hz": minima,
                               "compiled": compiled is not None, "stages": stages,
                               "files": files}, indent=2))
        return
    if proj is not None:
        click.echo(proj.describe())
    if choice is not None:
        click.echo(choice.describe())
    click.echo(f"{module.MODEL_NAME}: {result.solver} to t = {result.t[-1]:g} s: "
               f"{stats['steps']} steps, "
               f"{stats['rhs_calls']} rhs and {stats['jac_calls']} Jacobian calls, "
               f"{stats['lu_decompositions']} LU, {stats['wall_time']:.3f} s "
               f"(+{stats['compile_time']:.2f} s JIT/cache load"
               f"{', recompiled' if compiled else ''})")
    if stats["drift_position"] is not None:
        click.echo(f"  constraint drift: position {stats['drift_position']:.3g}, velocity "
                   f"{stats['drift_velocity']:.3g}")
    for name, fs in (minima or {}).items():
        click.echo(f"  envelope minima of {name} over the chirp: "
                   f"{', '.join(f'{f:.2f}' for f in fs[:3]) or 'none'} Hz")
    for kind, f in files.items():
        click.echo(f"  {kind}: {f}")


@main.command()
@click.argument("model", type=click.Path())
@click.option("--input", "direction", required=True, metavar="NAME",
              help="the excitation direction driven (e.g. pumping, roll, pitch)")
@click.option("--output", "output", required=True, metavar="NAME", help="the model output")
@click.option("--f-min", type=POSITIVE, default=5.0, show_default=True, help="band start [Hz]")
@click.option("--f-max", type=POSITIVE, default=25.0, show_default=True, help="band end [Hz]")
@click.option("--out", type=click.Path(dir_okay=False),
              help="CSV of f, |H|, phase [deg] on a 0.01 Hz grid")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE",
              callback=_param_items, help="override a parameter (no recompilation)")
@click.option("-o", "--out-dir", default="generated", show_default=True,
              help="where the generated module is kept")
@_method_opt
@_json_opt
@_user_errors
@_progress_opt
def frf(model, direction, output, f_min, f_max, out, params, out_dir, method, as_json):
    """Frequency response of an output to an excitation direction, linearized about the
    static equilibrium; its anti-resonances and resonances in the band."""
    from bgc.analysis import frf as bfrf
    if not 0 < f_min < f_max:
        raise BgcError(f"need 0 < --f-min < --f-max, got {f_min} and {f_max}", key="--f-min")
    check_writable(out, "--out")
    module, m, _ = ensure_module(model, out_dir, method)
    if output not in module.OUTPUT_NAMES:
        raise BgcError(f"unknown output '{output}'", key="--output",
                       hint="outputs: " + ", ".join(module.OUTPUT_NAMES))
    _check_overrides(model, params)
    with progress.stage("frequency response") as stage:
        lin = bfrf.linearize(module, m, direction, _parse_params(module, params))
        f, h = grid = bfrf.sweep(lin, output, f_min, f_max)
        anti, res = bfrf.extrema(lin, output, f_min, f_max, grid)
        stage.done(f"{progress.count(len(f), 'frequency', 'frequencies')}, "
                   f"{progress.count(len(anti), 'anti-resonance')}, "
                   f"{progress.count(len(res), 'resonance')}")
    report = {"model": m.name, "method": method, "input": direction, "output": output,
              "f_min": f_min, "f_max": f_max, "equilibrium_residual": lin.residual,
              "antiresonances_hz": [round(f, 2) for f in anti],
              "resonances_hz": [round(f, 2) for f in res]}
    if out:
        from bgc.analysis.results import write_table
        report["files"] = {"csv": str(write_table(out, ["f_hz", "abs_H", "phase_deg"],
                                                  [f, np.abs(h), np.degrees(np.angle(h))]))}
    if as_json:
        click.echo(json.dumps(report, indent=2))
        return
    click.echo(f"{m.name}: {output} / {direction} in [{f_min:g}, {f_max:g}] Hz, linearized "
               f"about the equilibrium (|dx/dt| = {lin.residual:.2g})")
    click.echo(f"  anti-resonances: {', '.join(f'{f:.2f}' for f in anti) or 'none'} Hz")
    click.echo(f"  resonances: {', '.join(f'{f:.2f}' for f in res) or 'none'} Hz")
    if out:
        click.echo(f"  csv: {report['files']['csv']}")


@main.command("run")
@click.argument("scene", type=click.Path())
@click.option("--out", "out_dir", default="results/scenes", show_default=True,
              type=click.Path(file_okay=False), help="where the CSV, PNG and JSON go")
@click.option("-o", "--gen-dir", default="generated/scenes", show_default=True,
              help="where the scene's reduced module goes")
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE",
              callback=_param_items, help="set a parameter the scene exposes (repeatable)")
@_json_opt
@_user_errors
@_progress_opt
def run_cmd(scene, out_dir, gen_dir, params, as_json):
    """Run a scene: build its reduced model (once), simulate, write CSV, PNG and a JSON
    summary."""
    from bgc.scene import scenes as bscene
    sc = bscene.load_scene(scene)
    values = {}
    for name, value in params:
        if name not in sc.expose:
            raise BgcError(f"parameter '{name}' is not exposed by scene {sc.name}",
                           key="-p", hint="exposed: " + (", ".join(sc.expose) or "none; "
                                                       "add it to the scene's expose list"))
        values[name] = value
    check_writable(out_dir, "--out", directory=True)
    check_writable(gen_dir, "-o", directory=True)
    summary = bscene.run_scene(sc, out_dir, gen_dir, values)
    if as_json:
        click.echo(json.dumps(summary, indent=2, default=str))
    else:
        st = summary["stats"]
        click.echo(f"scene {sc.name}: {summary['states']} states, {summary['solver']} to "
                   f"t = {summary['t_end']:g} s: {st['steps']} steps, "
                   f"{st['wall_time']:.3f} s")
        for r in summary["passes"]:
            click.echo(f"  {r['pass']:16s} states {r['states_before']} -> "
                       f"{r['states_after']}")
        for name, fs in (summary["envelope_minima_hz"] or {}).items():
            click.echo(f"  envelope minima of {name}: "
                       f"{', '.join(f'{f:.2f}' for f in fs[:3]) or 'none'} Hz")
        for kind, f in summary["files"].items():
            click.echo(f"  {kind}: {f}")
    if not summary["ok"]:
        raise click.ClickException(f"{sc.name}: {summary['error']} (results up to there "
                                   f"in {summary['files']['csv']})")


@main.command()
@click.option("--out", default="bench/results", show_default=True,
              type=click.Path(file_okay=False), help="where CSV, PNG and summary.md go")
@click.option("--part", "parts", multiple=True,
              type=click.Choice(["peers", "precision", "stiffness", "stability", "compile",
                                 "symmetry", "scenes"]),
              help="run only this part (repeatable; default: all)")
@click.option("--quick", is_flag=True,
              help="every part at small scale (a slider-crank, a pendulum): minutes")
@click.option("--repeats", type=int, default=3, show_default=True,
              help="peers: runs per integrator (the median is reported)")
@click.option("--budget", type=POSITIVE, default=60.0, show_default=True,
              help="work-precision: a series stops after a run longer than this [s]")
@click.option("--build", type=click.Path(file_okay=False),
              help="where the benchmarks' generated modules go (default: bench/build, "
                   "--quick: OUT/build)")
@_json_opt
@_user_errors
def bench(out, parts, quick, repeats, budget, build, as_json):
    """Measure speed against accuracy: peers, work-precision, parasitic stiffness,
    stability maps, compile cost (CSV + PNG + summary.md in --out)."""
    from bgc import bench as bbench
    if repeats < 1:
        raise BgcError(f"--repeats must be >= 1, got {repeats}", key="--repeats")
    check_writable(out, "--out", directory=True)
    report = bbench.run(out, parts or bbench.PARTS, quick, repeats, budget,
                        log=lambda m: click.echo(m, err=True), build=build)
    if as_json:
        click.echo(json.dumps({"summary": report["summary"], "targets": report["targets"]},
                              indent=2))
        return
    for t in report["targets"]:
        click.echo(f"target: {t}")
    click.echo(f"summary: {report['summary']}")


if __name__ == "__main__":
    main()
