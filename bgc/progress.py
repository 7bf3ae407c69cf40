"""Progress of the long stages (load, causality, equations, emit, ...) on stderr.

Why: a cold compile of a large model takes long; the user should see what bgc is doing
and how long each stage took, and a benchmark should read the same per-stage times.

A stage is timed with a context manager; ``done`` gives the counts shown when it ends::

    from bgc import progress

    with progress.stage("jacobian") as st:
        jt = jacobian.derive(system)
        st.done(f"{len(jt.entries)} entries")

That is all a new stage needs: it is shown, timed and recorded wherever it runs, in a
pipeline function or in the CLI. A stage inside another (e.g. "jacobian" inside "emit") is
indented one step; as a plain line it comes before its parent's, which ends later. A
stage with a known amount of work shows a bar: ``progress.stage("machine code",
total=n)``, then ``st.advance()`` after each item; ``st.update(text)`` changes the text
while it runs. A stage that raises (an error, Ctrl-C) is not recorded and prints no plain
line (the error line says what happened); the exception goes on unchanged. Counts read
better through ``progress.count(n, "kernel")`` (1 kernel, 2 kernels). Enter and leave
stages in the main thread; ``advance`` and ``update`` may come from worker threads.

Who sees it: the reporter in use, chosen once by the CLI (``for_stderr``): on a terminal
a live display (rich); else one plain line per finished stage on stderr,
``bgc: equations: 1662 assignments, 152 states (3.84 s)`` (none with ``--json``, whose
report holds the stage times); with ``--quiet`` nothing. The default is ``Silent``:
pipeline functions called from scripts and tests print nothing; a script may ask for the
lines with ``with progress.use(progress.Plain()): ...``.

Stage times, whatever the reporter: ``with progress.record() as times:`` collects
``{stage: seconds}`` of the stages finished inside it, in the order they finished (a
nested stage's time is also part of its parent's; a repeated name adds up). That is how
``Compiled.timings`` and ``bgc simulate --json``'s "stages" are filled.
"""

from __future__ import annotations

import sys
import time
from contextlib import contextmanager

# the start of every plain progress line (error lines start with "error:" or "interrupted")
PREFIX = "bgc: "


def count(n: int, word: str, plural: str | None = None) -> str:
    """``n`` things for people: 1 bond, 4 bonds, 2 bodies."""
    return f"{n} {word if n == 1 else plural or word + 's'}"


def seconds(t: float) -> str:
    """A duration for people: 0.01 s, 3.84 s, 12.7 s, 126 s."""
    return f"{t:.2f} s" if t < 10 else f"{t:.1f} s" if t < 100 else f"{t:.0f} s"


class Stage:
    """One running stage: its name, depth (0: not inside another stage), start time and
    the text shown for it."""

    def __init__(self, name: str, depth: int, total: int | None):
        self.name, self.depth, self.total = name, depth, total
        self.detail = ""
        self.completed = 0
        self.start = time.perf_counter()
        self.elapsed: float | None = None      # set when the stage ends
        self.handle = None                     # the reporter's own (a rich task id)

    def done(self, detail: str = "") -> None:
        """The counts shown when the stage ends (e.g. "1662 assignments")."""
        self.detail = detail
        _reporter.update(self)

    def update(self, detail: str) -> None:
        """The text shown while the stage runs (a live display only)."""
        self.detail = detail
        _reporter.update(self)

    def advance(self, n: int = 1) -> None:
        """``n`` more items of ``total`` done (a live display shows a bar)."""
        self.completed += n
        _reporter.update(self)


class Silent:
    """Shows nothing: the default, for library use, and ``--quiet``."""

    def start(self, st: Stage) -> None:
        """A stage began: nothing to show (a reporter that shows it overrides this)."""

    def update(self, st: Stage) -> None:
        """A running stage's text or count changed: nothing to show."""

    def end(self, st: Stage, failed: str | None) -> None:
        """A stage ended; ``failed``: None, "failed" (an exception) or "interrupted"
        (Ctrl-C): nothing to show."""


class Plain(Silent):
    """One line per finished stage: ``bgc: NAME: DETAIL (TIME)`` (a nested stage indented);
    a stage that failed prints nothing (the error line says what happened)."""

    def __init__(self, stream=None):
        self.stream = stream

    def end(self, st: Stage, failed: str | None) -> None:
        if failed:
            return
        detail = f": {st.detail}" if st.detail else ""
        stream = self.stream or sys.stderr
        print(f"{PREFIX}{'  ' * st.depth}{st.name}{detail} ({seconds(st.elapsed)})",
              file=stream, flush=True)


