"""The kernels stage in its parts, each on its own: ``lowering`` (every node kind and its
partials, JIT-compiled and compared with sympy's values), ``workspace`` (slots and
regions that never overlap, each block's solve chosen), ``steps`` (a program's typed
steps in the order a block needs them) and the assembly (``kernels.lower``: two IR
modules LLVM accepts, the programs and entry points there). ``linalg``'s: test_linalg.py."""

from __future__ import annotations

import ctypes
import re

import llvmlite.binding as llvm
import numpy as np
import pytest
import sympy as sp
from helpers import MODELS, jit

from bgc.codegen import kernels, lowering, steps, workspace
from bgc.codegen.emit import programs
from bgc.codegen.equations import LinearBlock
from bgc.errors import BgcError
from bgc.pipeline import build

x, y = sp.symbols("x y", real=True)


class _Slots:
    """The least of a layout ``lowering.Function`` reads: no slots, no tables."""
    slot: dict = {}
    tables: dict = {}


def _lowered(exprs, grads=()):
    """f(x, y) -> [each expr's value, then each (expr, wrt)'s partial] from IR."""
    decls: set = set()
    fn = lowering.Function("f", _Slots(), {x: 0, y: 1}, {}, decls)
    k = 0
    for e in exprs:
        fn.store("%out", k, fn.val(e))
        k += 1
    for e, w in grads:
        fn.store("%out", k, fn.grad(e, [w])[w])
        k += 1
    engine = jit("\n".join(sorted(decls)) + "\n" + fn.text(linkage=""))
    proto = ctypes.CFUNCTYPE(None, ctypes.c_double, *[ctypes.c_void_p] * 4)
    f = proto(engine.get_function_address("f"))

    def call(xv, yv):
        xs, out = np.array([xv, yv]), np.zeros(k)
        f(0.0, xs.ctypes.data, None, None, out.ctypes.data)
        return out
    call.engine = engine
    return call


# one expression of each node kind the lowering knows
KINDS = {
    "Add": x + 3 * y - 2,
    "Mul": -x * y / (1 + x ** 2) ** 3,
    "Pow": x ** 5 + x ** -2 + sp.sqrt(1 + y ** 2) + 1 / sp.sqrt(2 + x ** 2) + (2 + y ** 2) ** x
    + sp.exp(y),
    "unary": sp.sin(x) + sp.cos(y) + sp.log(2 + x) + sp.Abs(x) + sp.tan(y) + sp.asin(y / 3)
    + sp.acos(y / 3) + sp.atan(x) + sp.sinh(y) + sp.cosh(x) + sp.tanh(x),
    "atan2": sp.atan2(y, x),
    "Piecewise": sp.Piecewise((x ** 2, x < 0.5), (y, sp.And(x >= 0.5, y > 0)), (x * y, True)),
    "MinMax": sp.Min(x, y, 0.3) + sp.Max(x, 2 * y),
    "sign": sp.sign(x - y),
    "Heaviside": sp.Heaviside(x - 0.1),
}


@pytest.mark.parametrize("name", sorted(KINDS))
def test_each_node_kind_lowered_and_differentiated_as_sympy(name):
    e = KINDS[name]
    f = _lowered([e], [(e, x), (e, y)])
    rng = np.random.default_rng(7)
    for xv, yv in rng.uniform(-1.2, 1.2, (6, 2)):
        at = {x: xv, y: yv}
        want = [float(e.xreplace(at)),
                float(sp.diff(e, x).xreplace(at).replace(sp.DiracDelta, lambda *a: 0)),
                float(sp.diff(e, y).xreplace(at).replace(sp.DiracDelta, lambda *a: 0))]
        got = f(xv, yv)
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12), (name, xv, yv, got, want)


def test_node_kinds_are_dispatched_by_kind_and_unknown_ones_refused():
    assert lowering.kind(x + y) == "Add" and lowering.kind(sp.sin(x)) == "unary"
    assert lowering.kind(sp.gamma(x)) is None
    fn = lowering.Function("g", _Slots(), {x: 0}, {}, set())
    with pytest.raises(BgcError, match="no code for gamma"):
        fn.val(sp.gamma(x))
    with pytest.raises(BgcError, match="no derivative for gamma"):
        fn.grad(sp.gamma(x), [x])
    assert lowering.double(0.1) == "0x3FB999999999999A"       # exact bits


@pytest.fixture(scope="module")
def loop_system():
    """rr_loop with its algebraic loop left numeric: one linear block."""
    return build(MODELS / "rr_loop.yaml", max_symbolic_loop=0).system


