"""Stage **kernels**: an EquationSystem's run-time work as LLVM IR.

numba's compile time for one straight-line function grows faster than its length (the
SARIB's Jacobian: minutes); LLVM, given the same operations as IR, compiles them in about a
second. So everything a generated module computes is IR, compiled through llvmlite (the
LLVM binding numba itself uses) when the module is first imported on a machine; numba only
wraps it (``rhs``, ``jac``, ... stay numba functions a script can call or inline).

- **Programs**: ``rhs``, ``jac`` (its run-time partials), ``out``, ``guard``, ``con``:
  each its cone of assignments in causal order, in functions of at most ``CHUNK`` steps
  and about ``CHUNK_OPS`` instructions (LLVM's cost stays linear in the model's size).
  Values cross functions through one workspace ``w``: a slot per assigned symbol, a
  region per linear block; within a function they stay in registers. These chunks are
  a module of their own (``Kernels.ir_straight``), given only local passes.
- **Linear blocks** (algebraic loops, constraint blocks) are solved where the causal
  order reaches them, each by a function of its own (``@<prefix>_block<index>``): on the
  block's structure by sparse LU with static pivots (``bgc.codegen.elimination``'s plan,
  a loop over constant tables) where that pays, else (or where the pivots grow) LU with
  partial pivoting, or, where the constraints' rank at run time is below the block's
  size, least squares through LAPACK's SVD (scipy's dgesdd). A constraint block
  ``A = -K B`` is formed from K's and B's non-zeros only.
- **The Jacobian**: each assignment's partials by reverse-mode differentiation of its
  expression tree (``_Function.grad``: no symbolic derivative is ever formed), then the
  compressed forward-mode tape of ``bgc.codegen.jacobian`` as a loop over constant tables.
- **C entry points** ``void f(double t, double *x, double *p, double *out)`` for bgc's
  native integrators.

The IR is plain text, target-independent (no triple, no CPU), with every number written
exactly (hexadecimal doubles): the same model gives the same bytes on every machine.
"""

from __future__ import annotations

import re
import struct
from dataclasses import dataclass

import numpy as np
import sympy as sp

from bgc.codegen import elimination, instances
from bgc.codegen.equations import LinearBlock
from bgc.codegen.start import block_matrices
from bgc.errors import BgcError
from bgc.model import symbols
from bgc.model.signals import table, table_slope

# the functions' prefix while the IR is built (emit replaces it by the module's own)
PLACEHOLDER = "bgc_kernel_prefix"
CHUNK = 300          # assignments (or stores) per IR function
# a block is solved on its structure from this size, where elimination in the plan's
# order takes at most this share of dense LU's multiply-adds
SPARSE_MIN, SPARSE_WORK = 24, 0.5
# and at most about this many instructions: LLVM's passes cost more than linearly in a
# function's size, and a zcp chain's eliminated expressions make a few assignments long
CHUNK_OPS = 2000
# LLVM's IR passes at -O1 and instruction selection at -O0 (fast, local register
# allocation): on the SARIB's lagrange module 1 s instead of 11 s at -O2/-O2, and the
# rhs and Jacobian run as fast as numba's -O3 build of the same code did
IR_OPT, CODEGEN_OPT = 1, 0
# The straight-line chunks (most of the IR) take only local passes: -O1's loop passes
# find nothing in them and cost half the IR passes' time (loop vectorization alone 14 %
# on a 40-link zcp chain), while the rhs runs within a few per cent of -O1's. The loops
# (tape, solves) keep -O1 with its module passes: without them the Jacobian is 3x slower.
STRAIGHT_PASSES = ("instruction_combine", "simplify_cfg", "dead_code_elimination")

DBL = "double"
ARGS = "double %t, double* noalias %x, double* noalias %p, double* noalias %w, " \
       "double* noalias %out"
# sympy function -> LLVM intrinsic or C library function of one double
_UNARY = {sp.sin: "llvm.sin.f64", sp.cos: "llvm.cos.f64", sp.exp: "llvm.exp.f64",
          sp.log: "llvm.log.f64", sp.Abs: "llvm.fabs.f64", sp.tan: "tan", sp.asin: "asin",
          sp.acos: "acos", sp.atan: "atan", sp.sinh: "sinh", sp.cosh: "cosh",
          sp.tanh: "tanh"}
_CMP = {sp.StrictLessThan: "olt", sp.LessThan: "ole", sp.StrictGreaterThan: "ogt",
        sp.GreaterThan: "oge", sp.Equality: "oeq", sp.Unequality: "une"}


def double(v: float) -> str:
    """A double as an LLVM constant: its exact bits in hexadecimal (canonical, no noise)."""
    return "0x%016X" % struct.unpack("<Q", struct.pack("<d", float(v)))[0]


@dataclass
class Block:
    """Where linear block ``index`` lives in the workspace: A (n x n, row-major), b (n),
    u (n, the unknowns' slots), the rank's slot (-1: full rank, LU) and, for a block
    ``A = -K B``, K (n x d) and B (d x n), only their non-zeros written (``k_at``, ``b_at``:
    their positions); ``plan``: sparse LU's (None: dense)."""
    index: int
    n: int
    a: int
    b: int
    u: int
    rank: int = -1
    d: int = 0
    k: int = 0
    kb: int = 0
    lu: int = 0         # room for its LU factors (and a column, sparse)
    reg: int = -1       # regularized (``equations.Regularized``): eps's slot (-1: none)
    reg_rows: tuple = ()
    columns: int = 1    # right-hand sides (b: n x columns, row-major)
    # packed (a regularized constraint block with a plan): K, B and A hold only their
    # entries, K's and B's in their lists' order, A's in ``a_slot``'s (the entries sparse
    # LU reads): a few hundred kB where n x n and n x d regions spread over megabytes,
    # and each rhs touched them at random (IFToMM A02, N = 40: 2.9 MB for A, 4.7 MB for K)
    packed: bool = False
    a_slot: dict | None = None
    ls: int = 0         # rank < n: room for the least-squares solve (``lstsq_work``)
    k_at: tuple = ()
    b_at: tuple = ()
    a_at: tuple = ()    # a block that stores A itself: its entries' positions
    plan: elimination.Plan | None = None

    def touched(self) -> set:
        """The entries (row, column) of A that sparse LU reads: A's and its fill's."""
        pl = self.plan
        out = set(zip(*np.nonzero(self.pattern())))
        if pl is not None:
            for k in range(self.n):
                out.add((pl.rows[k], pl.cols[k]))
                out |= {(pl.rows[i], pl.cols[k]) for i in pl.lidx[pl.lptr[k]:pl.lptr[k + 1]]}
                out |= {(pl.rows[k], pl.cols[j]) for j in pl.uidx[pl.uptr[k]:pl.uptr[k + 1]]}
        return {(int(r), int(c)) for r, c in out}

    def pattern(self) -> np.ndarray:
        """A's structure: K B's, or the entries the block stores."""
        if not self.d:
            a = np.zeros((self.n, self.n), dtype=bool)
            a[tuple(np.array(self.a_at, dtype=np.int64).reshape(-1, 2).T)] = True
            return a
        k = np.zeros((self.n, self.d), dtype=np.int64)
        b = np.zeros((self.d, self.n), dtype=np.int64)
        k[tuple(np.array(self.k_at).T)] = 1
        b[tuple(np.array(self.b_at).T)] = 1
        return (k @ b) != 0


@dataclass
class Kernels:
    """The IR and what the numba side needs to know of it: the workspace size, the
    linear blocks (in the order of the solver's tables) and the tables' slots. The IR is
    two modules, compiled with different passes and linked: ``ir`` (the loops: the
    Jacobian's tape, the linear solves, the programs' drivers and entry points; -O1) and
    ``ir_straight`` (the programs' straight-line chunks; a few local passes)."""
    ir: str
    ir_straight: str
    n_work: int         # the Jacobian's workspace
    n_eval: int         # the other programs' (its first n_eval slots)
    blocks: list[Block]


class Layout:
    """Workspace slots: one per assigned symbol (a block's unknowns side by side), then a
    region per linear block, then each table's value and slope at the current t."""

    def __init__(self, system, columns: int):
        """``columns``: the most right-hand sides a block is solved for at once (the
        Jacobian's colours)."""
        self.slot: dict[sp.Symbol, int] = {}
        self.blocks: dict[int, Block] = {}
        self.size = 0
        for item in system.assignments:
            if isinstance(item, LinearBlock):
                for u in item.unknowns:
                    self._take(u)
                for v, _ in item.pre + item.chain:
                    self._take(v)
            else:
                self._take(item[0])
        start = None
        for item in system.assignments:
            if isinstance(item, LinearBlock):
                n = len(item.unknowns) // item.columns
                blk = Block(item.index, n, -1, self._region(n * item.columns),
                            self.slot[item.unknowns[0]], columns=item.columns)
                if item.rank is not None:
                    blk.rank = self._region(1)
                if item.regularize is not None:
                    blk.reg = self._region(len(item.regularize.rows))
                    blk.reg_rows = item.regularize.rows
                if item.factors is not None:
                    blk.d = item.factors[0]
                    blk.k_at = tuple((i, j) for i, j, _ in item.factors[1])
                    blk.b_at = tuple((i, j) for i, j, _ in item.factors[2])
                else:
                    blk.a_at = tuple((i, j) for i, j, _ in item.A)
                if n >= SPARSE_MIN and item.regularize is not None:   # pivots: its diagonal
                    blk.plan = elimination.analyse(blk.pattern(), SPARSE_WORK, diagonal=True)
                elif n >= SPARSE_MIN:
                    start = start if start is not None else block_matrices(system)
                    blk.plan = elimination.analyse(blk.pattern(), SPARSE_WORK,
                                                   start.get(item.index))
                blk.packed = bool(item.regularize is not None and item.factors is not None
                                  and blk.plan is not None)
                if blk.packed:
                    blk.a_slot = {rc: k for k, rc in enumerate(sorted(blk.touched()))}
                    blk.a = self._region(len(blk.a_slot))
                    blk.k, blk.kb = self._region(len(blk.k_at)), self._region(len(blk.b_at))
                else:
                    blk.a = self._region(n * n)
                    if item.factors is not None:
                        blk.k, blk.kb = (self._region(n * blk.d),
                                         self._region(blk.d * n))
                blk.lu = self._region(n * n + (n if blk.plan is not None else 0))
                if item.rank is not None:
                    blk.ls = self._region(lstsq_work(n, columns))
                self.blocks[item.index] = blk
        self.tables = {tb.index: (self._region(1), self._region(1))
                       for tb in system.tables}

    def _take(self, v):
        if v not in self.slot:
            self.slot[v] = self.size
            self.size += 1

    def _region(self, n: int) -> int:
        self.size += n
        return self.size - n


