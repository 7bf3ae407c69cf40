"""Stage **kernels**: the linear-algebra kernels of a generated module, in LLVM IR.

Fixed routines, the same for every model but for the module's prefix ``P``, written as IR
text in template files rendered by Jinja (as the module itself is), one per routine or
family, their loops counted in named values (``templates/macros.ll.j2``):
``tape.ll.j2`` (the Jacobian's compressed forward-mode tape, its scatter into J, the
tables' interpolation), ``lu.ll.j2`` (dense LU with partial pivoting), ``splu.ll.j2``
(sparse LU on an ``elimination.Plan``, its variant for a regularized block), ``ldl.ll.j2``
(L D L^T of a packed, symmetric definite block on its plan), ``lstsq.ll.j2`` (least squares through LAPACK's SVD for a block whose rank is below
its size), ``assemble.ll.j2`` (a constraint block's ``A = -K B`` from its non-zeros),
``packed.ll.j2`` (the same onto a packed block's lower triangle, its weights on the
diagonal, NaN for a singular one) and ``negate.ll.j2`` (an open block's ``-A`` into the Jacobian) and ``schur.ll.j2`` (the
model's Jacobian from the open one, where blocks stay open).

And per linear block (``LinearBlocks``, what the module assembly ``kernels.Module`` does
for each ``workspace.Block``): its function ``@<P>_block<index>`` (``blocks.ll.j2``), which
forms A where asked and solves on the block's plan, falling back to partial pivoting, and
the call of it (or of least squares, where the block's rank at run time is below its size).
"""

from __future__ import annotations

import jinja2
import numpy as np

from bgc.codegen import elimination
from bgc.codegen.lowering import Function, double
from bgc.codegen.workspace import Block

_ENV = jinja2.Environment(loader=jinja2.PackageLoader("bgc.codegen", "templates"),
                          autoescape=False, keep_trailing_newline=True, trim_blocks=True,
                          lstrip_blocks=True, undefined=jinja2.StrictUndefined)
MEMSET = "declare void @llvm.memset.p0i8.i64(i8*, i8, i64, i1)"
MEMCPY = "declare void @llvm.memcpy.p0i8.p0i8.i64(i8*, i8*, i64, i1)"
# the singular pivot of dense LU, relative to the largest |A|
LU_TINY = 1e-13
# the smallest pivot of sparse LU, relative to the largest |A|: a block's (what the dense
# LU calls singular), and a regularized block's, regular by construction, whose smallest
# pivots are the weights on its redundant directions, which may lie 12 decades below its
# largest entry: only a zero or non-finite pivot fails
SPLU_TINY, SPD_TINY = LU_TINY, 1e-300
# a kept singular value of least squares below this, relative to the largest, is singular
LSTSQ_CUT = 1e-10


def tape_ir(P: str) -> str:
    """``@<P>_tape``, ``@<P>_scatter``, ``@<P>_interp`` (``templates/tape.ll.j2``)."""
    return _ENV.get_template("tape.ll.j2").render(P=P)


def lu_ir(P: str) -> str:
    """``@<P>_lu(n, m, A, B, LU)``: A X = B by LU with partial pivoting
    (``templates/lu.ll.j2``)."""
    return _ENV.get_template("lu.ll.j2").render(P=P, tiny=double(LU_TINY))


def schur_ir(P: str, n: int, k: int, at: int) -> str:
    """``@<P>_jac_schur(t, x, p, w, J)``: the model's Jacobian (n x n) as the Schur
    complement of the open one (k unknowns of open blocks), its scratch in w from
    ``at`` (``schur_work``) (``templates/schur.ll.j2``)."""
    return _ENV.get_template("schur.ll.j2").render(P=P, n=n, k=k, at=at)


def schur_work(n: int, k: int) -> int:
    """The scratch ``schur_ir`` needs: the open Jacobian, A_uu, A_uu^-1 A_ux, A_uu's LU."""
    return (n + k) ** 2 + 2 * k * k + k * n


def lstsq_ir(P: str) -> str:
    """``@<P>_lstsq(n, m, A, B, r, ws)``: X = pinv(A) B keeping rank r, through LAPACK's
    SVD, into B; X NaN where A is singular (``templates/lstsq.ll.j2``)."""
    return _ENV.get_template("lstsq.ll.j2").render(P=P, cut=double(LSTSQ_CUT))


