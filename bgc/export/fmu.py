"""``bgc export MODEL --fmu OUT.fmu``: a model as a Functional Mock-up Unit (FMI 2.0,
Model Exchange and Co-Simulation) with a native shared library for linux64, so that a
tool without Python runs it.

The stages, one structure in and one out each:

- **build**: model file -> ``EquationSystem`` (``pipeline.build``, the method's passes),
  with the parameter values the command chose (``-p``, ``--parasitic auto``).
- **describe**: ``EquationSystem`` -> ``Unit``: the kernels' IR (the generated module's
  programs, ``emit.programs``, plus the event indicators), the variables with their
  value references, units and causality, the C of the initial state and largest step,
  the sparse plan of Radau's Newton matrices.
- **sources**: ``Unit`` -> modelDescription.xml and the model's C file (Jinja templates).
- **binary**: the kernels' object code (``objects.kernels_object``), bgc's Radau as object
  code (``radau.object_code``, once per machine) and the C layer (``runtime/``) linked by
  the system's C compiler (``toolchain``) into ``binaries/linux64/<model>.so``.
- **package**: the zip, written atomically.
"""

from __future__ import annotations

import hashlib
import tempfile
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

import jinja2
import numpy as np
import sympy as sp
from sympy.printing.c import C99CodePrinter

from bgc import progress
from bgc.errors import BgcError
from bgc.fileio import atomic_write, check_writable

FMI_VERSIONS = (2,)
PLATFORM = "linux64"
GUARD_TOLERANCE = 1e-3            # bgc.solvers.base.GUARD_TOLERANCE
STEPS_PER_PERIOD = 8              # the generated module's max_step
_HERE = Path(__file__).resolve().parent
RUNTIME = ("fmi2.c", "start.c", "linalg.c", "numba_rt.c")

_ENV = jinja2.Environment(loader=jinja2.FileSystemLoader(str(_HERE / "templates")),
                          trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True,
                          undefined=jinja2.StrictUndefined, autoescape=False)


def _c_string(text: str) -> str:
    """``text`` as a C string literal of printable ASCII (everything else escaped)."""
    out = []
    for ch in str(text).encode("utf-8"):
        c = chr(ch)
        out.append("\\" + c if c in '"\\' else c if 0x20 <= ch < 0x7F else f"\\{ch:03o}")
    return '"' + "".join(out) + '"'


def _xml(text) -> str:
    """``text`` for an XML attribute value (quotes and markup escaped, control
    characters dropped)."""
    s = "".join(ch for ch in str(text) if ch in "\t\n" or ord(ch) >= 0x20)
    return (s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;")
            .replace('"', "&quot;").replace("\n", "&#10;").replace("\t", "&#9;"))


def _real(v: float) -> str:
    """A double exactly, as the shortest decimal that reads back to it (XML, C)."""
    v = float(v)
    if not np.isfinite(v):
        raise BgcError(f"internal: a non-finite value {v} in an FMU")
    return repr(v)


_ENV.filters["xml"] = _xml
_ENV.filters["real"] = _real


class _CPrinter(C99CodePrinter):
    """sympy -> C for the initial state and largest step: parameters read from ``p``,
    every number exact (a double as its shortest round-trip decimal)."""

    def __init__(self, slots: dict):
        super().__init__({"strict": True})
        self.slots = slots

    def _print_Symbol(self, expr):
        if expr in self.slots:
            return self.slots[expr]
        raise BgcError(f"internal: {expr} has no value in an FMU's initial state")

    def _print_Float(self, expr):
        return _real(expr)

    def _print_Rational(self, expr):
        return f"({_real(expr.p)} / {_real(expr.q)})"

    def _print_Integer(self, expr):
        return _real(int(expr))


@dataclass
class Variable:
    """One scalar variable of the FMU: its value reference and what
    modelDescription.xml says of it."""
    vr: int
    name: str
    causality: str
    variability: str
    initial: str | None = None
    start: float | None = None
    unit: str = ""
    description: str = ""
    derivative: int | None = None       # a derivative: the index (1-based) of its state


@dataclass
class Unit:
    """What an FMU is made of: the model's kernels (IR), its variables and the data its
    C layer reads."""
    name: str
    method: str
    description: str
    variables: list[Variable]
    c_model: dict                       # templates/model.c.j2's context
    ir: str
    ir_straight: str
    prefix: str
    interfaces: tuple[str, ...]
    n_states: int
    n_indicators: int
    t_end: float
    rtol: float
    guid: str = ""
    notes: list[str] = field(default_factory=list)