class _Function:
    """One IR function under construction: ``val`` lowers an expression to an SSA value,
    reusing what this function has already computed."""

    def __init__(self, name: str, layout: Layout, states: dict, params: dict, decls: set):
        self.name, self.layout, self.states, self.params = name, layout, states, params
        self.decls = decls
        self.body: list[str] = []
        self.n = 0
        self.env: dict = {}
        self.memo: dict = {}

    def op(self, text: str) -> str:
        self.n += 1
        r = f"%v{self.n}"
        self.body.append(f"  {r} = {text}")
        return r

    def ptr(self, base: str, i: int) -> str:
        return self.op(f"getelementptr inbounds double, double* {base}, i64 {i}")

    def load(self, base: str, i: int) -> str:
        return self.op(f"load double, double* {self.ptr(base, i)}, align 8")

    def store(self, base: str, i: int, value: str):
        self.body.append(f"  store double {value}, double* {self.ptr(base, i)}, align 8")

    def call(self, fn: str, *args: str) -> str:
        self.decls.add(f"declare double @{fn}({', '.join([DBL] * len(args))})")
        return self.op(f"call double @{fn}({', '.join(f'double {a}' for a in args)})")

    def symbol(self, s) -> str:
        if s in self.env:
            return self.env[s]
        if s is symbols.t:
            v = "%t"
        elif s in self.states:
            v = self.load("%x", self.states[s])
        elif s in self.params:
            v = self.load("%p", self.params[s])
        elif s in self.layout.slot:
            v = self.load("%w", self.layout.slot[s])
        else:
            raise BgcError(f"internal: symbol {s} has no value in generated code")
        self.env[s] = v
        return v

    def assign(self, v, e):
        value = self.val(e)
        if v in self.env:               # assigned again (a loop's chain after u = 0)
            self.memo.clear()
        self.env[v] = value
        self.store("%w", self.layout.slot[v], value)

    def val(self, e) -> str:
        if e.is_Symbol:
            return self.symbol(e)
        if e.is_Number or e.is_NumberSymbol:
            return double(float(e)) if e is not sp.zoo else double(float("nan"))
        hit = self.memo.get(e)
        if hit is None:
            hit = self.memo[e] = self._lower(e)
        return hit

    def _fold(self, opcode: str, values: list[str]) -> str:
        acc = values[0]
        for v in values[1:]:
            acc = self.op(f"{opcode} double {acc}, {v}")
        return acc

    def _power(self, base: str, n: int) -> str:
        """base**n for an integer n >= 1 by repeated squaring."""
        result, square = None, base
        while True:
            if n & 1:
                result = square if result is None else self.op(f"fmul double {result}, {square}")
            n >>= 1
            if not n:
                return result
            square = self.op(f"fmul double {square}, {square}")

    def _lower(self, e) -> str:
        if e.is_Add:
            return self._fold("fadd", [self.val(a) for a in e.args])
        if e.is_Mul:
            coeff, rest = e.as_coeff_Mul()
            num, den = [], []
            for a in sp.Mul.make_args(rest):
                if a.is_Pow and a.exp.is_Integer and a.exp < 0:
                    den.append(self.val(a.base) if a.exp == -1 else self.val(a.base ** -a.exp))
                else:
                    num.append(self.val(a))
            if coeff not in (1, -1):
                num.insert(0, self.val(coeff))
            value = self._fold("fmul", num) if num else double(1.0)
            if den:
                value = self.op(f"fdiv double {value}, {self._fold('fmul', den)}")
            return self.op(f"fneg double {value}") if coeff == -1 else value
        if e.is_Pow:
            base, ex = e.args
            if base is sp.E:
                return self.call("llvm.exp.f64", self.val(ex))
            b = self.val(base)
            if ex.is_Integer and 0 < abs(int(ex)) <= 64:
                n = int(ex)
                pos = self._power(b, abs(n))
                return pos if n > 0 else self.op(f"fdiv double {double(1.0)}, {pos}")
            if ex == sp.S.Half:
                return self.call("llvm.sqrt.f64", b)
            if ex == -sp.S.Half:
                return self.op(f"fdiv double {double(1.0)}, "
                               f"{self.call('llvm.sqrt.f64', b)}")
            return self.call("llvm.pow.f64", b, self.val(ex))
        fn = type(e)
        if fn in _UNARY:
            return self.call(_UNARY[fn], self.val(e.args[0]))
        if fn is sp.atan2:
            return self.call("atan2", self.val(e.args[0]), self.val(e.args[1]))
        if fn is sp.Piecewise:
            pieces = list(e.args)
            out = double(float("nan"))
            if pieces[-1].cond == sp.true:
                out = self.val(pieces.pop().expr)
            for piece in reversed(pieces):
                out = self.select(self.cond(piece.cond), self.val(piece.expr), out)
            return out
        if fn in (sp.Min, sp.Max):          # Python's min/max, folded left to right
            pred = "olt" if fn is sp.Min else "ogt"
            acc = self.val(e.args[0])
            for a in e.args[1:]:
                v = self.val(a)
                acc = self.select(self.op(f"fcmp {pred} double {v}, {acc}"), v, acc)
            return acc
        if fn is sp.sign:
            x = self.val(e.args[0])
            zero = self.select(self.op(f"fcmp oeq double {x}, {double(0.0)}"),
                               double(0.0), double(float("nan")))
            neg = self.select(self.op(f"fcmp olt double {x}, {double(0.0)}"),
                              double(-1.0), zero)
            return self.select(self.op(f"fcmp ogt double {x}, {double(0.0)}"),
                               double(1.0), neg)
        if fn is sp.Heaviside:
            x = self.val(e.args[0])
            h0 = float(e.args[1]) if len(e.args) > 1 else 0.5
            at0 = self.select(self.op(f"fcmp oeq double {x}, {double(0.0)}"),
                              double(h0), double(0.0))
            return self.select(self.op(f"fcmp ogt double {x}, {double(0.0)}"),
                               double(1.0), at0)
        if fn is sp.DiracDelta:
            return double(0.0)      # zero almost everywhere; no impulse in a Jacobian
        if fn in (table, table_slope):
            if e.args[1] is not symbols.t:
                raise BgcError(f"internal: a table of {e.args[1]}, not of t")
            value, slope = self.layout.tables[int(e.args[0])]
            return self.load("%w", value if fn is table else slope)
        raise BgcError(f"internal: no code for {fn.__name__} in {e}")

    # -- derivatives: reverse mode through one expression's tree ----------------------
    def grad(self, e, wrt) -> dict:
        """{w: d e / d w} as IR values for the symbols ``wrt``: the adjoint of every node
        of ``e`` that depends on them, parents before children (a node shared by two
        parents is one node, visited once). Nothing symbolic is formed; each local
        derivative reuses the node values computed for ``e``."""
        wrt = set(wrt)
        dep: dict = {}
        order: list = []

        def visit(node) -> bool:
            hit = dep.get(node)
            if hit is not None:
                return hit
            if node.is_Symbol:
                d = node in wrt
            elif node.is_Number or node.is_NumberSymbol:
                d = False
            else:
                d = False
                for a in node.args:
                    if not isinstance(a, sp.Expr):   # a Piecewise's (expr, cond) pairs
                        a = a.args[0]
                    d = visit(a) or d
                if d:
                    order.append(node)
            dep[node] = d
            return d

        visit(e)
        adj = {e: double(1.0)}
        for node in reversed(order):
            a = adj.pop(node, None)
            if a is None:       # reached only through a zero derivative (sign, a step)
                continue
            for child, local in self._local(node, dep):
                if local is None:
                    c = a
                elif isinstance(local, tuple):        # ("select", i1): a where it holds
                    c = self.select(local[1], a, double(0.0))
                else:
                    c = self.op(f"fmul double {a}, {local}")
                adj[child] = self.op(f"fadd double {adj[child]}, {c}") if child in adj else c
        return {w: adj.get(w, double(0.0)) for w in wrt}

    def _local(self, node, dep):
        """(child, d node / d child) for the children of ``node`` that depend on the
        variables (None: 1; ("select", c): 1 where c holds, else 0)."""
        fn = type(node)
        if node.is_Add:
            return [(a, None) for a in node.args if dep.get(a)]
        if node.is_Mul:
            args = node.args
            vals = [self.val(a) for a in args]
            out = []
            for i, a in enumerate(args):
                if dep.get(a):
                    others = vals[:i] + vals[i + 1:]
                    out.append((a, self._fold("fmul", others) if others else None))
            return out
        if node.is_Pow:
            base, ex = node.args
            out = []
            if base is sp.E:
                return [(ex, self.val(node))] if dep.get(ex) else []
            if dep.get(base):
                if ex == 1:
                    out.append((base, None))
                elif ex.is_Number:
                    out.append((base, self.op(f"fmul double {self.val(ex)}, "
                                              f"{self.val(base ** (ex - 1))}")))
                else:
                    q = self.op(f"fdiv double {self.val(node)}, {self.val(base)}")
                    out.append((base, self.op(f"fmul double {self.val(ex)}, {q}")))
            if dep.get(ex):
                out.append((ex, self.op(f"fmul double {self.val(node)}, "
                                        f"{self.call('llvm.log.f64', self.val(base))}")))
            return out
        if fn is sp.atan2:
            y, x = node.args
            vy, vx = self.val(y), self.val(x)
            r = self.op(f"fadd double {self.op(f'fmul double {vx}, {vx}')}, "
                        f"{self.op(f'fmul double {vy}, {vy}')}")
            out = []
            if dep.get(y):
                out.append((y, self.op(f"fdiv double {vx}, {r}")))
            if dep.get(x):
                out.append((x, self.op(f"fneg double {self.op(f'fdiv double {vy}, {r}')}")))
            return out
        if fn is sp.Piecewise:
            out, before = [], "false"
            for piece in node.args:
                c = self.cond(piece.cond)
                if dep.get(piece.expr):
                    free = self.op(f"xor i1 {before}, true")
                    out.append((piece.expr, ("select", self.op(f"and i1 {c}, {free}"))))
                before = self.op(f"or i1 {before}, {c}")
            return out
        if fn in (sp.Min, sp.Max):            # to the argument Python's min/max picks
            pred = "olt" if fn is sp.Min else "ogt"
            acc, pick = self.val(node.args[0]), "0"
            for i, a in enumerate(node.args[1:], 1):
                v = self.val(a)
                c = self.op(f"fcmp {pred} double {v}, {acc}")
                acc = self.select(c, v, acc)
                pick = self.op(f"select i1 {c}, i64 {i}, i64 {pick}")
            return [(a, ("select", self.op(f"icmp eq i64 {pick}, {i}")))
                    for i, a in enumerate(node.args) if dep.get(a)]
        if fn in (sp.sign, sp.Heaviside, sp.DiracDelta, table, table_slope):
            return []                         # zero almost everywhere
        if fn in _LOCAL and len(node.args) == 1:
            x = node.args[0]
            return [(x, _LOCAL[fn](self, x, node))] if dep.get(x) else []
        raise BgcError(f"internal: no derivative for {fn.__name__} in {node}")

    def select(self, c: str, a: str, b: str) -> str:
        return self.op(f"select i1 {c}, double {a}, double {b}")

    def cond(self, c) -> str:
        """An i1 value for a condition (relations, and/or/not, true/false)."""
        if c == sp.true or c == sp.false:
            return "true" if c == sp.true else "false"
        if type(c) in _CMP:
            return self.op(f"fcmp {_CMP[type(c)]} double {self.val(c.lhs)}, "
                           f"{self.val(c.rhs)}")
        if isinstance(c, (sp.And, sp.Or)):
            parts = [self.cond(a) for a in c.args]
            opcode = "and" if isinstance(c, sp.And) else "or"
            acc = parts[0]
            for q in parts[1:]:
                acc = self.op(f"{opcode} i1 {acc}, {q}")
            return acc
        if isinstance(c, sp.Not):
            return self.op(f"xor i1 {self.cond(c.args[0])}, true")
        raise BgcError(f"internal: no code for the condition {c}")

    def text(self, linkage: str = "internal ") -> str:
        return "\n".join([f"define {linkage}void @{self.name}({ARGS}) noinline nounwind {{",
                          "entry:", *self.body, "  ret void", "}"])


