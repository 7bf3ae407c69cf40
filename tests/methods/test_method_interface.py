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


class Relaxed(ConstraintMethod):
    """A fourth method through every hook: L an effort source whose effort, the joint
    force ``lam``, is the parasitic spring-damper's ``k g + c dg/dt`` on the geometric
    deflection, written as the relaxation ``lam = lam + w (k g + c dg/dt - lam)``: a loop
    in ``lam`` that the method solves as a constraint block of its own (``A = w``,
    ``b = w (k g + c dg/dt)``), the weight ``relaxed__w`` a parameter. ``calls``: the
    hooks in the order the stages called them."""

    name = "relaxed"
    passes_singular = True          # compliant: no rank to watch

    def __init__(self):
        self.calls: list[str] = []

    def constraint_element(self, ex, joint, d, zero):
        from bgc.graph.bondgraph import Constraint
        from bgc.model import symbols
        self.calls.append("constraint_element")
        L = ex.add(f"{zero}__L", "MSe", joint.loc,
                   effort=symbols.multiplier(joint.name, d.label))
        ex.constraints.append(Constraint(joint.name, d.label, L, d.g, d.rotational))
        return [L]

    def restructure(self, graph, open_loops=True):
        from dataclasses import replace
        self.calls.append("restructure")
        return replace(graph, method_plan=tuple(c.name for c in graph.constraints))

    def loops_closed(self, graph):
        self.calls.append("loops_closed")
        assert graph.method_plan == tuple(c.name for c in graph.constraints)
        return False

    def new_state(self, builder):
        self.calls.append("new_state")
        return {"forces": []}

    def massless_body(self, builder, name, bond, sign, E, F):
        self.calls.append("massless_body")
        return False                # the element rule's own balance of forces

    def embed(self, builder):
        self.calls.append("embed")

    def constraint_equations(self, b):
        from bgc.graph.expand import joint_param
        from bgc.model import symbols
        self.calls.append("constraint_equations")
        w = symbols.param("relaxed__w")
        out = []
        for c in b.g.constraints:
            _, s, E, F = b.port(c.element)
            rate = -s * F
            kind = "rot_" if c.rotational else ""
            k = symbols.param(joint_param(c.joint, kind + "stiffness"))
            damping = symbols.param(joint_param(c.joint, kind + "damping"))
            lam = symbols.multiplier(c.joint, c.label)
            b.define(lam, lam + w * (k * c.g + damping * rate - lam), c.element)
            b.method_state["forces"].append(lam)
            out.append((c.name, c.g, rate))
        return out

    def tear_first(self, b, comp):
        self.calls.append("tear_first")
        return [v for v in comp if v in b.method_state["forces"]]

    def loop_block(self, b, loop):
        import sympy as sp

        from bgc.methods.base import LoopSolution
        from bgc.symbolic.linear import LinearBlock
        self.calls.append("loop_block")
        forces = b.method_state["forces"]
        if not set(loop.tears) <= set(forces):
            return None
        loop.kind = "relaxed"
        w = sp.Symbol("P_relaxed__w", real=True)
        rhs = [b.eqs[t].xreplace({t: 0}) for t in loop.tears]     # w (k g + c dg/dt)
        a = [(i, i, w) for i in range(len(loop.tears))]
        block = LinearBlock(loop.index, tuple(loop.tears), tuple(a), tuple(rhs),
                            tuple(b.eqs[t] for t in loop.tears))
        before, block, after = self.constraint_block(b, block)
        return LoopSolution([f"{len(loop.tears)} relaxed joint force(s)"],
                            before + [block] + loop.chain() + after)

    def constraint_block(self, builder, block):
        self.calls.append("constraint_block")
        return [], block, []

    def parameters(self, model, constraints):
        self.calls.append("parameters")
        return [("relaxed__w", 0.5)]

    def role(self, constraint):
        return "force"

    def static_loads(self):
        return False

    def report(self, compiled):
        n = sum(lp.kind == "relaxed" for lp in compiled.system.loops)
        return {"relaxed_blocks": n}, [f"{n} relaxed joint forces"]

    def hides_loop(self, loop):
        return loop.kind == "relaxed"

    def storage(self, graph, name):
        return None


