"""Components in their parts: what the assembly shares (``scope``: an instance's
locations, exact numbers), its expressions written in flat names (``expressions``), and
the names a model may take (``model.names``)."""

from __future__ import annotations

import ast

import sympy as sp

from bgc.errors import Loc
from bgc.model.components import InstanceLoc, QName, Scope
from bgc.model.components.assembler import Assembler
from bgc.model.components.scope import _exact, _number
from bgc.model.document import from_text
from bgc.model.names import module_name_problem, suggest_module_name


def test_a_scope_names_the_instance_a_value_came_through():
    loc = Loc("c.yaml", 3, 5)
    assert Scope("m.yaml").loc(loc) is loc
    inner = Scope("c.yaml", prefix="leg_2.", via="instance 'leg_2'").loc(loc)
    assert isinstance(inner, InstanceLoc) and str(inner) == "c.yaml:3:5 (in instance 'leg_2')"
    assert Scope("m.yaml", o=sp.Matrix([0, 0, 1])).placed and not Scope("m.yaml").placed


def test_numbers_stay_exact():
    assert _exact(sp.Float(0.1) * sp.Symbol("x")) == sp.Rational(1, 10) * sp.Symbol("x")
    assert _number(sp.Integer(3)) == 3 and _number(sp.Rational(1, 4)) == 0.25
    assert _number(sp.Rational(1, 3)) == "1/3"


def test_an_instances_expression_in_flat_names():
    doc = from_text("name: m\nparameters: {k: 1.0}\n", "m.yaml")
    a = Assembler("m.yaml", doc)
    scope = Scope("c.yaml", prefix="leg_2.", rename={"k": QName("leg_2.k")},
                  subst={"N": ast.Constant(4)})         # a constant, put in
    assert a._rewrite("2*k + N", scope, Loc("c.yaml", 1), "x") == "2 * leg_2.k + 4"
    assert a._rewrite("N / 8", scope, Loc("c.yaml", 1), "x") == 0.5      # a number


def test_a_model_name_must_be_a_module_name_that_shadows_nothing():
    assert module_name_problem("pendulum") is None
    assert "keyword" in module_name_problem("class")
    assert "shadow" in module_name_problem("numpy")
    assert suggest_module_name("2 fast") == "m_2_fast"
