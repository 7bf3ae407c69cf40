"""What several commands share: their common options (``--json``, ``--method``,
``--keep-loops``, ``--quiet``), the number types of their values and the ``-p NAME=VALUE``
parameter overrides, checked before any work."""

from __future__ import annotations

import difflib
import functools
import math
from pathlib import Path

import click
import numpy as np

from bgc import methods, progress
from bgc.errors import BgcError
from bgc.fileio import check_writable
from bgc.model.model import FIXED_STEP_SOLVERS, MAX_POINTS, SOLVERS

json_option = click.option("--json", "as_json", is_flag=True, help="print the report as JSON")
def excitation_options(context: str = ""):
    """The four options that choose a model's excitation (``--excitation``, ``--direction``,
    ``--amplitude``, ``--frequency``; ``context``: what they apply to, before each help)."""
    def add(fn):
        for opt in reversed((
                click.option("--excitation", "exc_kind", metavar="KIND",
                             help=context + "the model's excitation g(t) (e.g. constant, "
                                            "sine, chirp)"),
                click.option("--direction", "exc_dir", metavar="NAME",
                             help=context + "where the excitation acts (e.g. pumping, roll, "
                                            "pitch)"),
                click.option("--amplitude", type=NUMBER,
                             help="excitation amplitude (default: the model's)"),
                click.option("--frequency", type=POSITIVE,
                             help="sine excitation frequency [Hz]"))):
            fn = opt(fn)
        return fn
    return add


out_dir_option = click.option("-o", "--out-dir", default="generated", show_default=True,
                              help="where the generated module is kept")
method_option = click.option("--method", type=click.Choice(methods.NAMES), default=methods.DEFAULT,
                             show_default=True, help="how constraint elements are handled")
parasitic_option = click.option(
    "--parasitic", "parasitic_mode", type=click.Choice(["given", "auto"]), default="given",
    show_default=True, help="method parasitic: the joints' stiffness and damping as the "
                            "model gives them, or chosen from the eigenfrequencies "
                            "(bgc.methods.parasitic.auto)")
loops_option = click.option("--keep-loops", is_flag=True,
                            help="method zcp: keep kinematic loops (class-4 ZCPs) closed, an "
                                 "index-2 DAE that --solver native integrates, instead of "
                                 "opening them with break variables")


def progress_option(fn):
    """``--quiet``, and the command run with its progress reporter (``progress.for_stderr``);
    placed under ``app.user_errors``, so that a live display is closed before an error
    line."""
    @click.option("-q", "--quiet", is_flag=True,
                  help="no progress report on stderr (errors are still reported)")
    @functools.wraps(fn)
    def wrapper(*args, quiet, **kwargs):
        with progress.use(progress.for_stderr(quiet, kwargs.get("as_json", False))):
            return fn(*args, **kwargs)
    return wrapper


class Number(click.ParamType):
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


NUMBER, POSITIVE = Number(), Number(positive=True)
POINTS = click.IntRange(2, MAX_POINTS)


def param_items(ctx, param, items) -> tuple[tuple[str, float], ...]:
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


def params_option(help_text: str):
    """``-p/--param NAME=VALUE``, repeatable, parsed by ``param_items``."""
    return click.option("-p", "--param", "params", multiple=True, metavar="NAME=VALUE",
                        callback=param_items, help=help_text)


def parse_params(module, items, base=None) -> np.ndarray:
    """The parameter array of a generated module (its defaults, or ``base``) with the
    ``-p`` values ``items`` set; an unknown name is refused, naming the valid ones."""
    p = np.array(module.PARAMS if base is None else base, dtype=np.float64)
    for name, value in items:
        if name not in module.PARAM_NAMES:
            raise BgcError(f"unknown parameter '{name}'", key="--param",
                           hint="parameters: " + ", ".join(module.PARAM_NAMES))
        p[module.PARAM_NAMES.index(name)] = value
    return p


def check_params(decl, items, key: str = "--param") -> None:
    """Refuse ``-p`` names the model does not declare (``pipeline.Declared``), naming the
    valid ones (the model's own first, then those bgc adds: joints' values, methods')."""
    for name, _ in items:
        if name not in decl.params:
            own = [n for n in decl.params if "__" not in n]
            added = [n for n in decl.params if "__" in n]
            near = difflib.get_close_matches(name, decl.params, 3)
            raise BgcError(f"unknown parameter '{name}' of model {decl.name}", key=key,
                           hint=(f"did you mean {' or '.join(near)}? " if near else "")
                           + "parameters: " + (", ".join(own) or "none")
                           + (f"; and {len(added)} that bgc adds, e.g. "
                              f"{', '.join(added[:3])}" if added else ""))


