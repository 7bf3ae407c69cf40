"""The commands the documentation shows, run as a user runs them (tests/docs).

A document's examples are its ```console blocks: a line ``$ bgc ...`` (a trailing ``\\``
continues it on the next line) is a command; the lines after it, up to the next command or
the end of the block, are what it prints on stdout. In them ``...`` stands for any text
within a line, and a line that is only ``...`` for any number of lines; everything else
is compared as written, so a number an example shows is the number the command prints.
A last line ``(exit status N)`` says the command fails with that status (else: 0).

``DocRuns`` runs a command once per test session, in a fresh directory of its own where
``models/``, ``scenes/`` and ``docs/`` are the repository's (read-only) and
``generated/`` is the session's shared directory of compiled modules (``conftest.gen_dir``,
so a module is compiled once per session, under the same lock the ``compiled`` fixture
takes); the result is kept on disk, so a test on another pytest-xdist worker that shows
the same command reads it instead of running it again. A sweep without ``--scheduler``
runs on a session's two-worker Dask cluster of threads instead of the local process
cluster it would start (the same points and numbers, without starting worker processes
for each sweep: the process cluster has tests of its own in tests/sweep).
"""

from __future__ import annotations

import contextlib
import fcntl
import hashlib
import json
import os
import re
import shlex
import shutil
from dataclasses import dataclass
from pathlib import Path

from helpers import ROOT, SLOW_MODELS

# documents whose ```console blocks are run
DOCS = ("README.md", "docs/cli.md", "docs/tutorial.md", "docs/main-job.md")
# what a command's directory sees of the repository
LINKED = ("models", "scenes", "docs")


@dataclass(frozen=True)
class Example:
    """One command a document shows, and what it shows the command printing."""
    doc: str                    # the document, relative to the repository
    line: int                   # where the command starts in it
    command: str                # as written, continuation lines joined
    shown: tuple[str, ...]      # the output lines shown (none: not shown)

    @property
    def argv(self) -> list[str]:
        """The arguments after ``bgc``."""
        return shlex.split(self.command)[1:]

    @property
    def slow(self) -> bool:
        return is_slow(self.argv)

    @property
    def id(self) -> str:
        return f"{self.doc}:{self.line}"


def is_slow(argv: list[str]) -> bool:
    """Whether a command runs the SARIB (a SARIB model, a scene: all of them are the
    SARIB's, the main job: bgc simulate or bgc report without MODEL), the benchmarks or
    builds an FMU (a C compile and link; tests/export has fast tests of its own): a slow
    test's."""
    if argv[0] in ("run", "bench", "export"):
        return True
    if any(Path(a).stem in SLOW_MODELS or Path(a).parts[0] == "scenes"
           for a in argv if a.endswith(".yaml")):
        return True
    return argv[0] in ("simulate", "report") and not any(a.endswith(".yaml") for a in argv)


def examples(doc: str) -> list[Example]:
    """The examples of ``doc`` (a path relative to the repository), in order."""
    found = []
    lines = (ROOT / doc).read_text().splitlines()
    i = 0
    while i < len(lines):
        if lines[i].strip() != "```console":
            i += 1
            continue
        i += 1
        current = None
        while i < len(lines) and lines[i].strip() != "```":
            text = lines[i]
            if text.startswith("$ "):
                start, command = i + 1, text[2:]
                while command.endswith("\\"):
                    i += 1
                    command = command[:-1].rstrip() + " " + lines[i].strip()
                current = [start, command, []]
                found.append(current)
            elif current is None:
                raise ValueError(f"{doc}:{i + 1}: output before any command in a console "
                                 "block")
            else:
                current[2].append(text)
            i += 1
        i += 1
    out = []
    for start, command, shown in found:
        if not command.startswith("bgc "):
            raise ValueError(f"{doc}:{start}: a console block runs bgc commands only, "
                             f"not {command!r}")
        while shown and not shown[-1].strip():
            shown.pop()
        out.append(Example(doc, start, command, tuple(shown)))
    return out


def shown_pattern(shown) -> re.Pattern:
    """The regular expression of an example's shown output (``...`` as above)."""
    parts = []
    for line in shown:
        if line.strip() == "...":
            parts.append(r"(?:[^\n]*\n)*?")
        else:
            parts.append(".*?".join(map(re.escape, line.rstrip().split("..."))) + r"[ \t]*\n")
    return re.compile("".join(parts))


def check_shown(example: Example, stdout: str) -> None:
    """The command's stdout is what the example shows (each line, in order, all of it)."""
    text = "\n".join(line.rstrip() for line in stdout.rstrip("\n").splitlines()) + "\n"
    if not shown_pattern(example.shown).fullmatch(text):
        raise AssertionError(f"{example.id}: `{example.command}` printed\n{stdout}\n"
                             f"where the document shows\n" + "\n".join(example.shown))


@dataclass(frozen=True)
class Ran:
    """What a command did: its exit status, stdout, stderr and the directory it ran in."""
    exit_code: int
    stdout: str
    stderr: str
    cwd: Path

    def json(self):
        return json.loads(self.stdout)


