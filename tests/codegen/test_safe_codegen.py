"""Generated source is code users run (issue 23, item 2).

Nothing from a model file, its name or path, its description, units or names reaches the
generated module except as a validated identifier or an escaped literal. A model *file
name* holding ``\"\"\"``, a line break and code used to be copied into the module's
docstring, and importing the module ran the code. A module name must be an identifier
that shadows neither ``__init__`` nor the standard library nor an installed package.
"""

from __future__ import annotations

import ast
import json
import os
import subprocess
import sys

import pytest
from click.testing import CliRunner
from helpers import ROOT, bgc, error_lines

from bgc.cli import main
from bgc.codegen import emit
from bgc.codegen.emit import module_name_problem, py_str
from bgc.errors import BgcError
from bgc.model import load
from bgc.pipeline import build, compile_model



def payload(tag: str, sep: str = "\n") -> str:
    """Text that, pasted raw into a docstring, closes it and creates the directory
    ``pwned_<tag>`` (in the importing process's working directory)."""
    return f'x"""{sep}__import__("os").mkdir("pwned_{tag}"){sep}"""'


def rc_model(name: str = "hostile", description: str = "an RC circuit", unit: str = "ohm",
             note: str = "a resistor") -> str:
    """A small RC model; the strings are written as YAML (JSON) escaped scalars."""
    q = json.dumps
    return f"""name: {name}
description: {q(description)}
parameters:
  R: {{value: 10.0, unit: {q(unit)}, description: {q(note)}}}
  C: {{value: 1.0e-3, unit: F}}
elements:
  source: {{type: Se, effort: 1.0, description: {q(note)}}}
  loop: {{type: "1"}}
  resistor: {{type: R, R: R, description: {q(note)}}}
  capacitor: {{type: C, C: C}}
bonds:
  - [source, loop]
  - [loop, resistor]
  - [loop, capacitor]
outputs:
  v_C: capacitor.e
"""


HOSTILE_FILES = {
    "newline": payload("newline") + ".yaml",
    "cr": payload("cr", "\r") + ".yaml",
    "formfeed": payload("ff", "\x0c\n") + ".yaml",
    "quote": "it's \"q\".yaml",
    "triple": 'tri"""ple""".yaml',
    "backslash": "back\\slash\\.yaml",
    "trailing_backslash": "ends\\",
    "unicode": "uni é \u2028 \u2029 \U0001f600 \u202e.yaml",
    "non_utf8": os.fsdecode(b"bad\xff\xfe.yaml"),
}


def calls_in(source: str) -> set:
    """Names of every function called at the top level of a module (outside defs)."""
    tree = ast.parse(source)
    names = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.ClassDef)):
            continue
        for sub in ast.walk(node):
            if isinstance(sub, ast.Call):
                f = sub.func
                names.add(f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "?"))
    return names


@pytest.fixture(scope="module")
def hostile_build(tmp_path_factory):
    """Each hostile file name built into its own output directory: its module written
    (the emit stage, where names become source); the one ``bgc simulate`` runs
    (``newline``) compiled to machine code as well (``bgc compile``), the others' machine
    code, the same RC circuit's, is left to the import that needs it."""
    root = tmp_path_factory.mktemp("hostile")
    built = {}
    for key, fname in HOSTILE_FILES.items():
        src = root / f"src_{key}"
        src.mkdir()
        path = src / fname
        path.write_text(rc_model(
            description=payload(f"desc_{key}"), unit=payload(f"unit_{key}"),
            note=payload(f"note_{key}")), encoding="utf-8")
        if key == "newline":
            _, module = compile_model(path, root / f"gen_{key}")
        else:
            module = emit.write(build(path).system, root / f"gen_{key}")
        built[key] = (fname, module)
    return root, built


def test_hostile_strings_reach_source_only_escaped(hostile_build):
    _, built = hostile_build
    for key, (fname, module) in built.items():
        source = module.read_text(encoding="utf-8")
        assert source.isascii(), key
        assert "mkdir" not in calls_in(source), key
        assert "pwned" not in ast.get_docstring(ast.parse(source)), key
        # the file name is kept, exactly, as a literal
        tree = ast.parse(source)
        consts = {t.targets[0].id: t.value.value for t in tree.body
                  if isinstance(t, ast.Assign) and isinstance(t.targets[0], ast.Name)
                  and isinstance(t.value, ast.Constant)}
        assert consts["MODEL_FILE"] == fname, key
        assert consts["MODEL_NAME"] == "hostile"


def test_importing_hostile_modules_runs_nothing(hostile_build):
    """Import every module in a fresh interpreter (as bgc simulate does) and call its
    Python-level functions: no sentinel directory appears."""
    root, built = hostile_build
    cwd = root / "cwd"
    cwd.mkdir()
    paths = [str(m) for _, m in built.values()]
    code = f"""
import importlib.util, sys
for i, path in enumerate({paths!r}):
    spec = importlib.util.spec_from_file_location(f"gen{{i}}.m", path)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    mod.initial_state(mod.PARAMS); mod.max_step(mod.PARAMS)
    assert mod.MODEL_NAME == "hostile" and mod.__doc__.count("pwned") == 0
print("imported", len({paths!r}))
"""
    proc = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True,
                          text=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(ROOT)))
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert f"imported {len(paths)}" in proc.stdout
    assert list(cwd.iterdir()) == [], "the injected code ran"


