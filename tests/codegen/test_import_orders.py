"""A generated module works however it is imported (issue 23, item 5).

numba's on-disk cache (``cache=True``, in ``__pycache__`` beside the module) records the
module's ``__name__`` and imports that name again when it loads a compiled function. A
module imported by bare name (``import rlc``) before bgc imported it as ``gen.rlc`` left
a cache every later ``bgc simulate`` failed to load (``ModuleNotFoundError: No module named
'rlc'``), and the reverse. Each step here is a fresh interpreter sharing one output
directory, with numba's cache beside the module (no NUMBA_CACHE_DIR), as a user has it.
"""

from __future__ import annotations

import pytest

import os
import subprocess
import sys
from pathlib import Path

from helpers import ROOT

RLC = ROOT / "models" / "rlc.yaml"

CALL = """
import numpy as np
x, p = {m}.X0, {m}.PARAMS
dx, J, y = {m}.rhs(0.0, x, p), {m}.jac(0.0, x, p), {m}.outputs(0.0, x, p)
assert dx.shape == (2,) and J.shape == (2, 2) and y.shape == (3,)
assert np.all(np.isfinite(dx)) and np.all(np.isfinite(J)) and np.all(np.isfinite(y))
assert {m}.rhs.signatures and {m}.MODEL_NAME == "rlc"
{extra}
print("ok")
"""


def env():
    e = dict(os.environ, PYTHONPATH=str(ROOT))
    e.pop("NUMBA_CACHE_DIR", None)
    return e


def python(code: str, cwd: Path):
    proc = subprocess.run([sys.executable, "-c", code], cwd=cwd, capture_output=True,
                          text=True, timeout=300, env=env())
    assert proc.returncode == 0 and proc.stdout.strip().endswith("ok"), (
        f"\nstdout: {proc.stdout}\nstderr: {proc.stderr[-3000:]}")


def bare_import(tmp: Path, extra: str = ""):
    """``sys.path.insert(0, 'gen'); import rlc`` from a directory where ``gen`` itself is
    not importable as a package."""
    elsewhere = tmp / "elsewhere"
    elsewhere.mkdir(exist_ok=True)
    python(f"import sys; sys.path.insert(0, {str(tmp / 'gen')!r}); import rlc\n"
           + CALL.format(m="rlc", extra=extra), elsewhere)


def package_import(tmp: Path, extra: str = ""):
    python(f"import sys; sys.path.insert(0, {str(tmp)!r}); from gen import rlc\n"
           + CALL.format(m="rlc", extra=extra), tmp)


def simulate(tmp: Path, *extra):
    proc = subprocess.run([sys.executable, "-m", "bgc.cli", "simulate", str(RLC), "-o", "gen",
                           "--t-end", "0.005", "--out", "x.csv", *extra], cwd=tmp,
                          capture_output=True, text=True, timeout=300, env=env())
    assert proc.returncode == 0, f"\nstdout: {proc.stdout}\nstderr: {proc.stderr[-3000:]}"
    assert (tmp / "x.csv").is_file()


def compile_(tmp: Path):
    proc = subprocess.run([sys.executable, "-m", "bgc.cli", "compile", str(RLC), "-o", "gen"],
                          cwd=tmp, capture_output=True, text=True, timeout=300, env=env())
    assert proc.returncode == 0, proc.stderr


def cached(tmp: Path) -> set:
    return {p.name.split("-")[0] for p in (tmp / "gen" / "__pycache__").glob("*.nbi")}


@pytest.mark.slow       # three cold processes; the module imported standalone stays in make test (test_codegen)
def test_bare_import_first_then_simulate_and_package_import(tmp_path):
    compile_(tmp_path)
    bare_import(tmp_path)
    assert {"rlc.rhs", "rlc.jac", "rlc.outputs"} <= cached(tmp_path)   # cached beside it
    simulate(tmp_path)
    package_import(tmp_path)
    bare_import(tmp_path)


@pytest.mark.slow       # 6 s: the bare-first order stays in make test
def test_simulate_first_then_bare_and_package_import(tmp_path):
    simulate(tmp_path)
    bare_import(tmp_path, extra="assert len(rlc.native_entry_points()) == 3")
    package_import(tmp_path, extra="assert len(rlc.native_entry_points()) == 3")
    simulate(tmp_path)


@pytest.mark.slow       # 5 s: the other two orders stay in make test
def test_both_names_in_one_process(tmp_path):
    """Imported under both names in one interpreter (then by bgc's own import), each
    module object runs, from the one cache."""
    compile_(tmp_path)
    python(f"""
import sys
sys.path[:0] = [{str(tmp_path / 'gen')!r}, {str(tmp_path)!r}]
import rlc
from gen import rlc as rlc2
from bgc.codegen.emit import import_module
rlc3 = import_module({str(tmp_path / 'gen' / 'rlc.py')!r})
for m in (rlc, rlc2, rlc3):
    assert m.rhs(0.0, m.X0, m.PARAMS).shape == (2,)
print("ok")
""", tmp_path)
    python(f"""
import sys
sys.path.insert(0, {str(tmp_path / 'gen')!r})
import rlc
assert rlc.jac(0.0, rlc.X0, rlc.PARAMS).shape == (2, 2)
print("ok")
""", tmp_path / "gen")
