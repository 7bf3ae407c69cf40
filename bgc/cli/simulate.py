"""``bgc simulate``: compile a model if needed, choose its parameters (``-p``, an
excitation, ``--parasitic auto``), integrate, write CSV and PNG, report the statistics.

The command's options are gathered in one ``SimulateOptions``; the run goes through
``_prepare`` (the module), ``_choose_parameters``, ``_integrate``, ``_write_files`` and
``_report``, each reading the options and the ``_Run`` so far. Whatever needs sympy or the
loader is imported only where it is used: on a fresh module the warm path imports neither
(``pipeline.ensure_module``, tests/cli/test_warm_start.py).
"""

from __future__ import annotations

import functools
import json
import math
from dataclasses import dataclass, field, fields, replace
from pathlib import Path

import click
import numpy as np
from click.core import ParameterSource

from bgc import progress
from bgc.cli.app import main, user_errors
from bgc.cli.options import (
    NUMBER,
    POINTS,
    POSITIVE,
    check_method_options,
    check_out_dir,
    check_overrides,
    check_params,
    check_solver,
    check_window,
    excitation_options,
    json_option,
    loops_option,
    method_option,
    out_dir_option,
    output_points,
    params_option,
    parse_params,
    split_constants,
    progress_option,
    set_excitation,
)
from bgc.errors import BgcError
from bgc.fileio import check_writable
from bgc.methods.parasitic import SEPARATION
from bgc.model.limits import MAX_PLANNED_STEPS
from bgc.model.model import FIXED_STEP_SOLVERS, MAX_POINTS, Settings
from bgc.pipeline import ensure_module
from bgc.simulate import SOLVERS

# The main job, `make run`, what `bgc simulate` runs without MODEL: the SARIB shipped with
# bgc (bgc.data) under its chirp along pumping, with ideal joints (method zcp) and native
# Radau at rtol = atol = 1e-4 (within 2.3e-4 of the ideal joints' reference;
# docs/main-job.md says why); the CSV (outputs only), the PNG, the envelopes and a zoom
# on the anti-resonance in results/ under the current directory. tests/cli/test_main_job.py
# checks this is the run the Makefile's `run` makes.
MAIN_MODEL = "sarib.yaml"
MAIN_JOB = {"exc_kind": "chirp", "exc_dir": "pumping", "solver": "native", "method": "zcp",
            "rtol": 1e-4, "atol": 1e-4}
MAIN_ZOOM = (17.8, 18.2)
MAIN_RESULTS = "results/sarib_{direction}_{kind}"


@dataclass(frozen=True)
class SimulateOptions:
    """What ``bgc simulate`` was asked: its options by click's names (None: not given)."""
    model: str
    t_end: float | None
    rtol: float | None
    atol: float | None
    solver: str | None
    step: float | None
    points: int | None
    max_steps: int | None
    params: tuple[tuple[str, float], ...]       # -p NAME=VALUE, checked (param_items)
    out: str | None
    plot: str | None
    states: bool
    out_dir: str
    parasitic_mode: str                         # "given" | "auto"
    separation: float
    exc_kind: str | None
    exc_dir: str | None
    amplitude: float | None
    frequency: float | None
    zoom: tuple[float, float] | None
    report: str | None
    method: str
    keep_loops: bool
    as_json: bool
    constants: dict = field(default_factory=dict)  # -p of the model's constants (compile)


@dataclass
class _Run:
    """One run as it proceeds: the module and its Model (None on the warm path), the
    Compiled if it was rebuilt, the seconds of each stage before integrating, the
    parameters and choices made, then the Result and the files written."""
    module: object
    model: object
    compiled: object
    stages: dict
    settings: Settings
    p: np.ndarray | None = None
    excitation: dict | None = None
    parasitic: object = None        # parasitic.auto's choice
    result: object = None
    files: dict = field(default_factory=dict)
    minima: dict | None = None      # envelope minima [Hz] per output, under a chirp
    curves: dict | None = None      # the chirp's envelopes (envelope.chirp_sweep)
    linear: object = None           # its linear picture (linear.LinearView), if it has one
    linear_error: str | None = None  # why there is none (not at rest, no excitation, ...)
    explained: dict | None = None   # name -> (anti-resonances, transients) of the minima
    noise: dict = field(default_factory=dict)   # name -> peak of outputs that are noise
    units: dict = field(default_factory=dict)   # name -> unit the model declares


