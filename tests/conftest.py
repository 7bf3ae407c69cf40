"""Shared fixtures: shipped models compiled once per session into a temporary directory
(tests never write into the repository's generated/)."""

from __future__ import annotations

from pathlib import Path

import pytest

from bgc.pipeline import compile_model
from bgc.emit import import_module

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
# models whose numba compilation and runs take minutes: their tests are marked slow
SLOW_MODELS = {"sarib"}


def model_params(names=None):
    """pytest parameters for the shipped models (all by default), slow ones marked."""
    names = names or sorted(p.stem for p in MODELS.glob("*.yaml"))
    return [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_MODELS else n for n in names]


@pytest.fixture(scope="session")
def gen_dir(tmp_path_factory):
    return tmp_path_factory.mktemp("bgcgen")


@pytest.fixture(scope="session")
def compiled(gen_dir):
    """compiled(name) -> generated module of models/<name>.yaml (cached per session)."""
    cache = {}

    def get(name: str):
        if name not in cache:
            _, path = compile_model(MODELS / f"{name}.yaml", gen_dir)
            cache[name] = import_module(path)
        return cache[name]
    return get


def rel_err(actual, expected) -> float:
    """Largest deviation relative to the largest magnitude of the expected trajectory."""
    import numpy as np
    actual, expected = np.asarray(actual), np.asarray(expected)
    return float(np.max(np.abs(actual - expected)) / np.max(np.abs(expected)))
