"""The stages chained: model file -> equation system -> generated module."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

from . import causality, emit, equations, expand, load, progress, zcp
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
    """Run load (unless given a Model) -> expand -> (zcp) -> causality -> equations, each a
    progress stage (timed in ``Compiled.timings``). ``open_loops``: method zcp opens
    kinematic loops with break variables (else refuses them). ``derive_options`` go to
    ``equations.derive`` (e.g. ``max_symbolic_loop``)."""
    with progress.record() as timings:
        if not isinstance(model, Model):
            model = _load(model)
        with progress.stage("causality") as st:
            graph = expand.expand(model, method)
            if method == "zcp":
                graph = zcp.assign(graph, open_loops)
            cg = causality.assign(graph)
            st.done(f"{progress.count(len(graph.elements), 'element')}, "
                    f"{progress.count(len(graph.bonds), 'bond')} ({method})")
        with progress.stage("equations") as st:
            system = equations.derive(cg, **derive_options)
            st.done(f"{progress.count(len(system.assignments), 'assignment')}, "
                    f"{progress.count(len(system.states), 'state')}")
    return Compiled(model, cg, system, timings)


def _load(path: str | Path) -> Model:
    """The load stage: the model file read and checked."""
    with progress.stage("load") as st:
        model = load.load(path)
        parts = [("element", model.elements), ("bond", model.bonds), ("body", model.bodies),
                 ("joint", model.joints)]
        st.done(f"{model.name}: " + ", ".join(
            progress.count(len(v), k, "bodies" if k == "body" else None) for k, v in parts
            if v))
    return model


def compile_model(model: str | Path | Model, out_dir: str | Path = "generated",
                  method: str = "parasitic", **derive_options) -> tuple[Compiled, Path]:
    """Build and write ``out_dir/<name>.py``, then compile its machine code, so that a
    later ``import`` or ``bgc simulate`` compiles nothing; nothing is written if a stage
    before the module's fails."""
    check_writable(out_dir, "output directory", directory=True)   # before the work
    with progress.record() as timings:
        c = build(model, method, **derive_options)
        with progress.stage("emit") as st:
            path = emit.write(c.system, out_dir)
            st.done(f"{path.name}, {path.stat().st_size / 1e3:.0f} kB")
        machine_code(path)
    c.timings = timings
    return c, path


def machine_code(path: Path):
    """The machine-code stage: import the generated module, which compiles its LLVM
    kernels for this machine (``bgc.kernels``; or loads them, compiled before), and
    compile its numba wrappers (or load them from numba's cache)."""
    with progress.stage("machine code") as st:
        module = emit.import_module(path)
        module.compile_all()
        size = len(module._KERNEL_IR) + len(module._KERNEL_IR_STRAIGHT)
        st.done(f"{progress.count(module.KERNEL_FUNCTIONS, 'kernel')}, " + (
            f"{size / 1e6:.1f} MB" if size >= 1e6 else f"{size / 1e3:.0f} kB") + " of LLVM IR")
    return module


def ensure_module(model_path: str | Path, out_dir: str | Path = "generated",
                  method: str = "parasitic", open_loops: bool = True, on_load=None):
    """The generated module for a model, recompiled only if missing or stale (method zcp
    with ``open_loops=False``: its own module, ``<name>_zcp_closed.py``). ``on_load`` is
    called with the Model as soon as it is read (e.g. to start other work beside the
    build)."""
    with progress.record() as timings:
        model = _load(model_path)
        if on_load is not None:
            on_load(model)
        kind = equations.variant(method, open_loops)
        path = emit.module_path(model.name, out_dir, kind)
        compiled = None
        if emit.is_stale(path, model.digest, kind):
            compiled, path = compile_model(model, out_dir, method, open_loops=open_loops)
        module = emit.import_module(path)
    if compiled is not None:
        compiled.timings = timings        # its load too
    return module, model, compiled
