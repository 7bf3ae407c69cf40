"""The ``bgc`` command group and how a command's failure reaches the user.

User mistakes (BgcError) are printed as one line and exit with status 2; with ``--json``
the same error is printed as a JSON object; click's own usage errors take the same one-line
form. Ctrl-C exits with status 130 and no traceback.
"""

from __future__ import annotations

import atexit
import contextlib
import functools
import json
import os
import sys
import threading
import traceback
import warnings
from pathlib import Path

import click

from bgc import __version__
from bgc.errors import BgcError, SimulationError
from bgc.simulate import Interrupted

# exit status of a run stopped by Ctrl-C (128 + SIGINT, as a shell reports it)
EXIT_INTERRUPTED = 130


class _Bgc(click.Group):
    """The bgc group; click's own usage errors (a bad option value, an unknown option, a
    missing argument) are shown as one line in bgc's form, ``error: OPTION: message
    (hint: ...)``, with exit status 2, instead of click's usage block."""

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True,
             **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, False, **extra)
        warnings.showwarning = _show_warning
        try:
            rv = super().main(args, prog_name, complete_var, False, **extra)
        except click.UsageError as exc:
            click.echo(usage_line(exc), err=True)
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            exc.show()
            sys.exit(exc.exit_code)
        except click.Abort:         # Ctrl-C outside a command's own handling
            click.echo("interrupted (Ctrl-C)", err=True)
            sys.exit(EXIT_INTERRUPTED)
        except Exception as exc:    # noqa: BLE001 - the last resort: never a traceback
            click.echo(internal_line(exc), err=True)
            sys.exit(EXIT_INTERNAL)
        sys.exit(rv if isinstance(rv, int) else 0)


# exit status of an unexpected failure inside bgc (a bug), against 2 for a user's mistake
EXIT_INTERNAL = 1


def internal_line(exc: BaseException) -> str:
    """One line for an exception bgc did not expect: what it was, where in bgc it was
    raised, and how to report it (never a traceback; ``BGC_TRACEBACK=1`` shows one)."""
    if os.environ.get("BGC_TRACEBACK"):
        traceback.print_exception(exc)
    tb = traceback.extract_tb(exc.__traceback__)
    ours = [f for f in tb if f"{os.sep}bgc{os.sep}" in f.filename] or tb
    where = (f" at {Path(ours[-1].filename).name}:{ours[-1].lineno}" if ours else "")
    text = str(exc).splitlines()[0][:200] if str(exc) else ""
    return ("error: internal error in bgc: " + type(exc).__name__ + (f": {text}" if text
            else "") + where + " (hint: this is a bug in bgc, not in your input: please "
            "report it to bgc's maintainers with the command, the model file and what "
            "BGC_TRACEBACK=1 prints)")


def _show_warning(message, category, filename, lineno, file=None, line=None):
    """A library's warning as one line of bgc's (no source line, no path): what it said
    and which library said it. Numerical conditions worth reporting are said by bgc
    itself where they arise; this is the net for the rest."""
    lib = Path(filename).parts
    who = next((p for p in ("numpy", "scipy", "numba", "sympy", "matplotlib", "dask")
                if p in lib), "python")
    click.echo(f"warning: {who}: {str(message).splitlines()[0][:200]}", err=True)


def usage_line(exc: click.UsageError) -> str:
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


def user_errors(fn):
    """BgcError: one line (and the JSON object with --json), partial results of a failed
    run saved, exit 2. Ctrl-C: a note on stderr (the results so far saved if the
    integration was under way), exit 130, no traceback."""
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        try:
            return fn(*args, **kwargs)
        except BgcError as exc:
            interrupted = isinstance(exc, Interrupted)
            if isinstance(exc, SimulationError) and exc.result is not None:
                exc.partial = _save_partial(exc.result, kwargs)
            if kwargs.get("as_json"):
                click.echo(json.dumps(exc.to_dict()))
            click.echo(f"{'interrupted' if interrupted else 'error'}: {exc}", err=True)
            if getattr(exc, "partial", None):
                click.echo(f"partial results up to t = {exc.result.t[-1]:.6g} written to "
                           f"{exc.partial}", err=True)
            sys.exit(EXIT_INTERRUPTED if interrupted else 2)
        except KeyboardInterrupt:
            click.echo("interrupted (Ctrl-C): nothing was written", err=True)
            sys.exit(EXIT_INTERRUPTED)
        except (click.ClickException, click.Abort, click.exceptions.Exit):
            raise
        except Exception as exc:    # noqa: BLE001 - the last resort: never a traceback
            if kwargs.get("as_json"):
                click.echo(json.dumps({"error": internal_line(exc)[len("error: "):],
                                       "internal": True}))
            click.echo(internal_line(exc), err=True)
            sys.exit(EXIT_INTERNAL)
    return wrapper


def _save_partial(result, kwargs) -> str | None:
    """A failed run's results so far, to the command's ``--out`` (if it has one); the
    file written, or None."""
    from bgc.analysis.results import write_csv
    out = kwargs.get("out")
    if out and len(result.t):
        write_csv(result, out, kwargs.get("states", True))
        return str(out)
    return None


@click.group(cls=_Bgc)
@click.version_option(__version__, prog_name="bgc")
def main():
    """bgc: compile bond-graph models to fast simulation code."""


def entry():
    """The ``bgc`` console script (and ``python -m bgc.cli``): the command group, then the
    process ends as soon as the command's output is out and the ``atexit`` handlers ran,
    without the interpreter's teardown, which frees every object one by one: after a
    large build, millions of sympy nodes (0.6 s of a 13 s ``bgc compile`` of A02 with 40
    windows; compilers skip the same work, mypy's ``hard_exit`` too). Where a thread of
    the command's is still running, the interpreter's own exit waits for it instead."""
    try:
        main()
        code = 0
    except SystemExit as exc:
        if exc.code is None or isinstance(exc.code, int):
            code = exc.code or 0
        else:
            print(exc.code, file=sys.stderr)
            code = 1
    if any(not t.daemon for t in threading.enumerate() if t is not threading.main_thread()):
        sys.exit(code)
    try:
        atexit._run_exitfuncs()
    finally:
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(OSError, ValueError):  # a closed pipe: nothing to say
                stream.flush()
        os._exit(code)
