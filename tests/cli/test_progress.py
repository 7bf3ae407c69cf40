"""Progress of the long stages on stderr (bgc.progress, issue 24 item 5): one plain line
per finished stage when stderr is not a terminal, a live display on one, nothing with
--quiet, never in --json's stdout (whose report holds the stage times), nothing from
library calls. No timing is asserted beyond its form."""

from __future__ import annotations

import io
import json
import os
import re
import subprocess
import sys

import pytest
from click.testing import CliRunner
from helpers import MODELS, ROOT

from bgc import progress
from bgc.cli import main
from bgc.pipeline import compile_model, ensure_module

RLC = MODELS / "rlc.yaml"
LINE = re.compile(r"^bgc: ( *)([a-z][a-z ]*?)(?:: (.+))? \((\d+(?:\.\d+)?) s\)$")
COMPILE_STAGES = ["load", "causality", "equations", "jacobian", "emit", "machine code"]


def bgc(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def stages(stderr: str) -> dict[str, str]:
    """{stage: its counts} from plain progress lines; every line must be one."""
    out = {}
    for ln in stderr.splitlines():
        m = LINE.match(ln)
        assert m, f"not a progress line: {ln!r}"
        assert m[2] not in out, f"stage {m[2]} reported twice"
        out[m[2]] = m[3]
    return out


def in_order(names, wanted) -> bool:
    it = iter(names)
    return all(w in it for w in wanted)


# ------------------------------------------------------------------------ the CLI
def test_compile_prints_one_line_per_stage_with_counts_and_time(tmp_path):
    r = bgc("compile", RLC, "-o", tmp_path)
    assert r.exit_code == 0, r.output
    got = stages(r.stderr)
    assert in_order(list(got), COMPILE_STAGES), got
    assert "bgc:" not in r.stdout
    m = re.search(r"\((\d+) states, (\d+) assignments", r.stdout)
    assert got["equations"] == f"{m[2]} assignments, {m[1]} states"
    assert got["load"].startswith("rlc: ") and "bonds" in got["load"]
    assert got["emit"].startswith("rlc.py, ")


def test_simulate_reports_stages_quiet_silences_them_json_times_them(tmp_path):
    r = bgc("simulate", RLC, "-o", tmp_path, "--t-end", 0.01, "--json")
    assert r.exit_code == 0, r.output
    assert r.stderr == ""                       # no plain lines beside JSON
    report = json.loads(r.stdout)
    assert report["compiled"] is True
    assert in_order(list(report["stages"]), COMPILE_STAGES), report["stages"]
    assert all(isinstance(t, float) and t >= 0 for t in report["stages"].values())
    assert "integrate" not in report["stages"]  # its times are in "stats"

    r = bgc("simulate", RLC, "-o", tmp_path, "--t-end", 0.01, "--json")
    report = json.loads(r.stdout)                 # the module is fresh: only read
    assert report["compiled"] is False and list(report["stages"]) == ["load"]

    r = bgc("simulate", RLC, "-o", tmp_path, "--t-end", 0.01)
    assert r.exit_code == 0, r.output
    got = stages(r.stderr)
    assert list(got) == ["load", "integrate"], got
    assert re.fullmatch(r"native, \d+ steps to t = 0\.01 s, \d+\.\d+ s of it JIT/cache load",
                        got["integrate"]), got["integrate"]
    assert "bgc:" not in r.stdout and "native to t = 0.01 s" in r.stdout

    (tmp_path / "rlc.py").unlink()              # recompile, quietly
    out = ["-o", tmp_path]
    for args in (["simulate", RLC, "--t-end", 0.01, *out], ["compile", RLC, *out],
                 ["check", RLC]):
        r = bgc(*args, "--quiet")
        assert (r.exit_code, r.stderr) == (0, ""), (args, r.output)
        assert r.stdout


def test_every_long_command_takes_quiet():
    for cmd in ("check", "compile", "simulate", "frf", "run"):
        r = bgc(cmd, "--help")
        assert "--quiet" in r.stdout, cmd


def test_ctrl_c_in_a_stage_exits_130_after_the_stages_done(tmp_path, monkeypatch):
    from bgc.codegen import equations

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt
    monkeypatch.setattr(equations, "derive", interrupted)
    r = bgc("compile", RLC, "-o", tmp_path)
    assert r.exit_code == 130, r.output
    *done, last = r.stderr.splitlines()
    assert list(stages("\n".join(done))) == ["load", "causality"]
    assert last == "interrupted (Ctrl-C): nothing was written"
    assert not list(tmp_path.iterdir())


def test_a_terminal_gets_the_live_display_and_stdout_stays_clean(tmp_path):
    """stderr a pseudo-terminal, stdout a pipe: the stages are drawn on the terminal
    (rich), stdout holds the command's line only."""
    pty = pytest.importorskip("pty")
    master, slave = pty.openpty()
    env = dict(os.environ, PYTHONPATH=str(ROOT), TERM="xterm", COLUMNS="100")
    env.pop("NO_COLOR", None)
    proc = subprocess.Popen([sys.executable, "-m", "bgc.cli", "compile", str(RLC), "-o",
                             str(tmp_path)], stdout=subprocess.PIPE, stderr=slave,
                            env=env, cwd=tmp_path)
    os.close(slave)
    shown = b""
    while True:
        try:
            chunk = os.read(master, 65536)
        except OSError:            # the terminal closed with the process
            break
        if not chunk:
            break
        shown += chunk
    out = proc.stdout.read().decode()
    assert proc.wait(timeout=120) == 0, shown
    os.close(master)
    text = shown.decode(errors="replace")
    for name in COMPILE_STAGES:
        assert name in text, text
    assert "✓" in text and "\x1b[" in text         # drawn, not plain lines
    assert "bgc: " not in text
    assert out.startswith("wrote ") and out.count("\n") == 1, out


# --------------------------------------------------------------------- the library
def test_library_calls_print_nothing_and_still_time_their_stages(tmp_path, capfd):
    c, path = compile_model(RLC, tmp_path / "a")
    module, model, compiled = ensure_module(RLC, tmp_path / "b")
    out, err = capfd.readouterr()
    assert (out, err) == ("", "")
    assert list(c.timings) == COMPILE_STAGES
    assert list(compiled.timings) == COMPILE_STAGES     # its load as well
    assert module.MODEL_NAME == model.name == "rlc"


def test_plain_lines_nested_failed_and_recorded():
    buf = io.StringIO()
    with progress.use(progress.Plain(buf)), progress.record() as outer:
        with progress.stage("emit") as st:
            with progress.stage("jacobian") as inner:
                inner.done(progress.count(1, "entry", "entries"))
            st.done(progress.count(3, "kernel"))
        with pytest.raises(ValueError), progress.record() as failed:
            with progress.stage("machine code", total=3) as st:
                st.advance()
                raise ValueError("bad")
    lines = buf.getvalue().splitlines()
    assert [LINE.match(ln).group(1, 2, 3) for ln in lines] == [
        ("  ", "jacobian", "1 entry"), ("", "emit", "3 kernels")]
    assert list(outer) == ["jacobian", "emit"] and outer["emit"] >= outer["jacobian"]
    assert failed == {}                           # a failed stage is not recorded


def test_silent_by_default_and_chosen_by_the_stream(monkeypatch, capsys):
    with progress.stage("load") as st:
        st.done("x")
    assert capsys.readouterr() == ("", "")

    class Tty(io.StringIO):
        def isatty(self):
            return True
    for stream, quiet, as_json, kind in [
            (io.StringIO(), False, False, progress.Plain),
            (io.StringIO(), False, True, progress.Silent),
            (io.StringIO(), True, False, progress.Silent),
            (Tty(), False, True, progress.Live),
            (Tty(), True, False, progress.Silent)]:
        monkeypatch.setattr(sys, "stderr", stream)
        assert type(progress.for_stderr(quiet, as_json)) is kind


def test_live_display_shows_the_stages_and_closes_on_ctrl_c():
    from rich.console import Console
    buf = io.StringIO()
    live = progress.Live(Console(file=buf, force_terminal=True, width=100))
    with progress.use(live):
        with progress.stage("equations") as st:
            st.update("deriving")
            st.done("7 assignments, 2 states")
        assert live.progress is None                 # closed between stages
        with pytest.raises(KeyboardInterrupt):
            with progress.stage("machine code", total=4) as st:
                st.advance(2)
                raise KeyboardInterrupt
        assert live.progress is None
    text = buf.getvalue()
    assert "equations" in text and "7 assignments, 2 states" in text and "✓" in text
    assert "machine code" in text and "interrupted" in text and "✗" in text