def _one_over_sqrt(f, arg):
    """1 / sqrt(arg)."""
    return f.op(f"fdiv double {double(1.0)}, {f.call('llvm.sqrt.f64', f.val(arg))}")


# d f(x) / dx for the functions of one argument, from x and the node f(x) itself
_LOCAL = {
    sp.sin: lambda f, x, n: f.val(sp.cos(x)),
    sp.cos: lambda f, x, n: f.op(f"fneg double {f.val(sp.sin(x))}"),
    sp.exp: lambda f, x, n: f.val(n),
    sp.log: lambda f, x, n: f.op(f"fdiv double {double(1.0)}, {f.val(x)}"),
    sp.tan: lambda f, x, n: f.op(f"fadd double {double(1.0)}, "
                                 f"{f.op(f'fmul double {f.val(n)}, {f.val(n)}')}"),
    sp.asin: lambda f, x, n: _one_over_sqrt(f, 1 - x ** 2),
    sp.acos: lambda f, x, n: f.op(f"fneg double {_one_over_sqrt(f, 1 - x ** 2)}"),
    sp.atan: lambda f, x, n: f.op(f"fdiv double {double(1.0)}, {f.val(1 + x ** 2)}"),
    sp.sinh: lambda f, x, n: f.val(sp.cosh(x)),
    sp.cosh: lambda f, x, n: f.val(sp.sinh(x)),
    sp.tanh: lambda f, x, n: f.op(f"fsub double {double(1.0)}, "
                                  f"{f.op(f'fmul double {f.val(n)}, {f.val(n)}')}"),
    sp.Abs: lambda f, x, n: f.val(sp.sign(x)),
}


def _steps(items, outputs, layout: Layout):
    """A program's work as (kind, ...) steps, and where it is cut: ``("solve", index)``
    after the stores of each linear block."""
    for item in items:
        if not isinstance(item, LinearBlock):
            yield ("set", item[0], item[1])
            continue
        blk = layout.blocks[item.index]
        n = blk.n
        for v, e in item.pre:
            yield ("set", v, e)
        if item.factors is not None:        # A = -K B, formed from their non-zeros
            _, K, B = item.factors
            for k, (i, j, e) in enumerate(K):
                yield ("store", blk.k + (k if blk.packed else i * blk.d + j), e)
            for k, (i, j, e) in enumerate(B):
                yield ("store", blk.kb + (k if blk.packed else i * n + j), e)
        else:
            yield ("zero", blk.a, n * n)
            for i, j, e in item.A:
                yield ("store", blk.a + i * n + j, e)
        if item.b is None:      # the right-hand side at u = 0, through the chain
            for u in item.unknowns:
                yield ("set", u, sp.S.Zero)
            for v, e in item.chain:
                yield ("set", v, e)
            for i, e in enumerate(item.tear_eqs):
                yield ("store", blk.b + i, e)
        else:
            for i, e in enumerate(item.b):
                yield ("store", blk.b + i, e)
        if item.rank is not None:
            yield ("store", blk.rank, item.rank)
        if item.regularize is not None:
            for k, w in enumerate(item.regularize.weights):
                yield ("store", blk.reg + k, w)
        yield ("solve", item.index)
    for out in outputs:
        if isinstance(out[1], list):          # (e, [(slot, w)]): pv[slot] = d e / d w
            yield ("grad",) + tuple(out)
        else:
            yield ("out",) + tuple(out)


