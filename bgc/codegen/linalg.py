"""Stage **kernels**: the linear-algebra kernels of a generated module, in LLVM IR.

Fixed routines, the same for every model but for the module's prefix ``P``:
- written as IR text in template files rendered by Jinja (as the module itself is):
  ``templates/tape.ll.j2`` (the Jacobian's compressed forward-mode tape, its scatter into J,
  the tables' interpolation) and ``templates/lu.ll.j2`` (dense LU with partial pivoting);
- built by ``Asm``, a small IR builder with counted loops, where the routine's loops nest
  over tables (``splu_ir``: sparse LU on an ``elimination.Plan``; ``lstsq_ir``: least
  squares through LAPACK's SVD for a block whose rank is below its size; ``assemble_ir``
  and ``packed_ir``: a constraint block's ``A = -K B`` from its non-zeros; ``ldl_ir``:
  L D L^T of a symmetric one, packed).

And per linear block (``LinearBlocks``, what the module assembly ``kernels.Module`` does
for each ``workspace.Block``): its function ``@<P>_block<index>``, which forms A where
asked and solves on the block's plan, falling back to partial pivoting, and the call of it
(or of least squares, where the block's rank at run time is below its size).
"""

from __future__ import annotations

import jinja2
import numpy as np

from bgc.codegen import elimination
from bgc.codegen.lowering import Function, double
from bgc.codegen.workspace import Block

_ENV = jinja2.Environment(loader=jinja2.PackageLoader("bgc.codegen", "templates"),
                          autoescape=False, keep_trailing_newline=True, trim_blocks=True,
                          undefined=jinja2.StrictUndefined)
# the singular pivot of dense LU, relative to the largest |A|
LU_TINY = 1e-13


def tape_ir(P: str) -> str:
    """``@<P>_tape``, ``@<P>_scatter``, ``@<P>_interp`` (``templates/tape.ll.j2``)."""
    return _ENV.get_template("tape.ll.j2").render(P=P)


def lu_ir(P: str) -> str:
    """``@<P>_lu(n, m, A, B, LU)``: A X = B by LU with partial pivoting
    (``templates/lu.ll.j2``)."""
    return _ENV.get_template("lu.ll.j2").render(P=P, tiny=double(LU_TINY))


MEMSET = "declare void @llvm.memset.p0i8.i64(i8*, i8, i64, i1)"
MEMCPY = "declare void @llvm.memcpy.p0i8.p0i8.i64(i8*, i8*, i64, i1)"


class Asm:
    """Hand-written IR with counted loops (their counters in allocas, which LLVM's
    mem2reg turns into registers): the least-squares solve and the A = -K B product."""

    def __init__(self, header: str, counters: list[str]):
        self.lines = [header, "entry:"] + [f"  %{c} = alloca i64" for c in counters]
        self.k = 0

    def __call__(self, text: str) -> str:
        self.lines.append("  " + text)
        return text.split(" = ", 1)[0] if " = " in text else ""

    def tmp(self) -> str:
        self.k += 1
        return f"%t{self.k}"

    def op(self, text: str) -> str:
        r = self.tmp()
        self(f"{r} = {text}")
        return r

    def label(self, name: str):
        self.lines.append(f"{name}:")

    def at(self, base: str, index: str, kind: str = "double") -> str:
        return self.op(f"getelementptr inbounds {kind}, {kind}* {base}, i64 {index}")

    def load(self, base: str, index: str) -> str:
        return self.op(f"load double, double* {self.at(base, index)}, align 8")

    def store(self, value: str, base: str, index: str):
        self(f"store double {value}, double* {self.at(base, index)}, align 8")

    def loop(self, counter: str, lo: str, hi: str, body):
        """for counter in range(lo, hi): body(value of counter)."""
        self.k += 1
        k = self.k
        self(f"store i64 {lo}, i64* %{counter}")
        self(f"br label %L{k}.head")
        self.label(f"L{k}.head")
        i = self.op(f"load i64, i64* %{counter}")
        self(f"%L{k}.c = icmp slt i64 {i}, {hi}")
        self(f"br i1 %L{k}.c, label %L{k}.body, label %L{k}.end")
        self.label(f"L{k}.body")
        body(i)
        nxt = self.op(f"add i64 {i}, 1")
        self(f"store i64 {nxt}, i64* %{counter}")
        self(f"br label %L{k}.head")
        self.label(f"L{k}.end")

    def when(self, cond: str, body):
        """if cond: body()."""
        self.k += 1
        k = self.k
        self(f"br i1 {cond}, label %W{k}.then, label %W{k}.end")
        self.label(f"W{k}.then")
        body()
        self(f"br label %W{k}.end")
        self.label(f"W{k}.end")

    def accumulate(self, value: str):
        """%acc += value."""
        total = self.op(f"fadd double {self.op('load double, double* %acc')}, {value}")
        self(f"store double {total}, double* %acc")

    def text(self) -> str:
        return "\n".join(self.lines + ["}"])


