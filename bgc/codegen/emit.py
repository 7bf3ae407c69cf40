"""Stage **emit**: EquationSystem -> Python source of a numba module, written atomically.

The module holds ``rhs(t, x, p)``, ``jac(t, x, p)`` and ``outputs(t, x, p)`` as
``@njit(cache=True)`` functions of the parameter array ``p`` (changing a value never
recompiles), plus metadata. Each function computes only the assignments its results
depend on, in causal order. The same input gives the same bytes.
"""

from __future__ import annotations

import hashlib
import keyword
import math
import re
from dataclasses import fields, replace
from pathlib import Path

import jinja2
import sympy as sp

from bgc import __version__, methods, progress
from bgc.codegen import kernels, start, workspace
from bgc.codegen.equations import EquationSystem, LinearBlock
from bgc.codegen.jacobian import tape
from bgc.codegen.module_file import (  # noqa: F401
    import_module,
    is_stale,
    model_hash,
    module_name_problem,
    module_path,
    stored_hash,
    suggest_module_name,
)
from bgc.codegen.printer import code
from bgc.errors import BgcError
from bgc.fileio import atomic_write
from bgc.model import symbols
from bgc.symbolic.algorithms import reads, substitute

_ENV = jinja2.Environment(loader=jinja2.PackageLoader("bgc.codegen", "templates"),
                          trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True,
                          undefined=jinja2.StrictUndefined)


def py_str(text: str) -> str:
    """``text`` as a double-quoted Python string literal of printable ASCII only: safe
    anywhere in generated source, a docstring included (no quote of its own survives
    unescaped, no line break, no non-ASCII character, no lone surrogate)."""
    out = []
    for ch in str(text):
        o = ord(ch)
        if ch in '"\\':
            out.append("\\" + ch)
        elif 0x20 <= o < 0x7F:
            out.append(ch)
        elif o < 0x100:
            out.append(f"\\x{o:02x}")
        elif o < 0x10000:
            out.append(f"\\u{o:04x}")
        else:
            out.append(f"\\U{o:08x}")
    return '"' + "".join(out) + '"'


def _ident(text: str, what: str = "name") -> str:
    """``text`` if it is a plain identifier (it is written into code as is)."""
    if not (isinstance(text, str) and text.isascii() and text.isidentifier()
            and not keyword.iskeyword(text)):
        raise BgcError(f"{what} {text!r} is not a valid Python name",
                       hint="letters, digits and '_', not starting with a digit")
    return text


def _float(value) -> str:
    """A number as a Python float literal (``repr``, which round-trips; a non-finite value
    as ``float('nan')`` / ``float('inf')``, which are no Python literals)."""
    v = float(value)
    return repr(v) if math.isfinite(v) else f'float("{v}")'


def _literal(value) -> str:
    """A setting's value (text, whole number or float) as a Python literal."""
    if isinstance(value, str):
        return py_str(value)
    return str(value) if isinstance(value, int) else _float(value)


def _doc(text: str) -> str:
    """``text`` for a docstring: a plain dotted name as is, anything else as an escaped
    literal (which cannot end the docstring)."""
    return text if re.fullmatch(r"[A-Za-z0-9_.\[\]]+", str(text)) else py_str(text)


def _ir_block(text: str) -> str:
    """LLVM IR as a triple-quoted literal: bgc's IR holds no quote and no backslash (it
    names nothing from the model), which this checks rather than assumes."""
    if '"' in text or "\\" in text:
        return py_str(text)
    return '"""\\\n' + text + '"""'


def _int64s(values) -> str:
    """A numpy int64 array of integers as text numpy parses: a list display of A02's
    Jacobian pattern (27 669 entries) cost Python 0.04 s to compile, this 1 ms."""
    return f'np.fromstring("{" ".join(map(str, values))}", dtype=np.int64, sep=" ")'


_ENV.filters["pystr"] = py_str
_ENV.filters["irblock"] = _ir_block
_ENV.filters["int64s"] = _int64s
_ENV.filters["doc"] = _doc
_ENV.filters["ident"] = _ident
def _defines(item) -> list:
    if isinstance(item, LinearBlock):
        return list(item.unknowns) + [v for v, _ in item.pre]
    return [item[0]]


