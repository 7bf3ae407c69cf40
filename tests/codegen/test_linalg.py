"""The kernels' linear algebra on its own (``bgc.codegen.linalg``, ``templates/*.ll.j2``):
each routine's template rendered, in each of its variants, to IR that LLVM parses and
verifies; then run against numpy: dense LU (and NaN for a singular
block), least squares through LAPACK's SVD on a rank-deficient block, the open blocks'
-A, the model's Jacobian as the Schur complement of the open one, and each kind of linear block's function (A stored or formed from its factors; dense
or sparse on a plan; regularized; packed), through the routines it calls."""

from __future__ import annotations

import ctypes

import llvmlite.binding as llvm
import numpy as np
import pytest
from helpers import jit

from bgc.codegen import elimination, kernels, linalg, workspace

DECLS = [linalg.MEMSET, linalg.MEMCPY, "declare double @llvm.fabs.f64(double)",
         "declare void @t_dgesdd(i8*, i32*, i32*, double*, i32*, double*, double*, i32*, "
         "double*, i32*, double*, i32*, i32*, i32*)"]
# each template's routines: its IR and the functions it defines, in order
ROUTINES = {
    "tape": (lambda: linalg.tape_ir("t"), ["t_tape", "t_scatter", "t_interp"]),
    "lu": (lambda: linalg.lu_ir("t"), ["t_lu"]),
    "lstsq": (lambda: linalg.lstsq_ir("t"), ["t_lstsq"]),
    "assemble": (lambda: linalg.assemble_ir("t"), ["t_assemble"]),
    "negate": (lambda: linalg.negate_ir("t"), ["t_negate"]),
    "schur": (lambda: "declare void @t_lu(i64, i64, double*, double*, double*)\n"
              "declare void @t_jac_full(double, double*, double*, double*, double*)\n"
              + linalg.schur_ir("t", 5, 3, 7), ["t_jac_schur"]),
    "packed": (lambda: linalg.packed_ir("t"),
               ["t_assemble_packed", "t_raise", "t_nanfill", "t_ldl"]),
    "splu": (lambda: linalg.splu_ir("t"), ["t_splu"]),
    "splu_spd": (lambda: linalg.splu_ir("t", spd=True), ["t_splu_spd"]),
}
P = ctypes.c_void_p
I64 = ctypes.c_int64


@pytest.mark.parametrize("name", sorted(ROUTINES))
def test_each_template_renders_ir_llvm_verifies(name):
    render, defined = ROUTINES[name]
    ir = render()
    assert "{{" not in ir and "{%" not in ir and "{#" not in ir
    module = llvm.parse_assembly("\n".join(DECLS + [ir]))
    module.verify()
    assert [f.name for f in module.functions if not f.is_declaration] == defined
    assert ir == render()                          # the same text every time


def test_splu_variants_differ_only_where_they_should():
    plain, spd = linalg.splu_ir("t"), linalg.splu_ir("t", spd=True)
    assert linalg.double(linalg.SPLU_TINY) in plain and linalg.double(linalg.SPD_TINY) in spd
    assert "%g.l.bounded" in plain and "%g.l.bounded" not in spd     # L unbounded: spd
    assert "define i1 @t_splu(" in plain and "define i1 @t_splu_spd(" in spd