def lstsq_ir(P: str) -> str:
    """``@<P>_lstsq(n, m, A, B, r, ws)``: redundant constraints (rank r < n) share the load
    by least squares, as the numba code before it did: the pseudo-inverse through LAPACK's
    dgesdd (scipy's, as numpy's), keeping r singular values. One below 1e-10 of the
    largest, a non-finite A or a failed SVD is a singular configuration: X is NaN. B
    (n x m, row-major) is overwritten with X; ``ws`` holds ``workspace.lstsq_work(n,
    m)`` doubles.
    A's buffer read as column-major is A^T = U' S V'^T, so A = V' S U'^T: A's left
    singular vectors are the rows of V'^T, its right ones the columns of U'."""
    a = Asm(f"define void @{P}_lstsq(i64 %n, i64 %m, double* noalias %A, "
            f"double* noalias %B, i64 %r, double* noalias %ws) nounwind {{",
            ["i", "j", "q"])
    for v, ty in (("jobz", "i8"), ("dim", "i32"), ("lwork", "i32"), ("info", "i32"),
                  ("acc", "double")):
        a(f"%{v} = alloca {ty}")
    nn = a.op("mul i64 %n, %n")
    nm = a.op("mul i64 %n, %m")
    fail = "%singular"
    # any non-finite entry: x - x is NaN
    def finite(i):
        v = a.load("%A", i)
        z = a.op(f"fsub double {v}, {v}")
        bad = a.op(f"fcmp uno double {z}, {z}")
        go_on = a.tmp()[1:]
        a(f"br i1 {bad}, label {fail}, label %{go_on}")
        a.label(go_on)
    a.loop("i", "0", nn, finite)
    ac, u = "%ws", a.at("%ws", nn)
    vt = a.at(u, nn)
    s = a.at(vt, nn)
    wm = a.at(s, "%n")
    work = a.at(wm, nm)
    lw = a.op(f"add i64 {a.op(f'mul i64 {nn}, 7')}, {a.op('mul i64 %n, 12')}")
    iwork = a.op(f"bitcast double* {a.at(work, lw)} to i32*")
    a(f"call void @llvm.memcpy.p0i8.p0i8.i64(i8* {a.op(f'bitcast double* {ac} to i8*')}, "
      f"i8* {a.op('bitcast double* %A to i8*')}, i64 {a.op(f'mul i64 {nn}, 8')}, i1 false)")
    a("store i8 65, i8* %jobz")                                          # 'A'
    a(f"store i32 {a.op('trunc i64 %n to i32')}, i32* %dim")
    a(f"store i32 {a.op(f'trunc i64 {lw} to i32')}, i32* %lwork")
    a(f"call void @{P}_dgesdd(i8* %jobz, i32* %dim, i32* %dim, double* {ac}, i32* %dim, "
      f"double* {s}, double* {u}, i32* %dim, double* {vt}, i32* %dim, double* {work}, "
      f"i32* %lwork, i32* {iwork}, i32* %info)")
    info = a.op("load i32, i32* %info")
    ok = a.op(f"icmp eq i32 {info}, 0")
    rok = a.op("icmp sge i64 %r, 1")
    go = a.op(f"and i1 {ok}, {rok}")
    a(f"br i1 {go}, label %rank, label {fail}")
    a.label("rank")
    s0 = a.load(s, "0")
    sr = a.load(s, a.op("add i64 %r, -1"))
    small = a.op(f"fcmp ole double {sr}, {a.op(f'fmul double {double(1e-10)}, {s0}')}")
    a(f"br i1 {small}, label {fail}, label %solve")
    a.label("solve")

    def w_row(q):                       # W[q, c] = sum_i V'^T[q, i] B[i, c] / s[q]
        def w_col(c):
            a("store double 0.0, double* %acc")

            def term(i):
                x = a.load(vt, a.op(f"add i64 {q}, {a.op(f'mul i64 {i}, %n')}"))
                b = a.load("%B", a.op(f"add i64 {a.op(f'mul i64 {i}, %m')}, {c}"))
                a.accumulate(a.op(f"fmul double {x}, {b}"))
            a.loop("i", "0", "%n", term)
            total = a.op("load double, double* %acc")
            a.store(a.op(f"fdiv double {total}, {a.load(s, q)}"), wm,
                    a.op(f"add i64 {a.op(f'mul i64 {q}, %m')}, {c}"))
        a.loop("j", "0", "%m", w_col)
    a.loop("q", "0", "%r", w_row)

    def x_row(i):                       # X[i, c] = sum_q U'[i, q] W[q, c]
        def x_col(c):
            a("store double 0.0, double* %acc")

            def term(q):
                x = a.load(u, a.op(f"add i64 {i}, {a.op(f'mul i64 {q}, %n')}"))
                w = a.load(wm, a.op(f"add i64 {a.op(f'mul i64 {q}, %m')}, {c}"))
                a.accumulate(a.op(f"fmul double {x}, {w}"))
            a.loop("q", "0", "%r", term)
            a.store(a.op("load double, double* %acc"), "%B",
                    a.op(f"add i64 {a.op(f'mul i64 {i}, %m')}, {c}"))
        a.loop("j", "0", "%m", x_col)
    a.loop("i", "0", "%n", x_row)
    a("ret void")
    a.label("singular")
    a.loop("i", "0", nm, lambda i: a.store(double(float("nan")), "%B", i))
    a("ret void")
    return a.text()