class DocRuns:
    """Commands run once per session (see the module's docstring); ``runs(command)``."""

    def __init__(self, gen_dir: Path):
        self.gen_dir = Path(gen_dir)
        self.root = self.gen_dir / "docruns"
        self.root.mkdir(exist_ok=True)
        self._cluster = None

    def __call__(self, command: str) -> Ran:
        key = hashlib.sha256(command.encode()).hexdigest()[:16]
        record = self.root / f"{key}.json"
        with _locked(self.root / f"{key}.lock"):
            if not record.exists():
                cwd = self.root / key
                shutil.rmtree(cwd, ignore_errors=True)      # a run that did not finish
                cwd.mkdir()
                ran = self._run(command, cwd)
                record.write_text(json.dumps({"exit_code": ran.exit_code, "stdout":
                                              ran.stdout, "stderr": ran.stderr}))
        kept = json.loads(record.read_text())
        return Ran(kept["exit_code"], kept["stdout"], kept["stderr"], self.root / key)

    def _run(self, command: str, cwd: Path) -> Ran:
        from click.testing import CliRunner

        from bgc.cli import main
        from bgc.errors import BgcError
        argv = shlex.split(command)[1:]
        for name in LINKED:
            (cwd / name).symlink_to(ROOT / name)
        (cwd / "generated").symlink_to(self.gen_dir)
        try:
            self._prepare(argv, cwd)
        except BgcError:                    # the command says what is wrong
            pass
        if argv[0] == "sweep" and "--scheduler" not in argv:
            argv += ["--scheduler", self.cluster_address()]
        here = os.getcwd()
        os.chdir(cwd)
        try:
            r = CliRunner().invoke(main, argv)
        finally:
            os.chdir(here)
        if r.exception is not None and not isinstance(r.exception, SystemExit):
            raise r.exception
        return Ran(r.exit_code, r.stdout, r.stderr, cwd)

    def _prepare(self, argv: list[str], cwd: Path) -> None:
        """The module a command will use, compiled into the shared directory first under
        the ``compiled`` fixture's lock (two workers never build one module at once)."""
        from bgc import methods
        from bgc.cli import main
        from bgc.codegen import emit
        from bgc.model import load
        from bgc.pipeline import compile_model
        cmd = main.commands[argv[0]]
        if argv[0] not in ("simulate", "report", "frf", "modes", "tune", "sweep"):
            return
        ctx = cmd.make_context(argv[0], list(argv[1:]), resilient_parsing=True)
        p = ctx.params
        if p.get("out_dir") != "generated":
            return
        model, method = p.get("model"), p["method"]
        if model is None and argv[0] == "report":
            return                          # (its main job compiles as bgc simulate's)
        if model is None:                  # the main job
            from bgc.cli.simulate import resolve
            o = resolve(p, ctx)
            model, method = o.model, o.method
        path = cwd / model if not os.path.isabs(model) else Path(model)
        kind = methods.variant(method, not p.get("keep_loops"))
        with _locked(self.gen_dir / f"{path.stem}_{method}.lock"):
            m = load.load(path)
            target = emit.module_path(m.name, self.gen_dir, kind)
            if emit.is_stale(target, m.digest, kind):
                compile_model(m, self.gen_dir, method,
                              open_loops=not p.get("keep_loops"))

    def cluster_address(self) -> str:
        """A two-worker Dask cluster of threads in this process, started at first use."""
        if self._cluster is None:
            import logging

            from distributed import LocalCluster
            self._cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                         dashboard_address=None,
                                         silence_logs=logging.ERROR)
        return self._cluster.scheduler_address

    def close(self) -> None:
        if self._cluster is not None:
            self._cluster.close()


@contextlib.contextmanager
def _locked(path: Path):
    with open(path, "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def stated(doc: str, pattern: str) -> str:
    """The number a document states where ``pattern`` (a regular expression with one
    group, matched once in the document's text, line breaks as spaces) finds it, as
    written."""
    text = re.sub(r"\s+", " ", (ROOT / doc).read_text())
    found = re.findall(pattern, text)
    assert len(found) == 1, f"{doc}: {pattern!r} matches {len(found)} times"
    return found[0]


def agrees(value: float, written: str) -> bool:
    """Whether ``value`` is ``written`` to the precision it is written with: its decimals
    (``17.95``), its significant digits in scientific notation (``7.1e-5``), or exactly
    (an integer)."""
    w = written.replace("−", "-")
    if re.fullmatch(r"-?\d+", w):
        return round(value) == int(w)
    m = re.fullmatch(r"(-?\d+(?:\.(\d+))?)e([-+]?\d+)", w)
    if m:
        digits = len(m.group(1).lstrip("-").replace(".", "").lstrip("0"))
        return float(f"{value:.{max(digits, 1) - 1}e}") == float(w)
    decimals = len(w.split(".")[1])
    return f"{value:.{decimals}f}" == w
