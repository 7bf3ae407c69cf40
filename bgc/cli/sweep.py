"""``bgc sweep``: metrics of a model (FRF extrema, RMS and peak of outputs in a window)
over a grid or a Latin hypercube of its parameters, in parallel on a Dask cluster
(``bgc.sweep``: plan, run, write)."""

from __future__ import annotations

import json
import time
from contextlib import nullcontext
from pathlib import Path
from types import SimpleNamespace

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
    excitation_options,
    json_option,
    loops_option,
    method_option,
    out_dir_option,
    output_points,
    parasitic_option,
    parse_params,
    progress_option,
    set_excitation,
    split_constants,
)
from bgc.errors import BgcError
from bgc.fileio import check_writable


@main.command()
@click.argument("model", type=click.Path())
@click.option("-p", "--param", "params", multiple=True, metavar="NAME=START:STOP:COUNT",
              help="a swept parameter: COUNT values from START to STOP (a grid over all "
                   "of them), or NAME=START:STOP with --samples; NAME=VALUE fixes one")
@click.option("--samples", type=click.IntRange(1), metavar="N",
              help="N points of a Latin hypercube over the ranges instead of a grid")
@click.option("--seed", type=int, help="--samples: the seed of the hypercube")
@click.option("--frf", "frfs", multiple=True, metavar="INPUT:OUTPUT",
              help="anti-resonances and resonances of OUTPUT driven along the excitation "
                   "direction INPUT, as bgc frf finds them")
@click.option("--f-min", type=POSITIVE, default=5.0, show_default=True,
              help="--frf: band start [Hz]")
@click.option("--f-max", type=POSITIVE, default=25.0, show_default=True,
              help="--frf: band end [Hz]")
@click.option("--metric", "windows", multiple=True, metavar="KIND:OUTPUT[:T0:T1]",
              help="rms (root mean square) or peak (largest |value|) of OUTPUT over "
                   "[T0, T1] s of a run (without T0:T1: all of it)")
@click.option("--t-end", type=POSITIVE,
              help="--metric: end of the run [s] (default: the largest T1, else the "
                   "model's)")
@excitation_options("--metric: ")
@click.option("--scheduler", metavar="tcp://HOST:PORT",
              help="run on this Dask scheduler's workers (default: a local cluster)")
@click.option("--workers", type=click.IntRange(1), metavar="N",
              help="local cluster: N worker processes (default: one per core)")
@click.option("--out", type=click.Path(dir_okay=False),
              help="CSV of the points (and .parquet beside it if pyarrow is installed)")
@click.option("--plot", type=click.Path(dir_okay=False),
              help="PNG stem: <stem>_<metric>.png per metric, against each parameter")
@out_dir_option
@method_option
@parasitic_option
@loops_option
@json_option
@user_errors
@progress_option
def sweep(**o):
    """Compute metrics of MODEL at every point of a grid (or a Latin hypercube) of its
    parameters, in parallel on a Dask cluster: the local cores, or --scheduler's.

    Each point's row in --out holds its parameters, its metrics and, if one failed there,
    the message (the other points go on). --json prints {"points": [...]}."""
    from bgc.sweep import plan as splan
    from bgc.sweep import runner
    from bgc.sweep.metrics import parse_frf, parse_window
    o = SimpleNamespace(**o)
    axes, fixed = _axes(o.params, o.samples is not None)
    frfs = tuple(parse_frf(t) for t in o.frfs)
    windows = tuple(parse_window(t) for t in o.windows)
    if not frfs and not windows:
        raise BgcError("no metric to compute", key="--frf",
                       hint="give --frf INPUT:OUTPUT or --metric KIND:OUTPUT[:T0:T1]")
    if o.seed is not None and o.samples is None:
        raise BgcError("--seed needs --samples", key="--seed")
    if o.workers is not None and o.scheduler is not None:
        raise BgcError("--workers sets the local cluster's size, not --scheduler's",
                       key="--workers", hint="start as many workers on the scheduler")
    if frfs:
        from bgc.analysis.frf import check_band
        check_band(o.f_min, o.f_max)
    if (o.exc_kind is None) != (o.exc_dir is None):
        raise BgcError("--excitation and --direction go together",
                       key="--excitation" if o.exc_kind is None else "--direction",
                       hint="give both, e.g. --excitation chirp --direction pumping")
    check_method_options(o.method, o.keep_loops, o.parasitic_mode, linearizes=bool(frfs))
    check_out_dir(o.out_dir)
    check_writable(o.out, "--out")
    check_writable(o.plot, "--plot")
    if o.plot:
        from bgc.analysis.results import plot_format
        plot_format(o.plot, "--plot")
    pl = splan.plan(axes, o.samples, o.seed)
    job, module, punits = _job(o, axes, fixed, frfs, windows)
    source = Path(job.module_path).read_bytes()
    with progress.use(progress.Silent()) if o.as_json else nullcontext(), \
            progress.stage("sweep", total=len(pl)) as st:
        start = time.perf_counter()
        with runner.connect(o.scheduler, o.workers) as client:
            workers = len(client.scheduler_info()["workers"])
            st.update(f"{len(pl)} points on {progress.count(workers, 'worker')}")
            points = runner.run(client, job, pl.values, source,
                                on_point=lambda _: st.advance())
            wall = time.perf_counter() - start     # the cluster's start, not its close
        failed = sum(p.error is not None for p in points)
        st.done(f"{progress.count(len(pl), 'point')} on {progress.count(workers, 'worker')}"
                f", {failed} with an error")
    files = _write(o, points, pl.names, job.metrics, module, punits)
    _report(o, pl, points, workers, wall, files, module)


