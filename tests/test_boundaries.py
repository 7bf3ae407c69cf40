"""The boundaries docs/architecture.md states, read from the source by its imports (``ast``:
every import, at the top of a module or inside a function): the run side (``bgc/solvers``,
``bgc/simulate.py``) sees a generated module, never a constraint method, and no bgc module
imports itself through others."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

BGC = Path(__file__).resolve().parent.parent / "bgc"


def _modules() -> dict[str, Path]:
    """Every module of bgc by dotted name (a package by its ``__init__``)."""
    out = {}
    for f in BGC.rglob("*.py"):
        parts = list(f.relative_to(BGC.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


MODULES = _modules()


def imports(name: str) -> set[str]:
    """The bgc modules ``name`` imports anywhere in its source: ``from bgc.x import y``
    counts as bgc.x.y where y is a module, else as bgc.x."""
    path = MODULES[name]
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            for a in node.names:
                sub = f"{base}.{a.name}"
                found.add(sub if sub in MODULES else base)
    return {m for m in found if m in MODULES and m != name}


def cycles(names) -> list[list[str]]:
    """The import cycles among ``names`` (strongly connected components of more than one
    module, Tarjan's algorithm), each sorted."""
    graph = {n: sorted(imports(n) & set(names)) for n in names}
    index, low, stack, on, out = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return out


RUN_SIDE = sorted(m for m in MODULES if m == "bgc.simulate" or m.startswith("bgc.solvers"))


def test_the_scan_sees_imports_at_the_top_and_inside_functions():
    """The scan itself: simulate's solvers at its top, rk4 inside a native solver's
    method, a relative-free ``from bgc.solvers import consistent`` as the module."""
    assert "bgc.solvers.native_solver" in imports("bgc.simulate")
    assert "bgc.solvers.consistent" in imports("bgc.simulate")
    assert "bgc.solvers.rk4" in imports("bgc.solvers.native_solver")
    assert cycles(["bgc.simulate", "bgc.solvers.base"]) == []


@pytest.mark.parametrize("name", RUN_SIDE)
def test_the_run_side_imports_no_constraint_method(name):
    """What a run needs of a method travels in its generated module (``CONSTRAINT_NAMES``,
    ``IMPOSED``, the rank parameter) or lives in bgc/solvers (``consistent``)."""
    assert not {m for m in imports(name) if m == "bgc.methods"
                or m.startswith("bgc.methods.")}, f"{name} imports a constraint method"


# the compile side's cycles, left to the codegen work of issue 41 (item 4: its modules in
# named parts); every other module is held to none below
CODEGEN = "bgc.codegen"


def test_no_import_cycle_outside_codegen():
    outside = [m for m in MODULES if not m.startswith(CODEGEN)]
    assert cycles(outside) == []


def test_no_import_cycle():
    assert cycles(list(MODULES)) == []


LONGEST = 120       # lines of a function, its docstring included (issue 41, item 3)


def test_no_function_over_120_lines_outside_codegen():
    """A long body is parts not yet named: the step loop calls its Newton solve, error
    estimate, step-size control and dense output (radau5's parts, inlined by numba)."""
    long = []
    for name, path in MODULES.items():
        if name.startswith(CODEGEN):
            continue
        for node in ast.walk(ast.parse(path.read_text(), str(path))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > LONGEST:
                    long.append(f"{name}.{node.name}: {lines} lines")
    assert long == []


LONGEST_MODULE = 800     # lines of a module under bgc/ (issue 41, item 2)


def test_no_module_over_800_lines():
    """A long module is several parts under one name (radau5's Newton matrices are
    radau5_lu; kernels' lowering, linear algebra and assembly are modules of their own)."""
    long = {name: n for name, path in MODULES.items()
            if (n := len(path.read_text().splitlines())) > LONGEST_MODULE}
    assert long == {}
