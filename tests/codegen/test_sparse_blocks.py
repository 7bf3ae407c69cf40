"""The constraint blocks' sparse LU (``bgc.codegen.elimination``'s plan, the kernels'
``@<prefix>_splu``): its plan on structures with a zero diagonal, the IR kernel itself on
such a block, its hand-over to partial pivoting, and a generated module that solves its
blocks sparse against the same module solving them dense."""

from __future__ import annotations

import ctypes

import numpy as np
import pytest
from helpers import MODELS, jit

from bgc.codegen import elimination, linalg, workspace
from bgc.codegen.emit import import_module
from bgc.pipeline import compile_model


def _saddle(rng, n_free: int = 6, n_mult: int = 30):
    """A KKT-like block [[0, C], [C^T, D]]: its first rows have a zero diagonal (as the
    twist rates of massless bodies in a lagrange block), sparse elsewhere."""
    n = n_free + n_mult
    a = np.zeros((n, n))
    for j in range(n_free):                   # each free unknown meets 3 multipliers
        for i in rng.choice(n_mult, 3, replace=False):
            a[j, n_free + i] = a[n_free + i, j] = rng.normal()
    for i in range(n_mult):                   # D: a banded, diagonally dominant part
        a[n_free + i, n_free + i] = 4.0 + rng.random()
        for k in (i - 1, i + 1):
            if 0 <= k < n_mult:
                a[n_free + i, n_free + k] = rng.normal() * 0.5
    return a


def _splu():
    """The IR kernel, JIT-compiled alone: f(n, m, A, X, LU, *plan tables) -> bool."""
    engine = jit("declare double @llvm.fabs.f64(double)\n" + linalg.splu_ir("t"))
    proto = ctypes.CFUNCTYPE(ctypes.c_bool, ctypes.c_int64, ctypes.c_int64,
                             *[ctypes.c_void_p] * 9)
    fn = proto(engine.get_function_address("t_splu"))
    fn.engine = engine                        # keep it alive

    def solve(a, plan, b):
        x = np.array(b, dtype=np.float64, order="C")
        lu = np.zeros(a.size + a.shape[0])
        tables = [np.ascontiguousarray(getattr(plan, k), dtype=np.int64)
                  for k in elimination.Plan._fields]
        a = np.ascontiguousarray(a)
        ok = fn(a.shape[0], x.shape[1], a.ctypes.data, x.ctypes.data, lu.ctypes.data,
                *[t.ctypes.data for t in tables])
        return ok, x
    return solve


def test_transversal_puts_a_non_zero_on_every_pivot():
    a = _saddle(np.random.default_rng(0))
    assert not np.all(np.diag(a) != 0)
    match = elimination.transversal(a != 0)
    assert np.all(a[match, np.arange(a.shape[0])] != 0)
    singular = a != 0
    singular[:, 3] = False                    # an empty column: no matching
    assert elimination.transversal(singular) is None


def test_start_values_keep_pivots_off_entries_that_start_at_zero():
    """A structural entry that is 0 at the start (a sine of an angle starting at 0) is no
    pivot when another matching exists."""
    a = _saddle(np.random.default_rng(1))
    start = a.copy()
    j = 0
    rows = np.flatnonzero(a[:, j])
    start[rows[0], j] = 0.0                   # structurally there, zero at the start
    plan = elimination.analyse(a != 0, 1.0, start)
    pivots = set(zip(plan.rows.tolist(), plan.cols.tolist()))
    assert (int(rows[0]), j) not in pivots
    assert all(start[r, c] != 0 for r, c in pivots)


def test_splu_kernel_solves_a_block_with_a_zero_diagonal():
    rng = np.random.default_rng(2)
    a = _saddle(rng)
    plan = elimination.analyse(a != 0, 1.0, a)
    assert plan.entries < a.size / 2          # sparse: fill stays well below dense
    b = rng.normal(size=(a.shape[0], 3))
    ok, x = _splu()(a, plan, b)
    assert ok
    assert np.allclose(x, np.linalg.solve(a, b), rtol=1e-12, atol=1e-12)


def test_splu_kernel_hands_a_zero_pivot_to_partial_pivoting():
    """Static pivots chosen at the start may vanish later: the kernel says so (False) and
    leaves the right-hand side as it was, for the dense LU to take."""
    rng = np.random.default_rng(3)
    a = _saddle(rng)
    plan = elimination.analyse(a != 0, 1.0, a)
    later = a.copy()
    later[plan.rows[0], plan.cols[0]] = 0.0   # the first pivot is now exactly zero
    b = rng.normal(size=(a.shape[0], 1))
    ok, x = _splu()(later, plan, b)
    assert not ok and np.array_equal(x, b)