def test_dense_lu_template_solves_and_fills_nan_when_singular():
    engine = jit("\n".join(DECLS[:3] + [linalg.lu_ir("t")]))
    lu = ctypes.CFUNCTYPE(None, I64, I64, P, P, P)(engine.get_function_address("t_lu"))
    rng = np.random.default_rng(1)
    a = rng.normal(size=(7, 7))
    b = rng.normal(size=(7, 2))
    xb, work = b.copy(), np.zeros(49)
    lu(7, 2, a.ctypes.data, xb.ctypes.data, work.ctypes.data)
    assert np.allclose(xb, np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
    a[3] = 2 * a[1]                                   # singular
    xb = b.copy()
    lu(7, 2, a.ctypes.data, xb.ctypes.data, work.ctypes.data)
    assert np.isnan(xb).all()


def _lapack(name: str) -> int:
    """The address of scipy's LAPACK routine ``name`` (as a generated module finds it)."""
    from scipy.linalg import cython_lapack
    capsule = cython_lapack.__pyx_capi__[name]
    api = ctypes.pythonapi
    api.PyCapsule_GetName.restype = ctypes.c_char_p
    api.PyCapsule_GetName.argtypes = [ctypes.py_object]
    api.PyCapsule_GetPointer.restype = ctypes.c_void_p
    api.PyCapsule_GetPointer.argtypes = [ctypes.py_object, ctypes.c_char_p]
    return api.PyCapsule_GetPointer(capsule, api.PyCapsule_GetName(capsule))


def test_lstsq_template_is_the_rank_r_pseudo_inverse_and_nan_when_singular():
    llvm.add_symbol("t_dgesdd", _lapack("dgesdd"))
    engine = jit("\n".join(DECLS + [linalg.lstsq_ir("t")]))
    lstsq = ctypes.CFUNCTYPE(None, I64, I64, P, P, I64, P)(
        engine.get_function_address("t_lstsq"))
    rng = np.random.default_rng(5)
    n, m = 7, 3
    u, _ = np.linalg.qr(rng.normal(size=(n, n)))
    v, _ = np.linalg.qr(rng.normal(size=(n, n)))
    a = u @ np.diag([4.0, 2.0, 1.0, 0.5, 0.25, 0.0, 0.0]) @ v.T     # rank 5
    b = rng.normal(size=(n, m))
    ws = np.zeros(workspace.lstsq_work(n, m))

    def solve(a, r):
        x = b.copy()
        lstsq(n, m, np.ascontiguousarray(a).ctypes.data, x.ctypes.data, r, ws.ctypes.data)
        return x
    assert np.allclose(solve(a, 5), np.linalg.pinv(a, rcond=1e-10) @ b, rtol=1e-10,
                       atol=1e-12)
    assert np.isnan(solve(a, 6)).all()             # a kept singular value at zero
    assert np.isnan(solve(a, 0)).all()
    bad = a.copy()
    bad[2, 3] = np.inf
    assert np.isnan(solve(bad, 5)).all()


def test_negate_template_writes_minus_the_entries_it_is_given():
    engine = jit(linalg.negate_ir("t").replace("define internal", "define"))
    negate = ctypes.CFUNCTYPE(None, P, P, I64, P, P)(engine.get_function_address("t_negate"))
    w = np.arange(1.0, 7.0)
    src, dst = np.array([4, 0, 2], dtype=np.int64), np.array([1, 5, 3], dtype=np.int64)
    J = np.zeros(6)
    negate(J.ctypes.data, w.ctypes.data, 3, src.ctypes.data, dst.ctypes.data)
    assert J.tolist() == [0.0, -5.0, 0.0, -3.0, 0.0, -1.0]


# a stand-in for the open Jacobian: J (na x na) is x, as given
_JAC_FULL = """define void @t_jac_full(double %t, double* %x, double* %p, double* %w, double* %J) {
entry:
  %j8 = bitcast double* %J to i8*
  %x8 = bitcast double* %x to i8*
  call void @llvm.memcpy.p0i8.p0i8.i64(i8* %j8, i8* %x8, i64 NBYTES, i1 false)
  ret void
}"""


@pytest.mark.parametrize("n, k", [(6, 4), (1, 1), (3, 7)])
def test_schur_template_is_the_jacobian_of_the_states_and_nan_when_singular(n, k):
    na, at = n + k, 5
    stub = _JAC_FULL.replace("NBYTES", str(8 * na * na))
    engine = jit("\n".join(DECLS[:3] + [stub, linalg.lu_ir("t"),
                                        linalg.schur_ir("t", n, k, at)]))
    schur = ctypes.CFUNCTYPE(None, ctypes.c_double, P, P, P, P)(
        engine.get_function_address("t_jac_schur"))
    rng = np.random.default_rng(n + 10 * k)
    a = rng.normal(size=(na, na))
    a[:n, n:][rng.random((n, k)) < 0.5] = 0.0          # A_xu sparse: its zeros skipped
    w = np.full(at + linalg.schur_work(n, k), np.nan)   # the scratch is written first

    def run(a):
        J = np.full((n, n), 7.0)
        schur(0.0, np.ascontiguousarray(a).ctypes.data, None, w.ctypes.data, J.ctypes.data)
        return J
    ref = a[:n, :n] - a[:n, n:] @ np.linalg.solve(a[n:, n:], a[n:, :n])
    assert np.allclose(run(a), ref, rtol=1e-10, atol=1e-12)
    a[n:, n:][0] = 0.0                                  # A_uu singular
    J = run(a)
    assert np.isnan(J[np.abs(a[:n, n:]).sum(axis=1) > 0]).all()
    assert np.array_equal(J[np.abs(a[:n, n:]).sum(axis=1) == 0],
                          a[:n, :n][np.abs(a[:n, n:]).sum(axis=1) == 0])


class _Module(linalg.LinearBlocks):
    """What ``LinearBlocks`` uses of the module assembly: a prefix, its functions, their
    declarations and constant tables (in the IR: no ``data`` kept apart)."""
    array = kernels.Module.array

    def __init__(self):
        self.prefix, self.functions, self.decls, self.globals = "t", [], set(), []
        self.data = None

    def text(self) -> str:
        routines = [linalg.lu_ir("t"), linalg.assemble_ir("t"), linalg.splu_ir("t"),
                    linalg.splu_ir("t", spd=True), linalg.packed_ir("t")]
        return "\n\n".join(sorted(self.decls | set(DECLS[:3])) + self.globals
                           + self.functions + routines)


# kind -> (formed from factors, on a plan, regularized, packed)
BLOCKS = {"stored": (False, False, False, False), "stored_plan": (False, True, False, False),
          "stored_spd_plan": (False, True, True, False),
          "factored": (True, False, False, False), "factored_plan": (True, True, False, False),
          "factored_reg": (True, False, True, False), "packed": (True, True, True, True)}


def _factors(rng, n: int, d: int):
    """F (d x n) sparse with full column rank (each row two entries, the first n rows a
    unit diagonal and a neighbour 3 columns on) and K = -F^T: A = -K F = F^T F, sparse and
    symmetric positive definite (what a regularized block is)."""
    f = np.zeros((d, n))
    for q in range(d):
        i = q if q < n else int(rng.integers(n))
        f[q, i] = 1.0 + rng.random()
        f[q, (i + 3) % n] = rng.normal()
    return -f.T.copy(), f


def _block(kind: str, n: int = 30, d: int = 36, m: int = 2, singular: bool = False):
    """A block of ``kind``, its function JIT-compiled, called with assemble on: (X, the
    matrix it should have solved, B, whether it was solved on its plan: sparse LU's column
    at the end of LU written, which dense LU leaves alone)."""
    factored, planned, reg, packed = BLOCKS[kind]
    rng = np.random.default_rng(sorted(BLOCKS).index(kind))
    K, F = _factors(rng, n, d)
    if singular:                    # a column of F zero: a zero row and column of A
        F[:, 4] = 0.0
    weights = 1e-3 * (1.0 + rng.random(n)) * (not singular)
    A = -K @ F
    blk = workspace.Block(0, n, 0, 0, 0, reg=0 if reg else -1,
                          reg_rows=tuple(range(n)) if reg else ())
    if factored:
        blk.d = d
        blk.k_at = tuple(zip(*np.nonzero(K)))
        blk.b_at = tuple(zip(*np.nonzero(F)))
    else:
        blk.a_at = tuple(zip(*np.nonzero(A)))
    if planned:
        blk.plan = elimination.analyse(blk.pattern(), workspace.SPARSE_WORK, A,
                                       diagonal=reg)
        assert blk.plan is not None
    want = A + np.diag(weights) if reg and factored else A
    a_buf, k_buf, f_buf = A.ravel().copy(), K.ravel().copy(), F.ravel().copy()
    if packed:
        blk.packed = True
        blk.a_slot = blk.lower_slots()
        a_buf = np.zeros(n + len(blk.plan.lidx))
        k_buf = np.array([K[i, j] for i, j in blk.k_at])
        f_buf = np.array([F[i, j] for i, j in blk.b_at])
    mod = _Module()
    mod.block(blk)
    engine = jit(mod.text())
    args = [I64, P, P, P, P, P, ctypes.c_bool] + [P] * reg
    fn = ctypes.CFUNCTYPE(None, *args)(engine.get_function_address("t_block0"))
    b = rng.normal(size=(n, m))
    x, lu = b.copy(), np.zeros(n * n + 3 * n)       # (L D L^T: n + nl + 2n of it)
    fn(m, a_buf.ctypes.data, k_buf.ctypes.data, f_buf.ctypes.data, x.ctypes.data,
       lu.ctypes.data, True, *[weights.ctypes.data] * reg)
    on_plan = bool(np.any(lu[len(blk.plan.lidx) + 2 * n:len(blk.plan.lidx) + 3 * n])) \
        if packed else bool(np.any(lu[n * n:n * n + n]))
    return x, want, b, on_plan


@pytest.mark.parametrize("kind", sorted(BLOCKS))
def test_each_kind_of_block_function_solves_its_block(kind):
    x, a, b, sparse = _block(kind)
    assert np.allclose(x, np.linalg.solve(a, b), rtol=1e-10, atol=1e-12)
    assert sparse == BLOCKS[kind][1]


def test_a_singular_packed_block_gives_nan():
    x, _, _, _ = _block("packed", singular=True)
    assert np.isnan(x).all()