def _axes(items, sampled: bool):
    """``-p`` values: the swept axes (a range) and the fixed (name, value) pairs."""
    from bgc.sweep.plan import parse_axis
    axes, fixed = [], []
    for item in items:
        name, eq, value = item.partition("=")
        if eq and ":" not in value:
            try:
                fixed.append((name, NUMBER.convert(value, None, None)))
            except click.BadParameter as exc:
                raise BgcError(f"{item!r}: {exc.message}", key="--param") from None
        else:
            axes.append(parse_axis(item, sampled))
    return axes, tuple(fixed)


def _job(o, axes, fixed, frfs, windows):
    """The module (compiled if stale), the names checked against it, the base parameters
    (defaults, the excitation, the fixed -p values), the run of the window metrics: the
    runner's Job, and the module."""
    from bgc.model.model import Settings
    from bgc.pipeline import ensure_module
    from bgc.simulate import precompile_loop
    from bgc.sweep.metrics import Metrics, Run
    from bgc.sweep.runner import Job

    def loop_beside(settings):          # the native loop compiles beside the model's build
        if windows:
            precompile_loop(settings.solver)
    constants, fixed = split_constants(o.model, fixed)     # -p N=40: another mechanism
    swept = split_constants(o.model, [(a.name, a.start) for a in axes])[0]
    if swept:
        raise BgcError(f"-p {next(iter(swept))}: a compile-time constant of the model cannot "
                       "be swept (each value is another mechanism, another module)",
                       key="--param", hint="fix it (-p NAME=VALUE) and sweep parameters")

    def check(decl):            # against the model, before any compile
        check_params(decl, [(a.name, a.start) for a in axes] + list(fixed))
        for m, key in [(m, "--frf") for m in frfs] + [(m, "--metric") for m in windows]:
            try:
                check_output(decl, m.output, key)
            except BgcError as exc:
                raise BgcError(f"{m.label}: {exc.message}", key=key, hint=exc.hint) from None
        for m in frfs:
            try:
                check_direction(decl, m.direction, "--frf")
            except BgcError as exc:
                raise BgcError(f"{m.label}: {exc.message}", key="--frf",
                               hint=exc.hint) from None
        if o.exc_kind is not None:
            check_direction(decl, o.exc_dir, "--direction")
            decl.model.excitation.select(o.exc_kind, o.exc_dir, o.amplitude, o.frequency)
        for ends in ([a.start for a in axes], [a.stop for a in axes]):
            check_overrides(o.model, fixed + tuple(zip([a.name for a in axes], ends)),
                            constants=constants)
    module, model, _ = ensure_module(o.model, o.out_dir, o.method,
                                     open_loops=not o.keep_loops, on_load=loop_beside,
                                     check=check, constants=constants)
    names = list(module.PARAM_NAMES)
    p = parse_params(module, fixed)
    if set_excitation(module, model, p, o):
        p = parse_params(module, fixed, base=p)     # the fixed -p values win
    if o.parasitic_mode == "auto":     # the joints' values chosen once, at the base point
        from bgc.methods import parasitic
        p, _ = parasitic.auto(module, model, module.initial_state(p), p)
        p = parse_params(module, fixed, base=p)
    st = Settings(**module.SETTINGS)
    run = None
    if windows:
        ends = [w.t1 for w in windows]
        t_end = o.t_end or (max(ends) if None not in ends else st.t_end)
        late = [w.label for w in windows if w.t1 is not None and w.t1 > t_end]
        if late:
            raise BgcError(f"{late[0]}: the window ends after the run (t_end = {t_end:g} s)",
                           key="--metric", hint="a later --t-end or an earlier T1")
        run = Run(t_end, st.rtol, st.atol, st.solver, output_points(st, t_end))
        _await_loop(st.solver)
    metrics = Metrics(frfs, windows, o.f_min, o.f_max, run)
    job = Job(module.__file__, module.MODEL_HASH, model if frfs else None, p,
              tuple(a.name for a in axes), tuple(names.index(a.name) for a in axes), metrics)
    from bgc.analysis.results import parameter_unit
    units = {a.name: parameter_unit(model, a.name) for a in axes}
    return job, module, units