# The Jacobian tape as a loop (see bgc.codegen.jacobian): row r of the compressed sensitivities d
# (n_rows x nc) is the sum over its entries m of pv[m] times row src[m],
# or, for src[m] < 0, added into column -src[m]-1. @{P} is the module's prefix. Not
# inlined: it is called once per stretch between linear blocks, and -O1 vectorized each
# inlined copy (a 40-link zcp chain: 120 copies, half the IR passes' time), while the
# Jacobian ran no faster (SARIB parasitic and lagrange, best of 30 alternated runs).
_TAPE = """\
define internal void @{P}_tape(double* noalias %d, double* noalias %pv, i64 %start, \
i64 %stop, i64 %nc, i64* %ptr, i64* %src) noinline nounwind {
entry:
  %none = icmp sge i64 %start, %stop
  br i1 %none, label %exit, label %row
row:
  %r = phi i64 [ %start, %entry ], [ %r.next, %row.end ]
  %m0.a = getelementptr inbounds i64, i64* %ptr, i64 %r
  %m0 = load i64, i64* %m0.a, align 8
  %r.next = add i64 %r, 1
  %m1.a = getelementptr inbounds i64, i64* %ptr, i64 %r.next
  %m1 = load i64, i64* %m1.a, align 8
  %rbase = mul i64 %r, %nc
  %some = icmp slt i64 %m0, %m1
  br i1 %some, label %edge, label %row.end
edge:
  %m = phi i64 [ %m0, %row ], [ %m.next, %edge.end ]
  %s.a = getelementptr inbounds i64, i64* %src, i64 %m
  %s = load i64, i64* %s.a, align 8
  %wv.a = getelementptr inbounds double, double* %pv, i64 %m
  %wv = load double, double* %wv.a, align 8
  %seed = icmp slt i64 %s, 0
  br i1 %seed, label %state, label %chain
state:
  %col = sub i64 -1, %s
  %i.s = add i64 %rbase, %col
  %p.s = getelementptr inbounds double, double* %d, i64 %i.s
  %v.s = load double, double* %p.s, align 8
  %v.s1 = fadd double %v.s, %wv
  store double %v.s1, double* %p.s, align 8
  br label %edge.end
chain:
  %sbase = mul i64 %s, %nc
  %nocol = icmp sle i64 %nc, 0
  br i1 %nocol, label %edge.end, label %cols
cols:
  %j = phi i64 [ 0, %chain ], [ %j.next, %cols ]
  %i.d = add i64 %rbase, %j
  %i.r = add i64 %sbase, %j
  %p.d = getelementptr inbounds double, double* %d, i64 %i.d
  %p.r = getelementptr inbounds double, double* %d, i64 %i.r
  %v.d = load double, double* %p.d, align 8
  %v.r = load double, double* %p.r, align 8
  %prod = fmul double %wv, %v.r
  %sum = fadd double %v.d, %prod
  store double %sum, double* %p.d, align 8
  %j.next = add i64 %j, 1
  %jdone = icmp sge i64 %j.next, %nc
  br i1 %jdone, label %edge.end, label %cols
edge.end:
  %m.next = add i64 %m, 1
  %mdone = icmp sge i64 %m.next, %m1
  br i1 %mdone, label %row.end, label %edge
row.end:
  %rdone = icmp sge i64 %r.next, %stop
  br i1 %rdone, label %exit, label %row
exit:
  ret void
}

define internal void @{P}_scatter(double* noalias %J, double* noalias %d, i64 %nnz, \
i64 %n, i64 %nc, i64* %ii, i64* %jj, i64* %row, i64* %col) nounwind {
entry:
  %none = icmp sle i64 %nnz, 0
  br i1 %none, label %exit, label %loop
loop:
  %k = phi i64 [ 0, %entry ], [ %k.next, %loop ]
  %i.a = getelementptr inbounds i64, i64* %ii, i64 %k
  %i = load i64, i64* %i.a, align 8
  %j.a = getelementptr inbounds i64, i64* %jj, i64 %k
  %j = load i64, i64* %j.a, align 8
  %r.a = getelementptr inbounds i64, i64* %row, i64 %k
  %r = load i64, i64* %r.a, align 8
  %c.a = getelementptr inbounds i64, i64* %col, i64 %k
  %c = load i64, i64* %c.a, align 8
  %in = mul i64 %i, %n
  %to = add i64 %in, %j
  %rn = mul i64 %r, %nc
  %from = add i64 %rn, %c
  %p.from = getelementptr inbounds double, double* %d, i64 %from
  %v = load double, double* %p.from, align 8
  %p.to = getelementptr inbounds double, double* %J, i64 %to
  store double %v, double* %p.to, align 8
  %k.next = add i64 %k, 1
  %done = icmp sge i64 %k.next, %nnz
  br i1 %done, label %exit, label %loop
exit:
  ret void
}

; np.interp(t, tt, yy) (held at the end values outside, NaN for NaN), or with %slope
; the slope of the segment t lies in (0 outside), as the numba code had it
define internal double @{P}_interp(double %t, double* %tt, double* %yy, i64 %n, \
i1 %slope) nounwind {
entry:
  br label %scan
scan:
  %k = phi i64 [ -1, %entry ], [ %k1, %next ]
  %k1 = add i64 %k, 1
  %end = icmp sge i64 %k1, %n
  br i1 %end, label %found, label %test
test:
  %tk.a = getelementptr inbounds double, double* %tt, i64 %k1
  %tk = load double, double* %tk.a, align 8
  %le = fcmp ole double %tk, %t
  br i1 %le, label %next, label %found
next:
  br label %scan
found:
  %last = add i64 %n, -1
  %below = icmp slt i64 %k, 0
  %above = icmp sge i64 %k, %last
  %out = or i1 %below, %above
  br i1 %out, label %outside, label %inside
inside:
  %t0.a = getelementptr inbounds double, double* %tt, i64 %k
  %t0 = load double, double* %t0.a, align 8
  %t1.a = getelementptr inbounds double, double* %tt, i64 %k1
  %t1 = load double, double* %t1.a, align 8
  %y0.a = getelementptr inbounds double, double* %yy, i64 %k
  %y0 = load double, double* %y0.a, align 8
  %y1.a = getelementptr inbounds double, double* %yy, i64 %k1
  %y1 = load double, double* %y1.a, align 8
  %dy = fsub double %y1, %y0
  %dt = fsub double %t1, %t0
  %m = fdiv double %dy, %dt
  br i1 %slope, label %ret.m, label %value
ret.m:
  ret double %m
value:
  %u = fsub double %t, %t0
  %mu = fmul double %m, %u
  %v = fadd double %mu, %y0
  ret double %v
outside:
  br i1 %slope, label %ret.zero, label %clamp
ret.zero:
  ret double 0.0
clamp:
  %nan = fcmp uno double %t, %t
  br i1 %nan, label %ret.t, label %ends
ret.t:
  ret double %t
ends:
  %at = select i1 %below, i64 0, i64 %last
  %ye.a = getelementptr inbounds double, double* %yy, i64 %at
  %ye = load double, double* %ye.a, align 8
  ret double %ye
}
"""