@main.command()
@click.argument("model", type=click.Path(), required=False)
@click.option("--t-end", type=POSITIVE, help="end time [s] (default: the model's)")
@click.option("--rtol", type=POSITIVE, help="relative tolerance (default: the model's or 1e-6)")
@click.option("--atol", type=POSITIVE, help="absolute tolerance (default: the model's or 1e-8)")
@click.option("--solver", help="integrator (default: the model's, else native): "
              + "; ".join(f"{name}: {s.description}" for name, s in SOLVERS.items()))
@click.option("--step", type=POSITIVE, help="fixed-step solvers (rk4): the step [s]")
@click.option("--points", type=POINTS,
              help="number of output times (default: the model's simulation.points, or "
                   "1001, over its t_end; a --t-end keeps that spacing)")
@click.option("--max-steps", type=click.IntRange(1), help="stop the run after this many "
              "steps, keeping its results (default: 10^6; rk4: its planned steps)")
@params_option("override a parameter (no recompilation)")
@click.option("--out", type=click.Path(dir_okay=False), help="CSV of t, states, outputs")
@click.option("--plot", type=click.Path(dir_okay=False), help="PNG of the outputs")
@click.option("--states/--no-states", default=True, show_default=True,
              help="whether the CSV holds the states besides t and the outputs (without "
                   "MODEL: --no-states)")
@out_dir_option
@click.option("--parasitic", "parasitic_mode", type=click.Choice(["given", "auto"]),
              default="given", show_default=True,
              help="method parasitic: the joints' stiffness and damping as the model gives "
                   "them, or chosen from the eigenfrequencies")
@click.option("--separation", type=NUMBER, default=SEPARATION, show_default=True,
              help="--parasitic auto: parasitic frequencies over the highest functional one")
@excitation_options()
@click.option("--zoom", type=(NUMBER, NUMBER), metavar="T0 T1",
              help="with --plot: also <plot>_zoom.png over [T0, T1], outputs that differ "
                   "only by a number (F_A1_z, F_A2_z) in one panel")
@click.option("--report", type=click.Path(dir_okay=False),
              help="an HTML report of the run (bgc report): zoomable plots, the frequency "
                   "response and modes, the mechanism in 3D")
@method_option
@loops_option
@json_option
@user_errors
@progress_option
def simulate(**options):
    """Compile MODEL if needed and integrate it; print solver statistics.

    Without MODEL: the main job, the run `make run` makes, from any directory: the SARIB
    shipped with bgc under its chirp along pumping (--excitation and --direction choose
    others: roll, pitch; sine, constant), native Radau; it writes
    results/sarib_<direction>_<kind>.csv (outputs only), .png, _envelope.png,
    _zoom.png (17.8..18.2 s, when the run reaches it) and .html (the report) under the
    current directory, and the module to generated/. --out, --plot, --zoom, --report,
    --states, --solver and the other options override those choices.
    """
    o = resolve(options, click.get_current_context())
    _check_options(o)
    run = _prepare(o, functools.partial(_check_declared, o))
    _choose_parameters(o, run)
    _integrate(o, run)
    _write_files(o, run)
    _report(o, run)


def run_for(o: SimulateOptions) -> _Run:
    """The run ``o`` asks for, its files written: what ``bgc report`` runs."""
    _check_options(o)
    run = _prepare(o, functools.partial(_check_declared, o))
    _choose_parameters(o, run)
    _integrate(o, run)
    _write_files(o, run)
    return run