@dataclass
class Exported:
    """What ``export`` wrote (``bgc export --json``)."""
    fmu: str
    fmi: str
    model: str
    method: str
    interfaces: list[str]
    states: int
    parameters: int
    outputs: int
    inputs: int
    event_indicators: int
    bytes: int
    compiler: str
    timings: dict
    notes: list[str]

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def export(model, fmu, method: str = "parasitic", fmi: int = 2, params=(),
           open_loops: bool = True, parasitic: str = "given", separation: float = 100.0,
           out_dir="generated") -> Exported:
    """Write ``fmu`` for ``model`` (a model file) under ``method``; ``params``: (name,
    value) pairs that become the FMU's parameter defaults. Everything the command line
    can get wrong is refused before any work."""
    from bgc import methods
    from bgc.export import toolchain
    if fmi not in FMI_VERSIONS:
        raise BgcError(f"FMI {fmi} export is not available (this bgc writes FMI "
                       f"{', '.join(map(str, FMI_VERSIONS))})", key="--fmi",
                       hint="use --fmi 2")
    if getattr(methods.get(method), "passes_singular", False):
        raise BgcError(f"--method {method} projects the state back onto the constraints "
                       "after every step, which the FMU's integrator (and an importer's) "
                       "does not do", key="--method",
                       hint="export under lagrange or zcp (ideal joints, exact) or parasitic")
    if Path(fmu).suffix != ".fmu":
        raise BgcError(f"an FMU's file name ends in .fmu, got {str(fmu)!r}", key="--fmu")
    check_writable(fmu, "--fmu")
    compiler = toolchain.find()
    t0 = time.perf_counter()
    with progress.record() as timings:
        system, p, inputs = _build(model, method, open_loops, params, parasitic, separation,
                                   out_dir)
        with progress.stage("describe") as st:
            unit = describe(system, p, inputs)
            st.done(f"{unit.n_states} states, {len(unit.variables)} variables, "
                    f"{unit.n_indicators} event indicators")
        with progress.stage("binary") as st:
            binary = build_binary(unit, compiler)
            st.done(f"{unit.name}.so, {len(binary) / 1e3:.0f} kB ({compiler.name})")
        with progress.stage("package") as st:
            size = package(unit, binary, fmu)
            st.done(f"{fmu}, {size / 1e3:.0f} kB")
    timings["total"] = time.perf_counter() - t0
    counts = {c: sum(v.causality == c for v in unit.variables)
              for c in ("parameter", "output", "input")}
    return Exported(str(fmu), "2.0", unit.name, method, list(unit.interfaces), unit.n_states,
                    counts["parameter"], counts["output"], counts["input"], unit.n_indicators,
                    size, compiler.name, timings, unit.notes)


def _build(model, method, open_loops, params, parasitic, separation, out_dir):
    """The equation system and the parameter values the FMU starts from."""
    from bgc import pipeline
    from bgc.cli.options import check_overrides, check_params, split_constants
    from bgc.export.inputs import add_inputs
    from bgc.model import load
    constants, params = split_constants(model, params)    # -p N=40: another mechanism
    with progress.stage("load") as st:
        m = load.load(model, constants=constants)
        inputs = add_inputs(m)
        st.done(f"{m.name}: {progress.count(len(inputs), 'input')}")
    check_params(pipeline.Declared.of_model(m, method), params)     # before the build
    check_overrides(model, [(n, v) for n, v in params if n in m.parameters],
                    constants=constants)
    c = pipeline.build(m, method, open_loops)
    system = c.system
    names = [name for _, name, _ in system.params]
    p = np.array([float(v) for _, _, v in system.params], dtype=np.float64)
    check_params(pipeline.Declared.of_system(system), params)       # the exact ones
    if parasitic == "auto":
        from bgc.methods import parasitic as par
        module, _, _ = pipeline.ensure_module(model, out_dir, method, open_loops,
                                              constants=constants)
        given = _set(p.copy(), names, params)
        p, _ = par.auto(module, c.model, module.initial_state(given), given, separation)
    p = _set(p, names, params)
    if system.algebraic:
        _check_index2(model, method, open_loops, out_dir, p, constants)
    return system, p, inputs


