"""Shared fixtures: shipped models compiled once per session into a temporary directory
(tests never write into the repository's generated/)."""

from __future__ import annotations

import fcntl
import os
import sys
from pathlib import Path

# One BLAS thread per process: `make test` runs a pytest-xdist worker per core, and
# OpenBLAS's own threads on top of them oversubscribe the cores (a 152-state complex solve,
# the SARIB's frequency response: 1.2 ms on one thread, 40 ms on two beside a busy
# worker). Set before numpy is imported; subprocesses inherit it.
if "numpy" not in sys.modules:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest

from bgc.codegen import emit
from bgc.codegen.emit import import_module
from bgc.model import load
from bgc.pipeline import compile_model

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
# models whose numba compilation and runs take minutes: their tests are marked slow (the
# one-leg SARIB is checked against the rig in test_sarib and in bench's symmetry part at
# CI scale)
SLOW_MODELS = {"sarib", "sarib_one_leg"}


def model_params(names=None):
    """pytest parameters for the shipped models (all by default), slow ones marked."""
    names = names or sorted(p.stem for p in MODELS.glob("*.yaml"))
    return [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_MODELS else n for n in names]


@pytest.fixture(scope="session")
def gen_dir(tmp_path_factory):
    """One directory for the whole run, shared by pytest-xdist workers (their base temp
    directories are siblings), so each model is compiled and JIT-compiled once."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    path = root / "bgcgen"
    path.mkdir(exist_ok=True)
    return path


@pytest.fixture(scope="session")
def compiled(gen_dir):
    """compiled(name, method) -> generated module of models/<name>.yaml (cached per
    session)."""
    cache = {}

    def get(name: str, method: str = "parasitic"):
        if (name, method) not in cache:
            # one worker compiles (source and machine code, cached on disk) while the
            # others wait, then load it
            with open(gen_dir / f"{name}_{method}.lock", "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                model = load.load(MODELS / f"{name}.yaml")
                path = emit.module_path(model.name, gen_dir, method)
                if emit.is_stale(path, model.digest, method):
                    compile_model(model, gen_dir, method)
                mod = import_module(path)
                for f in (mod.rhs, mod.jac, mod.outputs):
                    f(0.0, mod.X0, mod.PARAMS)
                fcntl.flock(lock, fcntl.LOCK_UN)
            cache[name, method] = mod
        return cache[name, method]
    return get


def rel_err(actual, expected) -> float:
    """Largest deviation relative to the largest magnitude of the expected trajectory."""
    import numpy as np
    actual, expected = np.asarray(actual), np.asarray(expected)
    return float(np.max(np.abs(actual - expected)) / np.max(np.abs(expected)))


def fd_jacobian(mod, t, x, p):
    """Central differences of a generated module's rhs, to check its analytic jac."""
    import numpy as np
    fd = np.empty((len(x), len(x)))
    for j in range(len(x)):
        h = 1e-6 * max(abs(x[j]), 1e-2)
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        fd[:, j] = (mod.rhs(t, xp, p) - mod.rhs(t, xm, p)) / (2 * h)
    return fd


def error_lines(stderr: str) -> list[str]:
    """stderr's lines without bgc's progress lines (``bgc: STAGE: ... (TIME)``, one per
    finished stage when stderr is not a terminal): what a failing run says."""
    from bgc.progress import PREFIX
    return [ln for ln in stderr.splitlines() if not ln.startswith(PREFIX)]