@pytest.fixture
def penalty(monkeypatch):
    monkeypatch.setitem(methods.REGISTRY, "penalty", f"{__name__}:Penalty")
    monkeypatch.setattr(methods, "_made", {})
    return methods.get("penalty")


@pytest.fixture
def relaxed(monkeypatch):
    monkeypatch.setitem(methods.REGISTRY, "relaxed", f"{__name__}:Relaxed")
    monkeypatch.setattr(methods, "_made", {})
    return methods.get("relaxed")


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


def test_a_fourth_method_through_every_hook_with_a_block_of_its_own(relaxed, tmp_path,
                                                                    compiled):
    """Every hook is asked, in the order of the stages; the method's own state and plan
    travel only through its hooks; its loops are its constraint blocks (one per joint
    force, A = w), which the kernels solve; and the forces it solves are the parasitic
    spring-damper's: the pendulum under it runs as under parasitic."""
    import numpy as np
    import sympy as sp

    from bgc.codegen.emit import import_module
    from bgc.codegen.equations import LinearBlock
    from bgc.pipeline import compile_model
    from bgc.simulate import simulate

    c, path = compile_model(MODELS / "pendulum.yaml", tmp_path, "relaxed")
    first = {h: relaxed.calls.index(h) for h in set(relaxed.calls)}
    assert set(first) == {"constraint_element", "restructure", "new_state", "embed",
                          "constraint_equations", "tear_first", "loop_block",
                          "constraint_block", "parameters", "loops_closed"}
    assert first["constraint_element"] < first["restructure"] < first["new_state"] \
        < first["embed"] < first["constraint_equations"] < first["tear_first"] \
        < first["loop_block"] < first["constraint_block"] < first["parameters"]
    blocks = [a for a in c.system.assignments if isinstance(a, LinearBlock)]
    assert len(blocks) == 5 and [lp.kind for lp in c.system.loops] == ["relaxed"] * 5
    assert all(len(b.unknowns) == 1 and b.A[0][2] == sp.Symbol("P_relaxed__w", real=True)
               for b in blocks)
    assert relaxed.hides_loop(c.system.loops[0]) and relaxed.stabilisation is None
    assert relaxed.report(c) == ({"relaxed_blocks": 5}, ["5 relaxed joint forces"])
    assert {n for _, n, _ in c.system.params} >= {"relaxed__w"}
    assert "_block0(" in path.read_text()                # solved by the kernels
    mod = import_module(path)
    par = compiled("pendulum")          # under parasitic: the session's module
    p = mod.PARAMS.copy()
    p[list(mod.PARAM_NAMES).index("relaxed__w")] = 0.25   # any weight: the same forces
    r1 = simulate(mod, t_end=0.3, rtol=1e-8, atol=1e-10, params=p,
                  check_drift=False)           # compliant: its joints deflect
    r2 = simulate(par, t_end=0.3, rtol=1e-8, atol=1e-10)
    assert r1.t[-1] == r2.t[-1] == 0.3
    x1, x2 = r1.y[-1, 0], r2.y[-1, 0]                    # rod.x: the swing
    assert abs(x1 - x2) <= 1e-4 * abs(x2 - r2.y[0, 0]), (x1, x2)
    relaxed.calls.clear()
    cardan = tmp_path / "cardan.yaml"           # a cross of negligible mass between hinges
    cardan.write_text("""name: cardan
gravity: 9.81
bodies:
  cross: {mass: 0, com: [0, 0, 0]}
  rod: {mass: 2.0, com: [0, 0, -0.5], inertia: [0.2, 0.2, 0.01]}
joints:
  h1: {type: revolute, between: [fixed_frame, cross], at: [0, 0, 0], axis: [0, 1, 0]}
  h2: {type: revolute, between: [cross, rod], at: [0, 0, 0], axis: [1, 0, 0]}
""")
    m = build(cardan, "relaxed")
    assert "massless_body" in relaxed.calls
    assert any(lp.kind == "negligible-mass" for lp in m.system.loops)   # the rule's own
