"""Hostile input gets a clean answer within 10 s (issue 23, item 3): YAML, expressions,
numbers and scene files (output paths: ``cli/test_output_files.py``).

Every case runs the CLI in a subprocess with a 10 s timeout and requires exit status 2, at
most two lines on stderr, the first ``error: FILE:LINE:COL: KEY: message (hint: ...)``
(``error: OPTION: message (hint: ...)`` for a command-line option), no traceback, and the
working directory (model, output directory) exactly as it was. Test names start with the
category (``test_yaml_``, ``test_expr_``, ``test_number_``, ``test_scene_``) so they can be
counted per category.

The limits the cases run into are bgc's documented ones: ``load.MAX_FILE_BYTES``,
``MAX_NODES``, ``MAX_DEPTH``; ``expr.MAX_CHARS``, ``MAX_DEPTH``, ``MAX_EXPONENT``;
``model.MAX_POINTS``; ``limits.MAX_PLANNED_STEPS``.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

import pytest
from helpers import ERROR_LINE, MODELS, bgc, error_lines, snapshot

from bgc.model import limits, load
from bgc.model.model import MAX_POINTS

OPTION_LINE = re.compile(
    r"^error: (?P<key>-[-\w]+|[A-Z]+): (?P<msg>.+) \(hint: (?P<hint>.+)\)$")

# a small valid model; cases replace one line of it
BASE = """\
name: m
parameters:
  C1: 1.0
  Z: 0.0
elements:
  s: {type: Se, effort: 1.0}
  c: {type: C, C: C1, q0: 0.0}
bonds:
  - [s, c]