def assemble_ir(P: str) -> str:
    """``@<P>_assemble(n, d, A, K, F, full, na, apos, ne, kpos, krow, bptr, bcol)``:
    a constraint block's A = -K F from the non-zeros of K and F
    (``templates/assemble.ll.j2``)."""
    return _ENV.get_template("assemble.ll.j2").render(P=P)


def negate_ir(P: str) -> str:
    """``@<P>_negate(J, w, k, src, dst)``: J[dst[e]] = -w[src[e]] for e < k
    (``templates/negate.ll.j2``)."""
    return _ENV.get_template("negate.ll.j2").render(P=P)


def packed_ir(P: str) -> str:
    """What packed blocks share (``templates/packed.ll.j2``): ``@<P>_assemble_packed(A,
    K, F, ne, kptr, kb, tgt)`` (A[tgt[t]] -= K[e] F[kb[t]] over K's entries e and their
    products t in ``kptr[e]:kptr[e+1]``, those onto the lower triangle), ``@<P>_raise(A,
    R, k, diag)`` (A[diag[e]] += R[e]), ``@<P>_nanfill(X, n, m)``; and the factorization,
    ``@<P>_ldl`` (``templates/ldl.ll.j2``: L D L^T on the block's plan, left-looking;
    false where a pivot is zero, not finite or of the other sign than the first)."""
    return "\n\n".join((_ENV.get_template("packed.ll.j2").render(P=P).rstrip("\n"),
                         ldl_ir(P)))


def ldl_ir(P: str) -> str:
    """``i1 @<P>_ldl(n, m, nl, A, X, LU, perm, lptr, lidx, rptr, rk, rq)``: A X = B in
    place for a symmetric definite A held as its lower triangle in its plan's order (a
    packed block), by L D L^T on that structure (``templates/ldl.ll.j2``)."""
    return _ENV.get_template("ldl.ll.j2").render(P=P)


def splu_ir(P: str, spd: bool = False) -> str:
    """``i1 @<P>_splu(n, m, A, X, LU, rows, cols, lptr, lidx, uptr, uidx)``: A X = B in
    place by LU on an ``elimination.Plan``'s structure; false, X untouched, where a pivot
    is too small or the factors grow past ``GROWTH_LIMIT`` (the caller then pivots).
    ``spd`` (``@<P>_splu_spd``): a regularized block, symmetric positive definite: only a
    zero or non-finite pivot fails, L unbounded (``templates/splu.ll.j2``)."""
    return _ENV.get_template("splu.ll.j2").render(
        P=P, name="_spd" if spd else "", spd=spd, packed=False,
        limit=double(elimination.GROWTH_LIMIT), tiny=double(SPD_TINY if spd else SPLU_TINY))