def table_entry(a: Asm, base: str, i: str) -> str:
    """``base[i]`` of an i64 table."""
    return a.op(f"load i64, i64* {a.at(base, i, 'i64')}, align 8")


def assemble_ir(P: str) -> str:
    """``@<P>_assemble(n, d, A, K, F, full, na, apos, ne, kpos, krow, bptr, bcol)``:
    A = -K F (K: n x d, F: d x n) from their non-zeros: K's at ``kpos`` (flat, in rows
    ``krow``), F's row q at columns ``bcol[bptr[q]:bptr[q+1]]``. A is zeroed first where
    it is non-zero (``apos``), or everywhere (``full``: for a dense solve)."""
    a = Asm(f"define void @{P}_assemble(i64 %n, i64 %d, double* noalias %A, "
            f"double* noalias %K, double* noalias %F, i1 %full, i64 %na, i64* %apos, "
            f"i64 %ne, i64* %kpos, i64* %krow, i64* %bptr, i64* %bcol) nounwind {{",
            ["e", "r"])
    a("br i1 %full, label %all, label %some")
    a.label("all")
    nbytes = a.op(f"mul i64 {a.op('mul i64 %n, %n')}, 8")
    a(f"call void @llvm.memset.p0i8.i64(i8* {a.op('bitcast double* %A to i8*')}, i8 0, "
      f"i64 {nbytes}, i1 false)")
    a("br label %sum")
    a.label("some")
    a.loop("e", "0", "%na", lambda e: a.store("0.0", "%A", table_entry(a, "%apos", e)))
    a("br label %sum")
    a.label("sum")

    def entry(e):
        pos, i = table_entry(a, "%kpos", e), table_entry(a, "%krow", e)
        q = a.op(f"sub i64 {pos}, {a.op(f'mul i64 {i}, %d')}")
        c = a.load("%K", pos)
        row, frow = a.op(f"mul i64 {i}, %n"), a.op(f"mul i64 {q}, %n")

        def update(r):
            j = table_entry(a, "%bcol", r)
            at = a.op(f"add i64 {row}, {j}")
            f = a.load("%F", a.op(f"add i64 {frow}, {j}"))
            a.store(a.op(f"fsub double {a.load('%A', at)}, {a.op(f'fmul double {c}, {f}')}"),
                    "%A", at)
        a.loop("r", table_entry(a, "%bptr", q), table_entry(a, "%bptr", a.op(f"add i64 {q}, 1")),
               update)
    a.loop("e", "0", "%ne", entry)
    a("ret void")
    return a.text()