simulation: {t_end: 1.0}
"""


def model(**lines) -> str:
    """BASE with the line starting with each key (``s=``, ``c=``, ``C1=``, ``sim=``...)
    replaced by the given text."""
    out = BASE
    starts = {"s": "  s:", "c": "  c:", "C1": "  C1:", "Z": "  Z:", "sim": "simulation:"}
    for k, text in lines.items():
        old = next(ln for ln in BASE.splitlines() if ln.startswith(starts[k]))
        out = out.replace(old, text)
    return out


def _snap(root: Path) -> dict:
    return {k: v for k, v in snapshot(root).items() if "__pycache__" not in k}


def refused(tmp_path: Path, *args, key: str | None = None, line: int | None = None,
            contains: tuple[str, ...] = (), option: bool = False) -> re.Match:
    """Run ``bgc *args`` in ``tmp_path``: exit 2 within 10 s, one or two stderr lines in
    bgc's error form (``key``, ``line`` and ``contains`` checked), no traceback, nothing
    in ``tmp_path`` changed or added."""
    before = _snap(tmp_path)
    proc = bgc(*args, cwd=tmp_path, timeout=10)
    detail = f"\nstdout: {proc.stdout[-2000:]!r}\nstderr: {proc.stderr[-2000:]!r}"
    assert "Traceback" not in proc.stderr + proc.stdout, detail
    assert proc.returncode == 2, f"exit {proc.returncode}" + detail
    lines = error_lines(proc.stderr)
    assert 1 <= len(lines) <= 2, detail
    m = (OPTION_LINE if option else ERROR_LINE).match(lines[0])
    assert m, "not bgc's error form" + detail
    assert m["hint"].strip(), detail
    if key is not None:
        assert m["key"] == key, f"expected key {key!r}" + detail
    if line is not None:
        assert int(m["line"]) == line, f"expected line {line}" + detail
    for s in contains:
        assert s in m["msg"], f"message lacks {s!r}" + detail
    assert _snap(tmp_path) == before, "the directory changed" + detail
    return m


def line_of(text: str, marker: str) -> int:
    return next(i for i, ln in enumerate(text.splitlines(), 1) if marker in ln)


def write(tmp_path: Path, text: str | bytes, name: str = "model.yaml") -> Path:
    path = tmp_path / name
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    return path


@pytest.fixture(params=["check", "compile"])
def cmd(request, tmp_path):
    """``check MODEL`` or ``compile MODEL -o out`` (out must stay absent)."""
    return (lambda path: ["check", path]) if request.param == "check" else (
        lambda path: ["compile", path, "-o", tmp_path / "out"])


# ---------------------------------------------------------------------------- YAML
def billion_laughs(levels: int = 9) -> str:
    rows = ["lol0: &lol0 [lol, lol, lol, lol, lol, lol, lol, lol, lol]"]
    rows += [f"lol{i}: &lol{i} [" + ", ".join([f"*lol{i - 1}"] * 9) + "]"
             for i in range(1, levels + 1)]
    return "\n".join(rows) + "\n" + BASE


def test_yaml_billion_laughs_is_refused_while_composing(tmp_path, cmd):
    text = billion_laughs()
    m = refused(tmp_path, *cmd(write(tmp_path, text)), contains=("aliases",))
    # refused at the first node whose expansion passes the limit, before lol9 (line 10)
    assert int(m["line"]) < 10 and 10 * 9 ** int(m["line"]) > load.MAX_NODES


def test_yaml_recursive_alias(tmp_path):
    text = BASE.replace("  Z: 0.0", "  Z: &z [1, *z]")
    refused(tmp_path, "check", write(tmp_path, text), line=line_of(text, "&z"),
            contains=("contains it",))


def test_yaml_merge_key_is_refused_with_a_hint(tmp_path):
    text = BASE.replace("  c: {type: C, C: C1, q0: 0.0}",
                        "  c: {<<: {type: C}, C: C1}")
    m = refused(tmp_path, "check", write(tmp_path, text), line=line_of(text, "<<"),
                contains=("merge key",))
    assert "alias" in m["hint"]


@pytest.mark.parametrize("value", [
    "!!python/object/apply:os.system ['touch pwned']",
    "!!binary aGVsbG8=",
    "!local 3",
], ids=["python-apply", "binary", "local-tag"])
def test_yaml_tags_are_refused_and_nothing_runs(tmp_path, value):
    text = BASE.replace("  Z: 0.0", f"  Z: {value}")
    refused(tmp_path, "check", write(tmp_path, text), line=line_of(text, "  Z:"),
            contains=("tag",))
    assert not (tmp_path / "pwned").exists()


@pytest.mark.parametrize("opening, closing", [("[", "]"), ("{a: ", "}")],
                         ids=["lists", "mappings"])
def test_yaml_deep_nesting_is_refused_without_recursion_error(tmp_path, opening, closing):
    text = BASE + "description: " + opening * 10_000 + closing * 10_000 + "\n"
    refused(tmp_path, "check", write(tmp_path, text), contains=("nested",))


def test_yaml_50_mb_file_is_refused_at_once(tmp_path):
    path = write(tmp_path, BASE + "description: ")
    with open(path, "r+b") as fh:       # a sparse 50 MB file
        fh.truncate(50 * 2 ** 20)
    refused(tmp_path, "check", path, key="model", contains=("larger than",))


def test_yaml_file_just_under_the_size_limit_loads(tmp_path):
    """The limit refuses only what is too big: a valid model padded to ~0.9 MiB with
    comments loads (and in far less than 10 s)."""
    pad = ("# " + "x" * 76 + "\n") * (int(0.9 * load.MAX_FILE_BYTES) // 79)
    path = write(tmp_path, pad + BASE)
    proc = bgc("check", path, cwd=tmp_path, timeout=10)
    assert proc.returncode == 0, proc.stderr


def test_yaml_non_utf8_bytes_are_located(tmp_path):
    data = BASE.encode().replace(b"name: m", b"name: m\ndescription: caf\xe9")
    m = refused(tmp_path, "check", write(tmp_path, data), line=2, contains=("UTF-8",))
    assert m["col"] == "17"


@pytest.mark.parametrize("char", [b"\x00", b"\x07"], ids=["NUL", "BEL"])
def test_yaml_control_character_is_located(tmp_path, char):
    data = BASE.encode().replace(b"name: m", b"name: m\ndescription: a" + char + b"b")
    m = refused(tmp_path, "check", write(tmp_path, data), line=2, contains=("character",))
    assert m["col"] == "15"


@pytest.mark.parametrize("kind, command", [
    ("fifo", "check"), ("fifo", "compile"), ("directory", "check"), ("/dev/zero", "check"),
    ("/dev/null", "compile")])
def test_yaml_fifo_device_or_directory_as_model(tmp_path, kind, command):
    if kind == "fifo":
        path = tmp_path / "model.yaml"
        os.mkfifo(path)         # opening it would block until a writer comes
        assert stat.S_ISFIFO(path.lstat().st_mode)
    elif kind == "directory":
        path = tmp_path / "model.yaml"
        path.mkdir()
    else:
        path = Path(kind)
    args = ["check", path] if command == "check" else ["compile", path, "-o",
                                                         tmp_path / "out"]
    m = refused(tmp_path, *args, key="model")
    assert {"fifo": "FIFO", "directory": "directory"}.get(kind, "device") in m["msg"]


def test_yaml_fifo_as_a_scenes_model(tmp_path):
    os.mkfifo(tmp_path / "model.yaml")
    scene = write(tmp_path, "model: model.yaml\noutputs: [x]\ntime: {end: 1.0}\n",
                  "scene.yaml")
    refused(tmp_path, "check", scene, key="model", line=1)


# ---------------------------------------------------------------------- expressions
@pytest.mark.parametrize("law", ["10**10**10", "(1 + C1)**(10**10)", "(10**200)**2"])
def test_expr_huge_powers_do_not_hang(tmp_path, law):
    text = model(c=f'  c: {{type: C, C: "{law}"}}')
    refused(tmp_path, "check", write(tmp_path, text), key="elements.c.C",
            line=line_of(text, "  c:"))


@pytest.mark.parametrize("law", [
    "+".join(["C1"] * 10_000),                       # 10 000 terms
    "sin(" * 300 + "C1" + ")" * 300,                 # under the length limit, deep
    "-" * 5_000 + "C1",                              # nested unary minus
], ids=["sum-10000-terms", "nested-calls", "unary-minus"])
def test_expr_long_or_deep_expressions_without_recursion_error(tmp_path, law):
    text = model(c=f'  c: {{type: C, C: "{law}"}}')
    refused(tmp_path, "check", write(tmp_path, text), key="elements.c.C",
            line=line_of(text, "  c:"))


@pytest.mark.parametrize("where, law, culprit", [
    ("c", "C1/Z", "1/Z"),
    ("s", "1/0", "value"),
    ("q0", "C1/(2*Z)", "1/Z"),
    ("s", "log(0)", "value"),
    ("c", "C1 + log(Z)", "log(Z)"),
    ("s", "sqrt(-1)", "complex"),
    ("s", "acos(2)", "complex"),
    ("s", "asin(C1 + 1) + t", "complex"),
    ("s", "1e308*10", "float range"),
], ids=["param-div-zero", "div-zero", "initial-div-zero", "log0", "param-log0",
        "sqrt-1", "acos2", "asin-beside-t", "overflow"])
def test_expr_constants_must_be_finite_reals(tmp_path, where, law, culprit):
    if where == "s":
        text, key = model(s=f'  s: {{type: Se, effort: "{law}"}}'), "elements.s.effort"
    elif where == "q0":
        text, key = model(c=f'  c: {{type: C, C: C1, q0: "{law}"}}'), "elements.c.q0"
    else:
        text, key = model(c=f'  c: {{type: C, C: "{law}"}}'), "elements.c.C"
    m = refused(tmp_path, "check", write(tmp_path, text), key=key,
                line=line_of(text, "  s:" if where == "s" else "  c:"))
    assert culprit in m["msg"]
    assert "P_" not in m["msg"], "internal symbol names leaked into the message"


def test_expr_state_dependent_division_is_accepted(tmp_path):
    """Only what is constant is judged: 1/q and log(q) may be fine at run time."""
    text = model(c='  c: {type: C, effort: "q/C1 + 0*log(1 + q**2)"}')
    proc = bgc("check", write(tmp_path, text), cwd=tmp_path, timeout=10)
    assert proc.returncode == 0, proc.stderr


# -------------------------------------------------------------------------- numbers
@pytest.mark.parametrize("where, digits", [("C1", 400), ("C1", 5_000), ("s", 400),
                                           ("law", 400)])
def test_number_huge_integers(tmp_path, where, digits):
    big = "1" + "0" * digits
    text = {"C1": model(C1=f"  C1: {big}"),
            "s": model(s=f"  s: {{type: Se, effort: {big}}}"),
            "law": model(c=f'  c: {{type: C, C: "C1*{big}"}}')}[where]
    refused(tmp_path, "check", write(tmp_path, text),
            line=line_of(text, {"C1": "  C1:", "s": "  s:", "law": "  c:"}[where]))


@pytest.mark.parametrize("text, key", [
    (model(C1="  C1: 5.0e-324"), "elements.c.C"),
    ("name: m\nbodies:\n  b: {mass: 1.0e-320, com: [0, 0, 0], inertia: [1, 1, 1]}\n",
     "bodies.b.mass"),
], ids=["capacitance", "mass"])
def test_number_subnormal_divisors_are_refused(tmp_path, text, key):
    """A subnormal capacitance, inertance, mass or moment of inertia divides in the
    equations and its reciprocal is beyond the float range: refused, saying so."""
    m = refused(tmp_path, "check", write(tmp_path, text), key=key)
    assert "subnormal" in m["msg"] + m["hint"]


def test_number_subnormal_values_that_do_not_divide_are_accepted(tmp_path):
    """Where a subnormal is harmless (a source effort, an initial charge) it is kept."""
    text = model(s="  s: {type: Se, effort: 5.0e-324}",
                 c="  c: {type: C, C: C1, q0: 1.0e-310}")
    proc = bgc("check", write(tmp_path, text), cwd=tmp_path, timeout=10)
    assert proc.returncode == 0, proc.stderr


SINE = "signals:\n  sig: {type: sine, amplitude: 1.0, frequency: 1.0}\n"


@pytest.mark.parametrize("text, key", [
    (model(C1="  C1: .nan"), "parameters.C1"),
    (model(c="  c: {type: C, C: C1, q0: .nan}"), "elements.c.q0"),
    (model(s="  s: {type: Se, effort: .inf}"), "elements.s.effort"),
    (model(sim="simulation: {t_end: .inf}"), "simulation.t_end"),
    (model(sim="simulation: {rtol: .nan}"), "simulation.rtol"),
    (model(s="  s: {type: Se, effort: sig}") + SINE.replace("amplitude: 1.0",
                                                            "amplitude: .nan"),
     "signals.sig.amplitude"),
    (model(s="  s: {type: Se, effort: sig}") + SINE.replace("frequency: 1.0",
                                                            "frequency: .inf"),
     "signals.sig.frequency"),
    (("name: m\nbodies:\n  b: {mass: 1, com: [0, 0, 0], inertia: [1, 1, 1], "
      "velocity: [.nan, 0, 0]}\n"), "bodies.b.velocity[0]"),
], ids=["param-nan", "initial-nan", "effort-inf", "t_end-inf", "rtol-nan",
        "amplitude-nan", "frequency-inf", "body-velocity-nan"])
def test_number_nan_and_inf_in_the_model(tmp_path, text, key):
    m = refused(tmp_path, "check", write(tmp_path, text), key=key)
    assert "finite" in m["msg"]


@pytest.mark.parametrize("signal, key", [
    ("sig: {type: sine, amplitude: 1.0, frequency: 1.0e12}", "signals.sig.frequency"),
    ("sig: {type: chirp, t1: 0.1, t2: 0.2, t3: 0.9, f_start: 1, f_end: 1.0e12}",
     "signals.sig.f_end"),
    ("sig: {type: sine, amplitude: 1.0, frequency: C1}", "signals.sig.frequency"),
], ids=["sine", "chirp", "sine-parameter"])
def test_number_signal_frequency_the_run_cannot_resolve(tmp_path, signal, key):
    text = (model(s="  s: {type: Se, effort: sig}", C1="  C1: 1.0e12")
            .replace("C: C1", "C: 1.0") + "signals:\n  " + signal + "\n")
    m = refused(tmp_path, "check", write(tmp_path, text), key=key,
                line=line_of(text, "sig: {"))
    assert f"{limits.MAX_PLANNED_STEPS:.0e}" in m["msg"]


@pytest.mark.parametrize("text, key, rule", [
    (model(C1="  C1: 0"), "elements.c.C", "> 0"),
    (model(C1="  C1: -1.0e-6"), "elements.c.C", "> 0"),
    (model(c="  c: {type: I, I: 0}"), "elements.c.I", "> 0"),
    ("name: m\nbodies:\n  b: {mass: -1, com: [0, 0, 0], inertia: [1, 1, 1]}\n",
     "bodies.b.mass", ">= 0"),
    ("name: m\nbodies:\n  b: {mass: 1, com: [0, 0, 0], inertia: [0, 1, 1]}\n",
     "bodies.b.inertia", "positive definite"),
], ids=["C-zero", "C-negative", "I-zero", "mass-negative", "inertia-zero"])
def test_number_zero_or_negative_storage(tmp_path, text, key, rule):
    m = refused(tmp_path, "check", write(tmp_path, text), key=key)
    assert rule in m["msg"]


@pytest.mark.parametrize("points", ["1", "1.5", "1.0e12"])
def test_number_simulation_points(tmp_path, points):
    text = model(sim=f"simulation: {{t_end: 1.0, points: {points}}}")
    m = refused(tmp_path, "check", write(tmp_path, text), key="simulation.points")
    assert str(MAX_POINTS) in m["msg"]


@pytest.mark.parametrize("args, key", [
    (["--t-end", "nan"], "--t-end"), (["--t-end", "-1"], "--t-end"),
    (["--t-end", "0"], "--t-end"),
    (["--points", "-5"], "--points"), (["--points", str(MAX_POINTS + 1)], "--points"),
    (["--rtol", "0"], "--rtol"), (["--atol", "-1e-8"], "--atol"),
    (["--step", "nan"], "--step"), (["--frequency", "-3"], "--frequency"),
    (["--zoom", "0", "nan"], "--zoom"),
    (["-p", "R=nan"], "--param"), (["-p", "R"], "--param"),
], ids=lambda v: " ".join(v) if isinstance(v, list) else None)
def test_number_command_line_options(tmp_path, args, key):
    """Refused while the options are read: before any compile, nothing written."""
    refused(tmp_path, "simulate", MODELS / "rlc.yaml", "-o", tmp_path / "gen",
            "--out", tmp_path / "out.csv", *args, key=key, option=True)


@pytest.fixture(scope="module")
def msd(tmp_path_factory, compiled, gen_dir):
    """A working directory for runs of msd_forced (a 3 Hz sine force), whose module is
    the session's (in ``gen_dir``)."""
    compiled("msd_forced")
    return tmp_path_factory.mktemp("msd")