def _await_loop(solver: str) -> None:
    """The native step loop compiled into numba's cache here, before the workers start:
    they load it from there instead of each compiling it (tens of seconds cold)."""
    from bgc.simulate import SOLVERS
    from bgc.solvers import native
    loop = getattr(SOLVERS.get(solver), "loop", None)
    if loop is not None:
        native.await_precompiled(loop)


def _write(o, points, names, metrics, module, punits) -> dict:
    """The CSV (and Parquet) and the plots asked for (``punits``: the swept parameters'
    units); their paths."""
    from bgc.analysis.results import output_units
    from bgc.sweep import write
    files: dict = {}
    if not (o.out or o.plot):
        return files
    cols = write.table(points, names, metrics)
    if o.out:
        files["csv"] = str(write.write_csv(o.out, cols))
        parquet = write.write_parquet(o.out, cols)
        if parquet is not None:
            files["parquet"] = str(parquet)
    if o.plot:
        paths = write.plots(o.plot, cols, names, metrics, output_units(module),
                            module.MODEL_NAME, punits)
        files["plots"] = {k: str(v) for k, v in paths.items()}
    return files


def _report(o, pl, points, workers, wall, files, module) -> None:
    """The points as JSON (``{"points": [...]}`` and the run's facts), or a summary and a
    line per point (the first 20)."""
    busy, cpu = sum(p.seconds for p in points), sum(p.cpu for p in points)
    per = max(len(points), 1)
    if o.as_json:
        click.echo(json.dumps({
            "model": module.MODEL_NAME, "plan": pl.kind, "parameters": list(pl.names),
            "workers": workers, "wall_time": wall, "busy_time": busy, "cpu_time": cpu,
            "points": [{"index": p.index, "params": p.params, "metrics": p.values,
                        "error": p.error, "seconds": p.seconds, "cpu_seconds": p.cpu}
                       for p in points],
            "files": files}, indent=2))
        return
    click.echo(f"{module.MODEL_NAME}: {progress.count(len(pl), 'point')} ({pl.kind} over "
               f"{', '.join(pl.names)}) on {progress.count(workers, 'worker')} in "
               f"{progress.seconds(wall)} ({progress.seconds(busy / per)} of work a point, "
               f"{progress.seconds(cpu / per)} of CPU)")
    for p in points[:20]:
        where = " ".join(f"{n}={v:.6g}" for n, v in p.params.items())
        click.echo(f"  {where}: " + "; ".join(
            f"{k} {_text(v)}" for k, v in p.values.items()) + (
            f"  error: {p.error}" if p.error else ""))
    if len(points) > 20:
        click.echo(f"  ... {len(points) - 20} more" + (" in the CSV" if o.out else ""))
    for kind in ("csv", "parquet"):
        if kind in files:
            click.echo(f"  {kind}: {files[kind]}")
    for path in files.get("plots", {}).values():
        click.echo(f"  plot: {path}")


def _text(value) -> str:
    """A metric's value in a line: an FRF's extrema in Hz, a number, or - (failed)."""
    if value is None:
        return "-"
    if isinstance(value, dict):
        return (f"anti {', '.join(f'{f:.2f}' for f in value['antiresonances_hz']) or 'none'}"
                f" res {', '.join(f'{f:.2f}' for f in value['resonances_hz']) or 'none'} Hz")
    return f"{value:.6g}"
