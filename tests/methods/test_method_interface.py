"""The constraint methods behind one interface (issue 25, item 2): each registered method
is found by name, a fourth one is one class, and nothing outside ``bgc/methods/`` branches
on a method's name."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest
from helpers import MODELS

from bgc import methods
from bgc.errors import BgcError
from bgc.methods.base import ConstraintMethod
from bgc.pipeline import build

BGC = Path(methods.__file__).resolve().parent.parent


class Penalty(ConstraintMethod):
    """A fourth method, as a user would add one: L a stiff spring alone (no damper)."""

    name = "penalty"

    def constraint_element(self, ex, joint, d, zero):
        import sympy as sp

        from bgc.graph.expand import joint_param
        from bgc.model import symbols
        kind = "rot_" if d.rotational else ""
        k = symbols.param(joint_param(joint.name, kind + "stiffness"))
        return [ex.add(f"{zero}__L", "C", joint.loc, k=k, initial=sp.S.Zero)]


@pytest.fixture
def penalty(monkeypatch):
    monkeypatch.setitem(methods.REGISTRY, "penalty", f"{__name__}:Penalty")
    monkeypatch.setattr(methods, "_made", {})
    return methods.get("penalty")


def _kinds(compiled, suffix):
    return sorted(el.kind for n, el in compiled.causal.graph.elements.items()
                  if n.endswith(suffix))


def test_each_registered_method_is_found_by_its_name():
    assert methods.NAMES == ("parasitic", "lagrange", "zcp", "augmented")
    assert methods.DEFAULT == "parasitic"
    for name in methods.NAMES:
        m = methods.get(name)
        assert isinstance(m, ConstraintMethod) and m.name == name
    assert methods.get("zcp").stabilisation == "zcp__alpha"
    assert methods.get("parasitic").stabilisation is None
    with pytest.raises(BgcError, match="unknown constraint method 'nope'") as e:
        methods.get("nope")
    assert "parasitic, lagrange, zcp, augmented" in e.value.hint


def test_what_l_becomes_under_each_method():
    """The pendulum's hinge blocks 5 directions: parasitic puts a spring (C, or an effort
    source where it starts deflected under its static load) and a damper (R) on each,
    lagrange an effort source (its multiplier), zcp flow sources, augmented an effort
    source as lagrange's (its block regularized, no rank parameter)."""
    model = MODELS / "pendulum.yaml"
    par, lag, zcp, aug = (build(model, m) for m in methods.NAMES)
    assert len(_kinds(par, "__L")) == 5 and set(_kinds(par, "__L")) <= {"C", "MSe"}
    assert _kinds(par, "__Lc") == ["R"] * 5
    assert not par.system.constraints
    assert _kinds(lag, "__L") == ["MSe"] * 5 and not _kinds(lag, "__Lc")
    assert len(lag.system.constraints) == 5 and not lag.system.imposed
    assert {n for _, n, _ in lag.system.params} >= {"lagrange__alpha", "lagrange__rank"}
    assert len(zcp.system.imposed) == 5                  # the tree joint: flow sources
    assert len(zcp.system.states) < len(lag.system.states)  # dependent momenta dropped
    assert _kinds(aug, "__L") == ["MSe"] * 5 and len(aug.system.constraints) == 5
    assert {n for _, n, _ in aug.system.params} >= {"augmented__alpha", "augmented__eps"}
    assert "lagrange__rank" not in {n for _, n, _ in aug.system.params}
    assert aug.system.projection and methods.get("augmented").passes_singular


def test_a_fourth_method_is_one_class(penalty):
    c = build(MODELS / "pendulum.yaml", "penalty")
    assert c.system.method == "penalty" and c.causal.graph.method == "penalty"
    assert _kinds(c, "__L") == ["C"] * 5 and not _kinds(c, "__Lc")
    stiff = [el.fields["k"] for n, el in c.causal.graph.elements.items() if n.endswith("__L")]
    assert all(str(k).endswith("stiffness") for k in stiff), stiff
    assert not c.system.constraints                     # no multipliers: compliant joints
    assert methods.variant("penalty", open_loops=False) == "penalty"


def _method_name_tests(tree: ast.AST):
    """Comparisons of a method (``method``, ``o.method``, ``system.method`` ...) with a
    method's name (``method == "zcp"``, ``method in ("lagrange", ...)``)."""
    names = set(methods.NAMES)

    def is_method(node) -> bool:
        return (isinstance(node, ast.Name) and "method" in node.id) or \
            (isinstance(node, ast.Attribute) and "method" in node.attr)

    def has_name(node) -> bool:
        consts = node.elts if isinstance(node, (ast.Tuple, ast.List, ast.Set)) else [node]
        return any(isinstance(c, ast.Constant) and c.value in names for c in consts)

    for node in ast.walk(tree):
        if isinstance(node, ast.Compare):
            sides = [node.left, *node.comparators]
            if any(map(is_method, sides)) and any(map(has_name, sides)):
                yield node.lineno


def test_nothing_outside_methods_branches_on_a_method_name():
    found = []
    for path in sorted(BGC.rglob("*.py")):
        rel = path.relative_to(BGC)
        if rel.parts[0] in ("methods", "bench"):   # bench compares the methods, by design
            continue
        found += [f"{rel}:{line}" for line in _method_name_tests(ast.parse(path.read_text()))]
    assert not found, found