def split_constants(model, items) -> tuple[dict, tuple]:
    """``-p`` values split into the model's compile-time constants (its ``constants:``:
    another value builds another module) and its parameters (the rest). Reads the model's
    YAML only; a file it cannot read is left to the command's own load to report."""
    from bgc.model import document
    if model is None or not items:
        return {}, tuple(items)
    try:
        doc = document.read(model)
    except BgcError:
        return {}, tuple(items)
    consts = doc.get("constants") if isinstance(doc, dict) else None
    names = set(consts) if isinstance(consts, dict) else set()
    return ({n: v for n, v in items if n in names},
            tuple((n, v) for n, v in items if n not in names))


def check_overrides(model, items, *, constants: dict | None = None) -> None:
    """Refuse ``-p`` values that the model's own checks refuse (a capacitance, inertance
    or mass not > 0, a constant that becomes infinite or complex): the model is read
    again with them (and the compile-time ``constants`` given), and its error is told as
    the option's."""
    if not items:
        return
    from bgc.model import load
    try:
        load.load(model, overrides=dict(items), constants=constants)
    except BgcError as exc:
        given = ", ".join(f"{n}={v:g}" for n, v in items)
        where = f" ({exc.key} at {exc.loc})" if exc.loc else ""
        raise BgcError(f"{given}: {exc.message}{where}", key="--param",
                       hint=exc.hint) from None


def check_solver(name: str, step, key: str = "--solver") -> None:
    """A solver name bgc has, and a fixed-step one given its ``--step``; before any
    work (``key``: the option, or the model setting, that named it)."""
    if name not in SOLVERS:
        raise BgcError(f"unknown solver '{name}'", key=key,
                       hint="valid solvers: " + ", ".join(SOLVERS))
    if name in FIXED_STEP_SOLVERS and step is None:
        given = "" if key == "--solver" else f" (the model's {key})"
        raise BgcError(f"solver {name}{given} takes a fixed step: give --step H (s)",
                       key=key if key == "--solver" else "--step",
                       hint=f"e.g. --solver {name} --step 1e-4, or an adaptive solver "
                            "(--solver native)")


def check_method_options(method: str, keep_loops: bool = False, parasitic: str = "given",
                         separation: float | None = None, linearizes: bool = False) -> None:
    """Options that apply to some constraint methods only: ``--keep-loops`` (those that
    can keep loops closed; not for a command that ``linearizes``: a closed loop's module
    is a DAE whose Jacobian alone is not its dynamics), ``--parasitic auto`` and
    ``--separation`` (parasitic, which has compliant joints); refused with the method
    that would take them."""
    if keep_loops and linearizes:
        raise BgcError("--keep-loops: a linearization needs the kinematic loops opened "
                       "(a closed loop's module is an index-2 DAE)", key="--keep-loops",
                       hint="drop --keep-loops (the loops opened with break variables give "
                            "the same dynamics)")
    if keep_loops and method not in methods.CLOSES_LOOPS:
        raise BgcError(f"--keep-loops applies to --method {' or '.join(methods.CLOSES_LOOPS)}"
                       f", not {method}", key="--keep-loops",
                       hint="drop --keep-loops, or use --method zcp")
    if parasitic == "auto" and methods.get(method).ideal:   # auto sets compliant joints
        raise BgcError(f"--parasitic auto applies to --method parasitic, not {method}",
                       key="--parasitic", hint="drop --parasitic or use --method parasitic")
    if separation is not None and not separation > 1:
        raise BgcError(f"--separation must be > 1, got {separation:g}", key="--separation",
                       hint="parasitic frequencies this many times the highest functional "
                            "one, e.g. 100")


def check_window(window, key: str, what: str = "T0 T1") -> None:
    """A window or range given as two numbers: its start before its end."""
    lo, hi = window
    if not lo < hi:
        raise BgcError(f"{key} {lo:g} {hi:g}: the start must be before the end",
                       key=key, hint=f"give {what} with the smaller first, e.g. "
                                     f"{key} {min(lo, hi):g} {max(lo, hi):g}"
                       if lo != hi else f"give {what} with the smaller first")


# suffixes of the files bgc writes: a directory option given one of these is a mistake
# (``-o sine.csv`` meant ``--out sine.csv``)
FILE_SUFFIXES = (".csv", ".png", ".svg", ".pdf", ".json", ".html", ".parquet", ".fmu",
                 ".txt", ".yaml", ".yml", ".py")


