"""Bad model input is refused cleanly.

For every mistake below, ``bgc check MODEL`` and ``bgc compile MODEL -o DIR`` must

- exit with status 2,
- print exactly one line to stderr:
  ``error: <file>:<line>:<col>: <key>: <message> (hint: <what would be valid>)``,
  naming the line of the offending YAML text and the key path of the offending value,
- print no traceback,
- write nothing (DIR, and the working directory, stay empty).

Each test writes a small model into ``tmp_path``; the expected line is computed from the
model text (the line holding a marker string), never hard-coded.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import textwrap
from dataclasses import dataclass
from pathlib import Path

import pytest
from click.testing import CliRunner
from helpers import ERROR_LINE, error_lines

from bgc.cli import main
from bgc.model.model import KINDS
from bgc.simulate import SOLVERS

# ---------------------------------------------------------------------------- helpers
@dataclass
class Reported:
    """The parsed error line."""
    text: str
    line: int
    col: int
    key: str
    msg: str
    hint: str


def model_text(text: str) -> str:
    return textwrap.dedent(text).lstrip("\n")


def line_of(text: str, marker: str, nth: int = 1) -> int:
    """1-based number of the ``nth`` line of ``text`` that contains ``marker``."""
    hits = [i for i, ln in enumerate(text.splitlines(), 1) if marker in ln]
    assert len(hits) >= nth, f"marker {marker!r} occurs {len(hits)} times in the model"
    return hits[nth - 1]


@pytest.fixture(params=["check", "compile"])
def cmd(request) -> str:
    return request.param


def run_bad(tmp_path: Path, monkeypatch, cmd: str, text: str, *, at: str, key: str,
            nth: int = 1, contains: tuple[str, ...] = ()) -> Reported:
    """Run ``bgc <cmd>`` on the model ``text`` and check the common error contract.

    ``at`` (with ``nth``) marks the offending line, ``key`` is the expected key path and
    every string in ``contains`` must appear in the message.
    """
    text = model_text(text)
    path = tmp_path / "model.yaml"
    path.write_text(text, encoding="utf-8")
    line = line_of(text, at, nth)
    out_dir = tmp_path / "out"
    cwd = tmp_path / "cwd"          # check must not write generated/ either
    cwd.mkdir()
    monkeypatch.chdir(cwd)

    args = [cmd, str(path)] + (["-o", str(out_dir)] if cmd == "compile" else [])
    result = CliRunner().invoke(main, args)
    everything = result.output + result.stderr
    detail = f"\nstdout: {result.stdout!r}\nstderr: {result.stderr!r}"

    assert "Traceback" not in everything, detail
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"bgc raised {result.exception!r}" + detail)
    assert result.exit_code == 2, f"exit code {result.exit_code}" + detail
    lines = error_lines(result.stderr)
    assert len(lines) == 1, f"expected one stderr line, got {len(lines)}" + detail
    err = lines[0]
    assert err.startswith("error: "), detail
    assert f"{path}:{line}:" in err, f"expected {path.name}:{line}:" + detail
    m = ERROR_LINE.match(err)
    assert m, "not 'error: file:line:col: key: message (hint: ...)'" + detail
    assert m["key"] == key, f"expected key {key!r}" + detail
    assert "hint: " in err and m["hint"].strip(), detail
    for s in contains:
        assert s in m["msg"], f"message lacks {s!r}" + detail

    assert not list(cwd.iterdir()), f"wrote into the working directory: {list(cwd.iterdir())}"
    assert not out_dir.exists() or not list(out_dir.iterdir()), (
        f"wrote into the output directory: {list(out_dir.iterdir())}")
    assert not list(tmp_path.rglob("*.py")), "a .py file was written"
    return Reported(err, int(m["line"]), int(m["col"]), m["key"], m["msg"], m["hint"])


# ------------------------------------------------------------------ 1. malformed YAML
BAD_INDENT = """
    name: bad
    elements:
      source: {type: Se, effort: 1.0}
       cap: {type: C, C: 1.0}
    bonds:
      - [source, cap]
    """

UNCLOSED_BRACKET = """
    name: bad
    elements:
      source: {type: Se, effort: 1.0}
      r: {type: R, R: 1.0}
    bonds:
      - [source, r
    outputs:
      v: r.e
    """


@pytest.mark.parametrize("text, at, key", [
    (BAD_INDENT, "   cap:", "elements"),
    (UNCLOSED_BRACKET, "- [source, r", "bonds"),
], ids=["bad-indentation", "unclosed-bracket"])
def test_malformed_yaml(tmp_path, monkeypatch, cmd, text, at, key):
    err = run_bad(tmp_path, monkeypatch, cmd, text, at=at, key=key,
                  contains=("malformed YAML",))
    assert "indentation" in err.hint or "bracket" in err.hint or "]" in err.hint


# ------------------------------------------------------------- 2. unknown element type
def test_unknown_element_type(tmp_path, monkeypatch, cmd):
    err = run_bad(tmp_path, monkeypatch, cmd, """
        name: bad
        elements:
          source: {type: Se, effort: 1.0}
          thing: {type: Q}
        bonds:
          - [source, thing]
        """, at="thing:", key="elements.thing.type", contains=("'Q'",))
    valid = [k.strip() for k in err.hint.split(":", 1)[1].split(",")]
    assert set(valid) == {k for k, spec in KINDS.items() if spec.user}, err.text


# ------------------------------------------------------------------ 3. wrong arity
JUNCTION_ONE_BOND = """
    name: bad
    elements:
      source: {type: Se, effort: 1.0}
      loop: {type: "1"}
    bonds:
      - [source, loop]
    """

C_BONDED_TWICE = """
    name: bad
    elements:
      source: {type: Se, effort: 1.0}
      node: {type: "0"}
      cap: {type: C, C: 1.0}
      r: {type: R, R: 1.0}
    bonds:
      - [source, node]
      - [node, cap]
      - [cap, r]
    """

TF_BOTH_IN = """
    name: bad
    elements:
      source: {type: Se, effort: 1.0}
      tf: {type: TF, ratio: 2.0}
      cap: {type: C, C: 1.0}
    bonds:
      - [source, tf]
      - [cap, tf]
    """


@pytest.mark.parametrize("text, name, contains", [
    (JUNCTION_ONE_BOND, "loop", ("1 bond", "at least 2")),
    (C_BONDED_TWICE, "cap", ("2 bonds", "exactly 1", "b2", "b3")),
    (TF_BOTH_IN, "tf", ("2 bonds pointing in",)),
], ids=["junction-one-bond", "C-two-bonds", "TF-both-in"])
def test_wrong_arity(tmp_path, monkeypatch, cmd, text, name, contains):
    run_bad(tmp_path, monkeypatch, cmd, text, at=f"{name}:", key=f"elements.{name}",
            contains=contains)


# ------------------------------------------------------------------ 4. dangling bond
def test_dangling_bond(tmp_path, monkeypatch, cmd):
    err = run_bad(tmp_path, monkeypatch, cmd, """
        name: bad
        elements:
          source: {type: Se, effort: 1.0}
          loop: {type: "1"}
          r: {type: R, R: 1.0}
        bonds:
          - [source, loop]
          - [loop, ghost]
          - [loop, r]
        """, at="ghost", key="bonds[1]", contains=("'ghost'",))
    assert all(n in err.hint for n in ("source", "loop", "r")), err.text


# ------------------------------------------------------------------ 5. duplicate bond
@pytest.mark.parametrize("dup, nth", [("[loop, r]", 2), ("[r, loop]", 1)],
                         ids=["same-way", "reversed"])
def test_duplicate_bond(tmp_path, monkeypatch, cmd, dup, nth):
    text = f"""
        name: bad
        elements:
          source: {{type: Se, effort: 1.0}}
          loop: {{type: "1"}}
          r: {{type: R, R: 1.0}}
        bonds:
          - [source, loop]
          - [loop, r]
          - {dup}
        """
    err = run_bad(tmp_path, monkeypatch, cmd, text, at=f"- {dup}", nth=nth, key="bonds[2]",
                  contains=("duplicate bond",))
    first = line_of(model_text(text), "- [loop, r]")
    assert f"line {first}" in err.hint, err.text


# ------------------------------------------------------------------ 6. duplicate names
def test_parameter_and_element_same_name(tmp_path, monkeypatch, cmd):
    text = """
        name: bad
        parameters:
          cap: 1.0e-6
        elements:
          source: {type: Se, effort: 1.0}
          loop: {type: "1"}
          r: {type: R, R: 1.0}
          cap: {type: C, C: 1.0e-6}
        bonds:
          - [source, loop]
          - [loop, r]
          - [loop, cap]
        """
    err = run_bad(tmp_path, monkeypatch, cmd, text, at="cap: {type: C", key="elements.cap",
                  contains=("duplicate name 'cap'",))
    assert f"line {line_of(model_text(text), 'cap: 1.0e-6')}" in err.hint, err.text


def test_duplicate_yaml_key_in_elements(tmp_path, monkeypatch, cmd):
    text = """
        name: bad
        elements:
          source: {type: Se, effort: 1.0}
          loop: {type: "1"}
          r: {type: R, R: 1.0}
          r: {type: R, R: 2.0}
        bonds:
          - [source, loop]
          - [loop, r]
        """
    err = run_bad(tmp_path, monkeypatch, cmd, text, at="r: {type: R", nth=2,
                  key="elements.r", contains=("duplicate",))
    assert f"line {line_of(model_text(text), 'r: {type: R')}" in err.hint, err.text


# --------------------------------------------------------- 7. bad expressions
EXPR_MODEL = """
    name: bad
    parameters:
      k: 2.0
    elements:
      source: {{type: Se, effort: 1.0}}
      loop: {{type: "1"}}
      r: {{type: R, R: 1.0}}
      spring: {{type: C, C: "{law}"}}
    bonds:
      - [source, loop]
      - [loop, r]
      - [loop, spring]
    """


def test_unknown_symbol_in_expression(tmp_path, monkeypatch, cmd):
    err = run_bad(tmp_path, monkeypatch, cmd, EXPR_MODEL.format(law="1/kk"), at="spring:",
                  key="elements.spring.C", contains=("'kk'",))
    assert "valid names" in err.hint and re.search(r"\bk\b", err.hint), err.text


def test_caret_is_not_power(tmp_path, monkeypatch, cmd):
    err = run_bad(tmp_path, monkeypatch, cmd, EXPR_MODEL.format(law="k^2"), at="spring:",
                  key="elements.spring.C", contains=("'^'",))
    assert "**" in err.hint, err.text


# ------------------------------------------------------- 8. non-numeric parameter
def test_non_numeric_parameter(tmp_path, monkeypatch, cmd):
    run_bad(tmp_path, monkeypatch, cmd, """
        name: bad
        parameters:
          k: abc
        elements:
          source: {type: Se, effort: 1.0}
          spring: {type: C, k: k}
        bonds:
          - [source, spring]
        """, at="k: abc", key="parameters.k", contains=("'abc'",))


# ---------------------------------------------------- 9. non-physical parameters
NEGATIVE_MASS = """
    name: bad
    parameters:
      m: -1
    elements:
      force: {type: Se, effort: 1.0}
      mass: {type: I, I: m}
    bonds:
      - [force, mass]
    """

ZERO_CAPACITANCE = """
    name: bad
    elements:
      source: {type: Se, effort: 1.0}
      loop: {type: "1"}
      r: {type: R, R: 1.0}
      cap: {type: C, C: 0}
    bonds:
      - [source, loop]
      - [loop, r]
      - [loop, cap]
    """

NEGATIVE_R = """
    name: bad
    elements:
      source: {type: Se, effort: 1.0}
      loop: {type: "1"}
      r: {type: R, R: -5}
      cap: {type: C, C: 1.0}
    bonds:
      - [source, loop]
      - [loop, r]
      - [loop, cap]
    """


@pytest.mark.parametrize("text, at, key, contains", [
    (NEGATIVE_MASS, "mass:", "elements.mass.I", ("must be > 0", "-1", "parameter 'm'")),
    (ZERO_CAPACITANCE, "cap:", "elements.cap.C", ("must be > 0", "got 0")),
    (NEGATIVE_R, "r:", "elements.r.R", ("must be >= 0", "-5")),
], ids=["negative-mass", "zero-capacitance", "negative-R"])
def test_non_physical_parameter(tmp_path, monkeypatch, cmd, text, at, key, contains):
    err = run_bad(tmp_path, monkeypatch, cmd, text, at=at, key=key, contains=contains)
    if "parameter 'm'" in contains:     # the message also points at where m is set
        assert f"line {line_of(model_text(text), 'm: -1')}" in err.msg, err.text


# ---------------------------------------------------- 10. causality conflicts
TWO_SE_ON_0 = """
    name: bad
    elements:
      e1: {type: Se, effort: 1.0}
      e2: {type: Se, effort: 2.0}
      node: {type: "0"}
      r: {type: R, R: 1.0}
    bonds:
      - [e1, node]
      - [e2, node]
      - [node, r]
    """

TWO_SF_ON_1 = """
    name: bad
    elements:
      f1: {type: Sf, flow: 1.0}
      f2: {type: Sf, flow: 2.0}
      loop: {type: "1"}
      r: {type: R, R: 1.0}
    bonds:
      - [f1, loop]
      - [f2, loop]
      - [loop, r]
    """


@pytest.mark.parametrize("text, junction, sources", [
    (TWO_SE_ON_0, "node", ("e1", "e2")),
    (TWO_SF_ON_1, "loop", ("f1", "f2")),
], ids=["two-Se-on-0", "two-Sf-on-1"])
def test_causality_conflict(tmp_path, monkeypatch, cmd, text, junction, sources):
    err = run_bad(tmp_path, monkeypatch, cmd, text, at=f"{junction}:",
                  key=f"elements.{junction}", contains=("causality conflict",))
    t = model_text(text)
    for i, src in enumerate(sources, 1):       # both bonds and both sources are named
        assert f"b{i}" in err.msg, err.text
        assert f"line {line_of(t, f'- [{src}, {junction}]')}" in err.msg, err.text
        assert f"'{src}'" in err.msg, err.text


# ---------------------------------------------------- 11. nonlinear algebraic loop
DIODE_LOOP = """
    name: diode_loop
    parameters:
      E: 10.0
      Is: 1.0e-12
      Vt: 0.025
      R2: 3000.0
      R3: 500.0
      C: 1.0e-6
    elements:
      source: {type: Se, effort: E}
      s1:     {type: "1"}
      d1:     {type: R, flow: "Is*(exp(e/Vt) - 1)"}
      node:   {type: "0"}
      r2:     {type: R, R: R2}
      s2:     {type: "1"}
      r3:     {type: R, R: R3}
      cap:    {type: C, C: C}
    bonds:
      - [source, s1]
      - [s1, d1]
      - [s1, node]
      - [node, r2]
      - [node, s2]
      - [s2, r3]
      - [s2, cap]
    """


def test_nonlinear_algebraic_loop(tmp_path, monkeypatch, cmd):
    # Located at the diode: the element that makes the loop nonlinear.
    err = run_bad(tmp_path, monkeypatch, cmd, DIODE_LOOP, at="d1:", key="elements.d1",
                  contains=("nonlinear algebraic loop",))
    assert all(n in err.msg for n in ("d1", "r2", "b2")), err.text


# ------------------------------------------------ 12. missing element attribute
def test_missing_attribute_in_output(tmp_path, monkeypatch, cmd):
    err = run_bad(tmp_path, monkeypatch, cmd, """
        name: bad
        elements:
          source: {type: Se, effort: 1.0}
          loop: {type: "1"}
          r: {type: R, R: 1.0}
          spring: {type: C, C: 1.0}
        bonds:
          - [source, loop]
          - [loop, r]
          - [loop, spring]
        outputs:
          x: spring.p
        """, at="x: spring.p", key="outputs.x", contains=("'.p'",))
    assert "spring.q" in err.hint, err.text


# ------------------------------------------------------ 13. missing section
def test_missing_bonds_section(tmp_path, monkeypatch, cmd):
    run_bad(tmp_path, monkeypatch, cmd, """
        name: bad
        elements:
          source: {type: Se, effort: 1.0}
          cap: {type: C, C: 1.0}
        """, at="name: bad", key="bonds", contains=("missing section 'bonds'",))


# ------------------------------------------------------ simulate: unknown solver
def test_simulate_unknown_solver(tmp_path, monkeypatch):
    path = tmp_path / "rc.yaml"
    path.write_text(model_text("""
        name: rc_ok
        elements:
          source: {type: Se, effort: 1.0}
          loop: {type: "1"}
          r: {type: R, R: 1.0}
          cap: {type: C, C: 1.0}
        bonds:
          - [source, loop]
          - [loop, r]
          - [loop, cap]
        """))
    monkeypatch.chdir(tmp_path)
    result = CliRunner().invoke(main, ["simulate", str(path), "--solver", "nope",
                                       "-o", str(tmp_path / "gen")])
    detail = f"\nstdout: {result.stdout!r}\nstderr: {result.stderr!r}"
    assert "Traceback" not in result.output + result.stderr, detail
    assert result.exit_code == 2, detail
    lines = error_lines(result.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: "), detail
    assert "nope" in lines[0] and "hint: " in lines[0], detail
    assert all(s in lines[0] for s in SOLVERS), detail


# ------------------------------------------------------ the real executable
def test_executable_exits_2_without_traceback(tmp_path):
    exe = shutil.which("bgc")
    assert exe is not None, "the console script `bgc` is installed by `pip install -e .`"
    path = tmp_path / "model.yaml"
    path.write_text(model_text(TWO_SE_ON_0))
    out_dir = tmp_path / "out"
    proc = subprocess.run([exe, "compile", str(path), "-o", str(out_dir)],
                          capture_output=True, text=True, cwd=tmp_path, timeout=300)
    detail = f"\nstdout: {proc.stdout!r}\nstderr: {proc.stderr!r}"
    assert proc.returncode == 2, detail
    assert "Traceback" not in proc.stderr + proc.stdout, detail
    lines = error_lines(proc.stderr)
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}:"), detail
    assert not out_dir.exists() or not list(out_dir.iterdir()), detail


def test_every_causality_conflict_is_reported(tmp_path):
    """Two independent conflicts in one model: both are named, in text and in --json."""
    import json
    model = tmp_path / "two.yaml"
    model.write_text(
        "elements:\n"
        "  e1: {type: Se, effort: 1.0}\n"
        "  e2: {type: Se, effort: 2.0}\n"
        "  n: {type: '0'}\n"
        "  r: {type: R, R: 1.0}\n"
        "  f1: {type: Sf, flow: 1.0}\n"
        "  f2: {type: Sf, flow: 2.0}\n"
        "  j: {type: '1'}\n"
        "  c: {type: C, C: 1.0}\n"
        "bonds: [[e1, n], [e2, n], [n, r], [f1, j], [f2, j], [j, c]]\n")
    result = CliRunner().invoke(main, ["check", str(model), "--json"])
    assert result.exit_code == 2
    report = json.loads(result.stdout)
    assert [c["key"] for c in report["conflicts"]] == ["elements.n", "elements.j"]
    assert [c["line"] for c in report["conflicts"]] == [4, 8]
    line = result.stderr.strip()
    assert "'e1'" in line and "'e2'" in line and "'f1'" in line and "'f2'" in line