_LU = """\
; Solve A X = B in place (B: n x m, row-major) by LU with partial pivoting, as the numba
; code before it: A is copied to LU; a pivot not above 1e-13 of the largest |A| (or a
; NaN in A) is a singular configuration and fills X with NaN, which stops the run where
; the simulator reports it.
define void @{P}_lu(i64 %n, i64 %m, double* noalias %A, double* noalias %B, \
double* noalias %LU) nounwind {
entry:
  %k.v = alloca i64
  %i.v = alloca i64
  %j.v = alloca i64
  %piv.v = alloca i64
  %mx.v = alloca double
  %nn = mul i64 %n, %n
  %nbytes = mul i64 %nn, 8
  %lu8 = bitcast double* %LU to i8*
  %a8 = bitcast double* %A to i8*
  call void @llvm.memcpy.p0i8.p0i8.i64(i8* %lu8, i8* %a8, i64 %nbytes, i1 false)
  store double 0.0, double* %mx.v
  store i64 0, i64* %i.v
  br label %max.head
max.head:
  %mi = load i64, i64* %i.v
  %mc = icmp slt i64 %mi, %nn
  br i1 %mc, label %max.body, label %max.end
max.body:
  %ma = getelementptr inbounds double, double* %A, i64 %mi
  %mv = load double, double* %ma
  %mabs = call double @llvm.fabs.f64(double %mv)
  %macc = load double, double* %mx.v
  %mnan = fcmp uno double %macc, %macc
  %mgt = fcmp ugt double %mabs, %macc
  %mpick = select i1 %mgt, double %mabs, double %macc
  %mnew = select i1 %mnan, double %macc, double %mpick
  store double %mnew, double* %mx.v
  %mi1 = add i64 %mi, 1
  store i64 %mi1, i64* %i.v
  br label %max.head
max.end:
  %mxf = load double, double* %mx.v
  %tiny = fmul double {TINY}, %mxf
  store i64 0, i64* %k.v
  br label %k.head
k.head:
  %k = load i64, i64* %k.v
  %kc = icmp slt i64 %k, %n
  br i1 %kc, label %k.body, label %back.start
k.body:
  %kn = mul i64 %k, %n
  %k1 = add i64 %k, 1
  store i64 %k, i64* %piv.v
  store i64 %k1, i64* %i.v
  br label %p.head
p.head:
  %pi = load i64, i64* %i.v
  %pc = icmp slt i64 %pi, %n
  br i1 %pc, label %p.body, label %p.end
p.body:
  %pin = mul i64 %pi, %n
  %pik = add i64 %pin, %k
  %pia = getelementptr inbounds double, double* %LU, i64 %pik
  %piv0 = load double, double* %pia
  %piabs = call double @llvm.fabs.f64(double %piv0)
  %pp = load i64, i64* %piv.v
  %ppn = mul i64 %pp, %n
  %ppk = add i64 %ppn, %k
  %ppa = getelementptr inbounds double, double* %LU, i64 %ppk
  %ppv = load double, double* %ppa
  %ppabs = call double @llvm.fabs.f64(double %ppv)
  %better = fcmp ogt double %piabs, %ppabs
  %pnew = select i1 %better, i64 %pi, i64 %pp
  store i64 %pnew, i64* %piv.v
  %pi1 = add i64 %pi, 1
  store i64 %pi1, i64* %i.v
  br label %p.head
p.end:
  %piv = load i64, i64* %piv.v
  %pvn = mul i64 %piv, %n
  %pvk = add i64 %pvn, %k
  %pva = getelementptr inbounds double, double* %LU, i64 %pvk
  %pvv = load double, double* %pva
  %pvabs = call double @llvm.fabs.f64(double %pvv)
  %ok = fcmp ogt double %pvabs, %tiny
  br i1 %ok, label %swap.test, label %singular
swap.test:
  %same = icmp eq i64 %piv, %k
  br i1 %same, label %elim.start, label %swap.lu
swap.lu:
  store i64 0, i64* %j.v
  br label %sl.head
sl.head:
  %sj = load i64, i64* %j.v
  %sc = icmp slt i64 %sj, %n
  br i1 %sc, label %sl.body, label %swap.b
sl.body:
  %sa.i = add i64 %kn, %sj
  %sb.i = add i64 %pvn, %sj
  %sa = getelementptr inbounds double, double* %LU, i64 %sa.i
  %sb = getelementptr inbounds double, double* %LU, i64 %sb.i
  %sav = load double, double* %sa
  %sbv = load double, double* %sb
  store double %sbv, double* %sa
  store double %sav, double* %sb
  %sj1 = add i64 %sj, 1
  store i64 %sj1, i64* %j.v
  br label %sl.head
swap.b:
  store i64 0, i64* %j.v
  %km = mul i64 %k, %m
  %pm = mul i64 %piv, %m
  br label %sb.head
sb.head:
  %tj = load i64, i64* %j.v
  %tc = icmp slt i64 %tj, %m
  br i1 %tc, label %sb.body, label %elim.start
sb.body:
  %ta.i = add i64 %km, %tj
  %tb.i = add i64 %pm, %tj
  %ta = getelementptr inbounds double, double* %B, i64 %ta.i
  %tb = getelementptr inbounds double, double* %B, i64 %tb.i
  %tav = load double, double* %ta
  %tbv = load double, double* %tb
  store double %tbv, double* %ta
  store double %tav, double* %tb
  %tj1 = add i64 %tj, 1
  store i64 %tj1, i64* %j.v
  br label %sb.head
elim.start:
  %kk.i = add i64 %kn, %k
  %kk.a = getelementptr inbounds double, double* %LU, i64 %kk.i
  %kkm = mul i64 %k, %m
  store i64 %k1, i64* %i.v
  br label %e.head
e.head:
  %ei = load i64, i64* %i.v
  %ec = icmp slt i64 %ei, %n
  br i1 %ec, label %e.body, label %k.next
e.body:
  %ein = mul i64 %ei, %n
  %eik.i = add i64 %ein, %k
  %eik.a = getelementptr inbounds double, double* %LU, i64 %eik.i
  %eik = load double, double* %eik.a
  %ekk = load double, double* %kk.a
  %f = fdiv double %eik, %ekk
  %fz = fcmp une double %f, 0.0
  br i1 %fz, label %row.lu, label %e.next
row.lu:
  store i64 %k1, i64* %j.v
  br label %rl.head
rl.head:
  %rj = load i64, i64* %j.v
  %rc = icmp slt i64 %rj, %n
  br i1 %rc, label %rl.body, label %row.b
rl.body:
  %rij.i = add i64 %ein, %rj
  %rkj.i = add i64 %kn, %rj
  %rij.a = getelementptr inbounds double, double* %LU, i64 %rij.i
  %rkj.a = getelementptr inbounds double, double* %LU, i64 %rkj.i
  %rij = load double, double* %rij.a
  %rkj = load double, double* %rkj.a
  %rfk = fmul double %f, %rkj
  %rnew = fsub double %rij, %rfk
  store double %rnew, double* %rij.a
  %rj1 = add i64 %rj, 1
  store i64 %rj1, i64* %j.v
  br label %rl.head
row.b:
  %eim = mul i64 %ei, %m
  store i64 0, i64* %j.v
  br label %rb.head
rb.head:
  %bj = load i64, i64* %j.v
  %bc = icmp slt i64 %bj, %m
  br i1 %bc, label %rb.body, label %e.next
rb.body:
  %bij.i = add i64 %eim, %bj
  %bkj.i = add i64 %kkm, %bj
  %bij.a = getelementptr inbounds double, double* %B, i64 %bij.i
  %bkj.a = getelementptr inbounds double, double* %B, i64 %bkj.i
  %bij = load double, double* %bij.a
  %bkj = load double, double* %bkj.a
  %bfk = fmul double %f, %bkj
  %bnew = fsub double %bij, %bfk
  store double %bnew, double* %bij.a
  %bj1 = add i64 %bj, 1
  store i64 %bj1, i64* %j.v
  br label %rb.head
e.next:
  %ei1 = add i64 %ei, 1
  store i64 %ei1, i64* %i.v
  br label %e.head
k.next:
  store i64 %k1, i64* %k.v
  br label %k.head
back.start:
  %last = add i64 %n, -1
  store i64 %last, i64* %k.v
  br label %u.head
u.head:
  %uk = load i64, i64* %k.v
  %uc = icmp sge i64 %uk, 0
  br i1 %uc, label %u.body, label %done
u.body:
  %ukn = mul i64 %uk, %n
  %ukm = mul i64 %uk, %m
  %uk1 = add i64 %uk, 1
  store i64 %uk1, i64* %i.v
  br label %ui.head
ui.head:
  %ui = load i64, i64* %i.v
  %uic = icmp slt i64 %ui, %n
  br i1 %uic, label %ui.body, label %ud.start
ui.body:
  %uki.i = add i64 %ukn, %ui
  %uki.a = getelementptr inbounds double, double* %LU, i64 %uki.i
  %uf = load double, double* %uki.a
  %ufz = fcmp une double %uf, 0.0
  br i1 %ufz, label %us.start, label %ui.next
us.start:
  %uim = mul i64 %ui, %m
  store i64 0, i64* %j.v
  br label %us.head
us.head:
  %sj2 = load i64, i64* %j.v
  %sc2 = icmp slt i64 %sj2, %m
  br i1 %sc2, label %us.body, label %ui.next
us.body:
  %xkj.i = add i64 %ukm, %sj2
  %xij.i = add i64 %uim, %sj2
  %xkj.a = getelementptr inbounds double, double* %B, i64 %xkj.i
  %xij.a = getelementptr inbounds double, double* %B, i64 %xij.i
  %xkj = load double, double* %xkj.a
  %xij = load double, double* %xij.a
  %xfx = fmul double %uf, %xij
  %xnew = fsub double %xkj, %xfx
  store double %xnew, double* %xkj.a
  %sj3 = add i64 %sj2, 1
  store i64 %sj3, i64* %j.v
  br label %us.head
ui.next:
  %ui1 = add i64 %ui, 1
  store i64 %ui1, i64* %i.v
  br label %ui.head
ud.start:
  %ukk.i = add i64 %ukn, %uk
  %ukk.a = getelementptr inbounds double, double* %LU, i64 %ukk.i
  %ukk = load double, double* %ukk.a
  store i64 0, i64* %j.v
  br label %ud.head
ud.head:
  %dj = load i64, i64* %j.v
  %dc = icmp slt i64 %dj, %m
  br i1 %dc, label %ud.body, label %u.next
ud.body:
  %dkj.i = add i64 %ukm, %dj
  %dkj.a = getelementptr inbounds double, double* %B, i64 %dkj.i
  %dkj = load double, double* %dkj.a
  %dnew = fdiv double %dkj, %ukk
  store double %dnew, double* %dkj.a
  %dj1 = add i64 %dj, 1
  store i64 %dj1, i64* %j.v
  br label %ud.head
u.next:
  %uk0 = add i64 %uk, -1
  store i64 %uk0, i64* %k.v
  br label %u.head
singular:
  %nm = mul i64 %n, %m
  store i64 0, i64* %j.v
  br label %nan.head
nan.head:
  %nj = load i64, i64* %j.v
  %nc = icmp slt i64 %nj, %nm
  br i1 %nc, label %nan.body, label %done
nan.body:
  %na = getelementptr inbounds double, double* %B, i64 %nj
  store double 0x7FF8000000000000, double* %na
  %nj1 = add i64 %nj, 1
  store i64 %nj1, i64* %j.v
  br label %nan.head
done:
  ret void
}
"""

_MEMSET = "declare void @llvm.memset.p0i8.i64(i8*, i8, i64, i1)"
_MEMCPY = "declare void @llvm.memcpy.p0i8.p0i8.i64(i8*, i8*, i64, i1)"


class _Asm:
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


