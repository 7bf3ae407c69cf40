"""Options and settings are checked before any work, and bad input writes nothing (issue
38, items 2, 3, 5 and 8).

Every case runs the CLI in its own process on a model that has never been compiled (so a
check made after the build would show): exit status 2, one line in bgc's error form naming
the option (or the model's file:line), no traceback, no internal error, no stage past
``load`` on stderr (the progress lines say which stages ran), and the working directory,
``-o`` included, exactly as it was.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest
from helpers import ERROR_LINE, MODELS, ROOT, bgc, error_lines, snapshot

OPTION_LINE = re.compile(r"^error: (?P<key>-[-\w/]+|[A-Z]+): (?P<msg>.+) "
                         r"\(hint: (?P<hint>.+)\)$")
# the stages of a build after load: none may have run when an option is refused
WORK = re.compile(r"^bgc: (causality|equations|jacobian|emit|machine code|integrate)\b",
                  re.M)



@pytest.fixture
def work(tmp_path) -> Path:
    """A directory holding fresh copies of rlc.yaml and of the tutorial's absorber (an
    excitation along ``rotor``, outputs a_cabin and x_tuned, parameters m_t and k_t)."""
    shutil.copy(MODELS / "rlc.yaml", tmp_path / "rlc.yaml")
    shutil.copy(ROOT / "docs" / "tutorial" / "absorber.yaml", tmp_path / "excited.yaml")
    return tmp_path


def refused(work: Path, *args, key: str, contains: tuple[str, ...] = (),
            located: bool = False) -> re.Match:
    """``bgc ARGS`` in ``work``: refused in one line naming ``key`` (an option, or with
    ``located`` the model's key at file:line), before any stage past load, nothing
    written."""
    before = snapshot(work)
    proc = bgc(*args, cwd=work, timeout=60)
    detail = f"\nstdout: {proc.stdout[-1500:]!r}\nstderr: {proc.stderr[-1500:]!r}"
    assert "Traceback" not in proc.stderr + proc.stdout, detail
    assert "internal error" not in proc.stderr, detail
    assert proc.returncode == 2, f"exit {proc.returncode}" + detail
    assert not WORK.search(proc.stderr), "refused after work" + detail
    lines = error_lines(proc.stderr)
    assert len(lines) == 1, detail
    m = (ERROR_LINE if located else OPTION_LINE).match(lines[0])
    assert m, "not bgc's error form" + detail
    assert m["key"] == key, f"expected key {key!r}" + detail
    for s in contains:
        assert s in lines[0], f"lacks {s!r}" + detail
    assert snapshot(work) == before, "something was written" + detail
    return m


SIM = ("simulate", "rlc.yaml", "-o", "gen", "--out", "r.csv")
EXC = ("simulate", "excited.yaml", "-o", "gen", "--out", "r.csv")
FRF = ("frf", "excited.yaml", "-o", "gen", "--input", "rotor", "--output", "a_cabin")
TUNE = ("tune", "excited.yaml", "-o", "gen", "--input", "rotor", "--output", "a_cabin",
        "--target-frequency", "17.5")


@pytest.mark.parametrize("args, key, words", [
    (SIM + ("-p", "RR=3"), "--param", ("unknown parameter 'RR'", "did you mean R")),
    (SIM + ("-p", "C=-1"), "--param", ("C=-1",)),
    (EXC + ("--excitation", "nope", "--direction", "rotor"), "--excitation", ("sine",)),
    (EXC + ("--excitation", "sine", "--direction", "pull"), "--direction", ("rotor",)),
    (EXC + ("--excitation", "sine"), "--direction", ("go together",)),
    (EXC + ("--excitation", "sine", "--direction", "rotor", "--frequency", "1e12"),
     "--frequency", ("steps",)),
    (SIM + ("--amplitude", "2"), "--amplitude", ("--excitation",)),
    (SIM + ("--solver", "rk4"), "--solver", ("--step",)),
    (SIM + ("--solver", "nope"), "--solver", ("native",)),
    (SIM + ("--solver", "bdf", "--step", "1e-4"), "--step", ("fixed-step",)),
    (SIM + ("--method", "lagrange", "--parasitic", "auto"), "--parasitic", ("parasitic",)),
    (SIM + ("--separation", "0"), "--separation", ("> 1",)),
    (SIM + ("--keep-loops",), "--keep-loops", ("zcp",)),
    (SIM + ("--zoom", "0.02", "0.01", "--plot", "r.png"), "--zoom", ("before the end",)),
    (SIM + ("--t-end", "1e308"), "--t-end", ("--points",)),
    (("simulate", "rlc.yaml", "-o", "sine.csv"), "-o", ("--out sine.csv",)),
    (FRF[:-2] + ("--output", "y"), "--output", ("outputs: a_cabin",)),
    (FRF[:-4] + ("--input", "pull", "--output", "a_cabin"), "--input", ("rotor",)),
    (FRF + ("--f-max", "1e12"), "--f-max", ("narrow the band",)),
    (FRF + ("--f-min", "30", "--f-max", "20"), "--f-min", ("--f-min <",)),
    (FRF + ("--keep-loops",), "--keep-loops", ("linearization",)),
    (TUNE + ("--tune", "mm"), "--tune", ("can be tuned",)),
    (TUNE + ("--tune", "m_t", "-p", "kk=1"), "--param", ("unknown parameter 'kk'",)),
    (TUNE + ("--tune", "m_t", "--set", "k_t=1"), "--set", ("-p NAME=VALUE",)),
    (TUNE + ("--param", "m_t"), "--param", ("--tune m_t",)),
    (("sweep", "excited.yaml", "-o", "gen", "-p", "k_t=100:200:2", "--frf", "rotor:y"),
     "--frf", ("unknown output 'y'",)),
    (("sweep", "excited.yaml", "-o", "gen", "-p", "kk=100:200:2", "--frf", "rotor:a_cabin"),
     "--param", ("unknown parameter 'kk'",)),
    (("draw", "rlc.yaml", "-o", "g.svg"), "-o", ("--out FILE",)),
    (("draw", "rlc.yaml", "--out", "g.svg", "--energy", "none.json"), "--energy",
     ("cannot read",)),
    (("energy", "rlc.yaml", "-o", "gen", "-p", "RR=3"), "--param", ("unknown parameter",)),
    (("energy", "rlc.yaml", "-o", "gen", "--sankey", "s.txt"), "--sankey", (".png",)),
    (("energy", "rlc.yaml", "-o", "gen", "--since", "1"), "--since", ("before the run's end",)),
    (("energy", "excited.yaml", "-o", "gen", "--excitation", "sine"), "--direction",
     ("go together",)),
    (("run", "pumping_chirp", "--out", "res"), "--out", ("--results DIR",)),
    (("compile", "rlc.yaml", "--method", "parasitic", "--keep-loops"), "--keep-loops",
     ("zcp",)),
], ids=lambda v: v if isinstance(v, str) else None)
def test_options_are_refused_before_any_work(work, args, key, words):
    refused(work, *args, key=key, contains=words)


def test_the_model_solver_setting_is_checked_at_load(work):
    (work / "m.yaml").write_text((work / "rlc.yaml").read_text().replace(
        "simulation: {t_end: 0.05}", "simulation: {t_end: 0.05, solver: nope}"))
    m = refused(work, "compile", "m.yaml", "-o", "gen", key="simulation.solver",
                located=True, contains=("native",))
    assert int(m["line"]) == 25


def test_a_model_fixing_rk4_needs_a_step(work):
    (work / "m.yaml").write_text((work / "rlc.yaml").read_text().replace(
        "simulation: {t_end: 0.05}", "simulation: {t_end: 0.05, solver: rk4}"))
    refused(work, "simulate", "m.yaml", "-o", "gen", key="--step",
            contains=("simulation.solver",))


PENDULUM = (MODELS / "pendulum.yaml").read_text()


@pytest.mark.parametrize("old, new, key", [
    ("gravity: 9.81", "gravity: 1.0e308", "gravity"),
    ("    mass: 2.0", "    mass: 1.0e308", "bodies.rod.mass"),
    ("    mass: 2.0", "    mass: 2.0\n    velocity: [1.0e308, 0, 0]", "bodies.rod.velocity[0]"),
])
def test_overflowing_values_are_refused_at_their_line_before_any_file(work, old, new, key):
    """The start evaluated in doubles, as the generated code will (``codegen.start``):
    an overflow names the value at its key; no module, no ``inf`` literal (a NameError on
    import, before)."""
    text = PENDULUM.replace(old, new, 1)
    (work / "p.yaml").write_text(text)
    before = snapshot(work)
    proc = bgc("simulate", "p.yaml", "-o", "gen", "--out", "r.csv", "-q", cwd=work, timeout=60)
    [line] = error_lines(proc.stderr)
    m = ERROR_LINE.match(line)
    assert proc.returncode == 2 and m and m["key"] == key, proc.stderr
    assert int(m["line"]) == next(i for i, ln in enumerate(text.splitlines(), 1)
                                  if new.splitlines()[-1] in ln)
    assert "not finite" in line or "inf" in line
    assert snapshot(work) == before


def test_a_step_effort_on_a_capacitor_runs(work):
    """A constant-valued piece of an ``ifelse`` was judged as a value (sympy's
    ExprCondPair has no evalf): a traceback before."""
    (work / "s.yaml").write_text(
        'elements:\n  s: {type: Se, effort: "ifelse(t > 0.1, 2.0, 0.0)"}\n'
        "  c: {type: C, C: 1.0}\n  r: {type: R, R: 1.0}\n  j: {type: \"1\"}\n"
        "bonds:\n  - [s, j]\n  - [j, c]\n  - [j, r]\noutputs:\n  charge: {expr: c.q}\n"
        "simulation: {t_end: 1.0}\n")
    proc = bgc("simulate", "s.yaml", "-o", "gen", "--out", "r.csv", "-q", cwd=work,
               timeout=120)
    assert proc.returncode == 0, proc.stderr
    last = (work / "r.csv").read_text().splitlines()[-1].split(",")
    assert abs(float(last[-1]) - 2.0 * (1 - 2.718281828459045 ** -0.9)) < 1e-5


def test_sources_bonded_straight_together_are_refused(work):
    (work / "s.yaml").write_text("elements:\n  s: {type: Se, effort: 1.0}\n"
                                 "  v: {type: Sf, flow: 1.0}\nbonds:\n  - [s, v]\n")
    m = refused(work, "check", "s.yaml", key="bonds.b1", located=True,
                contains=("Se 's'", "Sf 'v'"))
    assert int(m["line"]) == 5


SCENE = """\
model: rlc.yaml
outputs: [current]
time: {end: 0.01, points: 11}
"""


@pytest.mark.parametrize("extra, key, line, words", [
    ("expose: [R, nope]\n", "expose", 4, ("unknown parameter 'nope'",)),
    ("params: {R: 1.0, nope: 2.0}\n", "params.nope", 4, ("unknown parameter 'nope'",)),
    ("expose: [R, R]\n", "expose[1]", 4, ("twice",)),
], ids=["expose", "params", "expose-twice"])
def test_scene_names_are_located(work, extra, key, line, words):
    (work / "sc.yaml").write_text(SCENE + extra)
    m = refused(work, "check", "sc.yaml", key=key, located=True, contains=words)
    assert int(m["line"]) == line


def test_scene_outputs_listed_twice_are_refused(work):
    (work / "sc.yaml").write_text(SCENE.replace("[current]", "[current, v_C, current]"))
    m = refused(work, "run", "sc.yaml", key="outputs[2]", located=True, contains=("twice",))
    assert int(m["line"]) == 2


@pytest.mark.parametrize("where", ["top", "elements", "element", "outputs", "output",
                                   "simulation"])
def test_duplicate_keys_are_refused_at_every_level(work, where):
    text = (work / "rlc.yaml").read_text()
    dup = {"top": ("simulation:", "name: again\nsimulation:"),
           "elements": ("  loop:", "  loop: {type: \"1\"}\n  loop:"),
           "element": ("{type: R, R: R}", "{type: R, R: R, R: L}"),
           "outputs": ("  v_R:", "  v_C: {expr: capacitor.e}\n  v_R:"),
           "output": ("{expr: resistor.e, unit: V}", "{expr: resistor.e, unit: V, unit: A}"),
           "simulation": ("{t_end: 0.05}", "{t_end: 0.05, t_end: 1}")}[where]
    (work / "d.yaml").write_text(text.replace(*dup, 1))
    refused(work, "check", "d.yaml", key=_dup_key(where), located=True,
            contains=("duplicate key",))


def _dup_key(where: str) -> str:
    return {"top": "name", "elements": "elements.loop", "element": "elements.resistor.R",
            "outputs": "outputs.v_C", "output": "outputs.v_R.unit",
            "simulation": "simulation.t_end"}[where]


def test_an_unexpected_failure_is_one_line_with_exit_1(monkeypatch):
    """The last resort (``app.internal_line``): a bug in bgc is one line naming where and
    how to report it, exit status 1, never a traceback; user mistakes never reach it (the
    cases above check exit 2 and no 'internal error')."""
    from click.testing import CliRunner

    from bgc.cli import main

    def broken(*a, **k):
        raise ZeroDivisionError("float division by zero")
    monkeypatch.setattr("bgc.cli.check.build", broken)
    r = CliRunner().invoke(main, ["check", str(MODELS / "rlc.yaml"), "-q"])
    assert r.exit_code == 1
    [line] = r.output.strip().splitlines()
    assert line.startswith("error: internal error in bgc: ZeroDivisionError") and \
        "report it" in line and "Traceback" not in r.output


def test_a_library_warning_is_one_line_of_bgc(capsys):
    import warnings

    from bgc.cli import app
    app._show_warning(RuntimeWarning("overflow encountered in det"), RuntimeWarning,
                      "/x/site-packages/numpy/linalg/_linalg.py", 2100)
    err = capsys.readouterr().err
    assert err == "warning: numpy: overflow encountered in det\n"
    assert warnings.showwarning is not None


@pytest.mark.parametrize("model", ["dc_motor", "servo", "pendulum", "slider_crank",
                                   "rc_table", "geared_inertias"])
@pytest.mark.parametrize("method", ["parasitic", "lagrange", "zcp"])
def test_the_parameters_checked_before_the_build_cover_the_modules(model, method):
    """``-p`` names are checked against what the Model declares (``Declared.of_model``)
    before any build: every parameter the equations give the module must be among them,
    or a valid ``-p`` would be refused."""
    from bgc.pipeline import Declared, build
    c = build(MODELS / f"{model}.yaml", method)
    declared = Declared.of_model(c.model, method).params
    assert {n for _, n, _ in c.system.params} <= set(declared)