def test_workspace_slots_and_regions_do_not_overlap(loop_system):
    lay = workspace.Layout(loop_system, 3)
    assert sorted(lay.slot.values()) == list(range(len(lay.slot)))
    (blk,) = lay.blocks.values()
    regions = [(blk.a, blk.n * blk.n), (blk.b, blk.n * blk.columns), (blk.lu, blk.n * blk.n)]
    regions += [(v, 1) for pair in lay.tables.values() for v in pair]
    spans = sorted((a, a + n) for a, n in regions)
    assert spans[0][0] >= len(lay.slot) and spans[-1][1] <= lay.size
    assert all(e0 <= s1 for (_, e0), (s1, _) in zip(spans, spans[1:]))
    assert blk.plan is None and blk.rank < 0      # small, full rank: dense LU
    item = next(a for a in loop_system.assignments if isinstance(a, LinearBlock))
    assert blk.u == lay.slot[item.unknowns[0]] and blk.pattern().shape == (blk.n, blk.n)


def test_factor_pattern_is_the_product_structure_with_its_diagonal():
    K = [(0, 0, 1), (2, 1, 1)]
    B = [(0, 1, 1), (1, 0, 1)]
    want = np.eye(3, dtype=bool)
    want[0, 1] = want[2, 0] = True
    assert (workspace.factor_pattern(3, 2, K, B) == want).all()


def test_program_steps_write_a_block_before_solving_it(loop_system):
    lay = workspace.Layout(loop_system, 1)
    rhs, _ = programs(loop_system)[1]["rhs"]
    out = list(steps.program_steps(rhs, [(0, x), (x + y, [(1, x)])], lay))
    assert all(isinstance(s, (steps.Set, steps.Store, steps.Zero, steps.Solve, steps.Out,
                              steps.Grad)) for s in out)
    (k,) = [i for i, s in enumerate(out) if isinstance(s, steps.Solve)]
    blk = lay.blocks[out[k].index]
    before = out[:k]
    a_stores = {s.slot for s in before if isinstance(s, steps.Store)
                and blk.a <= s.slot < blk.a + blk.n * blk.n}
    b_stores = {s.slot for s in before if isinstance(s, steps.Store)
                and blk.b <= s.slot < blk.b + blk.n}
    assert a_stores and b_stores == set(range(blk.b, blk.b + blk.n))
    zero = [i for i, s in enumerate(before) if isinstance(s, steps.Zero)]
    assert zero and all(i < k for i in zero)
    assert out[-2] == steps.Out(0, x) and out[-1] == steps.Grad(x + y, [(1, x)])


def test_assembly_gives_two_modules_llvm_accepts(loop_system):
    system, progs, jt = programs(loop_system)
    kern = kernels.lower(system, "m", progs, jt)
    straight = llvm.parse_assembly(kern.ir_straight)
    loops = llvm.parse_assembly(kern.ir)
    straight.verify()
    loops.verify()
    defined = {f.name for f in loops.functions if not f.is_declaration}
    assert {"m_rhs", "m_jac", "m_out", "m_jac_full", "m_jac_vals", "m_block0", "m_lu",
            "m_rhs_entry", "m_jac_entry"} <= defined
    assert {f.name for f in straight.functions if not f.is_declaration} >= {"m_rhs_0"}
    assert kern.n_eval <= kern.n_work and [b.index for b in kern.blocks] == [0]


def test_integer_tables_kept_apart_are_declared_external_with_the_same_values(loop_system):
    """``lower(data=True)`` (a generated module's): every integer table leaves the IR,
    declared external with its length, its values in ``Kernels.data`` as the IR held them;
    the doubles stay in the IR."""
    system, progs, jt = programs(loop_system)
    inline = kernels.lower(system, "m", progs, jt)
    apart = kernels.lower(system, "m", progs, jt, data=True)
    assert inline.data is None and apart.data
    assert "x i64] [" not in apart.ir and "external" not in inline.ir
    loops = llvm.parse_assembly(apart.ir)
    loops.verify()
    for name, values in apart.data.items():
        g = loops.get_global_variable(f"m_{name}")
        assert g.is_declaration and f"[{len(values)} x i64]" in str(g.global_value_type)
        held = re.search(rf"@m_{name} = internal constant \[\d+ x i64\] \[([^\]]*)\]",
                         inline.ir)[1]
        assert [int(v.split()[1]) for v in held.split(", ")] == values
    assert apart.ir_straight == inline.ir_straight