def _lstsq_ir(P: str) -> str:
    """``@<P>_lstsq(n, m, A, B, r, ws)``: redundant constraints (rank r < n) share the load
    by least squares, as the numba code before it did: the pseudo-inverse through LAPACK's
    dgesdd (scipy's, as numpy's), keeping r singular values. One below 1e-10 of the
    largest, a non-finite A or a failed SVD is a singular configuration: X is NaN. B
    (n x m, row-major) is overwritten with X; ``ws`` holds ``lstsq_work(n, m)`` doubles.
    A's buffer read as column-major is A^T = U' S V'^T, so A = V' S U'^T: A's left
    singular vectors are the rows of V'^T, its right ones the columns of U'."""
    a = _Asm(f"define void @{P}_lstsq(i64 %n, i64 %m, double* noalias %A, "
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


def lstsq_work(n: int, m: int) -> int:
    """Doubles of workspace ``_lstsq_ir`` needs: A^T, U', V'^T, s, W, dgesdd's work for
    jobz 'A' (LAPACK asks 3 n^2 + max(n, 4 n^2 + 4 n) at most; 8 n to spare) and its
    8n int32 iwork."""
    return 3 * n * n + n + n * m + (7 * n * n + 12 * n) + 4 * n


def _index(a: _Asm, base: str, i: str) -> str:
    """``base[i]`` of an i64 table."""
    return a.op(f"load i64, i64* {a.at(base, i, 'i64')}, align 8")


def _assemble_ir(P: str) -> str:
    """``@<P>_assemble(n, d, A, K, F, full, na, apos, ne, kpos, krow, bptr, bcol)``:
    A = -K F (K: n x d, F: d x n) from their non-zeros: K's at ``kpos`` (flat, in rows
    ``krow``), F's row q at columns ``bcol[bptr[q]:bptr[q+1]]``. A is zeroed first where
    it is non-zero (``apos``), or everywhere (``full``: for a dense solve)."""
    a = _Asm(f"define void @{P}_assemble(i64 %n, i64 %d, double* noalias %A, "
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
    a.loop("e", "0", "%na", lambda e: a.store("0.0", "%A", _index(a, "%apos", e)))
    a("br label %sum")
    a.label("sum")

    def entry(e):
        pos, i = _index(a, "%kpos", e), _index(a, "%krow", e)
        q = a.op(f"sub i64 {pos}, {a.op(f'mul i64 {i}, %d')}")
        c = a.load("%K", pos)
        row, frow = a.op(f"mul i64 {i}, %n"), a.op(f"mul i64 {q}, %n")

        def update(r):
            j = _index(a, "%bcol", r)
            at = a.op(f"add i64 {row}, {j}")
            f = a.load("%F", a.op(f"add i64 {frow}, {j}"))
            a.store(a.op(f"fsub double {a.load('%A', at)}, {a.op(f'fmul double {c}, {f}')}"),
                    "%A", at)
        a.loop("r", _index(a, "%bptr", q), _index(a, "%bptr", a.op(f"add i64 {q}, 1")),
               update)
    a.loop("e", "0", "%ne", entry)
    a("ret void")
    return a.text()


def _negate_ir(P: str) -> str:
    """``@<P>_negate(J, w, k, src, dst)``: J[dst[e]] = -w[src[e]] for e < k."""
    a = _Asm(f"define internal void @{P}_negate(double* noalias %J, double* noalias %w, "
             f"i64 %k, i64* %src, i64* %dst) nounwind {{", ["e"])
    a.loop("e", "0", "%k", lambda e: a.store(
        a.op(f"fneg double {a.load('%w', _index(a, '%src', e))}"), "%J",
        _index(a, "%dst", e)))
    a("ret void")
    return a.text()


def factor_pattern(n: int, d: int, K, B) -> np.ndarray:
    """The structure of ``A = -K B`` (n x n) from the non-zeros of K (n x d) and B (d x
    n), as ``(i, j, ...)`` triples, with its diagonal."""
    k = np.zeros((n, d), dtype=np.int64)
    b = np.zeros((d, n), dtype=np.int64)
    for i, j, *_ in K:
        k[i, j] = 1
    for i, j, *_ in B:
        b[i, j] = 1
    return ((k @ b) != 0) | np.eye(n, dtype=bool)


def _packed_ir(P: str) -> str:
    """What packed blocks share: ``@<P>_assemble_packed(A, K, F, ne, kq, bptr, bidx,
    tgt)``, A[tgt[t]] -= K[e] F[bidx[r]] over K's entries e and B's row kq[e] (t counts
    the products); ``@<P>_raise(A, R, k, diag)``, A[diag[e]] += R[e]; ``@<P>_nanfill(X, n,
    m)``."""
    a = _Asm(f"define internal void @{P}_assemble_packed(double* noalias %A, double* "
             f"noalias %K, double* noalias %F, i64 %ne, i64* %kq, i64* %bptr, i64* %bidx, "
             f"i64* %tgt) nounwind {{", ["e", "r", "t"])
    a("store i64 0, i64* %t")

    def entry(e):
        c = a.load("%K", e)
        q = _index(a, "%kq", e)

        def product(r):
            t = a.op("load i64, i64* %t")
            at = _index(a, "%tgt", t)
            f = a.load("%F", _index(a, "%bidx", r))
            a.store(a.op(f"fsub double {a.load('%A', at)}, {a.op(f'fmul double {c}, {f}')}"),
                    "%A", at)
            a(f"store i64 {a.op(f'add i64 {t}, 1')}, i64* %t")
        a.loop("r", _index(a, "%bptr", q), _index(a, "%bptr", a.op(f"add i64 {q}, 1")),
               product)
    a.loop("e", "0", "%ne", entry)
    a("ret void")
    b = _Asm(f"define internal void @{P}_raise(double* noalias %A, double* noalias %R, "
             f"i64 %k, i64* %diag) nounwind {{", ["e"])

    def raise_(e):
        at = _index(b, "%diag", e)
        b.store(b.op(f"fadd double {b.load('%A', at)}, {b.load('%R', e)}"), "%A", at)
    b.loop("e", "0", "%k", raise_)
    b("ret void")
    c = _Asm(f"define internal void @{P}_nanfill(double* noalias %X, i64 %n, i64 %m) "
             f"nounwind {{", ["e"])
    c.loop("e", "0", c.op("mul i64 %n, %m"), lambda e: c.store(double(float("nan")), "%X", e))
    c("ret void")
    return "\n\n".join((a.text(), b.text(), c.text()))


def _splu_ir(P: str, spd: bool = False, packed: bool = False) -> str:
    """``i1 @<P>_splu(n, m, A, X, LU, rows, cols, lptr, lidx, uptr, uidx)``: solve A X = B
    (X holds B, n x m row-major; overwritten) by LU of ``A[rows][:, cols]`` on its
    diagonal along an ``elimination.Plan``, touching only the filled structure. False,
    X untouched, on a pivot not above 1e-13 of the largest |A| (what the dense LU calls
    singular) or an entry grown past ``GROWTH_LIMIT`` times it: the caller then pivots.
    LU holds n^2 + n doubles (the factors, held dense in the plan's order; a column).
    ``spd`` (``@<P>_splu_spd``, a regularized constraint block, symmetric positive
    definite): the multipliers of L are not bounded (they reach 1/sqrt(eps) there while
    the reduced matrices do not grow: elimination is as stable as Cholesky), U is."""
    name = "_packed" if packed else "_spd" if spd else ""
    extra = ", i64* %sd, i64* %sl, i64* %su" if packed else ""
    a = _Asm(f"define i1 @{P}_splu{name}(i64 %n, i64 %m, double* noalias %A, double* "
             f"noalias %X, double* noalias %LU, i64* %rows, i64* %cols, i64* %lptr, "
             f"i64* %lidx, i64* %uptr, i64* %uidx{extra}) nounwind {{",
             ["k", "q", "r", "c"])
    a("%big = alloca double")
    a("%acc = alloca double")
    a("store double 0.0, double* %big")
    x = a.at("%LU", a.op("mul i64 %n, %n"))
    fabs = "call double @llvm.fabs.f64(double {})"

    def at(i, j):
        return a.op(f"add i64 {a.op(f'mul i64 {i}, %n')}, {j}")

    def span(ptr, k):
        return _index(a, ptr, k), _index(a, ptr, a.op(f"add i64 {k}, 1"))

    def check(ok):                      # on to the next block, or give up
        go = a.tmp()[1:]
        a(f"br i1 {ok}, label %{go}, label %fail")
        a.label(go)

    def take(i, j, ri, cj):             # LU[i, j] = A[ri, cj]; track the largest
        # (packed: A's entry from its slot, ``ri`` the slot and ``cj`` None)
        v = a.load("%A", ri if cj is None else at(ri, cj))
        a.store(v, "%LU", at(i, j))
        mag, big = a.op(fabs.format(v)), a.op("load double, double* %big")
        more = a.op(f"fcmp ogt double {mag}, {big}")
        a(f"store double {a.op(f'select i1 {more}, double {mag}, double {big}')}, "
          "double* %big")

    def copy(k):
        if packed:
            take(k, k, _index(a, "%sd", k), None)
            a.loop("q", *span("%lptr", k), lambda q: take(
                _index(a, "%lidx", q), k, _index(a, "%sl", q), None))
            a.loop("r", *span("%uptr", k), lambda r: take(
                k, _index(a, "%uidx", r), _index(a, "%su", r), None))
            return
        rk, ck = _index(a, "%rows", k), _index(a, "%cols", k)
        take(k, k, rk, ck)
        a.loop("q", *span("%lptr", k), lambda q: (
            lambda i: take(i, k, _index(a, "%rows", i), ck))(_index(a, "%lidx", q)))
        a.loop("r", *span("%uptr", k), lambda r: (
            lambda j: take(k, j, rk, _index(a, "%cols", j)))(_index(a, "%uidx", r)))
    a.loop("k", "0", "%n", copy)
    big = a.op("load double, double* %big")
    limit = a.op(f"fmul double {double(elimination.GROWTH_LIMIT)}, {big}")
    # (spd: a regularized block is regular by construction, its smallest pivots the
    # weights on its redundant directions, which may lie 12 decades below its largest
    # entry: only a zero or non-finite pivot fails)
    spd = spd or packed
    tiny = a.op(f"fmul double {double(1e-300 if spd else 1e-13)}, {big}")

    def pivot(k):
        rk = a.at("%LU", a.op(f"mul i64 {k}, %n"))          # row k
        piv = a.load(rk, k)
        mag = a.op(fabs.format(piv))
        check(a.op(f"and i1 {a.op(f'fcmp ogt double {mag}, {tiny}')}, "
                   f"{a.op(f'fcmp ole double {mag}, {limit}')}"))

        def row(q):
            ri = a.at("%LU", a.op(f"mul i64 {_index(a, '%lidx', q)}, %n"))
            lik = a.op(f"fdiv double {a.load(ri, k)}, {piv}")
            a.store(lik, ri, k)

            def update(r):
                j = _index(a, "%uidx", r)
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
                a.at("%LU", a.op(f"mul i64 {_index(a, '%lidx', q)}, %n")), k)))
        a.loop("r", *span("%uptr", k), lambda r: bounded(a.load(rk, _index(a, "%uidx", r))))
    a.loop("k", "0", "%n", grown)

    def column(c):
        def gather(i):
            ri = _index(a, "%rows", i)
            a.store(a.load("%X", a.op(f"add i64 {a.op(f'mul i64 {ri}, %m')}, {c}")), x, i)
        a.loop("k", "0", "%n", gather)

        def forward(k):
            xk = a.load(x, k)

            def sub(q):
                i = _index(a, "%lidx", q)
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
                j = _index(a, "%uidx", r)
                a.accumulate(a.op(f"fneg double {a.op(f'fmul double {a.load(rk, j)}, {a.load(x, j)}')}"))
            a.loop("r", *span("%uptr", k), sub)
            a.store(a.op(f"fdiv double {a.op('load double, double* %acc')}, "
                         f"{a.load(rk, k)}"), x, k)
        a.loop("k", "0", "%n", backward)

        def scatter(i):
            ci = _index(a, "%cols", i)
            a.store(a.load(x, i), "%X", a.op(f"add i64 {a.op(f'mul i64 {ci}, %m')}, {c}"))
        a.loop("k", "0", "%n", scatter)
    a.loop("c", "0", "%m", column)
    a("ret i1 true")
    a.label("fail")
    a("ret i1 false")
    return a.text()


