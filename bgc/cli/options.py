"""What several commands share: their common options (``--json``, ``--method``,
``--keep-loops``, ``--quiet``), the number types of their values and the ``-p NAME=VALUE``
parameter overrides, checked before any work."""

from __future__ import annotations

import functools
import math

import click
import numpy as np

from bgc import methods, progress
from bgc.errors import BgcError
from bgc.model.model import MAX_POINTS

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


def check_overrides(model, items, constants: dict | None = None) -> None:
    """Refuse ``-p`` values that the model's own checks refuse (a capacitance, inertance
    or mass not > 0, a constant that becomes infinite or complex): the model is read
    again with them (and the ``constants`` given), and its error is told as the
    option's."""
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