def resolve(options: dict, ctx: click.Context) -> SimulateOptions:
    """The run's options: ``options`` (click's values by name) and, without MODEL, the
    main job's (``MAIN_JOB``) where the command line (``ctx``) gives none."""
    o = SimulateOptions(**{f.name: options[f.name] for f in fields(SimulateOptions)
                           if f.name in options})
    constants, params = split_constants(o.model, o.params)
    o = replace(o, constants=constants, params=params)
    if o.model is not None:
        return o
    given = {k for k in options if ctx.get_parameter_source(k) is not ParameterSource.DEFAULT}
    from bgc import data
    job = {k: getattr(o, k) if k in given else v for k, v in MAIN_JOB.items()}
    stem = MAIN_RESULTS.format(direction=job["exc_dir"], kind=job["exc_kind"])
    reaches = o.t_end is None or o.t_end >= MAIN_ZOOM[1]    # the model's t_end: 28 s
    return replace(o, model=str(data.path("models", MAIN_MODEL)), **job,
                   out=o.out or stem + ".csv", plot=o.plot or stem + ".png",
                   report=o.report or stem + ".html",
                   states=o.states if "states" in given else False,
                   zoom=o.zoom or (MAIN_ZOOM if reaches else None))


def _check_options(o: SimulateOptions) -> None:
    """What can be refused before the model is read: names, combinations and ranges of
    the options themselves, the output paths."""
    if o.solver is not None:
        check_solver(o.solver, o.step, "--solver")
    check_method_options(o.method, o.keep_loops, o.parasitic_mode, o.separation)
    if o.step is not None and (o.solver or "") not in FIXED_STEP_SOLVERS and o.solver:
        raise BgcError(f"--step applies to the fixed-step solvers "
                       f"({', '.join(FIXED_STEP_SOLVERS)}), not {o.solver}", key="--step",
                       hint="drop --step (an adaptive solver chooses its steps; --rtol and "
                            "--atol set its accuracy) or use --solver rk4")
    if (o.amplitude is not None or o.frequency is not None) and not (o.exc_kind or
                                                                      o.exc_dir):
        raise BgcError(f"{'--amplitude' if o.amplitude is not None else '--frequency'} "
                       f"needs --excitation KIND --direction NAME",
                       key="--amplitude" if o.amplitude is not None else "--frequency",
                       hint="it sets the chosen excitation's; add e.g. --excitation sine "
                            "--direction pumping")
    if (o.exc_kind is None) != (o.exc_dir is None):
        raise BgcError("--excitation and --direction go together",
                       key="--excitation" if o.exc_kind is None else "--direction",
                       hint="give both, e.g. --excitation chirp --direction pumping")
    if o.zoom is not None:
        check_window(o.zoom, "--zoom")
        if not o.plot:
            raise BgcError("--zoom draws a window of --plot's picture", key="--zoom",
                           hint="add --plot FILE.png")
    check_out_dir(o.out_dir)
    check_writable(o.out, "--out")       # before the run: a bad path fails at once
    check_writable(o.plot, "--plot")
    check_writable(o.report, "--report")
    if o.plot:
        from bgc.analysis.results import plot_format
        plot_format(o.plot, "--plot")


