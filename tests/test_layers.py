"""The compile side's boundaries, read from the source (every ``import`` anywhere in a
module: at its top, under ``TYPE_CHECKING`` or inside a function): ``bgc.model`` imports
no later stage; ``bgc.methods`` declares and ``bgc.codegen`` asks it, never the other way;
``bgc.symbolic`` (what the stages share) imports no stage; and no two compile-side modules
import each other, directly or through others (issue 41, item 4)."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

BGC = Path(__file__).resolve().parent.parent / "bgc"
COMPILE_SIDE = ("bgc.model", "bgc.mechanics", "bgc.graph", "bgc.methods", "bgc.codegen",
                "bgc.symbolic", "bgc.pipeline")


def _modules() -> dict[str, Path]:
    out = {}
    for f in BGC.rglob("*.py"):
        parts = list(f.relative_to(BGC.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = f
    return out


MODULES = _modules()


def _resolve(name: str) -> str | None:
    """The bgc module an imported name is, or lives in (None: not bgc's)."""
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def imports(module: str) -> set[str]:
    """The bgc modules ``module`` imports, wherever in it."""
    tree = ast.parse(MODULES[module].read_text(encoding="utf-8"))
    package = module if MODULES[module].name == "__init__.py" else module.rpartition(".")[0]
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            out |= {_resolve(a.name) for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:                    # relative: from the package up
                up = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join(up + ([base] if base else []))
            out |= {_resolve(f"{base}.{a.name}") or _resolve(base) for a in node.names}
    return out - {None, module}


def _within(module: str, packages) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def _violations(packages, forbidden) -> list[str]:
    return sorted(f"{m} imports {i}" for m in MODULES if _within(m, packages)
                  for i in imports(m) if _within(i, forbidden))


def test_the_scanner_sees_imports_wherever_they_are():
    assert "bgc.codegen.builder" in imports("bgc.codegen.elements")
    assert "bgc.symbolic.linear" in imports("bgc.methods.augmented")
    assert "bgc.graph.expand" in imports("bgc.methods.parasitic")      # inside a function
    assert "bgc.errors" in imports("bgc.model.load")


def test_model_imports_no_later_stage():
    assert not _violations(["bgc.model"], ["bgc.graph", "bgc.codegen", "bgc.methods",
                                           "bgc.scene", "bgc.solvers", "bgc.simulate",
                                           "bgc.pipeline", "bgc.cli", "bgc.analysis"])


def test_methods_declare_and_codegen_asks():
    assert not _violations(["bgc.methods"], ["bgc.codegen", "bgc.pipeline"])


def test_symbolic_imports_no_stage():
    assert not _violations(["bgc.symbolic"], [p for p in COMPILE_SIDE if p != "bgc.symbolic"])


def _cycles(nodes: list[str]) -> list[list[str]]:
    """The strongly connected components of more than one module (iterative Tarjan)."""
    from bgc.symbolic.algorithms import is_cyclic, strongly_connected
    deps = {m: sorted(i for i in imports(m) if i in nodes) for m in nodes}
    return [c for c in strongly_connected(nodes, deps) if is_cyclic(c, deps)]


def test_no_import_cycle_on_the_compile_side():
    nodes = sorted(m for m in MODULES if _within(m, COMPILE_SIDE))
    assert len(nodes) > 40
    assert not _cycles(nodes)


@pytest.mark.parametrize("edges,cyclic", [({"a": ["b"], "b": ["a"]}, True),
                                          ({"a": ["b"], "b": []}, False)])
def test_the_cycle_check_finds_a_cycle(edges, cyclic, monkeypatch):
    monkeypatch.setattr(sys.modules[__name__], "imports", lambda m: set(edges[m]))
    assert bool(_cycles(sorted(edges))) is cyclic
