"""The stages chained: model file -> equation system -> generated module."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

from . import causality, emit, equations, expand, load, zcp
from .causality import CausalGraph
from .equations import EquationSystem
from .fileio import check_writable
from .model import Model

# what the constraint element L of a blocked joint direction becomes (paper 11.2.5)
METHODS = ("parasitic", "lagrange", "zcp")


@dataclass
class Compiled:
    model: Model
    causal: CausalGraph
    system: EquationSystem
    timings: dict[str, float] = field(default_factory=dict)


def build(model: str | Path | Model, method: str = "parasitic", open_loops: bool = True,
          **derive_options) -> Compiled:
    """Run load (unless given a Model) -> expand -> (zcp) -> causality -> equations, timing
    each stage. ``open_loops``: method zcp opens kinematic loops with break variables
    (else refuses them). ``derive_options`` go to ``equations.derive`` (e.g.
    ``max_symbolic_loop``)."""
    timings = {}
    t0 = time.perf_counter()
    if not isinstance(model, Model):
        model = load.load(model)
    timings["load"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    graph = expand.expand(model, method)
    if method == "zcp":
        graph = zcp.assign(graph, open_loops)
    cg = causality.assign(graph)
    timings["causality"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    system = equations.derive(cg, **derive_options)
    timings["equations"] = time.perf_counter() - t0
    return Compiled(model, cg, system, timings)


def compile_model(model: str | Path | Model, out_dir: str | Path = "generated",
                  method: str = "parasitic", **derive_options) -> tuple[Compiled, Path]:
    """Build and write ``out_dir/<name>.py``; nothing is written if any stage fails."""
    check_writable(out_dir, "output directory", directory=True)   # before the work
    c = build(model, method, **derive_options)
    t0 = time.perf_counter()
    path = emit.write(c.system, out_dir)
    c.timings["emit"] = time.perf_counter() - t0
    return c, path


def ensure_module(model_path: str | Path, out_dir: str | Path = "generated",
                  method: str = "parasitic", open_loops: bool = True):
    """The generated module for a model, recompiled only if missing or stale (method zcp
    with ``open_loops=False``: its own module, ``<name>_zcp_closed.py``)."""
    model = load.load(model_path)
    kind = equations.variant(method, open_loops)
    path = emit.module_path(model.name, out_dir, kind)
    compiled = None
    if emit.is_stale(path, model.digest, kind):
        compiled, path = compile_model(model, out_dir, method, open_loops=open_loops)
    return emit.import_module(path), model, compiled