def refused_msd(work: Path, gen_dir: Path, *args, **kw) -> re.Match:
    """``refused`` for ``bgc simulate msd_forced.yaml -o GEN_DIR ARGS`` in ``work``:
    nothing written there, nor to msd_forced's module in the session's directory (or a
    temporary file of it: ``fileio.atomic_write``'s; the other files there are the other
    tests')."""
    def files():
        return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in gen_dir.iterdir()
                if p.name == "msd_forced.py" or p.name.startswith(".msd_forced.py.")}
    before = files()
    m = refused(work, "simulate", MODELS / "msd_forced.yaml", "-o", gen_dir, *args, **kw)
    assert files() == before, "msd_forced's module was written"
    return m


@pytest.mark.parametrize("args, key", [
    (["-p", "f_drive=1e12"], "--param"),
    (["--t-end", "1e9"], "--t-end"),
    (["--solver", "rk4", "--step", "1e-300"], "--step"),
], ids=["param-1e12-Hz", "t-end-1e9", "step-1e-300"])
def test_number_run_that_would_plan_billions_of_steps(msd, gen_dir, args, key):
    m = refused_msd(msd, gen_dir, *args, key=key, option=True)
    assert f"{limits.MAX_PLANNED_STEPS:.0e}" in m["msg"]