def _check_index2(model, method, open_loops, out_dir, p, constants=None):
    """A zcp model with its loops kept closed is an index-2 DAE, whose Newton matrices
    are singular where its algebraic equations are dependent: refused here, at the
    FMU's parameter values, as bgc simulate refuses it, not at the importer's run."""
    from bgc import pipeline, simulate
    module, _, _ = pipeline.ensure_module(model, out_dir, method, open_loops,
                                          constants=constants)
    x, q, _ = simulate.prepare(module, module.initial_state(p), p)
    simulate._check_index2(module, x, q, list(module.ALGEBRAIC), 0.0)


def _set(p, names, params):
    for name, value in params:
        p[names.index(name)] = value
    return p


def _indicators(system, rhs_asg) -> list:
    """The switching functions of the rhs: where a Piecewise's condition, a Min/Max, an
    Abs, sign or Heaviside changes branch with the state (a saturation, a diode, a
    stop); those of time alone are the signals' breakpoints, time events."""
    from bgc.codegen.equations import LinearBlock
    exprs = []
    for it in rhs_asg:
        if isinstance(it, LinearBlock):
            exprs += [e for _, _, e in it.A] + [e for _, e in it.pre + it.chain]
            exprs += list(it.b or ()) + list(it.tear_eqs)
            if it.factors is not None:
                exprs += [e for _, _, e in it.factors[1] + it.factors[2]]
        else:
            exprs.append(it[1])
    params = {s for s, _, _ in system.params}
    from bgc.model import symbols
    found = []

    def add(e):
        e = sp.sympify(e)
        free = e.free_symbols - params - {symbols.t}
        if free and e not in found and -e not in found:
            found.append(e)
    for e in exprs:
        for node in sp.preorder_traversal(e):
            if isinstance(node, sp.Piecewise):
                for piece in node.args:
                    for rel in piece.cond.atoms(sp.core.relational.Relational):
                        add(rel.lhs - rel.rhs)
            elif isinstance(node, (sp.Min, sp.Max)):
                args = node.args
                for a, b in zip(args, args[1:]):
                    add(a - b)
            elif isinstance(node, (sp.Abs, sp.sign, sp.Heaviside)):
                add(node.args[0])
    return found