def test_hostile_module_runs_under_bgc_simulate(hostile_build, tmp_path):
    """bgc simulate on the worst file name: it runs, and nothing else does."""
    root, built = hostile_build
    fname, module = built["newline"]
    model = next((root / "src_newline").iterdir())
    proc = bgc("simulate", str(model), "-o", str(module.parent), "--t-end", "0.01",
               cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("text", [
    "", "plain", '"', '"""', "'''", "\\", 'a"""b', "end\\", "\n", "\r\n", "\x00", "\x7f",
    "\u2028", "\u00e9", "\U0001f600", "\udcff", "\ufeff", '"\n__import__("os")\n"',
])
def test_py_str_is_an_exact_ascii_literal_safe_in_a_docstring(text):
    lit = py_str(text)
    assert lit.isascii() and lit.isprintable() and "\n" not in lit
    assert eval(lit) == text
    tree = ast.parse(f'"""doc {lit} doc"""\nx = {lit}\n')
    assert len(tree.body) == 2 and isinstance(tree.body[0].value, ast.Constant)


# -------------------------------------------------------------- module names
def run_cli(tmp_path, args):
    result = CliRunner().invoke(main, [str(a) for a in args])
    detail = f"\nstdout: {result.stdout!r}\nstderr: {result.stderr!r}"
    assert result.exit_code == 2, detail
    assert "Traceback" not in result.output + result.stderr, detail
    lines = error_lines(result.stderr)
    assert len(lines) == 1 and lines[0].startswith("error: "), detail
    return lines[0]


@pytest.fixture
def out_dir(tmp_path):
    gen = tmp_path / "gen"
    gen.mkdir()
    (gen / "__init__.py").write_text("# the user's package\nVALUE = 1\n")
    return gen


@pytest.mark.parametrize("name,suggestion", [
    ("__init__", "init"), ("__main__", "main"), ("numpy", "numpy_model"),
    ("sys", "sys_model"), ("os", "os_model"), ("class", "class_model"),
    ("scipy", "scipy_model"), ("bgc", "bgc_model"), ("'a-b'", "a_b"), ('"rlc\\n"', "rlc"),
])
def test_bad_module_name_key_is_refused(tmp_path, out_dir, name, suggestion):
    path = tmp_path / "model.yaml"
    path.write_text(rc_model(name=name))
    err = run_cli(tmp_path, ["compile", path, "-o", out_dir])
    assert err.startswith(f"error: {path}:1:7: name: model name "), err
    assert f"(hint: write name: {suggestion} " in err, err
    assert sorted(p.name for p in out_dir.iterdir()) == ["__init__.py"]
    assert (out_dir / "__init__.py").read_text() == "# the user's package\nVALUE = 1\n"


@pytest.mark.parametrize("stem", ["numpy", "__init__", "json", "class"])
def test_bad_file_stem_without_name_key_is_refused(tmp_path, out_dir, stem):
    path = tmp_path / f"{stem}.yaml"
    path.write_text("\n".join(rc_model().splitlines()[1:]) + "\n")    # no name: key
    err = run_cli(tmp_path, ["compile", path, "-o", out_dir])
    assert err.startswith(f"error: {path}:1:1: name: model name '{stem}' "), err
    assert "(hint: write name: " in err
    assert sorted(p.name for p in out_dir.iterdir()) == ["__init__.py"]


@pytest.mark.parametrize("key,text", [
    ("parameters", '  "R\\"\\"\\"\\nimport os": {value: 1.0}'),
    ("parameters", '  "R\\n": {value: 1.0}'),
    ("outputs", '  "v\\u2028x": capacitor.e'),
])
def test_hostile_names_are_refused(tmp_path, out_dir, key, text):
    lines = rc_model().splitlines()
    at = lines.index(f"{key}:") + 1
    path = tmp_path / "model.yaml"
    path.write_text("\n".join(lines[:at] + [text] + lines[at:]) + "\n")
    err = run_cli(tmp_path, ["compile", path, "-o", out_dir])
    assert "is not a valid name" in err, err
    assert sorted(p.name for p in out_dir.iterdir()) == ["__init__.py"]


def test_emit_refuses_a_shadowing_name_given_programmatically(tmp_path):
    """A Model built in Python (not from a file) is checked where the module is written."""
    from dataclasses import replace
    path = tmp_path / "ok.yaml"
    path.write_text(rc_model(name="ok"))
    model = replace(load.load(path), name="numpy")
    with pytest.raises(BgcError, match="would shadow the installed package 'numpy'"):
        compile_model(model, tmp_path / "gen")
    assert not (tmp_path / "gen" / "numpy.py").exists()


def test_valid_names_pass():
    for name in ("rlc", "pendulum", "sarib_one_leg", "x", "_private", "match", "Model2"):
        assert module_name_problem(name) is None, name
    assert emit.suggest_module_name("2 fast") == "m_2_fast"
