"""Stage **kernels**, its first part: sympy expressions lowered to LLVM IR values.

``Function`` is one IR function under construction. ``val`` lowers an expression to an
SSA value, reusing what the function has computed already; the lowering is one method per
node kind (``lower_Add``, ``lower_Pow``, ``lower_Piecewise``, ...: as numba's lowering
registers one implementation per operation), chosen by ``kind``. ``grad`` gives an
expression's partials by reverse mode through its tree, each node's local derivative again
one method per kind (``d_Add``, ``d_Mul``, ...; the functions of one argument by the rules
of ``_LOCAL``): no symbolic derivative is ever formed.

Every number is written exactly (``double``: hexadecimal bits), so the same expression
gives the same IR on every machine.
"""

from __future__ import annotations

import struct

import sympy as sp

from bgc.errors import BgcError
from bgc.model import symbols
from bgc.model.signals import table, table_slope

DBL = "double"
# a straight-line function's arguments (time, states, parameters, workspace, results)
ARGS = "double %t, double* noalias %x, double* noalias %p, double* noalias %w, " \
       "double* noalias %out"
# sympy function -> LLVM intrinsic or C library function of one double
UNARY = {sp.sin: "llvm.sin.f64", sp.cos: "llvm.cos.f64", sp.exp: "llvm.exp.f64",
         sp.log: "llvm.log.f64", sp.Abs: "llvm.fabs.f64", sp.tan: "tan", sp.asin: "asin",
         sp.acos: "acos", sp.atan: "atan", sp.sinh: "sinh", sp.cosh: "cosh",
         sp.tanh: "tanh"}
_CMP = {sp.StrictLessThan: "olt", sp.LessThan: "ole", sp.StrictGreaterThan: "ogt",
        sp.GreaterThan: "oge", sp.Equality: "oeq", sp.Unequality: "une"}
# node class -> the name of its kind (``Function.lower_<kind>``, ``Function.d_<kind>``);
# Add, Mul and Pow (and their subclasses) by sympy's own flags
_KIND = {**{f: "unary" for f in UNARY}, sp.atan2: "atan2", sp.Piecewise: "Piecewise",
         sp.Min: "MinMax", sp.Max: "MinMax", sp.sign: "sign", sp.Heaviside: "Heaviside",
         sp.DiracDelta: "DiracDelta", table: "table", table_slope: "table"}


def double(v: float) -> str:
    """A double as an LLVM constant: its exact bits in hexadecimal (canonical, no noise)."""
    return "0x%016X" % struct.unpack("<Q", struct.pack("<d", float(v)))[0]


def kind(e) -> str | None:
    """The kind of an expression node: "Add", "Mul", "Pow", a ``_KIND``, or None (a node
    no kernel computes)."""
    if e.is_Add:
        return "Add"
    if e.is_Mul:
        return "Mul"
    if e.is_Pow:
        return "Pow"
    return _KIND.get(type(e))


