"""The stages chained: model file -> equation system -> generated module.

The stages that need sympy (load past the YAML, causality, equations, emit) are imported
when they run: a run whose generated module is fresh reads the model file's YAML, finds
the module by the digest and imports it, and pays for none of them (``ensure_module``).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

from bgc import methods, progress
from bgc.codegen.module_file import (
    import_module,
    is_stale,
    module_name_syntax_problem,
    module_path,
)
from bgc.fileio import check_writable
from bgc.model import document, library
from bgc.model.model import Model, Settings

if TYPE_CHECKING:
    from bgc.codegen.equations import EquationSystem
    from bgc.graph.causality import CausalGraph



@dataclass(frozen=True)
class Declared:
    """What a model declares, against which a command checks its options before any
    work (``ensure_module``'s ``check``): its run-time parameters, outputs, settings and,
    where the Model is loaded, everything else it says (its excitation). From the Model
    right after load, before causality (``of_model``), or from a fresh module's metadata
    (``of_module``: the warm path, no sympy)."""
    name: str
    file: str
    params: tuple[str, ...]
    outputs: tuple[str, ...]
    settings: Settings
    model: Model | None = None
    module: object = None       # the fresh generated module (warm path), else None

    @classmethod
    def of_model(cls, model: Model, method: str) -> Declared:
        """From the Model: its parameters and those the method adds (the module's
        ``PARAM_NAMES`` once built; checked again there, before anything is written)."""
        added = [n for n, _ in methods.get(method).parameters(model, [])]
        return cls(model.name, model.file, tuple(model.parameters) + tuple(added),
                   tuple(o.name for o in model.outputs), model.settings, model)

    @classmethod
    def of_system(cls, system: EquationSystem) -> Declared:
        """From the equations: the module's parameters exactly, before it is written."""
        m = system.model
        return cls(m.name, m.file, tuple(n for _, n, _ in system.params),
                   tuple(n for n, _ in system.outputs), m.settings, m)

    @classmethod
    def of_module(cls, module, file: str) -> Declared:
        return cls(module.MODEL_NAME, str(file), tuple(module.PARAM_NAMES),
                   tuple(module.OUTPUT_NAMES), Settings(**module.SETTINGS), module=module)


@dataclass
class Compiled:
    model: Model
    causal: CausalGraph
    system: EquationSystem
    timings: dict[str, float] = field(default_factory=dict)


def build(model: str | Path | Model, method: str = "parasitic", open_loops: bool = True,
          constants: dict | None = None, **derive_options) -> Compiled:
    """Run load (unless given a Model) -> expand -> (zcp) -> causality -> equations, each a
    progress stage (timed in ``Compiled.timings``). ``open_loops``: method zcp opens
    kinematic loops with break variables (else refuses them). ``constants``: the model's
    compile-time constants given (``-p N=40``). ``derive_options`` go to
    ``equations.derive`` (e.g. ``max_symbolic_loop``)."""
    from bgc.codegen import equations
    from bgc.graph import causality, expand
    with progress.record() as timings, equations.gc_paused():
        if not isinstance(model, Model):
            model = _load(model, constants)
        with progress.stage("causality") as st:
            graph = methods.get(method).restructure(expand.expand(model, method), open_loops)
            cg = causality.assign(graph)
            st.done(f"{progress.count(len(graph.elements), 'element')}, "
                    f"{progress.count(len(graph.bonds), 'bond')} ({method})")
        with progress.stage("equations") as st:
            system = equations.derive(cg, **derive_options)
            st.done(f"{progress.count(len(system.assignments), 'assignment')}, "
                    f"{progress.count(len(system.states), 'state')}")
    return Compiled(model, cg, system, timings)


def _load(path: str | Path, constants: dict | None = None) -> Model:
    """The load stage: the model file read and checked (``constants``: compile-time
    constants given for the file's, ``-p N=40``)."""
    with progress.stage("load") as st:
        model = _model(document.read(path), str(path), st, constants)
    return model


def _model(doc, file: str, st: progress.Stage, constants: dict | None = None) -> Model:
    """The Model of a model file's document, counted in the load stage ``st``."""
    from bgc.model import load
    model = load.from_document(doc, file, constants=constants)
    parts = [("element", model.elements), ("bond", model.bonds), ("body", model.bodies),
             ("joint", model.joints)]
    if model.instances:
        parts.append(("instance", model.instances))
    st.done(f"{model.name}: " + ", ".join(
        progress.count(len(v), k, "bodies" if k == "body" else None) for k, v in parts if v))
    return model


def _fresh(doc, file: str, out_dir: str | Path, kind: str,
           constants: dict | None = None) -> Path | None:
    """The path of the generated module of a model file's YAML document if that module
    is fresh, else None. Fresh: its MODEL_HASH is this document's digest (with the
    component files it uses and the ``constants`` given: ``library.digest``) under this
    method and this compiler (``module_file.is_stale``), so it was written from this very
    document after it loaded without error; the document is not loaded again. None also
    when the digest does not capture the whole document (``document.plain_json``) or the
    model's name is refused: the full load then decides, and reports any error."""
    if not isinstance(doc, dict) or not document.plain_json(doc):
        return None
    name = doc.get("name", Path(file).stem)       # as load names it
    if module_name_syntax_problem(name) is not None:    # (the rest was checked when written)
        return None
    digest = library.digest(doc, file, constants)
    if digest is None:
        return None
    path = module_path(name, out_dir, kind)
    return None if is_stale(path, digest, kind) else path


def compile_model(model: str | Path | Model, out_dir: str | Path = "generated",
                  method: str = "parasitic", check=None, constants: dict | None = None,
                  **derive_options) -> tuple[Compiled, Path]:
    """Build and write ``out_dir/<name>.py``, then compile its machine code, so that a
    later ``import`` or ``bgc simulate`` compiles nothing; nothing is written if a stage
    before the module's fails, if ``check`` refuses what the equations declare (a
    command's options against the module's exact parameters) or if the model's own values
    make its start non-finite (``codegen.start.check``)."""
    from bgc.codegen import emit
    from bgc.codegen.equations import gc_paused
    check_writable(out_dir, "output directory", directory=True)   # before the work
    with progress.record() as timings, gc_paused():     # (emit: half its CPU at N = 160)
        c = build(model, method, constants=constants, **derive_options)
        if check is not None:
            check(Declared.of_system(c.system))
        with progress.stage("emit") as st:
            path = emit.write(c.system, out_dir)
            st.done(f"{path.name}, {path.stat().st_size / 1e3:.0f} kB")
        machine_code(path)
    c.timings = timings
    return c, path


def machine_code(path: Path):
    """The machine-code stage: import the generated module, which compiles its LLVM
    kernels for this machine (``bgc.codegen.kernels``; or loads them, compiled before), and
    compile its numba wrappers (or load them from numba's cache)."""
    with progress.stage("machine code") as st:
        module = import_module(path)
        module.compile_all()
        size = len(module._KERNEL_IR) + len(module._KERNEL_IR_STRAIGHT)
        st.done(f"{progress.count(module.KERNEL_FUNCTIONS, 'kernel')}, " + (
            f"{size / 1e6:.1f} MB" if size >= 1e6 else f"{size / 1e3:.0f} kB") + " of LLVM IR")
    return module


def ensure_module(model_path: str | Path, out_dir: str | Path = "generated",
                  method: str = "parasitic", open_loops: bool = True, on_load=None,
                  need_model: bool = True, check=None, constants: dict | None = None,
                  energy: bool = False):
    """The generated module for a model, recompiled only if missing or stale (method zcp
    with ``open_loops=False``: its own module, ``<name>_zcp_closed.py``); returns the
    module, the Model and the Compiled (None if nothing was compiled). ``check`` is
    called with what the model declares (``Declared``) right after it is read, before
    any causality, equations or compile: a command refuses its bad options there.
    ``on_load`` is called with the model's Settings once they passed (e.g. to start
    other work beside the build). ``need_model=False``: a fresh module is found from the
    YAML alone (``_fresh``) and the Model comes back as None; the module's SETTINGS and
    MODEL_NAME are the model's. ``constants``: the model's compile-time constants given
    (``-p N=40``), part of its digest: another value is another module. ``energy``: the
    energy variant (``codegen.energy``, ``<name>_<method>_energy.py``), every element's
    work and activity integrated."""
    kind = methods.variant(method, open_loops) + ("_energy" if energy else "")
    with progress.record() as timings:
        with progress.stage("load") as st:
            doc = document.read(model_path)
            fresh = None if need_model else _fresh(doc, str(model_path), out_dir, kind,
                                                   constants)
            if fresh is not None:
                st.done(f"{fresh.stem}: its generated module is up to date")
            else:
                model = _model(doc, str(model_path), st, constants)
        if fresh is not None:
            module = import_module(fresh)
            if check is not None:
                check(Declared.of_module(module, model_path))
            if on_load is not None:
                on_load(Settings(**module.SETTINGS))
            return module, None, None
        if check is not None:
            check(Declared.of_model(model, method))
        if on_load is not None:
            on_load(model.settings)
        path = module_path(model.name, out_dir, kind)
        compiled = None
        if is_stale(path, model.digest, kind):
            compiled, path = compile_model(model, out_dir, method, check=check,
                                           open_loops=open_loops,
                                           **({"energy": True} if energy else {}))
        module = import_module(path)
    if compiled is not None:
        compiled.timings = timings        # its load too
    return module, model, compiled