def negate_ir(P: str) -> str:
    """``@<P>_negate(J, w, k, src, dst)``: J[dst[e]] = -w[src[e]] for e < k."""
    a = Asm(f"define internal void @{P}_negate(double* noalias %J, double* noalias %w, "
            f"i64 %k, i64* %src, i64* %dst) nounwind {{", ["e"])
    a.loop("e", "0", "%k", lambda e: a.store(
        a.op(f"fneg double {a.load('%w', table_entry(a, '%src', e))}"), "%J",
        table_entry(a, "%dst", e)))
    a("ret void")
    return a.text()




def packed_ir(P: str) -> str:
    """What packed blocks share: ``@<P>_assemble_packed(A, K, F, ne, kptr, kb, tgt)``,
    A[tgt[t]] -= K[e] F[kb[t]] over K's entries e and their products t in
    ``kptr[e]:kptr[e+1]`` (those onto the lower triangle); ``@<P>_raise(A, R, k,
    diag)``, A[diag[e]] += R[e]; ``@<P>_nanfill(X, n, m)``; and the factorization
    (``ldl_ir``)."""
    a = Asm(f"define internal void @{P}_assemble_packed(double* noalias %A, double* "
            f"noalias %K, double* noalias %F, i64 %ne, i64* %kptr, i64* %kb, "
            f"i64* %tgt) nounwind {{", ["e", "t"])

    def entry(e):
        c = a.load("%K", e)

        def product(t):
            at = table_entry(a, "%tgt", t)
            f = a.load("%F", table_entry(a, "%kb", t))
            a.store(a.op(f"fsub double {a.load('%A', at)}, {a.op(f'fmul double {c}, {f}')}"),
                    "%A", at)
        a.loop("t", table_entry(a, "%kptr", e), table_entry(a, "%kptr", a.op(f"add i64 {e}, 1")),
               product)
    a.loop("e", "0", "%ne", entry)
    a("ret void")
    b = Asm(f"define internal void @{P}_raise(double* noalias %A, double* noalias %R, "
            f"i64 %k, i64* %diag) nounwind {{", ["e"])

    def raise_(e):
        at = table_entry(b, "%diag", e)
        b.store(b.op(f"fadd double {b.load('%A', at)}, {b.load('%R', e)}"), "%A", at)
    b.loop("e", "0", "%k", raise_)
    b("ret void")
    c = Asm(f"define internal void @{P}_nanfill(double* noalias %X, i64 %n, i64 %m) "
            f"nounwind {{", ["e"])
    c.loop("e", "0", c.op("mul i64 %n, %m"), lambda e: c.store(double(float("nan")), "%X", e))
    c("ret void")
    return "\n\n".join((a.text(), b.text(), c.text(), ldl_ir(P)))