class _Module:
    """The IR module: chunk functions, one function per program, the Jacobian's tape
    and the C entry points of the native integrators."""

    def __init__(self, prefix: str, system, layout: Layout):
        self.prefix, self.layout = prefix, layout
        self.states = {st.sym: i for i, st in enumerate(system.states)}
        self.params = {s: i for i, (s, _, _) in enumerate(system.params)}
        self.decls: set[str] = set()
        self.functions: list[str] = []
        self.straight: list[str] = []       # the programs' chunks (their own module)
        self.globals: list[str] = []
        self.instances = system.model.instances if system.model else {}
        self.loops = 0
        self.assigned = {it[1]: it[0] for it in system.assignments
                         if not isinstance(it, LinearBlock)} if self.instances else {}
        self.memo: dict = {}                # instances.schedule's, shared by the programs

    @staticmethod
    def _region(fn: _Function, offset: int, base: str = "%w") -> str:
        """An i8* to base[offset] (for memset and memcpy)."""
        return fn.op(f"bitcast double* {fn.ptr(base, offset)} to i8*")

    def zero(self, fn: _Function, base: str, offset: int, count: int):
        if count:
            self.decls.add(_MEMSET)
            fn.body.append(f"  call void @llvm.memset.p0i8.i64(i8* "
                           f"{self._region(fn, offset, base)}, i8 0, i64 {8 * count}, i1 false)")

    def copy(self, fn: _Function, to: int, frm: int, count: int):
        if count:
            self.decls.add(_MEMCPY)
            fn.body.append(f"  call void @llvm.memcpy.p0i8.p0i8.i64(i8* "
                           f"{self._region(fn, to)}, i8* {self._region(fn, frm)}, "
                           f"i64 {8 * count}, i1 false)")

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
        slots where ``assemble``, its diagonal raised by the weights, then sparse LU (SPD,
        pivots on the diagonal) on its plan; a zero or non-finite pivot gives NaN."""
        P, n, i, pl = self.prefix, blk.n, blk.index, blk.plan
        slot = blk.a_slot
        # the products K[e] F[b]: B's entries by row, each product's target slot in order
        by_row: dict = {}
        for e, (q, j) in enumerate(blk.b_at):
            by_row.setdefault(q, []).append((j, e))
        bptr, bidx = [0], []
        for q in range(blk.d):
            bidx += [e for _, e in by_row.get(q, [])]
            bptr.append(len(bidx))
        kq, tgt = [], []
        for r, q in blk.k_at:
            kq.append(q)
            tgt += [slot[(r, j)] for j, _ in by_row.get(q, [])]
        rows, cols = pl.rows, pl.cols
        src = {"sd": [slot[(int(rows[k]), int(cols[k]))] for k in range(n)],
               "sl": [slot[(int(rows[pl.lidx[q]]), int(cols[k]))] for k in range(n)
                      for q in range(pl.lptr[k], pl.lptr[k + 1])],
               "su": [slot[(int(rows[k]), int(cols[pl.uidx[r]]))] for k in range(n)
                      for r in range(pl.uptr[k], pl.uptr[k + 1])]}
        t = {k: self.array(f"block{i}_{k}", "i64", v) for k, v in (
            ("kq", kq), ("bptr", bptr), ("bidx", bidx), ("tgt", tgt),
            ("diag", [slot[(r, r)] for r in blk.reg_rows]),
            *[(k, v) for k, v in src.items()],
            *[(k, getattr(pl, k)) for k in elimination.Plan._fields])}
        plan_args = ", ".join(t[k] for k in elimination.Plan._fields)
        self.decls.add(_MEMSET)
        body = [f"define void @{P}_block{i}(i64 %m, double* noalias %A, double* noalias %K, "
                f"double* noalias %F, double* noalias %X, double* noalias %LU, "
                f"i1 %assemble, double* noalias %R) nounwind {{", "entry:",
                "  br i1 %assemble, label %form, label %solve", "form:",
                f"  %a8 = bitcast double* %A to i8*",
                f"  call void @llvm.memset.p0i8.i64(i8* %a8, i8 0, i64 {8 * len(slot)}, "
                "i1 false)",
                f"  call void @{P}_assemble_packed(double* %A, double* %K, double* %F, "
                f"i64 {len(kq)}, {t['kq']}, {t['bptr']}, {t['bidx']}, {t['tgt']})",
                f"  call void @{P}_raise(double* %A, double* %R, i64 {len(blk.reg_rows)}, "
                f"{t['diag']})",
                "  br label %solve", "solve:",
                f"  %ok = call i1 @{P}_splu_packed(i64 {n}, i64 %m, double* %A, double* %X, "
                f"double* %LU, {plan_args}, {t['sd']}, {t['sl']}, {t['su']})",
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
        a = _Asm(f"define internal void @{self.prefix}_block{i}_reg(double* noalias %A, "
                 f"double* noalias %R) nounwind {{", ["e"])
        def raise_(e):
            at = _index(a, diag, e)
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

    def solve(self, fn: _Function, blk: Block, at: int, columns: int, assemble: bool):
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

    def program(self, name: str, items, outputs):
        """``@<prefix>_<name>(t, x, p, w, out)``: the assignments in chunks, each linear
        block solved where the causal order reaches it."""
        chunks: list[str] = []       # calls, in order
        fn = None
        count = 0

        def flush():
            nonlocal fn, count
            if fn is not None and (fn.body or not chunks):
                self.straight.append(fn.text(linkage=""))
                chunks.append(f"  call void @{fn.name}(double %t, double* %x, double* %p, "
                              f"double* %w, double* %out)")
            fn = _Function(f"{self.prefix}_{name}_{len(chunks)}", self.layout, self.states,
                           self.params, self.decls)
            count = 0

        flush()
        for step in instances.schedule(list(_steps(items, outputs, self.layout)),
                                       self.instances, self.where, self.assigned,
                                       memo=self.memo):
            kind = step[0]
            if kind == "loop":              # instances of one part: a loop (instances.py)
                flush()
                chunks.append(self.loop(name, step[1]))
                continue
            if kind == "solve":
                blk = self.layout.blocks[step[1]]
                self.solve(fn, blk, blk.b, blk.columns, True)
                self.copy(fn, blk.u, blk.b, blk.n * blk.columns)
                flush()                 # what follows reads the unknowns from w
                continue
            if count >= CHUNK or fn.n >= CHUNK_OPS:
                flush()
            count += 1
            if kind == "set":
                fn.assign(step[1], step[2])
            elif kind == "store":
                fn.store("%w", step[1], fn.val(step[2]))
            elif kind == "out":
                fn.store("%out", step[1], fn.val(step[2]))
            elif kind == "grad":
                d = fn.grad(step[1], [w for _, w in step[2]])
                for slot, w in step[2]:
                    fn.store("%out", slot, d[w])
            else:
                self.zero(fn, "%w", step[1], step[2])
        flush()
        if self.layout.tables:
            chunks.insert(0, f"  call void @{self.prefix}_tables(double %t, double* %w)")
        self.functions.append("\n".join(
            [f"define void @{self.prefix}_{name}({ARGS}) nounwind {{", "entry:", *chunks,
             "  ret void", "}"]))

    def where(self, s) -> tuple[str, int]:
        """Where a symbol's value is: ("x", state), ("p", parameter) or ("w", slot)."""
        if s in self.states:
            return "x", self.states[s]
        if s in self.params:
            return "p", self.params[s]
        return "w", self.layout.slot[s]

    def loop(self, name: str, lp) -> str:
        """A loop over instances (``instances.Loop``): its template in the straight
        module, its driver and tables here; returns the program's call of it."""
        k, P = self.loops, self.prefix
        self.loops += 1
        template = f"{P}_{name}_tmpl{k}"
        self.straight.append(instances.template_ir(lp, template, self.layout, self.decls))
        width = max(len(lp.bases), 1)
        rows = self.array(f"{name}_rows{k}", "i64",
                          [x for r in lp.rows for x in (r or [0])])
        nc = len(lp.constants)
        consts = self.array(f"{name}_consts{k}", DBL, [x for r in lp.consts for x in r])
        self.functions.append(instances.driver_ir(f"{P}_{name}_loop{k}", template,
                                                  len(lp.rows), width, rows, (consts, nc),
                                                  ARGS))
        return (f"  call void @{P}_{name}_loop{k}(double %t, double* %x, double* %p, "
                f"double* %w, double* %out)")

    def tables(self, tables):
        """``@<prefix>_tables(t, w)``: each table's value and slope at t into w."""
        if not tables:
            return
        body = []
        for tb in tables:
            value, slope = self.layout.tables[tb.index]
            tt = self.array(f"table_t{tb.index}", DBL, tb.t)
            yy = self.array(f"table_y{tb.index}", DBL, tb.y)
            for at, flag in ((value, "false"), (slope, "true")):
                body += [f"  %v{at} = call double @{self.prefix}_interp(double %t, {tt}, "
                         f"{yy}, i64 {len(tb.t)}, i1 {flag})",
                         f"  %p{at} = getelementptr inbounds double, double* %w, i64 {at}",
                         f"  store double %v{at}, double* %p{at}, align 8"]
        self.functions.append("\n".join(
            [f"define internal void @{self.prefix}_tables(double %t, double* %w) nounwind {{",
             "entry:", *body, "  ret void", "}"]))

    def array(self, name: str, kind: str, values) -> str:
        """A constant global array; returns a pointer to its first element."""
        values = list(values) or [0]
        n = len(values)
        items = ", ".join(f"{kind} {double(v) if kind == DBL else int(v)}" for v in values)
        self.globals.append(f"@{self.prefix}_{name} = internal constant [{n} x {kind}] "
                            f"[{items}]")
        return (f"{kind}* getelementptr inbounds ([{n} x {kind}], [{n} x {kind}]* "
                f"@{self.prefix}_{name}, i64 0, i64 0)")

    def jacobian(self, jt, n: int):
        """The Jacobian from the run-time partials (program jac) and the tape through
        them (``@<prefix>_jac_tape(t, x, p, w)``), in two forms: ``@<prefix>_jac_full(t,
        x, p, w, J)``, J dense (N x N, N = n + the open blocks' unknowns) scattered from
        the tape's compressed rows, each open block's -A from its matrix; and
        ``@<prefix>_jac_vals(t, x, p, w, V)``, the same entries as values in the order of
        the pattern (``JAC_I``, ``JAC_J``): what the native integrator's sparse LU reads,
        whose cost follows the non-zeros (a dense N x N is 20 MB for IFToMM A02 at N = 40
        under method augmented, and writing it cost most of a Jacobian)."""
        P, lay = self.prefix, self.layout
        na = n + (jt.n_aug or 0)
        nc = jt.n_colours
        ptr = self.array("tape_ptr", "i64", jt.ptr)
        src = self.array("tape_src", "i64", jt.src)
        fn = _Function(f"{P}_jac_tape", lay, {}, {}, self.decls)
        pv, d = fn.ptr("%w", lay.pv), fn.ptr("%w", lay.d)
        fn.body.append(f"  call void @{P}_jac(double %t, double* %x, double* %p, "
                       f"double* %w, double* {pv})")
        self.zero(fn, "%w", lay.d, jt.n_rows * nc)
        for seg in jt.segments:
            if seg[0] == "tape":
                fn.body.append(f"  call void @{P}_tape(double* {d}, double* {pv}, "
                               f"i64 {seg[1]}, i64 {seg[2]}, i64 {nc}, {ptr}, {src})")
            else:                        # u's rows: A^-1 R, R in the rows before them
                b = seg[1]
                blk = lay.blocks[b.index]
                self.copy(fn, lay.d + (b.start + b.n) * nc, lay.d + b.start * nc, b.n * nc)
                self.solve(fn, blk, lay.d + (b.start + b.n) * nc, nc, False)
        self.functions.append(_TAPE.replace("{P}", P))
        self.functions.append(fn.text().replace(", double* noalias %out", "", 1))
        # the entries: from the tape's rows (k: their place in the pattern), and the open
        # blocks' rows on their own unknowns, -A (as regularized when formed)
        tape_at = [k for k, e in enumerate(jt.pattern) if e[2] >= 0]
        a_src, a_at = [], []
        for index, _, m, at in jt.opened or ():
            blk = lay.blocks[index]
            for k, (i, j, r) in enumerate(jt.pattern):
                if r < 0 and at <= i < at + m:
                    a_src.append(blk.a + (blk.a_slot[(i - at, j - at)] if blk.packed
                                          else (i - at) * m + (j - at)))
                    a_at.append(k)
        if a_src:
            self.functions.append(_negate_ir(P))
        tables = {k: self.array(k, "i64", v) for k, v in (
            ("jac_row", [jt.pattern[k][2] for k in tape_at]),
            ("jac_col", [jt.colours[jt.pattern[k][1]] for k in tape_at]),
            ("jac_zero", [0] * len(tape_at)), ("jac_k", tape_at),
            ("jac_i", [jt.pattern[k][0] for k in tape_at]),
            ("jac_j", [jt.pattern[k][1] for k in tape_at]))}
        for name, dense in (("jac_full", True), ("jac_vals", False)):
            fn = _Function(f"{P}_{name}", lay, {}, {}, self.decls)
            d = fn.ptr("%w", lay.d)
            fn.body.append(f"  call void @{P}_jac_tape(double %t, double* %x, double* %p, "
                           "double* %w)")
            if dense:               # J[i, j]: row i's offset i * na (zeroed first)
                self.zero(fn, "%J", 0, na * na)
                rows, cols, stride = tables["jac_i"], tables["jac_j"], na
            else:                   # V[k]: "row" 0, "column" k
                rows, cols, stride = tables["jac_zero"], tables["jac_k"], 0
            fn.body.append(f"  call void @{P}_scatter(double* %J, double* {d}, "
                           f"i64 {len(tape_at)}, i64 {stride}, i64 {nc}, {rows}, {cols}, "
                           f"{tables['jac_row']}, {tables['jac_col']})")
            if a_src:
                dst = [jt.pattern[k][0] * na + jt.pattern[k][1] for k in a_at] if dense \
                    else a_at
                fn.body.append(
                    f"  call void @{P}_negate(double* %J, double* %w, i64 {len(a_src)}, "
                    f"{self.array(f'{name}_a_src', 'i64', a_src)}, "
                    f"{self.array(f'{name}_a_dst', 'i64', dst)})")
            self.functions.append(fn.text(linkage="")
                                  .replace("double* noalias %out", "double* noalias %J", 1))

    def entry(self, name: str, program: str, n_work: int):
        """``@<prefix>_<name>(t, x, p, out)``: a C entry point for the native integrators,
        with a workspace of its own (malloc'ed: the SARIB's is ~100 kB, too large for a
        stack)."""
        self.decls |= {"declare i8* @malloc(i64)", "declare void @free(i8*)"}
        size = 8 * max(n_work, 1)
        self.functions.append("\n".join([
            f"define void @{self.prefix}_{name}(double %t, double* %x, double* %p, "
            f"double* %out) nounwind {{",
            "entry:",
            f"  %raw = call i8* @malloc(i64 {size})",
            "  %w = bitcast i8* %raw to double*",
            f"  call void @{self.prefix}_{program}(double %t, double* %x, double* %p, "
            f"double* %w, double* %out)",
            "  call void @free(i8* %raw)",
            "  ret void", "}"]))

    def text(self) -> str:
        """The loops' module: it declares the chunks it calls."""
        return "\n\n".join(sorted(self.decls) + self.globals + self.functions
                           + [_declaration(f) for f in self.straight]) + "\n"

    def straight_text(self) -> str:
        """The chunks' module: it declares what the other module defines with external
        linkage (among it the solves the chunks call)."""
        shared = [_declaration(f) for f in self.functions if not _DEFINE.search(f).group(1)]
        return "\n\n".join(sorted(self.decls) + shared + self.straight) + "\n"