def _ldl():
    """The packed block's L D L^T kernel, JIT-compiled alone: f(a, plan, b) -> (ok, x)
    with a (n x n) packed as a packed block holds it (``Block.lower_slots``)."""
    engine = jit("declare double @llvm.fabs.f64(double)\n" + linalg.ldl_ir("t"))
    proto = ctypes.CFUNCTYPE(ctypes.c_bool, ctypes.c_int64, ctypes.c_int64,
                             ctypes.c_int64, *[ctypes.c_void_p] * 9)
    fn = proto(engine.get_function_address("t_ldl"))

    def solve(a, plan, b):
        n, nl = a.shape[0], len(plan.lidx)
        blk = workspace.Block(0, n, 0, 0, 0, plan=plan)
        packed = np.zeros(n + nl)
        for (i, j), k in blk.lower_slots().items():
            packed[k] = a[i, j]
        rows = [[] for _ in range(n)]
        for k in range(n):
            for q in range(plan.lptr[k], plan.lptr[k + 1]):
                rows[plan.lidx[q]].append((k, q))
        tables = [np.ascontiguousarray(v, dtype=np.int64) for v in (
            plan.rows, plan.lptr, plan.lidx, np.cumsum([0] + [len(r) for r in rows]),
            [k for r in rows for k, _ in r], [q for r in rows for _, q in r])]
        x = np.array(b, dtype=np.float64, order="C")
        lu = np.zeros(n + nl + 2 * n)
        ok = fn(n, x.shape[1], nl, packed.ctypes.data, x.ctypes.data, lu.ctypes.data,
                *[t.ctypes.data for t in tables])
        return ok, x
    solve.engine = engine                     # keep it alive
    return solve


def test_ldl_kernel_solves_a_regularized_block_with_redundant_rows():
    """A regularized constraint block J M^-1 J^T + eps diag whose rows are redundant (J of
    rank below its rows) on its symmetric plan: the solution of numpy's solve to the
    round-off of its condition (12 decades); a matrix that is not definite is refused."""
    rng = np.random.default_rng(3)
    m, d = 24, 30
    J = np.zeros((m, d))
    for i in range(m):                        # a chain: each row on 4 coordinates
        J[i, rng.choice(np.arange(max(0, i - 2), min(d, i + 6)), 4, replace=False)] = \
            rng.normal(size=4)
    J[5] = J[3] - 2 * J[4]                    # redundant rows
    J[17] = J[12]
    a = J @ np.diag(rng.uniform(0.5, 2.0, d)) @ J.T
    a += 1e-8 * np.diag(np.diag(a))
    plan = elimination.analyse(a != 0, 1.0, diagonal=True)
    assert workspace.Block(0, m, 0, 0, 0, plan=plan).symmetric()
    b = rng.normal(size=(m, 2))
    ok, x = _ldl()(a, plan, b)
    assert ok
    ref = np.linalg.solve(a, b)
    assert np.abs(a @ x - b).max() <= 1e-6 * np.abs(b).max()
    assert np.abs(x - ref).max() <= 1e-4 * np.abs(ref).max()
    ok, x = _ldl()(a - 2 * np.diag(np.diag(a)) * (np.arange(m) == 7)[:, None], plan, b)
    assert not ok and np.array_equal(x, b)    # a pivot of the other sign: X untouched


@pytest.mark.parametrize("method", ["lagrange", pytest.param("zcp", marks=pytest.mark.slow)])
def test_module_solving_blocks_sparse_matches_dense(tmp_path, monkeypatch, compiled, method):
    """The four-bar's blocks, solved on their plans (the size threshold lowered), give the
    same rhs and Jacobian as the shipped threshold's dense solves, at states off the
    start (where the start's pivots are no longer exact)."""
    dense = compiled("four_bar", method)
    monkeypatch.setattr(workspace, "SPARSE_MIN", 2)
    _, path = compile_model(MODELS / "four_bar.yaml", tmp_path, method)
    assert "_splu(" in path.read_text()
    sparse = import_module(path)
    rng = np.random.default_rng(4)
    p = np.asarray(dense.PARAMS, dtype=np.float64)
    for _ in range(3):
        x = dense.X0 + 0.05 * rng.normal(size=dense.X0.shape)
        for f in ("rhs", "jac"):
            want, got = getattr(dense, f)(0.3, x, p), getattr(sparse, f)(0.3, x, p)
            assert np.allclose(got, want, rtol=1e-10, atol=1e-10 * np.abs(want).max())