@pytest.mark.parametrize("param, rule", [
    ("m=0", "inertance I of I 'mass' must be > 0"),
    ("m=-1.5", "inertance I of I 'mass' must be > 0"),
    ("k=-600", "'spring' must be > 0"),
    ("c=-6", "resistance R of R 'damper' must be >= 0"),
])
def test_number_parameter_overrides_obey_the_models_checks(msd, gen_dir, param, rule):
    """-p values go through the same checks as the model file's own values (a mass, a
    capacitance not > 0), refused as the option's error naming the element's line."""
    m = refused_msd(msd, gen_dir, "-p", param, "--out", msd / "r.csv", key="--param",
                    option=True)
    assert m["msg"].startswith(param + ": "), m["msg"]
    assert rule in m["msg"] and "set by -p" in m["msg"], m["msg"]
    assert "msd_forced.yaml:" in m["msg"]


# --------------------------------------------------------------------------- scenes
SCENE = "model: {model}\noutputs: [current]\ntime: {{end: 0.01}}\n"


@pytest.mark.parametrize("extra, key", [
    ("expose: 5", "expose"),
    ("expose: R", "expose"),

    ("solver: [bdf]", "solver"),
    ("method: {a: 1}", "method"),
    ("tolerances: [1.0e-6]", "tolerances"),

    ("params: [1]", "params"),

    ("params: {1: 2.0}", "params"),
    ("excitation: pumping", "excitation"),

    ("description: {a: 1}", "scene.description"),

], ids=lambda v: v.split(":")[0] + ":" + v.split(":", 1)[1].strip()[:8]
    if ":" in v else None)