def _check_declared(o: SimulateOptions, decl) -> None:
    """What is refused against what the model declares (``pipeline.Declared``), right
    after it is read and before any compile: ``-p`` names and values, the excitation,
    the model's solver and what it needs, the output times."""
    check_params(decl, o.params)
    check_overrides(decl.file, o.params, constants=o.constants)
    if o.exc_kind is not None and decl.model is not None:
        exc = decl.model.excitation
        if exc is None:
            raise BgcError(f"{decl.file} has no 'excitation' section", key="--excitation",
                           hint="declare excitation: {directions: ..., kinds: ...} in the "
                                "model, or drop --excitation and --direction")
        exc.select(o.exc_kind, o.exc_dir, o.amplitude, o.frequency)
    check_solver(o.solver or decl.settings.solver, o.step,
                 "--solver" if o.solver else "simulation.solver")
    t_end = o.t_end or decl.settings.t_end
    st = decl.settings
    if decl.module is not None and o.exc_kind is None:   # the module's own signals' plan
        _check_plan(decl.module, parse_params(decl.module, o.params), t_end, o.step,
                    "--param" if o.params else "--t-end")
    if o.points is None and o.t_end is not None and st.t_end > 0:
        n = (st.points - 1) * (o.t_end / st.t_end) + 1
        if not n <= MAX_POINTS:
            raise BgcError(f"--t-end {o.t_end:g} s at the model's output spacing "
                           f"({st.t_end / (st.points - 1):.3g} s) is {n:.3g} output times, "
                           f"more than bgc's limit of {MAX_POINTS:.0e}", key="--t-end",
                           hint="give the number of output times with --points N")
    if o.frequency is not None:
        from bgc.model.limits import too_fast
        why = too_fast(o.frequency, t_end)
        if why:
            raise BgcError(f"--frequency {o.frequency:g} Hz: {why}", key="--frequency",
                           hint="a lower --frequency or a shorter --t-end")
    if o.step is not None and t_end / o.step > MAX_PLANNED_STEPS:
        raise BgcError(f"--t-end {t_end:g} s in steps of {o.step:g} s is "
                       f"{t_end / o.step:.3g} steps, more than bgc's limit of "
                       f"{MAX_PLANNED_STEPS:.0e}", key="--step",
                       hint="a larger --step or a shorter --t-end")


def _prepare(o: SimulateOptions, check, energy: bool = False) -> _Run:
    """The model's generated module, rebuilt only if stale; the Model only for what reads
    it (an excitation, --parasitic auto): else a fresh module is found from the model
    file's YAML, without sympy (``pipeline.ensure_module``). ``check`` refuses bad options
    against what the model declares before any of it is compiled. ``energy``: the
    module's energy variant (``bgc energy``)."""
    from bgc.simulate import precompile_loop

    def loop_beside(settings):          # the native loop compiles beside the model's build
        precompile_loop(o.solver or settings.solver)
    need_model = (o.exc_kind is not None or o.exc_dir is not None
                  or o.parasitic_mode == "auto" or o.report is not None)
    with progress.record() as stages:       # what this run paid before integrating
        module, m, compiled = ensure_module(o.model, o.out_dir, o.method,
                                            open_loops=not o.keep_loops, on_load=loop_beside,
                                            need_model=need_model, check=check,
                                            constants=o.constants, energy=energy)
    st = Settings(**module.SETTINGS)        # the model's, as the module was written
    return _Run(module, m, compiled, stages, st)


def _choose_parameters(o: SimulateOptions, run: _Run) -> None:
    """The parameter array: the module's defaults, the excitation's, --parasitic auto's,
    then the explicit ``-p`` values, which always win; the step plan checked."""
    module = run.module
    run.p = parse_params(module, o.params)
    run.excitation = set_excitation(module, run.model, run.p, o)
    if run.excitation:
        run.p = parse_params(module, o.params, base=run.p)
    if o.parasitic_mode == "auto":
        from bgc.methods import parasitic
        run.p, run.parasitic = parasitic.auto(module, run.model, module.initial_state(run.p),
                                              run.p, o.separation)
        run.p = parse_params(module, o.params, base=run.p)
    key = "--frequency" if o.frequency is not None else "--param" if o.params else "--t-end"
    _check_plan(module, run.p, o.t_end or run.settings.t_end, o.step, key)


def _check_plan(module, p, t_end, step, key):
    """Refuse a run whose step plan exceeds ``limits.MAX_PLANNED_STEPS``: the fastest
    input signal's period (``max_step``, at the run's parameter values) over ``t_end``;
    ``key``: the option the error names when the signal is too fast."""
    from bgc.model.limits import STEPS_PER_PERIOD, too_fast
    h = float(module.max_step(p)) if hasattr(module, "max_step") else math.inf
    why = too_fast(1.0 / (STEPS_PER_PERIOD * h), t_end) if h > 0 else "no step is possible"
    if why:
        raise BgcError(f"the fastest input signal: {why}",
                       key=key,
                       hint="a lower frequency (--frequency, -p) or a shorter --t-end")