class Function:
    """One IR function under construction: ``val`` lowers an expression to an SSA value,
    reusing what this function has already computed. ``layout``: the workspace
    (``workspace.Layout``: a slot per assigned symbol, the tables'); ``states`` and
    ``params``: symbol -> index in x and p; ``decls``: the module's declarations, which
    the calls add to."""

    def __init__(self, name: str, layout, states: dict, params: dict, decls: set):
        self.name, self.layout, self.states, self.params = name, layout, states, params
        self.decls = decls
        self.body: list[str] = []
        self.n = 0
        self.env: dict = {}
        self.memo: dict = {}

    # -- instructions ------------------------------------------------------------------
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

    def select(self, c: str, a: str, b: str) -> str:
        return self.op(f"select i1 {c}, double {a}, double {b}")

    # -- values ------------------------------------------------------------------------
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

    def _lower(self, e) -> str:
        k = kind(e)
        if k is None:
            raise BgcError(f"internal: no code for {type(e).__name__} in {e}")
        return getattr(self, "lower_" + k)(e)

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

    # -- one method per node kind --------------------------------------------------------
    def lower_Add(self, e) -> str:
        return self._fold("fadd", [self.val(a) for a in e.args])

    def lower_Mul(self, e) -> str:
        """A product as numerator and denominator (negative integer powers divide once)."""
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

    def lower_Pow(self, e) -> str:
        """Integer powers by squaring, square roots by llvm.sqrt, the rest by llvm.pow."""
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

    def lower_unary(self, e) -> str:
        return self.call(UNARY[type(e)], self.val(e.args[0]))

    def lower_atan2(self, e) -> str:
        return self.call("atan2", self.val(e.args[0]), self.val(e.args[1]))

    def lower_Piecewise(self, e) -> str:
        """Selects from the last piece back (NaN where no condition holds)."""
        pieces = list(e.args)
        out = double(float("nan"))
        if pieces[-1].cond == sp.true:
            out = self.val(pieces.pop().expr)
        for piece in reversed(pieces):
            out = self.select(self.cond(piece.cond), self.val(piece.expr), out)
        return out

    def lower_MinMax(self, e) -> str:
        """Python's min/max, folded left to right."""
        pred = "olt" if type(e) is sp.Min else "ogt"
        acc = self.val(e.args[0])
        for a in e.args[1:]:
            v = self.val(a)
            acc = self.select(self.op(f"fcmp {pred} double {v}, {acc}"), v, acc)
        return acc

    def lower_sign(self, e) -> str:
        x = self.val(e.args[0])
        zero = self.select(self.op(f"fcmp oeq double {x}, {double(0.0)}"),
                           double(0.0), double(float("nan")))
        neg = self.select(self.op(f"fcmp olt double {x}, {double(0.0)}"),
                          double(-1.0), zero)
        return self.select(self.op(f"fcmp ogt double {x}, {double(0.0)}"),
                           double(1.0), neg)

    def lower_Heaviside(self, e) -> str:
        x = self.val(e.args[0])
        h0 = float(e.args[1]) if len(e.args) > 1 else 0.5
        at0 = self.select(self.op(f"fcmp oeq double {x}, {double(0.0)}"),
                          double(h0), double(0.0))
        return self.select(self.op(f"fcmp ogt double {x}, {double(0.0)}"),
                           double(1.0), at0)

    def lower_DiracDelta(self, e) -> str:
        return double(0.0)      # zero almost everywhere; no impulse in a Jacobian

    def lower_table(self, e) -> str:
        """A table's value or slope at t: the workspace slot ``@<prefix>_tables`` fills."""
        if e.args[1] is not symbols.t:
            raise BgcError(f"internal: a table of {e.args[1]}, not of t")
        value, slope = self.layout.tables[int(e.args[0])]
        return self.load("%w", value if type(e) is table else slope)

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
        variables (None: 1; ("select", c): 1 where c holds, else 0): ``d_<kind>``."""
        k = kind(node)
        if k is None or (k == "unary" and len(node.args) != 1):
            raise BgcError(f"internal: no derivative for {type(node).__name__} in {node}")
        return getattr(self, "d_" + k)(node, dep)

    def d_Add(self, node, dep):
        return [(a, None) for a in node.args if dep.get(a)]

    def d_Mul(self, node, dep):
        args = node.args
        vals = [self.val(a) for a in args]
        out = []
        for i, a in enumerate(args):
            if dep.get(a):
                others = vals[:i] + vals[i + 1:]
                out.append((a, self._fold("fmul", others) if others else None))
        return out

    def d_Pow(self, node, dep):
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

    def d_atan2(self, node, dep):
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

    def d_Piecewise(self, node, dep):
        """Each piece's expression where its condition is the first to hold."""
        out, before = [], "false"
        for piece in node.args:
            c = self.cond(piece.cond)
            if dep.get(piece.expr):
                free = self.op(f"xor i1 {before}, true")
                out.append((piece.expr, ("select", self.op(f"and i1 {c}, {free}"))))
            before = self.op(f"or i1 {before}, {c}")
        return out

    def d_MinMax(self, node, dep):
        """To the argument Python's min/max picks."""
        pred = "olt" if type(node) is sp.Min else "ogt"
        acc, pick = self.val(node.args[0]), "0"
        for i, a in enumerate(node.args[1:], 1):
            v = self.val(a)
            c = self.op(f"fcmp {pred} double {v}, {acc}")
            acc = self.select(c, v, acc)
            pick = self.op(f"select i1 {c}, i64 {i}, i64 {pick}")
        return [(a, ("select", self.op(f"icmp eq i64 {pick}, {i}")))
                for i, a in enumerate(node.args) if dep.get(a)]

    def d_sign(self, node, dep):
        return []                         # zero almost everywhere

    d_Heaviside = d_DiracDelta = d_table = d_sign

    def d_unary(self, node, dep):
        x = node.args[0]
        return [(x, _LOCAL[type(node)](self, x, node))] if dep.get(x) else []

    def text(self, linkage: str = "internal ") -> str:
        return "\n".join([f"define {linkage}void @{self.name}({ARGS}) noinline nounwind {{",
                          "entry:", *self.body, "  ret void", "}"])


def _one_over_sqrt(f: Function, arg) -> str:
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
