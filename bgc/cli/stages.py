"""``bgc check --stage STAGE MODEL``: the output of one stage of the compiler, as text or
JSON, so that each data structure between two stages can be looked at on its own.

- ``load``: the Model (``bgc.model.load.load``): parameters, signals, elements, bonds,
  bodies, joints, outputs, the run settings;
- ``expand``: the BondGraph (``bgc.graph.expand.expand``): elements by kind, bonds,
  multibond dimensions, the joints' blocked and free directions, the constraint elements;
- ``causality``: the CausalGraph (``bgc.pipeline.build``): each storage element's
  causality, each resistor's form, the strokes, the free choices;
- ``equations``: the EquationSystem (``bgc.pipeline.build``): states, assignments, linear
  blocks, algebraic loops, constraints, outputs;
- ``emit``: the generated module's source (``bgc.codegen.emit.render``, not written):
  where it would go and whether the one there is fresh, its size, its LLVM IR kernels.

Each view is a function of the stage's data structure to a plain dict (what ``--json``
prints); ``lines`` turns that dict into the text form. The causality, equations and emit
views run the pipeline up to their stage through ``build``, so that the constraint
method's own passes run as in a compile.
"""

from __future__ import annotations

import re
from collections import Counter

from bgc import progress

STAGES = ("load", "expand", "causality", "equations", "emit")


def report(stage: str, path: str, method: str, open_loops: bool, out_dir: str) -> dict:
    """The ``--json`` report of one stage of the model file ``path``."""
    if stage == "load":
        return load_view(_load(path))
    if stage == "expand":
        from bgc.graph import expand
        model = _load(path)
        with progress.stage("expand") as st:
            graph = expand.expand(model, method)
            st.done(f"{progress.count(len(graph.elements), 'element')}, "
                    f"{progress.count(len(graph.bonds), 'bond')} ({method})")
        return expand_view(graph)
    from bgc.pipeline import build
    c = build(path, method, open_loops=open_loops)
    if stage == "causality":
        return causality_view(c.causal)
    if stage == "equations":
        return equations_view(c.system)
    from bgc.codegen import emit
    with progress.stage("emit") as st:
        source = emit.render(c.system)
        st.done(f"{len(source.encode()) / 1e3:.0f} kB")
    return emit_view(c.system, source, out_dir)


def _load(path: str):
    """The load stage alone: the model file read and checked (``bgc.model.load.load``)."""
    from bgc.model import load
    with progress.stage("load") as st:
        model = load.load(path)
        st.done(model.name)
    return model


def load_view(model) -> dict:
    """The Model: what the file says, checked."""
    return {
        "stage": "load", "model": model.name, "file": model.file,
        "description": model.description, "digest": model.digest,
        "counts": {k: len(v) for k, v in (
            ("parameters", model.parameters), ("signals", model.signals),
            ("tables", model.tables), ("elements", model.elements), ("bonds", model.bonds),
            ("bodies", model.bodies), ("joints", model.joints), ("outputs", model.outputs))},
        "parameters": {p.name: {"value": p.value, "unit": p.unit}
                       for p in model.parameters.values()},
        "signals": {s.name: s.kind for s in model.signals.values()},
        "elements": {e.name: e.kind for e in model.elements.values()},
        "blocks": {b.name: b.kind for b in model.blocks.values()},
        "bonds": [{"bond": b.name, "from": b.src, "to": b.dst, "dim": b.dim}
                  for b in model.bonds],
        "bodies": {b.name: {"mass": b.mass, "inertia": list(b.inertia)}
                   for b in model.bodies.values()},
        "joints": {j.name: {"kind": j.kind, "between": [j.body1, j.body2]}
                   for j in model.joints.values()},
        "excitation": None if model.excitation is None else {
            "kinds": list(model.excitation.kinds),
            "directions": list(model.excitation.directions)},
        "outputs": [o.name for o in model.outputs],
        "settings": {k: getattr(model.settings, k)
                     for k in ("t_end", "rtol", "atol", "solver", "points")},
    }