def check_out_dir(path, key: str = "-o/--out-dir") -> None:
    """``-o`` is the directory of the generated modules in every command: a path that
    names one of the files bgc writes is refused, saying which option names that file."""
    if path is None:
        return
    suffix = Path(str(path)).suffix.lower()
    if suffix in FILE_SUFFIXES and not Path(path).is_dir():
        what = {".png": "--plot (or --out for bgc draw)", ".svg": "--out",
                ".pdf": "--out"}.get(suffix, "--out")
        raise BgcError(f"'{path}' looks like a file, but -o names the directory where the "
                       f"generated module is kept", key="-o",
                       hint=f"name the output file with {what} {path}; -o DIR (default: "
                            f"generated)")
    check_writable(path, "output directory", directory=True)


def check_output(decl, name: str, key: str = "--output") -> None:
    """An output the model declares."""
    if name not in decl.outputs:
        near = difflib.get_close_matches(name, decl.outputs, 3)
        raise BgcError(f"unknown output '{name}' of model {decl.name}", key=key,
                       hint=(f"did you mean {' or '.join(near)}? " if near else "")
                       + ("outputs: " + ", ".join(decl.outputs) if decl.outputs else
                          "the model declares no outputs: add an 'outputs:' section"))


def check_direction(decl, name: str, key: str = "--direction") -> None:
    """An excitation direction the model declares (its Model is loaded)."""
    exc = decl.model.excitation if decl.model is not None else None
    if exc is None:
        raise BgcError(f"{decl.file} has no 'excitation' section", key=key,
                       hint="declare excitation: {directions: ..., kinds: ...} in the model")
    if name not in exc.directions:
        raise BgcError(f"unknown excitation direction '{name}'", key=key,
                       hint="valid directions: " + ", ".join(exc.directions))


def retired_option(flag: str, instead: str, nargs: int = 1):
    """A hidden option an earlier bgc took: given, it is refused with one line saying
    what to write instead (scripts learn of the change; nothing runs)."""
    def refuse(ctx, param, value):
        if value not in (None, (), False):
            raise click.BadParameter(f"{flag} is no longer an option of 'bgc "
                                     f"{ctx.info_name}': write {instead}", ctx, param)
        return None
    return click.option(flag, f"_retired_{flag.strip('-').replace('-', '_')}", hidden=True,
                        multiple=nargs == 1, expose_value=False, callback=refuse,
                        is_eager=True)


def run_parameters(module, model, method, params, parasitic_mode, separation=None):
    """The module's parameters with ``-p`` applied; under ``--parasitic auto`` the joints'
    stiffness and damping chosen first (the explicit ``-p`` values still win): what a
    command that runs or linearizes a module starts from. (values, the parasitic choice or
    None)"""
    p = parse_params(module, params)
    if parasitic_mode != "auto":
        return p, None
    from bgc.methods import parasitic
    args = () if separation is None else (separation,)
    p, choice = parasitic.auto(module, model, module.initial_state(p), p, *args)
    return parse_params(module, params, base=p), choice


# what the run commands (simulate, sweep) share
def output_points(st, t_end: float | None) -> int:
    """The model's output times over ``t_end`` (``st``: its ``Settings``): its spacing
    (``st.points`` over its own t_end) kept, so that ``--t-end 0.01`` on the 28 s SARIB
    (28001 points, 1 ms) gives 11 output times, not 28001 within 10 ms."""
    if t_end is None or t_end == st.t_end or not st.t_end > 0:
        return st.points
    n = (st.points - 1) * (t_end / st.t_end) + 1       # a float: --t-end 1e308 is inf
    return MAX_POINTS if not n < MAX_POINTS else max(round(n), 2)   # (refused before)


def set_excitation(module, m, p, o) -> dict | None:
    """Set the parameters of the excitation the options ``o`` choose (``exc_kind``,
    ``exc_dir``, ``amplitude``, ``frequency``: simulate's and sweep's) in ``p`` (in place);
    what was chosen."""
    kind, direction = o.exc_kind, o.exc_dir
    if kind is None and direction is None:
        return None
    exc = m.excitation
    if exc is None:
        raise BgcError(f"{m.file} has no 'excitation' section", key="--excitation",
                       hint="declare excitation: {directions: ..., kinds: ...} in the model")
    if kind is None or direction is None:
        raise BgcError("--excitation and --direction go together", key="--excitation",
                       hint=f"kinds: {', '.join(exc.kinds)}; directions: "
                            f"{', '.join(exc.directions)}")
    for name, value in exc.select(kind, direction, o.amplitude, o.frequency).items():
        p[module.PARAM_NAMES.index(name)] = value
    return {"kind": kind, "direction": direction,
            "amplitude": float(p[module.PARAM_NAMES.index(exc.param(direction))]),
            "frequency": (float(p[module.PARAM_NAMES.index(exc.FREQUENCY)])
                          if exc.kinds[kind].kind == "sine" else None)}