def _free(item, memo: dict | None = None) -> set:
    """The symbols an assignment or a block reads (``memo``: ``algorithms.reads``', shared
    by the cones and the instance loops of one module's programs)."""
    if isinstance(item, LinearBlock):
        return item.free_symbols
    return item[1].free_symbols if memo is None else reads(item[1], memo)


def cone(assignments, targets, memo: dict | None = None):
    """The assignments that ``targets`` depend on, in their original order (``memo``:
    see ``_free``)."""
    need = set()
    for e in targets:
        need |= e.free_symbols if memo is None else reads(e, memo)
    keep = []
    for item in reversed(assignments):
        if any(v in need for v in _defines(item)):
            keep.append(item)
            need |= _free(item, memo)
    return keep[::-1], need


# elementary functions of one variable that are hoisted out of the expressions
_HOISTED = {sp.sin: "SIN", sp.cos: "COS", sp.tan: "TAN", sp.exp: "EXP", sp.log: "LOG"}


def hoist_calls(system: EquationSystem) -> tuple[EquationSystem, dict]:
    """Pass **hoist_calls**: every ``sin(q)``, ``cos(q)``, ... of a state, parameter or t
    becomes one assignment ``SIN_q = sin(q)`` at the head of the causal order, and every
    use reads the name. The SARIB's rotation matrices, Cardan rates and their partials
    repeat 84 such calls 786 times in the rhs and 2560 times in the Jacobian; each is a
    libm call at run time and a typed, lowered call in numba's compile. Returns the system
    and the mapping (call -> name), which the Jacobian's partials also take."""
    roots = {st.sym for st in system.states} | {s for s, _, _ in system.params}
    roots.add(symbols.t)
    exprs = []
    for item in system.assignments:
        if isinstance(item, LinearBlock):
            exprs += [e for _, _, e in item.A] + [e for _, e in item.pre + item.chain]
            exprs += list(item.b or ()) + list(item.tear_eqs)
            if item.factors is not None:
                exprs += [e for _, _, e in item.factors[1] + item.factors[2]]
        else:
            exprs.append(item[1])
    exprs += [e for _, e in system.outputs] + [e for _, e in system.guards]
    exprs += [e for _, g, r in system.constraints for e in (g, r) if e is not None]
    exprs += [e for _, e in system.projection]
    calls, reading, memo = set(), set(), {}
    for e in exprs:
        found = _calls(e, roots, memo)
        if found:
            calls |= found
            reading.add(e)
    mapping = {f: sp.Symbol(f"{_HOISTED[f.func]}_{f.args[0].name}", real=True)
               for f in sorted(calls, key=sp.default_sort_key)}
    if not mapping:
        return system, mapping

    swapped: dict = {}         # (the subexpressions the assignments share: once)

    def sub(e):         # only what reads a call: a substitution walks a whole expression
        return None if e is None else substitute(e, mapping, swapped) if e in reading else e
    head = [(v, f) for f, v in mapping.items()]
    body = [it.xreplace(mapping) if isinstance(it, LinearBlock) else (it[0], sub(it[1]))
            for it in system.assignments]
    return replace(system, assignments=head + body,
                   outputs=[(n, sub(e)) for n, e in system.outputs],
                   guards=[(w, sub(e)) for w, e in system.guards],
                   constraints=[(n, sub(g), sub(r)) for n, g, r in system.constraints],
                   projection=[(i, sub(e)) for i, e in system.projection]), mapping


_NONE: frozenset = frozenset()


def _calls(e, roots: set, memo: dict) -> frozenset:
    """The calls of ``_HOISTED`` functions of ``roots`` in ``e`` (sympy's ``atoms``,
    memoized on the subexpressions that the assignments share)."""
    hit = memo.get(id(e))
    if hit is not None and hit[0] is e:
        return hit[1]
    if not e.args:
        out = _NONE
    elif e.func in _HOISTED and e.args[0] in roots:
        out = frozenset((e,))
    else:
        out = _NONE.union(*(_calls(a, roots, memo) for a in e.args))
    memo[id(e)] = (e, out)
    return out


