"""The front end's shortcuts past sympy (forward_mode's differentiation and triviality
test, equations.matmul) must give exactly the expressions sympy gives: the generated code
is compared byte for byte."""

import random

import sympy as sp

from bgc import pipeline
from bgc.codegen.builder import matmul
from bgc.symbolic.forward_mode import derivative, directional, trivial

x, y, z, w = sp.symbols("x y z w", real=True)

SHAPES = [
    x, y, sp.S(3), sp.Float(0.25), x * y, -x, 2 * x * y, sp.Float(0.3) * x * y * z,
    x + y, x - 2 * y + sp.Float(0.1) * x * z, 2 * (x + y) * z,      # a number times a sum
    x * (y + z) * (x - w), (x + y) ** 2, 1 / (x + y), sp.sqrt(2) * x * sp.sqrt(3) * y,
    sp.cos(x) * sp.sin(y) - sp.sin(x) * sp.cos(y) * z, sp.cos(x * y) + x * sp.exp(x),
    sp.Rational(1, 3) * x * y + sp.Rational(2, 3) * x * y * z - x, x * y * x,
    (sp.Float(0.1) * x + sp.Float(0.2) * y) * (sp.Float(0.3) * x - z), sp.Abs(x) * y,
]


def test_derivative_is_sympys_diff_exactly():
    for e in SHAPES:
        for s in (x, y, z, w):
            got, want = derivative(e, s), sp.diff(e, s)
            assert sp.srepr(got) == sp.srepr(want), (e, s, got, want)


def test_directional_matches_the_chain_rule_by_sympy():
    sens = {x: {0: sp.S.One, 1: w}, y: {1: sp.S.One}, z: {0: sp.S(2) * w}}
    for e in SHAPES:
        want = {}
        for s in sorted((s for s in e.free_symbols if s in sens), key=lambda s: s.name):
            partial = sp.diff(e, s)
            if partial == 0:
                continue
            for j, ds in sens[s].items():
                want[j] = want.get(j, sp.S.Zero) + partial * ds
        want = {j: d for j, d in sorted(want.items()) if d != 0}
        got = directional(e, sens)
        assert list(got) == list(want)
        assert all(sp.srepr(got[j]) == sp.srepr(want[j]) for j in want), e


def test_trivial_is_number_symbol_or_negated_symbol():
    for e in SHAPES + [-y, -sp.Float(1.0) * y, -(x - y), -sp.cos(x), -1 / x]:
        want = e.is_Number or e.is_Symbol or (e.could_extract_minus_sign() and (-e).is_Symbol)
        assert trivial(e) == want, e


def test_references_resolve_to_the_same_expressions_as_a_full_map(tmp_path):
    """Only the referenced targets' references are built; what the equations and outputs
    read must be what the complete map gives."""
    from bgc.codegen import equations
    from bgc.graph import causality, expand
    from bgc.model import load
    model = load.load("models/double_pendulum.yaml")
    cg = causality.assign(expand.expand(model, "parasitic"))
    b = equations.Builder(cg)
    equations.build(b)
    b.resolve_refs()
    full = b.ref_map()
    assert b.refs and all(full[k] == v for k, v in b.refs.items())
    for o in model.outputs:
        assert o.expr.xreplace(b.refs) == o.expr.xreplace(full)
    system = pipeline.build(model, "parasitic").system
    assert [n for n, _ in system.outputs] == [o.name for o in model.outputs]


def test_matmul_is_sympys_product_exactly():
    pool = [0, 1, -1, sp.Rational(1, 2), 2, x, y, -z, x * y, x + y, sp.cos(x),
            sp.Float(0.5), sp.sqrt(2) / 2, sp.Float(0.1) * x]
    rng = random.Random(1)
    for _ in range(500):
        m, k, o = rng.randint(1, 3), rng.randint(1, 3), rng.randint(1, 3)
        A = sp.Matrix(m, k, [rng.choice(pool) for _ in range(m * k)])
        B = sp.Matrix(k, o, [rng.choice(pool) for _ in range(k * o)])
        got, want = matmul(A, B), A * B
        assert got.shape == want.shape
        assert [sp.srepr(e) for e in got] == [sp.srepr(e) for e in want], (A, B)