def test_scene_values_of_the_wrong_type(tmp_path, extra, key):
    text = SCENE.format(model=MODELS / "rlc.yaml") + extra + "\n"
    refused(tmp_path, "check", write(tmp_path, text, "scene.yaml"), key=key, line=4)


@pytest.mark.parametrize("body, key, line", [
    ("model: [a]\noutputs: [current]\ntime: {end: 0.01}\n", "model", 1),
    ("model: {rlc: 1}\noutputs: [current]\ntime: {end: 0.01}\n", "model", 1),
    (SCENE.replace("[current]", "current"), "outputs", 2),
    (SCENE.replace("[current]", "[[current]]"), "outputs[0]", 2),
    (SCENE.replace("{{end: 0.01}}", "0.01"), "time", 3),
    (SCENE.replace("{{end: 0.01}}", "{{end: .nan}}"), "time.end", 3),
], ids=["model-list", "model-mapping", "outputs-string", "outputs-nested", "time-number",
        "end-nan"])
def test_scene_required_keys_of_the_wrong_type(tmp_path, body, key, line):
    text = body.replace("{model}", str(MODELS / "rlc.yaml")).replace("{{", "{").replace(
        "}}", "}")
    refused(tmp_path, "check", write(tmp_path, text, "scene.yaml"), key=key, line=line)


def test_yaml_aliases_within_bounds_still_work(tmp_path):
    """Anchors and aliases are YAML a model may use: only an explosion is refused."""
    path = write(tmp_path,
                 "parameters:\n  R: &ohm {value: 10.0, unit: ohm}\n  R2: *ohm\n"
                 "  L: {value: 0.05, unit: H}\n  C: {value: 2.0e-5, unit: F}\n"
                 "elements:\n  source: {type: Se, effort: 1.0}\n  loop: {type: \"1\"}\n"
                 "  resistor: {type: R, R: R + R2}\n  inductor: {type: I, I: L}\n"
                 "  capacitor: {type: C, C: C}\n"
                 "bonds: [[source, loop], [loop, resistor], [loop, inductor], "
                 "[loop, capacitor]]\n")
    proc = bgc("check", path, cwd=tmp_path, timeout=30)
    assert proc.returncode == 0, proc.stderr