def expand_view(graph) -> dict:
    """The BondGraph: user elements, bodies and joints in one graph of multibonds."""
    return {
        "stage": "expand", "model": graph.model.name, "method": graph.method,
        "elements": len(graph.elements), "bonds": len(graph.bonds),
        "by_kind": dict(sorted(Counter(e.kind for e in graph.elements.values()).items())),
        "bond_dimensions": {str(d): n for d, n in
                            sorted(Counter(b.dim for b in graph.bonds).items())},
        "bodies": list(graph.bodies),
        "joints": {name: {"blocked": [d.label for d in dirs if d.blocked],
                          "free": [d.label for d in dirs if not d.blocked]}
                   for name, dirs in graph.joints.items()},
        "constraints": [c.name for c in graph.constraints],
    }


def causality_view(cg) -> dict:
    """The CausalGraph: SCAP's strokes and what they make of each element."""
    from bgc import methods
    rep = cg.report()
    method = methods.get(cg.graph.method)
    kinds = {n: cg.graph.elements[n].kind for n in rep["storage"]}
    return {
        "stage": "causality", "model": cg.graph.model.name, "method": cg.graph.method,
        "storage": {n: {"kind": kinds[n],
                        "causality": method.storage(cg.graph, n) or v}
                    for n, v in rep["storage"].items()},
        "resistors": rep["resistors"], "free_choices": rep["free_choices"],
        "strokes": rep["bonds"], "conflicts": [],
    }


def equations_view(system) -> dict:
    """The EquationSystem: states, sorted assignments, the blocks solved together."""
    from bgc.codegen.equations import LinearBlock

    def name(sym) -> str:
        return system.display.get(sym, sym.name)
    blocks = [a for a in system.assignments if isinstance(a, LinearBlock)]
    return {
        "stage": "equations", "model": system.model.name, "method": system.method,
        "states": [st.name for st in system.states],
        "dependent": dict(system.dependent),
        "assignments": len(system.assignments) - len(blocks),
        "linear_blocks": [{"index": b.index, "unknowns": [name(u) for u in b.unknowns]}
                          for b in blocks],
        "algebraic_loops": [lp.__dict__ for lp in system.loops],
        "constraints": [n for n, _, _ in system.constraints],
        "imposed": sorted(system.imposed),
        "algebraic_states": [system.states[i].name for i in system.algebraic],
        "parameters": len(system.params),
        "outputs": [n for n, _ in system.outputs],
        "guards": [w for w, _ in system.guards],
        "notes": list(system.notes),
    }


def emit_view(system, source: str, out_dir: str) -> dict:
    """The generated module's source: where ``bgc compile -o OUT_DIR`` writes it (and
    whether the module there is this one), its size and its LLVM IR functions."""
    from bgc.codegen import kernels
    from bgc.codegen.module_file import is_stale, module_path
    path = module_path(system.model.name, out_dir, system.variant)
    total = re.search(r"^KERNEL_FUNCTIONS = (\d+)$", source, re.MULTILINE)
    return {
        "stage": "emit", "model": system.model.name, "method": system.method,
        "module": str(path), "fresh": not is_stale(path, system.model.digest,
                                                   system.variant),
        "bytes": len(source.encode()), "lines": source.count("\n"),
        "kernel_functions": int(total.group(1)) if total else None,
        "kernels": {p: len(kernels.program_functions(source, p)) for p in kernels.PROGRAMS},
    }


def lines(rep: dict) -> list[str]:
    """The text form of a stage's report."""
    return _TEXT[rep["stage"]](rep)


def _names(items, empty: str = "none") -> str:
    return ", ".join(str(i) for i in items) or empty