def ldl_ir(P: str) -> str:
    """``i1 @<P>_ldl(n, m, nl, A, X, LU, perm, lptr, lidx, rptr, rk, rq)``: solve A X = B
    (X holds B, n x m row-major; overwritten) for a symmetric definite A held as its
    lower triangle in the plan's order (a packed block: the diagonal, then L's lists
    ``lidx[lptr[k]:lptr[k+1]]``, rows ascending), by L D L^T on that structure. Left-
    looking: column j gathered into a dense row of n (``LU`` after the factors), updated
    by the columns k whose L has row j (``rk[rptr[j]:rptr[j+1]]``, that entry at
    ``rq``), then scaled: half the multiply-adds of LU, every factor read in order, and
    ``LU`` holds n + nl + 2n doubles (the factors, the row, a column of X). False, X
    untouched, where a pivot is zero, not finite or of the other sign than the first (A
    not definite)."""
    a = Asm(f"define i1 @{P}_ldl(i64 %n, i64 %m, i64 %nl, double* noalias %A, double* "
            f"noalias %X, double* noalias %LU, i64* %perm, i64* %lptr, i64* %lidx, "
            f"i64* %rptr, i64* %rk, i64* %rq) nounwind {{", ["k", "q", "s", "c"])
    a("%big = alloca double")
    a("%acc = alloca double")
    a("store double 0.0, double* %big")
    fabs = "call double @llvm.fabs.f64(double {})"
    size = a.op("add i64 %n, %nl")
    lv = a.at("%LU", "%n")                      # L's entries
    w = a.at("%LU", size)                       # the dense row
    x = a.at(w, "%n")                           # a column of X

    def copy(k):                                # the factors start as A; its largest
        v = a.load("%A", k)
        a.store(v, "%LU", k)
        mag, big = a.op(fabs.format(v)), a.op("load double, double* %big")
        more = a.op(f"fcmp ogt double {mag}, {big}")
        a(f"store double {a.op(f'select i1 {more}, double {mag}, double {big}')}, "
          "double* %big")
    a.loop("k", "0", size, copy)
    tiny = a.op(f"fmul double {double(1e-300)}, {a.op('load double, double* %big')}")

    def span(ptr, k):
        return table_entry(a, ptr, k), table_entry(a, ptr, a.op(f"add i64 {k}, 1"))

    def column(j):
        a.store(a.load("%LU", j), w, j)
        a.loop("q", *span("%lptr", j), lambda q: a.store(
            a.load(lv, q), w, table_entry(a, "%lidx", q)))

        def update(s):                          # w -= L[:, k] D[k] L[j, k], rows >= j
            k = table_entry(a, "%rk", s)
            q0 = table_entry(a, "%rq", s)
            t = a.op(f"fmul double {a.load(lv, q0)}, {a.load('%LU', k)}")

            def sub(q):
                i = table_entry(a, "%lidx", q)
                a.store(a.op(f"fsub double {a.load(w, i)}, "
                             f"{a.op(f'fmul double {a.load(lv, q)}, {t}')}"), w, i)
            a.loop("q", q0, table_entry(a, "%lptr", a.op(f"add i64 {k}, 1")), sub)
        a.loop("s", *span("%rptr", j), update)
        d = a.load(w, j)
        same = a.op(f"fmul double {d}, {a.load('%LU', '0')}")    # the first pivot's sign
        ok = a.op(f"and i1 {a.op(f'fcmp ogt double {a.op(fabs.format(d))}, {tiny}')}, "
                  f"{a.op(f'fcmp ogt double {same}, 0.0')}")
        go = a.tmp()[1:]
        a(f"br i1 {ok}, label %{go}, label %fail")
        a.label(go)
        a.store(d, "%LU", j)
        a.loop("q", *span("%lptr", j), lambda q: a.store(
            a.op(f"fdiv double {a.load(w, table_entry(a, '%lidx', q))}, {d}"), lv, q))
    a.loop("k", "0", "%n", column)

    def solve(c):
        def at(i):
            row = table_entry(a, "%perm", i)
            return a.op(f"add i64 {a.op(f'mul i64 {row}, %m')}, {c}")
        a.loop("k", "0", "%n", lambda i: a.store(a.load("%X", at(i)), x, i))

        def forward(k):
            xk = a.load(x, k)

            def sub(q):
                i = table_entry(a, "%lidx", q)
                a.store(a.op(f"fsub double {a.load(x, i)}, "
                             f"{a.op(f'fmul double {a.load(lv, q)}, {xk}')}"), x, i)
            a.loop("q", *span("%lptr", k), sub)
        a.loop("k", "0", "%n", forward)
        a.loop("k", "0", "%n", lambda k: a.store(
            a.op(f"fdiv double {a.load(x, k)}, {a.load('%LU', k)}"), x, k))

        def backward(kk):
            k = a.op(f"sub i64 {a.op('add i64 %n, -1')}, {kk}")
            a(f"store double {a.load(x, k)}, double* %acc")

            def sub(q):
                i = table_entry(a, "%lidx", q)
                a.accumulate(a.op(f"fneg double "
                                  f"{a.op(f'fmul double {a.load(lv, q)}, {a.load(x, i)}')}"))
            a.loop("q", *span("%lptr", k), sub)
            a.store(a.op("load double, double* %acc"), x, k)
        a.loop("k", "0", "%n", backward)
        a.loop("k", "0", "%n", lambda i: a.store(a.load(x, i), "%X", at(i)))
    a.loop("c", "0", "%m", solve)
    a("ret i1 true")
    a.label("fail")
    a("ret i1 false")
    return a.text()