class LinearBlocks:
    """The linear blocks' functions and their calls, as the module assembly makes them:
    a mixin of ``kernels.Module``, whose ``prefix``, ``functions``, ``decls`` and ``array``
    (a constant table) it uses. The functions' text is ``templates/blocks.ll.j2``'s
    macros; what is here is each block's numbers and tables."""

    def block(self, blk: Block):
        """``@<prefix>_block<index>(m, A, K, F, X, LU, assemble)``: A X = B for B (n x m)
        in X, in place (``assemble``: first form A = -K F where A is non-zero): on the
        block's plan, or, where it has none or its pivots grow, with partial pivoting (A
        then formed in full). A regularized block (``reg``: an argument ``R``, eps) raises
        the diagonal of its rows by eps times itself as it forms A."""
        if blk.packed:
            self._packed_block(blk)
            return
        ir = _ENV.get_template("blocks.ll.j2").module
        P, n, i = self.prefix, blk.n, blk.index
        if blk.d:
            self._form(blk)
        if blk.reg >= 0:
            diag = self.array(f"block{i}_diag", "i64", [r * n + r for r in blk.reg_rows])
            # the constant's address, as an operand
            self.functions.append(str(ir.reg(P, i, len(blk.reg_rows), diag[len("i64* "):])))
        plan = None
        if blk.plan is not None:
            plan = ", ".join(self.array(f"block{i}_{k}", "i64", getattr(blk.plan, k))
                             for k in elimination.Plan._fields)
        self.functions.append(str(ir.block(P, i, n, bool(blk.d), plan, blk.reg >= 0)))

    def _packed_block(self, blk: Block):
        """A packed block's function (same arguments as ``block``'s): A = -K F onto its
        lower triangle where ``assemble`` (the products onto it only: A is symmetric,
        J M^-1 J^T), its diagonal raised by the weights, then L D L^T on its plan
        (``ldl.ll.j2``); a zero, non-finite or sign-changing pivot gives NaN."""
        P, n, i, pl = self.prefix, blk.n, blk.index, blk.plan
        slot = blk.a_slot
        order = np.empty(n, dtype=np.int64)
        order[pl.rows] = np.arange(n)
        by_row: dict = {}                   # B's entries by row: (column, entry)
        for e, (q, j) in enumerate(blk.b_at):
            by_row.setdefault(q, []).append((j, e))
        kptr, kb, tgt = [0], [], []         # each K entry's products onto the lower part
        for r, q in blk.k_at:
            for j, e in by_row.get(q, []):
                if order[j] <= order[r]:
                    kb.append(e)
                    tgt.append(slot[(r, j)])
            kptr.append(len(kb))
        rows: list = [[] for _ in range(n)]  # each pivot j's columns k with L[j, k]
        for k in range(n):
            for q in range(pl.lptr[k], pl.lptr[k + 1]):
                rows[pl.lidx[q]].append((k, q))
        t = {k: self.array(f"block{i}_{k}", "i64", v) for k, v in (
            ("kptr", kptr), ("kb", kb), ("tgt", tgt),
            ("diag", [slot[(r, r)] for r in blk.reg_rows]), ("perm", pl.rows),
            ("lptr", pl.lptr), ("lidx", pl.lidx),
            ("rptr", np.cumsum([0] + [len(r) for r in rows])),
            ("rk", [k for r in rows for k, _ in r]), ("rq", [q for r in rows for _, q in r]))}
        self.decls.add(MEMSET)
        self.functions.append(str(_ENV.get_template("blocks.ll.j2").module.packed_block(
            P, i, n, len(pl.lidx), len(blk.k_at), len(blk.reg_rows), t)))

    def _form(self, blk: Block):
        """``@<prefix>_block<index>_form(A, K, F, full)``: a constraint block's A = -K F
        from the non-zeros of K and F (``full``: A zeroed everywhere first)."""
        n, d, i = blk.n, blk.d, blk.index
        apos = sorted(r * n + c for r, c in blk.touched())
        rows = [[] for _ in range(d)]
        for q, j in sorted(blk.b_at):
            rows[q].append(j)
        k_at = sorted(blk.k_at)
        t = {k: self.array(f"block{i}_{k}", "i64", v) for k, v in (
            ("apos", apos), ("kpos", [r * d + q for r, q in k_at]),
            ("krow", [r for r, _ in k_at]),
            ("bptr", np.cumsum([0] + [len(r) for r in rows])),
            ("bcol", [j for r in rows for j in r]))}
        self.functions.append(str(_ENV.get_template("blocks.ll.j2").module.form(
            self.prefix, i, n, d, len(apos), len(k_at), t)))

    def solve(self, fn: Function, blk: Block, at: int, columns: int, assemble: bool):
        """A_blk X = B for B (n x columns) at w[at], in place (``assemble``: first form
        A = -K B): by the block's function, or, for a block whose rank at run time is
        below its size (redundant constraints), by least squares."""
        P, n = self.prefix, blk.n
        B, A = fn.ptr("%w", at), fn.ptr("%w", blk.a)
        K, F = (fn.ptr("%w", blk.k), fn.ptr("%w", blk.kb)) if blk.d else (A, A)
        reg = f", double* {fn.ptr('%w', blk.reg)}" if blk.reg >= 0 else ""
        call = (f"  call void @{P}_block{blk.index}(i64 {columns}, double* {A}, double* {K}, "
                f"double* {F}, double* {B}, double* {fn.ptr('%w', blk.lu)}, "
                f"i1 {'true' if assemble else 'false'}{reg})")
        if blk.rank < 0:
            fn.body.append(call)
            return
        r = fn.op(f"fptosi double {fn.load('%w', blk.rank)} to i64")
        fewer = fn.op(f"icmp slt i64 {r}, {n}")
        k = fn.n
        fn.body += [f"  br i1 {fewer}, label %ls{k}, label %lu{k}", f"ls{k}:"]
        if blk.d:                       # A in full, as the block's dense path forms it
            fn.body.append(f"  call void @{P}_block{blk.index}_form(double* {A}, "
                           f"double* {K}, double* {F}, i1 true)")
        fn.body += [f"  call void @{P}_lstsq(i64 {n}, i64 {columns}, double* {A}, "
                    f"double* {B}, i64 {r}, double* {fn.ptr('%w', blk.ls)})",
                    f"  br label %solved{k}", f"lu{k}:", call, f"  br label %solved{k}",
                    f"solved{k}:"]