def programs(system: EquationSystem, memo: dict | None = None
             ) -> tuple[EquationSystem, dict, object]:
    """The kernels' programs of a system (its calls hoisted, ``hoist_calls``): name ->
    (the assignments in causal order that its results need, [(out index, expr)]; jac's:
    none, and "rhs", the program it runs first: ``kernels.lower``), and
    the Jacobian's tape. ``kernels.lower`` turns them into IR (``memo``: the symbols each
    expression reads, for the cones here and the instance loops there)."""
    system, hoisted = hoist_calls(system)
    dx = [st.dsym for st in system.states]
    memo = {} if memo is None else memo
    rhs_asg, _ = cone(system.assignments, dx, memo)
    a_patterns = {it.index: workspace.factor_pattern(len(it.unknowns), *it.factors)
                  for it in rhs_asg if isinstance(it, LinearBlock)
                  and it.regularize is not None}
    with progress.stage("jacobian") as st:
        jt = tape(rhs_asg, system.states, a_patterns)
        st.done(f"{progress.count(len(jt.pattern), 'entry', 'entries')}, "
                f"{progress.count(jt.n_colours, 'colour')}, "
                f"{progress.count(len(jt.src), 'partial')}")
    solved = {b.index for b in jt.blocks}
    jac_targets = [e for e, _ in jt.partials] + [
        u for it in rhs_asg if isinstance(it, LinearBlock) and it.index in solved
        for u in it.unknowns]
    # the partials read values that rhs computes (all of them, when the tape's inputs
    # are rhs's): program jac runs rhs first and adds only the partials, instead of
    # computing those values again in code of its own (as much code as rhs: half the
    # instance loops' scheduling, lowering and LLVM's work of a large model). rhs's
    # assignments are a cone, closed under what they read: where every assigned value
    # the partials read is one of them, so is the partials' whole cone
    in_rhs = {v for it in rhs_asg for v in _defines(it)}
    assigned = {v for it in system.assignments for v in _defines(it)}
    read = set().union(*(reads(e, memo) for e in jac_targets))
    jac = (([], jt.partials, "rhs") if not (read - in_rhs) & assigned
           else (cone(system.assignments, jac_targets, memo)[0], jt.partials))
    out_exprs = [e for _, e in system.outputs]
    out_asg, _ = cone(system.assignments, out_exprs, memo)
    guard_exprs = [e for _, e in system.guards]
    guard_asg, _ = cone(system.assignments, guard_exprs, memo)
    con_exprs = ([sp.S.Zero if g is None else g for _, g, _ in system.constraints]
                 + [r for _, _, r in system.constraints])
    con_asg, _ = cone(system.assignments, con_exprs, memo)
    progs = {
        "rhs": (rhs_asg, list(enumerate(dx))),
        "jac": jac,
        "out": (out_asg, list(enumerate(out_exprs))),
        "guard": (guard_asg, list(enumerate(guard_exprs))),
        "con": (con_asg, list(enumerate(con_exprs)))}
    if system.projection:       # every state's correction (zero where it has none)
        corrections = dict(system.projection)
        proj = [(i, corrections.get(i, sp.S.Zero)) for i in range(len(system.states))]
        progs["proj"] = (cone(system.assignments, [e for _, e in proj], memo)[0], proj)
    return system, progs, jt