def splu_ir(P: str, spd: bool = False) -> str:
    """``i1 @<P>_splu(n, m, A, X, LU, rows, cols, lptr, lidx, uptr, uidx)``: solve A X = B
    (X holds B, n x m row-major; overwritten) by LU of ``A[rows][:, cols]`` on its
    diagonal along an ``elimination.Plan``, touching only the filled structure. False,
    X untouched, on a pivot not above 1e-13 of the largest |A| (what the dense LU calls
    singular) or an entry grown past ``GROWTH_LIMIT`` times it: the caller then pivots.
    LU holds n^2 + n doubles (the factors, held dense in the plan's order; a column).
    ``spd`` (``@<P>_splu_spd``, a regularized constraint block, symmetric positive
    definite): the multipliers of L are not bounded (they reach 1/sqrt(eps) there while
    the reduced matrices do not grow: elimination is as stable as Cholesky), U is."""
    name = "_spd" if spd else ""
    a = Asm(f"define i1 @{P}_splu{name}(i64 %n, i64 %m, double* noalias %A, double* "
            f"noalias %X, double* noalias %LU, i64* %rows, i64* %cols, i64* %lptr, "
            f"i64* %lidx, i64* %uptr, i64* %uidx) nounwind {{",
            ["k", "q", "r", "c"])
    a("%big = alloca double")
    a("%acc = alloca double")
    a("store double 0.0, double* %big")
    x = a.at("%LU", a.op("mul i64 %n, %n"))
    fabs = "call double @llvm.fabs.f64(double {})"

    def at(i, j):
        return a.op(f"add i64 {a.op(f'mul i64 {i}, %n')}, {j}")

    def span(ptr, k):
        return table_entry(a, ptr, k), table_entry(a, ptr, a.op(f"add i64 {k}, 1"))

    def check(ok):                      # on to the next block, or give up
        go = a.tmp()[1:]
        a(f"br i1 {ok}, label %{go}, label %fail")
        a.label(go)

    def take(i, j, ri, cj):             # LU[i, j] = A[ri, cj]; track the largest
        v = a.load("%A", at(ri, cj))
        a.store(v, "%LU", at(i, j))
        mag, big = a.op(fabs.format(v)), a.op("load double, double* %big")
        more = a.op(f"fcmp ogt double {mag}, {big}")
        a(f"store double {a.op(f'select i1 {more}, double {mag}, double {big}')}, "
          "double* %big")

    def copy(k):
        rk, ck = table_entry(a, "%rows", k), table_entry(a, "%cols", k)
        take(k, k, rk, ck)
        a.loop("q", *span("%lptr", k), lambda q: (
            lambda i: take(i, k, table_entry(a, "%rows", i), ck))(table_entry(a, "%lidx", q)))
        a.loop("r", *span("%uptr", k), lambda r: (
            lambda j: take(k, j, rk, table_entry(a, "%cols", j)))(table_entry(a, "%uidx", r)))
    a.loop("k", "0", "%n", copy)
    big = a.op("load double, double* %big")
    limit = a.op(f"fmul double {double(elimination.GROWTH_LIMIT)}, {big}")
    # (spd: a regularized block is regular by construction, its smallest pivots the
    # weights on its redundant directions, which may lie 12 decades below its largest
    # entry: only a zero or non-finite pivot fails)
    tiny = a.op(f"fmul double {double(1e-300 if spd else 1e-13)}, {big}")

    def pivot(k):
        rk = a.at("%LU", a.op(f"mul i64 {k}, %n"))          # row k
        piv = a.load(rk, k)
        mag = a.op(fabs.format(piv))
        check(a.op(f"and i1 {a.op(f'fcmp ogt double {mag}, {tiny}')}, "
                   f"{a.op(f'fcmp ole double {mag}, {limit}')}"))

        def row(q):
            ri = a.at("%LU", a.op(f"mul i64 {table_entry(a, '%lidx', q)}, %n"))
            lik = a.op(f"fdiv double {a.load(ri, k)}, {piv}")
            a.store(lik, ri, k)

            def update(r):
                j = table_entry(a, "%uidx", r)
                v = a.op(f"fsub double {a.load(ri, j)}, "
                         f"{a.op(f'fmul double {lik}, {a.load(rk, j)}')}")
                a.store(v, ri, j)
            a.loop("r", *span("%uptr", k), update)
        a.loop("q", *span("%lptr", k), row)
    a.loop("k", "0", "%n", pivot)

    def grown(k):                       # the factors' entries, once (not per update)
        rk = a.at("%LU", a.op(f"mul i64 {k}, %n"))

        def bounded(v):
            check(a.op(f"fcmp ole double {a.op(fabs.format(v))}, {limit}"))
        if not spd:
            a.loop("q", *span("%lptr", k), lambda q: bounded(a.load(
                a.at("%LU", a.op(f"mul i64 {table_entry(a, '%lidx', q)}, %n")), k)))
        a.loop("r", *span("%uptr", k), lambda r: bounded(a.load(rk, table_entry(a, "%uidx", r))))
    a.loop("k", "0", "%n", grown)

    def column(c):
        def gather(i):
            ri = table_entry(a, "%rows", i)
            a.store(a.load("%X", a.op(f"add i64 {a.op(f'mul i64 {ri}, %m')}, {c}")), x, i)
        a.loop("k", "0", "%n", gather)

        def forward(k):
            xk = a.load(x, k)

            def sub(q):
                i = table_entry(a, "%lidx", q)
                lik = a.load("%LU", at(i, k))
                a.store(a.op(f"fsub double {a.load(x, i)}, {a.op(f'fmul double {lik}, {xk}')}"),
                        x, i)
            a.loop("q", *span("%lptr", k), sub)
        a.loop("k", "0", "%n", forward)

        def backward(kk):
            k = a.op(f"sub i64 {a.op('add i64 %n, -1')}, {kk}")
            rk = a.at("%LU", a.op(f"mul i64 {k}, %n"))
            a(f"store double {a.load(x, k)}, double* %acc")

            def sub(r):
                j = table_entry(a, "%uidx", r)
                a.accumulate(a.op(f"fneg double {a.op(f'fmul double {a.load(rk, j)}, {a.load(x, j)}')}"))
            a.loop("r", *span("%uptr", k), sub)
            a.store(a.op(f"fdiv double {a.op('load double, double* %acc')}, "
                         f"{a.load(rk, k)}"), x, k)
        a.loop("k", "0", "%n", backward)

        def scatter(i):
            ci = table_entry(a, "%cols", i)
            a.store(a.load(x, i), "%X", a.op(f"add i64 {a.op(f'mul i64 {ci}, %m')}, {c}"))
        a.loop("k", "0", "%n", scatter)
    a.loop("c", "0", "%m", column)
    a("ret i1 true")
    a.label("fail")
    a("ret i1 false")
    return a.text()