def describe(system, p, inputs=None) -> Unit:
    """The FMU of an equation system at parameter values ``p``; ``inputs``: the
    parameters that are its inputs (``inputs.add_inputs``)."""
    inputs = inputs or {}
    from bgc import methods
    from bgc.codegen import emit, kernels
    from bgc.solvers.consistent import RANK_PARAM
    from bgc.solvers import sparse_lu
    m = system.model
    system_h, progs, jt = emit.programs(system)
    indicators = _indicators(system_h, progs["rhs"][0])
    if indicators:
        asg, _ = emit.cone(system_h.assignments, indicators)
        progs["ind"] = (asg, list(enumerate(indicators)))
    kern = kernels.lower(system_h, kernels.PLACEHOLDER, progs, jt)
    digest = hashlib.sha256(f"{kern.ir}\n{kern.ir_straight}".encode()).hexdigest()[:12]
    prefix = f"bgc_{m.name}_{digest}"
    ir = kern.ir.replace(kernels.PLACEHOLDER, prefix)
    ir_straight = kern.ir_straight.replace(kernels.PLACEHOLDER, prefix)
    n = len(system.states)
    names = [name for _, name, _ in system.params]
    slots = {s: f"p[{i}]" for i, (s, _, _) in enumerate(system.params)}
    printer = _CPrinter(slots)
    freqs = [s.frequency for s in m.signals.values() if s.frequency is not None]
    algebraic = list(system.algebraic)
    mass = None
    if algebraic:
        mass = np.eye(n)
        mass[algebraic, algebraic] = 0.0
    plan = sparse_lu.analyse(n, [i for i, _, _ in jt.pattern], [j for _, j, _ in jt.pattern],
                             mass)
    loads = [i for i, s in enumerate(names) if "__" in s and s.endswith("_load")]
    static = bool(m.static_loads and methods.get(system.method).static_loads())
    pose = [i for i, st in enumerate(system.states) if st.element in m.bodies]
    interfaces = ("ModelExchange", "CoSimulation") if not algebraic else ("CoSimulation",)
    notes = [] if not algebraic else [
        "the kinematic loops kept closed (--keep-loops) make an index-2 DAE: Model Exchange "
        "(ODEs only) is left out, Co-Simulation runs it with bgc's Radau"]
    # variables: states, derivatives, outputs, parameters (value references in that order)
    units = {o.name: o.unit or "" for o in m.outputs}
    fixed = set().union(*(st.initial.free_symbols for st in system.states), *(
        g.free_symbols for _, g, _ in system.constraints if g is not None))
    computed = set(loads) | ({names.index(RANK_PARAM)} if RANK_PARAM in names else set())
    variables = []
    for i, st in enumerate(system.states):
        variables.append(Variable(i, st.name, "local", "continuous", "calculated",
                                  description=f"state of {st.element}"))
    for i, st in enumerate(system.states):
        variables.append(Variable(n + i, f"der({st.name})", "local", "continuous",
                                  "calculated", derivative=i + 1))
    for k, (name, _) in enumerate(system.outputs):
        variables.append(Variable(2 * n + k, name, "output", "continuous", "calculated",
                                  unit=units.get(name, "")))
    base = 2 * n + len(system.outputs)
    for i, (sym, name, _) in enumerate(system.params):
        par = m.parameters.get(name)
        if name in inputs:
            continue
        if i in computed:
            variables.append(Variable(base + i, name, "calculatedParameter", "fixed",
                                      "calculated", unit=(par.unit or "") if par else "",
                                      description=_param_doc(name, True)))
            continue
        variables.append(Variable(
            base + i, name, "parameter", "fixed" if sym in fixed else "tunable", "exact",
            float(p[i]), (par.unit or "") if par else "", _param_doc(name, False)))
    in_params = [names.index(name) for name in inputs]
    for k, name in enumerate(inputs):
        fmi_name, unit_name, doc = inputs[name]
        variables.append(Variable(base + len(names) + k, fmi_name, "input", "continuous",
                                  None, 0.0, unit_name, doc))
    c_model = dict(
        name=m.name, prefix=prefix, kernels=list(progs) + ["jac_full"],
        entries=["rhs_entry", "jac_entry", "guard_entry"],
        lstsq=any(b.rank >= 0 for b in kern.blocks), has_ind=bool(indicators),
        x0=[printer.doprint(sp.sympify(st.initial)) for st in system.states],
        freq=printer.doprint(sp.Max(sp.S.Zero, *freqs)) if freqs else "0.0",
        steps_per_period=_real(STEPS_PER_PERIOD),
        p0=[_real(v) for v in p], breakpoints=[_real(b) for b in system.breakpoints],
        state_names=[_c_string(st.name) for st in system.states],
        param_names=[_c_string(s) for s in names],
        output_names=[_c_string(s) for s, _ in system.outputs],
        guard_names=[_c_string(w) for w, _ in system.guards],
        constraint_names=[_c_string(c) for c, _, _ in system.constraints],
        has_position=[int(g is not None) for _, g, _ in system.constraints],
        imposed=[int(c in system.imposed) for c, _, _ in system.constraints],
        pose=pose, algebraic=algebraic, loads=loads,
        excitation=[i for i, s in enumerate(names) if s.startswith("excitation__")],
        inputs=in_params, static_loads=int(static),
        rank_param=names.index(RANK_PARAM) if RANK_PARAM in names else -1,
        plan=[list(map(int, a)) for a in plan], n=n, n_work=kern.n_work,
        n_eval=kern.n_eval, n_ind=len(indicators), rtol=_real(m.settings.rtol),
        atol=_real(m.settings.atol), t_end=_real(m.settings.t_end),
        name_c=_c_string(m.name))
    unit = Unit(m.name, system.method, m.description or "", variables, c_model, ir,
                ir_straight, prefix, interfaces, n, len(indicators), m.settings.t_end,
                m.settings.rtol, notes=notes)
    unit.guid = _guid(unit)
    c_model["guid_c"] = _c_string(unit.guid)
    return unit