def _integrate(o: SimulateOptions, run: _Run) -> None:
    """The integrate stage: the options' settings, else the model's."""
    from bgc.simulate import simulate as integrate
    st = run.settings
    with progress.stage("integrate") as stage:
        result = integrate(run.module, t_end=o.t_end or st.t_end, rtol=o.rtol or st.rtol,
                           atol=o.atol or st.atol, solver=o.solver or st.solver,
                           points=o.points or output_points(st, o.t_end), params=run.p,
                           step=o.step, max_steps=o.max_steps)
        steps = result.stats.steps
        stage.done(f"{result.solver}, "
                   f"{progress.count(steps, 'step') if steps is not None else 'n/a steps'} to "
                   f"t = {result.t[-1]:g} s, "
                   f"{progress.seconds(result.stats.compile_time)} of it JIT/cache load")
    run.result = result


def _write_files(o: SimulateOptions, run: _Run) -> None:
    """--out's CSV, --plot's PNG and beside it, under a chirp, the envelopes against the
    instantaneous frequency (their minima told from the sweep's transients by the
    linearization's anti-resonances) and, with --zoom, a window; --report's HTML. Outputs
    below their noise floor (``bgc.analysis.noise``) are named, not drawn, and have no
    minima."""
    from bgc.analysis import noise
    from bgc.analysis.results import output_units, write_csv
    from bgc.analysis.results import plot as plot_png
    result, exc, files = run.result, run.excitation, run.files
    units = run.units = output_units(run.module)
    floor, run.noise = noise.of_result(result, units, o.rtol or run.settings.rtol)
    if o.out:
        files["csv"] = str(write_csv(result, o.out, o.states))
    title = f"{run.module.MODEL_NAME} ({o.method}, {result.solver}" + (
        f", {exc['kind']} {exc['direction']}" if exc else "") + ")"
    if o.plot:
        files["png"] = str(plot_png(result, o.plot, title=title, units=units, floor=floor))
    if exc:         # the Model is loaded (need_model)
        from bgc.analysis.envelope import chirp_sweep, minima_hz
        run.curves = chirp_sweep(run.model.excitation, exc, result, floor)
        run.minima = minima_hz(run.curves, 2)
    if run.curves is not None or o.report:
        _linear(run)
    if run.curves is not None and o.plot:
        from bgc.analysis.results import plot_envelopes
        path = Path(o.plot).with_name(Path(o.plot).stem + "_envelope.png")
        frf_anti = run.linear.anti if run.linear is not None else None
        files["envelope_png"] = str(plot_envelopes(run.curves, path, title, units, floor,
                                                   run.explained, frf_anti))
    if o.zoom and o.plot:
        t0, t1 = o.zoom
        path = Path(o.plot).with_name(Path(o.plot).stem + "_zoom.png")
        files["zoom_png"] = str(plot_png(result, path, title=title, window=(t0, t1),
                                         overlay=True, units=units, floor=floor))
    if o.report:
        from bgc.analysis import report
        with progress.stage("report") as stage:
            data = report.collect(run.module, run.model, result, run.p, o.method, title,
                                  exc, run.curves, run.linear, run.linear_error,
                                  run.explained, units, floor, run.noise)
            files["report"] = str(report.write(o.report, data))
            stage.done(f"{Path(o.report).stat().st_size / 1e6:.1f} MB")