_DEFINE = re.compile(r"^define (internal )?(\w+) @(\w+)\(([^)]*)\)", re.M)


def _declaration(definition: str) -> str:
    """``declare ...`` for the function that ``definition`` defines (no attributes)."""
    m = _DEFINE.search(definition)
    return f"declare {m.group(2)} @{m.group(3)}({m.group(4)})"


# the programs a module has (``proj``: method augmented's projection, where it has one),
# and the C entry points of the native integrators
PROGRAMS = ("rhs", "jac", "out", "guard", "con", "proj")
ENTRIES = (("rhs_entry", "rhs"), ("jac_entry", "jac_full"), ("guard_entry", "guard"),
           ("proj_entry", "proj"), ("jacv_entry", "jac_vals"))


def lower(system, prefix: str, programs: dict, jt) -> Kernels:
    """IR for ``programs`` (name -> (assignments in causal order, [(out index, expr)]):
    ``PROGRAMS``, and any other, e.g. an FMU's event indicators) and for the Jacobian
    from its tape ``jt`` (program ``jac`` computes the tape's partials); functions named
    ``<prefix>_<name>``, ``prefix`` an identifier."""
    layout = Layout(system, max(jt.n_colours, 1))
    n_eval = layout.size
    layout.pv = layout._region(max(len(jt.src), 1))
    layout.d = layout._region(jt.n_rows * jt.n_colours)
    mod = _Module(prefix, system, layout)
    blocks = layout.blocks.values()
    if blocks:
        mod.decls |= {_MEMCPY, "declare double @llvm.fabs.f64(double)"}
        mod.functions.append(_LU.replace("{P}", prefix).replace("{TINY}", double(1e-13)))
    if any(b.d for b in blocks):
        mod.decls.add(_MEMSET)
        mod.functions.append(_assemble_ir(prefix))
    if any(b.plan is not None and b.reg < 0 for b in blocks):
        mod.functions.append(_splu_ir(prefix))
    if any(b.plan is not None and b.reg >= 0 and not b.packed for b in blocks):
        mod.functions.append(_splu_ir(prefix, spd=True))
    if any(b.packed for b in blocks):
        mod.functions.append(_splu_ir(prefix, packed=True))
        mod.functions.append(_packed_ir(prefix))
    for blk in blocks:
        mod.block(blk)
    if any(b.rank >= 0 for b in blocks):
        mod.decls.add(f"declare void @{prefix}_dgesdd(i8*, i32*, i32*, double*, i32*, "
                      "double*, double*, i32*, double*, i32*, double*, i32*, i32*, i32*)")
        mod.functions.append(_lstsq_ir(prefix))
    mod.tables(system.tables)
    # PROGRAMS in their order, then any other a caller asks for (an FMU's indicators)
    for name in [n for n in PROGRAMS if n in programs] + [n for n in programs
                                                          if n not in PROGRAMS]:
        mod.program(name, *programs[name])
    mod.jacobian(jt, len(system.states))
    for name, program in ENTRIES:
        if program in programs or program.startswith("jac_"):
            mod.entry(name, program, layout.size if program.startswith("jac_") else n_eval)
    return Kernels(mod.text(), mod.straight_text(), layout.size, n_eval,
                   [layout.blocks[k] for k in sorted(layout.blocks)])


def program_functions(source: str, program: str) -> list[str]:
    """The bodies of the IR functions of one program ("rhs", "jac", "out", ...) in a
    generated module's source: what a benchmark counts and a test inspects."""
    prefix = re.search(r'^_KERNEL_PREFIX = "(\w+)"', source, re.M)
    if prefix is None:
        return []
    name = re.compile(rf"{prefix.group(1)}_{program}_\d+")
    return [m.group(2) for m in re.finditer(r"^define [^@\n]*@(\w+)\(.*?\n(.*?)^}", source,
                                            re.S | re.M) if name.fullmatch(m.group(1))]