def _param_doc(name: str, computed: bool) -> str:
    """What a parameter is, for those bgc adds (``<owner>__<what>``)."""
    if computed:
        return ("the constraints' rank, set at initialization (projection)"
                if name.endswith("__rank") else
                "the joint's static load, set at initialization (the model starts at rest)")
    if name.startswith("excitation__"):
        return "excitation: a direction's amplitude, a kind's weight or the sine's frequency"
    if name.endswith("__alpha"):
        return "Baumgarte stabilisation of the constraints [1/s]"
    if "__" in name:
        owner, what = name.split("__", 1)
        return f"{owner}: {what}"
    return ""


def _guid(unit: Unit) -> str:
    """A GUID from what the FMU holds: the same model and options give the same one."""
    h = hashlib.sha256("\n".join([unit.ir, unit.ir_straight, repr(unit.c_model), repr([
        (v.vr, v.name, v.causality, v.start) for v in unit.variables])]).encode()).hexdigest()
    return "{%s-%s-%s-%s-%s}" % (h[:8], h[8:12], h[12:16], h[16:20], h[20:32])


def model_description(unit: Unit) -> str:
    """modelDescription.xml (FMI 2.0)."""
    from bgc import __version__
    units = sorted({v.unit for v in unit.variables if v.unit})
    return _ENV.get_template("modelDescription2.xml.j2").render(
        u=unit, units=units, version=__version__,
        outputs=[i + 1 for i, v in enumerate(unit.variables) if v.causality == "output"],
        derivatives=[i + 1 for i, v in enumerate(unit.variables) if v.derivative],
        initial=[i + 1 for i, v in enumerate(unit.variables)
                 if v.causality in ("output", "calculatedParameter") or v.derivative
                 or (v.causality == "local" and v.initial == "calculated")])


def model_c(unit: Unit) -> str:
    return _ENV.get_template("model.c.j2").render(**unit.c_model)


def build_binary(unit: Unit, compiler) -> bytes:
    """The FMU's shared library."""
    from bgc.export import objects, radau
    with tempfile.TemporaryDirectory(prefix="bgc-fmu-") as tmp:
        tmp = Path(tmp)
        (tmp / "kernels.o").write_bytes(
            objects.kernels_object(unit.ir, unit.ir_straight, unit.prefix))
        (tmp / "radau5.o").write_bytes(radau.object_code())
        (tmp / "model.c").write_text(model_c(unit))
        (tmp / "exports.map").write_text("{\n  global: fmi2*;\n  local: *;\n};\n")
        out = tmp / f"{unit.name}.so"
        sources = [str(tmp / "model.c")] + [str(_HERE / "runtime" / f) for f in RUNTIME]
        compiler.link(out, sources, [tmp / "kernels.o", tmp / "radau5.o"],
                      [_HERE / "runtime", _HERE / "headers"], tmp / "exports.map")
        return out.read_bytes()


def package(unit: Unit, binary: bytes, fmu) -> int:
    """The zip (fixed timestamps: the same FMU gives the same bytes), written
    atomically; its size."""
    files = [("modelDescription.xml", model_description(unit).encode()),
             (f"binaries/{PLATFORM}/{unit.name}.so", binary),
             ("sources/model.c", model_c(unit).encode()),
             ("documentation/index.html", _documentation(unit).encode())]

    def write(path):
        with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
            for name, data in files:
                info = zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0))
                info.compress_type = zipfile.ZIP_DEFLATED
                info.external_attr = (0o755 if name.endswith(".so") else 0o644) << 16
                z.writestr(info, data)
    atomic_write(fmu, write, "--fmu")
    return Path(fmu).stat().st_size


def _documentation(unit: Unit) -> str:
    rows = "".join(f"<tr><td>{_xml(v.name)}</td><td>{v.causality}</td><td>"
                   f"{_xml(v.unit)}</td><td>{_xml(v.description)}</td></tr>\n"
                   for v in unit.variables if v.causality != "local")
    return (f"<!DOCTYPE html>\n<html><head><meta charset=\"utf-8\"><title>{_xml(unit.name)}"
            f"</title></head><body>\n<h1>{_xml(unit.name)} ({_xml(unit.method)})</h1>\n"
            f"<p>{_xml(unit.description)}</p>\n<p>Exported by bgc: {unit.n_states} states; "
            f"{', '.join(unit.interfaces)}.</p>\n<table>\n<tr><th>name</th><th>causality"
            f"</th><th>unit</th><th>description</th></tr>\n{rows}</table>\n</body></html>\n")