def render(system: EquationSystem) -> str:
    """The module source for an equation system."""
    memo: dict = {}
    system, progs, jt = programs(system, memo)
    m = system.model
    dx = [st.dsym for st in system.states]
    freqs = [s.frequency.xreplace(system.folded) if system.folded else s.frequency
             for s in m.signals.values() if s.frequency is not None]
    # every name the code assigns or reads is written as is: each must be an identifier
    for sym in ([sy for sy, _, _ in system.params] + [st.sym for st in system.states]
                + dx + [v for it in system.assignments for v in _defines(it)]):
        _ident(sym.name, "symbol")
    canonical = f"_bgc_{_ident(m.name, 'model name')}_{model_hash(m.digest, system.variant)}"
    kern = kernels.lower(system, kernels.PLACEHOLDER, progs, jt, memo, data=True)
    # the kernels' names: the module's and its IR's digest, with their tables' (one model
    # compiled with other options is other code; two such modules in one process must not
    # share a name)
    digest = hashlib.sha256("\n".join([kern.ir, kern.ir_straight, repr(kern.data)]).encode()
                            ).hexdigest()[:12]
    prefix = f"{canonical}_{digest}"
    ir = kern.ir.replace(kernels.PLACEHOLDER, prefix)
    ir_straight = kern.ir_straight.replace(kernels.PLACEHOLDER, prefix)
    x0_symbols = set().union(*(st.initial.free_symbols for st in system.states))
    units = {o.name: o.unit for o in m.outputs}
    ctx = dict(
        version=__version__, source=Path(m.file).name, method=system.method, name=m.name,
        settings=[(f.name, _literal(getattr(m.settings, f.name))) for f in fields(m.settings)],
        model_hash=model_hash(m.digest, system.variant),
        canonical=canonical, prefix=prefix, ir=ir, ir_straight=ir_straight,
        data=kern.data,
        n_functions=ir.count("\ndefine ") + ir_straight.count("\ndefine "),
        n_work=kern.n_work, n_eval=kern.n_eval, n_schur=kern.n_schur,
        lstsq=any(b.rank >= 0 for b in kern.blocks),
        ir_opt=kernels.IR_OPT, codegen_opt=kernels.CODEGEN_OPT,
        loops_codegen_opt=kernels.LOOPS_CODEGEN_OPT,
        straight_passes=kernels.STRAIGHT_PASSES,
        tables=[{"index": tb.index, "t": [_float(v) for v in tb.t],
                 "y": [_float(v) for v in tb.y]} for tb in system.tables],
        jac_i=[i for i, _, _ in jt.pattern], jac_j=[j for _, j, _ in jt.pattern],
        state_names=[st.name for st in system.states],
        param_names=[name for _, name, _ in system.params],
        output_names=[name for name, _ in system.outputs],
        output_units=[units.get(name) or "" for name, _ in system.outputs],
        x0_params=[f"{sy.name} = p[{i}]" for i, (sy, _, _) in enumerate(system.params)
                   if sy in x0_symbols],
        freq_params=[f"{sy.name} = p[{i}]" for i, (sy, _, _) in enumerate(system.params)
                     if any(f.has(sy) for f in freqs)],
        freq=code(sp.Max(sp.S.Zero, *freqs)) if freqs else "0.0",
        x0=[code(st.initial) for st in system.states],
        p0=[_float(v) for _, _, v in system.params],
        breakpoints=[_float(b) for b in system.breakpoints],
        n=len(system.states),
        n_jac=len(system.states) + jt.n_aug,
        constraint_names=[n for n, _, _ in system.constraints],
        has_position=[int(g is not None) for _, g, _ in system.constraints],
        imposed=[int(n in system.imposed) for n, _, _ in system.constraints],
        algebraic=system.algebraic,
        projects=bool(system.projection),
        passes_singular=bool(methods.get(system.method).passes_singular),
        pose=[i for i, st in enumerate(system.states) if st.element in m.bodies],
        guard_names=[what for what, _ in system.guards],
        energy=system.energy or [],
        quadrature=system.quadrature,
        static_loads=bool(m.static_loads and methods.get(system.method).static_loads()),
    )
    return _ENV.get_template("module.py.j2").render(**ctx)


def write(system: EquationSystem, out_dir: str | Path = "generated") -> Path:
    """Render and write ``out_dir/<name>.py`` atomically (temp file + rename), if the
    system's start is finite for the model's own values (``start.check``): nothing is
    written for a model that could not run."""
    start.check(system)
    source = render(system)
    path = module_path(system.model.name, out_dir, system.variant)
    problem = module_name_problem(path.stem)
    if problem:
        raise BgcError(f"cannot write module {str(path)!r}: {problem}",
                       hint=f"give the model (or scene) another 'name:', e.g. "
                            f"{suggest_module_name(system.model.name)!r}")
    init = path.parent / "__init__.py"
    if not init.exists():
        atomic_write(init, '"""Modules generated by `bgc compile`."""\n', "module")
    atomic_write(path, source, "module")
    return path