class LinearBlocks:
    """The linear blocks' functions and their calls, as the module assembly makes them:
    a mixin of ``kernels.Module``, whose ``prefix``, ``functions``, ``decls`` and ``array``
    (a constant table) it uses."""

    def block(self, blk: Block):
        """``@<prefix>_block<index>(m, A, K, F, X, LU, assemble)``: A X = B for B (n x m)
        in X, in place (``assemble``: first form A = -K F where A is non-zero): on the
        block's plan, or, where it has none or its pivots grow, with partial pivoting (A
        then formed in full). A regularized block (``reg``: an argument ``R``, eps) raises
        the diagonal of its rows by eps times itself as it forms A."""
        P, n, i = self.prefix, blk.n, blk.index
        if blk.packed:
            self._packed_block(blk)
            return
        if blk.d:
            self._form(blk)
        form = (f"  call void @{P}_block{i}_form(double* %A, double* %K, double* %F, i1 "
                "{})")
        reg = ""
        if blk.reg >= 0:
            form += f"\n  call void @{P}_block{i}_reg(double* %A, double* %R)"
            reg = ", double* noalias %R"
            self._regularize(blk)
        body = [f"define void @{P}_block{i}(i64 %m, double* noalias %A, double* noalias %K, "
                f"double* noalias %F, double* noalias %X, double* noalias %LU, "
                f"i1 %assemble{reg}) nounwind {{", "entry:"]
        if blk.d and blk.plan is not None:
            body += ["  br i1 %assemble, label %form, label %sparse", "form:",
                     form.format("false")]
        body += ["  br label %sparse", "sparse:"]
        if blk.plan is not None:
            tables = ", ".join(self.array(f"block{i}_{k}", "i64", getattr(blk.plan, k))
                               for k in elimination.Plan._fields)
            spd = "_spd" if blk.reg >= 0 else ""
            body += [f"  %ok = call i1 @{P}_splu{spd}(i64 {n}, i64 %m, double* %A, double* "
                     f"%X, double* %LU, {tables})", "  br i1 %ok, label %done, label %dense"]
        else:
            body += ["  br label %dense"]
        body += ["dense:"]
        if blk.d:           # in full (the sparse path formed only what it reads)
            body += ["  br i1 %assemble, label %full, label %lu", "full:", form.format("true"),
                     "  br label %lu", "lu:"] if blk.plan is None else [form.format("true")]
        body += [f"  call void @{P}_lu(i64 {n}, i64 %m, double* %A, double* %X, double* %LU)",
                 "  br label %done", "done:", "  ret void", "}"]
        self.functions.append("\n".join(body))

    def _packed_block(self, blk: Block):
        """A packed block's function (same arguments as ``block``'s): A = -K F into its
        lower triangle where ``assemble`` (the products onto it only: A is symmetric,
        J M^-1 J^T), its diagonal raised by the weights, then L D L^T on its plan
        (``ldl_ir``); a zero, non-finite or sign-changing pivot gives NaN."""
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
        nl = len(pl.lidx)
        self.decls.add(MEMSET)
        body = [f"define void @{P}_block{i}(i64 %m, double* noalias %A, double* noalias %K, "
                f"double* noalias %F, double* noalias %X, double* noalias %LU, "
                f"i1 %assemble, double* noalias %R) nounwind {{", "entry:",
                "  br i1 %assemble, label %form, label %solve", "form:",
                "  %a8 = bitcast double* %A to i8*",
                f"  call void @llvm.memset.p0i8.i64(i8* %a8, i8 0, i64 {8 * (n + nl)}, "
                "i1 false)",
                f"  call void @{P}_assemble_packed(double* %A, double* %K, double* %F, "
                f"i64 {len(blk.k_at)}, {t['kptr']}, {t['kb']}, {t['tgt']})",
                f"  call void @{P}_raise(double* %A, double* %R, i64 {len(blk.reg_rows)}, "
                f"{t['diag']})",
                "  br label %solve", "solve:",
                f"  %ok = call i1 @{P}_ldl(i64 {n}, i64 %m, i64 {nl}, double* %A, "
                f"double* %X, double* %LU, {t['perm']}, {t['lptr']}, {t['lidx']}, "
                f"{t['rptr']}, {t['rk']}, {t['rq']})",
                "  br i1 %ok, label %done, label %nan", "nan:",
                f"  call void @{P}_nanfill(double* %X, i64 {n}, i64 %m)",
                "  br label %done", "done:", "  ret void", "}"]
        self.functions.append("\n".join(body))

    def _regularize(self, blk: Block):
        """``@<prefix>_block<index>_reg(A, R)``: A[r, r] += R[k] on the block's
        regularized rows r = ``reg_rows[k]``."""
        n, i = blk.n, blk.index
        diag = self.array(f"block{i}_diag", "i64", [r * n + r for r in blk.reg_rows])
        diag = diag[len("i64* "):]          # the constant's address, as an operand
        a = Asm(f"define internal void @{self.prefix}_block{i}_reg(double* noalias %A, "
                 f"double* noalias %R) nounwind {{", ["e"])
        def raise_(e):
            at = table_entry(a, diag, e)
            a.store(a.op(f"fadd double {a.load('%A', at)}, {a.load('%R', e)}"), "%A", at)
        a.loop("e", "0", str(len(blk.reg_rows)), raise_)
        a("ret void")
        self.functions.append(a.text())

    def _form(self, blk: Block):
        """``@<prefix>_block<index>_form(A, K, F, full)``: a constraint block's A = -K F
        from the non-zeros of K and F (``full``: A zeroed everywhere first)."""
        n, d, i = blk.n, blk.d, blk.index
        apos = sorted(r * n + c for r, c in blk.touched())
        rows = [[] for _ in range(d)]
        for q, j in sorted(blk.b_at):
            rows[q].append(j)
        k_at = sorted(blk.k_at)
        ptr = {k: self.array(f"block{i}_{k}", "i64", v) for k, v in (
            ("apos", apos), ("kpos", [r * d + q for r, q in k_at]),
            ("krow", [r for r, _ in k_at]),
            ("bptr", np.cumsum([0] + [len(r) for r in rows])),
            ("bcol", [j for r in rows for j in r]))}
        self.functions.append("\n".join([
            f"define void @{self.prefix}_block{i}_form(double* noalias %A, double* noalias "
            f"%K, double* noalias %F, i1 %full) nounwind {{", "entry:",
            f"  call void @{self.prefix}_assemble(i64 {n}, i64 {d}, double* %A, double* %K, "
            f"double* %F, i1 %full, i64 {len(apos)}, {ptr['apos']}, i64 {len(k_at)}, "
            f"{ptr['kpos']}, {ptr['krow']}, {ptr['bptr']}, {ptr['bcol']})", "  ret void", "}"]))

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