def _load_lines(r: dict) -> list[str]:
    out = [f"{r['model']} ({r['file']})" + (f": {r['description']}" if r["description"]
                                           else "")]
    out.append("  " + ", ".join(progress.count(n, "body" if k == "bodies" else k[:-1], k)
                                for k, n in r["counts"].items()))
    out += [f"  parameter {n} = {p['value']:g}" + (f" [{p['unit']}]" if p["unit"] else "")
            for n, p in r["parameters"].items()]
    out += [f"  signal {n}: {kind}" for n, kind in r["signals"].items()]
    out += [f"  element {n}: {kind}" for n, kind in r["elements"].items()]
    out += [f"  block {n}: {kind}" for n, kind in r["blocks"].items()]
    out += [f"  bond {b['bond']}: {b['from']} -> {b['to']}"
            + (f" (dim {b['dim']})" if b["dim"] != 1 else "") for b in r["bonds"]]
    out += [f"  body {n}: mass {b['mass']:g}, inertia {_names(f'{v:g}' for v in b['inertia'])}"
            for n, b in r["bodies"].items()]
    out += [f"  joint {n}: {j['kind']} between {j['between'][0] or 'the fixed frame'} and "
            f"{j['between'][1] or 'the fixed frame'}" for n, j in r["joints"].items()]
    if r["excitation"]:
        out.append(f"  excitation: kinds {_names(r['excitation']['kinds'])}; directions "
                   f"{_names(r['excitation']['directions'])}")
    out.append(f"  outputs: {_names(r['outputs'])}")
    s = r["settings"]
    out.append(f"  simulation: t_end {s['t_end']:g} s, rtol {s['rtol']:g}, atol "
               f"{s['atol']:g}, solver {s['solver']}, {s['points']} points")
    return out


def _expand_lines(r: dict) -> list[str]:
    dims = ", ".join(f"{n} of dimension {d}" for d, n in r["bond_dimensions"].items())
    out = [(f"{r['model']} ({r['method']}): {r['elements']} elements, {r['bonds']} bonds "
           f"({dims or 'none'})"),
           "  elements by kind: " + _names(f"{_KIND.get(k, k)}: {n}"
                                           for k, n in r["by_kind"].items())]
    if r["bodies"]:
        out.append(f"  bodies: {_names(r['bodies'])}")
    out += [f"  joint {n}: blocked {_names(j['blocked'])}; free {_names(j['free'])}"
            for n, j in r["joints"].items()]
    if r["constraints"]:
        out.append(f"  constraint elements: {len(r['constraints'])} "
                   f"({_names(r['constraints'])})")
    return out


_KIND = {"0": "0-junction", "1": "1-junction"}


def _causality_lines(r: dict) -> list[str]:
    out = [f"{r['model']} ({r['method']}): causality: no conflicts"]
    out += [f"  {s['kind']} {n}: {s['causality']}" for n, s in r["storage"].items()]
    out += [f"  R {n}: {form}" for n, form in r["resistors"].items()]
    out += [f"  bond {s['bond']}: {s['from']} -> {s['to']}, effort into {s['effort_into']}"
            for s in r["strokes"]]
    out += [f"note: {c}" for c in r["free_choices"]]
    return out


def _equations_lines(r: dict) -> list[str]:
    c = progress.count
    out = [(f"{r['model']} ({r['method']}): {c(len(r['states']), 'state')}, "
            f"{c(r['assignments'], 'assignment')}, "
            f"{c(len(r['linear_blocks']), 'linear block')}, "
            f"{c(r['parameters'], 'parameter')}, {c(len(r['outputs']), 'output')}"),
           f"  states: {_names(r['states'])}"]
    out += [f"  dependent state {st} ({n}: derivative causality)"
            for n, st in r["dependent"].items()]
    out += [f"  linear block {b['index']}: {len(b['unknowns'])} unknowns "
            f"({_names(b['unknowns'])})" for b in r["linear_blocks"]]
    out.append(f"algebraic loops: {len(r['algebraic_loops']) or 'none'}")
    from bgc.codegen.equations import Loop
    out += [f"  {Loop(**lp).describe()}" for lp in r["algebraic_loops"]]
    if r["constraints"]:
        out.append(f"constraints: {len(r['constraints'])} ({len(r['imposed'])} imposed "
                   f"flows, {len(r['algebraic_states'])} algebraic states)")
    out.append(f"outputs: {_names(r['outputs'])}")
    out += [f"note: {n}" for n in r["notes"]]
    return out


def _emit_lines(r: dict) -> list[str]:
    fresh = "the module there is this one" if r["fresh"] else "not written yet or stale"
    return [(f"{r['model']} ({r['method']}): {r['module']} ({fresh}), {r['bytes']} bytes, "
            f"{r['lines']} lines"),
            f"  LLVM IR: {r['kernel_functions']} functions; by program: "
            + ", ".join(f"{p} {n}" for p, n in r["kernels"].items())]


_TEXT = {"load": _load_lines, "expand": _expand_lines, "causality": _causality_lines,
         "equations": _equations_lines, "emit": _emit_lines}