def _linear(run: _Run) -> None:
    """The run's linear picture (``analysis.linear``): modes and the frequency response
    to its excitation direction over the chirp's band (else a band around the modes);
    under a chirp, which envelope minima it explains. Where the model has none (not at
    rest at its start, no excitation), why, in ``run.linear_error``."""
    from bgc.analysis import envelope, linear, mechanism
    from bgc.errors import BgcError
    exc, m = run.excitation, run.model
    chirp = m.excitation.kinds[exc["kind"]].numbers \
        if exc and m.excitation.kinds[exc["kind"]].kind == "chirp" else None
    band = (min(chirp["f_start"], chirp["f_end"]), max(chirp["f_start"], chirp["f_end"])) \
        if chirp else (None, None)
    try:
        with progress.stage("linearize") as stage:
            mech = mechanism.of_model(m, run.module, run.p)
            run.linear = linear.analyse(run.module, m, exc["direction"] if exc else None,
                                        run.p, *band, mechanism=mech,
                                        skip=tuple(run.noise))
            stage.done(f"{progress.count(len(run.linear.modal.modes), 'mode')}"
                       + (f", {progress.count(len(run.linear.f), 'frequency', 'frequencies')}"
                          if exc else ""))
    except (BgcError, np.linalg.LinAlgError) as err:
        run.linear_error = str(err)
        return
    if run.curves is not None:
        view = run.linear
        quiet = {n: [] for n in run.noise}
        run.explained = envelope.explain(run.curves, chirp, {**view.anti, **quiet},
                                         view.lag(*band))


def _report(o: SimulateOptions, run: _Run) -> None:
    """The run's report on stdout: JSON, or the statistics as lines."""
    result, module = run.result, run.module
    stats = result.stats.to_dict()
    proj, choice = result.projection, run.parasitic
    if o.as_json:
        click.echo(json.dumps({"model": module.MODEL_NAME, "method": o.method,
                               "solver": result.solver,
                               "t_end": float(result.t[-1]), "stats": stats,
                               "projection": proj.to_dict() if proj else None,
                               "parasitic": choice.to_dict() if choice else None,
                               "excitation": run.excitation,
                               "envelope_minima_hz": run.minima,
                               "envelope_transients_hz": {
                                   n: [round(f, 2) for f in t]
                                   for n, (_, t) in run.explained.items()
                               } if run.explained else None,
                               "frf_antiresonances_hz": {
                                   n: [round(f, 2) for f in a]
                                   for n, a in run.linear.anti.items()
                               } if run.linear is not None and run.excitation else None,
                               "linear_error": run.linear_error,
                               "noise_outputs": run.noise,
                               "compiled": run.compiled is not None, "stages": run.stages,
                               "files": run.files}, indent=2))
        return
    if proj is not None:
        click.echo(proj.describe())
    if choice is not None:
        click.echo(choice.describe())
    count = result.stats.text          # "n/a": a count the solver does not report
    click.echo(f"{module.MODEL_NAME}: {result.solver} to t = {result.t[-1]:g} s: "
               f"{count('steps')} steps, "
               f"{count('rhs_calls')} rhs and {count('jac_calls')} Jacobian calls, "
               f"{count('lu_decompositions')} LU, {stats['wall_time']:.3f} s "
               f"(+{stats['compile_time']:.2f} s JIT/cache load"
               f"{', recompiled' if run.compiled else ''})")
    if stats["drift_position"] is not None:
        click.echo(f"  constraint drift: position {stats['drift_position']:.3g}, velocity "
                   f"{stats['drift_velocity']:.3g}")
    for name, peak in run.noise.items():
        click.echo(f"  {name}: numerical noise (peak {peak:.2g} {run.units[name]}), no "
                   f"minima, stated in the plots")
    for name, fs in (run.minima or {}).items():
        if name in run.noise:
            continue
        line = f"  envelope minima of {name} over the chirp: " \
               f"{', '.join(f'{f:.2f}' for f in fs[:3]) or 'none'} Hz"
        if run.explained:
            anti, trans = run.explained[name]
            fa = run.linear.anti.get(name, [])
            line += (f"; anti-resonance{'s' if len(anti) != 1 else ''} "
                     f"{', '.join(f'{f:.2f}' for f in anti) or 'none'} (the FRF's: "
                     f"{', '.join(f'{f:.2f}' for f in fa) or 'none'})")
            if trans:
                line += (f"; {', '.join(f'{f:.2f}' for f in trans[:3])} the sweep's "
                         "transient")
        click.echo(line)
    if run.linear_error and run.minima:
        click.echo(f"  (minima not checked against the FRF: {run.linear_error})")
    for kind, f in run.files.items():
        click.echo(f"  {kind}: {f}")