class Live(Silent):
    """A live display on a terminal (rich): a spinner, the stage's text, a bar when its
    amount of work is known, and the elapsed time; a finished stage stays as a line with a
    check mark (a failed one with a cross). The display runs only while a stage does, so
    what a command prints between and after stages never meets it; stdout is never
    redirected into it."""

    def __init__(self, console=None):
        self.console = console
        self.progress = None

    def _open(self):
        from rich.console import Console
        from rich.progress import (
            BarColumn,
            Progress,
            ProgressColumn,
            SpinnerColumn,
            TextColumn,
        )
        from rich.text import Text

        class Status(SpinnerColumn):
            def render(self, task):
                mark = task.fields.get("mark")
                return Text(mark[0], style=mark[1]) if mark else super().render(task)

        class Bar(BarColumn):
            def render(self, task):
                return super().render(task) if task.fields.get("bar") else Text("")

        class Elapsed(ProgressColumn):
            def render(self, task):
                return Text(seconds(task.elapsed or 0.0), style="progress.elapsed")

        self.progress = Progress(
            Status(), TextColumn("{task.description}"), Bar(bar_width=30), Elapsed(),
            console=self.console or Console(stderr=True), transient=False,
            redirect_stdout=False, redirect_stderr=True)
        self.progress.start()

    @staticmethod
    def _text(st: Stage) -> str:
        from rich.markup import escape
        detail = f": {escape(st.detail)}" if st.detail else ""
        return f"{'  ' * st.depth}[bold]{escape(st.name)}[/bold]{detail}"

    def start(self, st: Stage) -> None:
        if self.progress is None:
            self._open()
        st.handle = self.progress.add_task(self._text(st), total=st.total,
                                           bar=st.total is not None)

    def update(self, st: Stage) -> None:
        if self.progress is not None and st.handle is not None:
            self.progress.update(st.handle, description=self._text(st),
                                 completed=st.completed)

    def end(self, st: Stage, failed: str | None) -> None:
        if self.progress is None or st.handle is None:
            return
        if failed:
            st.detail = failed
        mark = ("✗", "red") if failed else ("✓", "green")
        self.progress.update(st.handle, description=self._text(st), mark=mark,
                             completed=st.total if st.total is not None and not failed
                             else st.completed)
        self.progress.stop_task(st.handle)
        if st.depth == 0:                 # the last stage running: close the display
            self.progress.stop()
            self.progress = None


_reporter: Silent = Silent()
_running: list[Stage] = []
_recorders: list[dict] = []


def for_stderr(quiet: bool = False, as_json: bool = False) -> Silent:
    """The reporter for a command: nothing with ``quiet``; a live display when stderr is a
    terminal; else plain lines, but not with ``as_json`` (a program reading the JSON
    often reads stderr with it: the JSON holds the stage times instead)."""
    stream = sys.stderr
    isatty = getattr(stream, "isatty", None)
    if quiet:
        return Silent()
    if isatty is not None and isatty():
        return Live()
    return Silent() if as_json else Plain(stream)


@contextmanager
def use(reporter: Silent):
    """Report the stages run inside through ``reporter`` (then restore the previous)."""
    global _reporter
    previous, _reporter = _reporter, reporter
    try:
        yield reporter
    finally:
        _reporter = previous


@contextmanager
def record():
    """``{stage: seconds}`` of the stages finished inside (see the module docstring)."""
    times: dict[str, float] = {}
    _recorders.append(times)
    try:
        yield times
    finally:
        del _recorders[next(i for i, r in enumerate(_recorders) if r is times)]


@contextmanager
def stage(name: str, total: int | None = None):
    """Time and show the stage ``name`` run inside; yields its ``Stage`` (for ``done``,
    ``update``, ``advance``). ``total``: its number of items, if known."""
    st = Stage(name, len(_running), total)
    _running.append(st)
    _reporter.start(st)
    failed = None
    try:
        yield st
    except KeyboardInterrupt:
        failed = "interrupted"
        raise
    except BaseException:
        failed = "failed"
        raise
    finally:
        st.elapsed = time.perf_counter() - st.start
        del _running[next(i for i, r in enumerate(_running) if r is st)]
        if not failed:
            for times in _recorders:
                times[name] = times.get(name, 0.0) + st.elapsed
        _reporter.end(st, failed)
