"""Safe parsing of user expressions into sympy (a whitelist over Python's ast, never eval).

An expression may use numbers, the names it is given (parameters, signals, ``t``, local law
variables), references ``name.attr`` resolved by a callback, ``pi``, the arithmetic
operators, comparisons inside ``ifelse`` and the functions in ``FUNCTIONS``.
"""

from __future__ import annotations

import ast
import math
import sys
from typing import Callable

import sympy as sp

from bgc.errors import Loc, ModelError

FUNCTIONS: dict[str, Callable] = {
    "sin": sp.sin, "cos": sp.cos, "tan": sp.tan,
    "asin": sp.asin, "acos": sp.acos, "atan": sp.atan, "atan2": sp.atan2,
    "sinh": sp.sinh, "cosh": sp.cosh, "tanh": sp.tanh,
    "exp": sp.exp, "log": sp.log, "sqrt": sp.sqrt,
    "abs": sp.Abs, "sign": sp.sign, "min": sp.Min, "max": sp.Max,
}
CONSTANTS = {"pi": sp.pi}
RESERVED = set(FUNCTIONS) | set(CONSTANTS) | {"ifelse", "t", "e", "f", "q", "p"}

_BINOPS = {ast.Add: lambda a, b: a + b, ast.Sub: lambda a, b: a - b,
           ast.Mult: lambda a, b: a * b, ast.Div: lambda a, b: a / b,
           ast.Pow: lambda a, b: a ** b}
_CMPS = {ast.Lt: sp.Lt, ast.LtE: sp.Le, ast.Gt: sp.Gt, ast.GtE: sp.Ge}

# Limits that keep a hostile expression from hanging or crashing bgc (issue 23): the
# longest expression in the shipped models is ~150 characters, nested ~6 deep, with
# exponents up to 3. Exponents are bounded because sympy evaluates a power of numbers
# exactly (10**10**10 would never finish); a larger one means a value no float holds.
MAX_CHARS = 10_000           # characters in one expression
MAX_DEPTH = 100              # nesting of operators and calls (a flat sum or product is one)
MAX_EXPONENT = 1000          # |n| of a numeric exponent x**n
FLOAT_MAX = sys.float_info.max


def number(value) -> sp.Expr:
    """A YAML number as a sympy number (integers stay exact, floats become Float);
    ValueError if it is not finite or beyond the float range."""
    if isinstance(value, bool):
        raise TypeError("bool is not a number")
    if isinstance(value, int):
        if abs(value) > FLOAT_MAX:
            raise ValueError(f"an integer of ~{int(value.bit_length() * 0.30103) + 1} "
                             f"digits is beyond the float range (+-{FLOAT_MAX:.4g})")
        return sp.Integer(value)
    if not math.isfinite(value):
        raise ValueError(f"{value} is not finite")
    return sp.Float(value)


# Operators that chain without nesting: a + b - c is one sum, a * b / c one product.
_CHAINS = ((ast.Add, ast.Sub), (ast.Mult, ast.Div))


def _chain(node) -> tuple | None:
    """The chain (``_CHAINS`` entry) a binary operation belongs to, or None."""
    if isinstance(node, ast.BinOp):
        for ops in _CHAINS:
            if isinstance(node.op, ops):
                return ops
    return None


def _depth(tree: ast.AST) -> int:
    """Nesting depth of a parse tree, without recursion. A chain of sums (or of products)
    is one level, however many terms it has: Python parses ``a + b + c`` as ``(a + b) +
    c``, but nothing in it nests, and a user's energy written as 160 terms must load."""
    deepest, todo = 0, [(tree, 1)]
    while todo:
        node, d = todo.pop()
        deepest = max(deepest, d)
        chain = _chain(node)
        todo.extend((c, d if chain is not None and _chain(c) is chain else d + 1)
                    for c in ast.iter_child_nodes(node)
                    if not isinstance(c, (ast.operator, ast.expr_context)))
    return deepest


def _parse_tree(text: str) -> ast.Expression:
    """Python's parse tree of an expression of at most ``MAX_CHARS`` characters. Python
    builds the tree of ``a + b + c ...`` nested one level per term and refuses more levels
    than its recursion limit allows, so a flat sum of a few thousand terms (which
    ``_depth`` counts as one level) needs the limit raised while it parses."""
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(max(old, MAX_CHARS + 100))
    try:
        return ast.parse(text, mode="eval")
    finally:
        sys.setrecursionlimit(old)


def _log10(x: sp.Expr) -> float:
    """log10 of a non-negative sympy number of any size (math.log10 takes big ints);
    -inf for zero (which sympy 1.13+ tells apart from Float 0.0, but not always)."""
    if x.is_zero:
        return -math.inf
    if x.is_Integer:
        return math.log10(int(x))
    try:
        return math.log10(float(x))
    except (OverflowError, ValueError):
        return math.inf


def _bad_value(v: sp.Expr) -> str | None:
    """Why a constant (no free symbols) is not a finite real number, or None."""
    if v.has(sp.zoo, sp.oo, -sp.oo, sp.nan):
        return "is infinite or undefined (a division by zero, log(0), ...)"
    try:
        z = complex(v.evalf(30))
    except (TypeError, ValueError, OverflowError, ZeroDivisionError):
        return "has no numeric value"
    if not (math.isfinite(z.real) and math.isfinite(z.imag)):
        return "is infinite or beyond the float range"
    if z.imag != 0:
        return f"is complex ({z.real:.6g}{z.imag:+.6g}j): outside the function's real domain"
    return None


def check_finite(e: sp.Expr, values: dict) -> tuple[sp.Expr, str] | None:
    """The smallest part of ``e`` that is constant once ``values`` (symbol -> float, the
    parameters' values) are put in and is not a finite real number (1/0, log(0),
    sqrt(-1), acos(2), a constant beyond the float range), with the reason; None if
    there is none. Parts that depend on time or the state are not judged."""
    # only the values of the symbols ``e`` reads: a model with many parameters (an
    # assembly's instances each have their own) parses many expressions
    values = {k: sp.Float(values[k]) for k in e.free_symbols if k in values}
    known = set(values)

    def constant(x):
        return x.free_symbols <= known

    def bad(x):         # only values are judged: not a Piecewise's (expr, cond) pairs,
        if not isinstance(x, sp.Expr):      # its conditions or other non-values
            return None
        return _bad_value(x.xreplace(values)) if constant(x) else None

    def smallest(x):
        for a in x.args:
            if isinstance(a, sp.Basic) and not isinstance(a, (sp.Symbol, sp.Number)):
                found = smallest(a)
                if found:
                    return found
        why = bad(x)
        return (x, why) if why else None

    def fast_ok(x):      # the whole expression at once; only a failure is searched
        if constant(x) and isinstance(x, sp.Expr):
            return bad(x) is None
        return all(fast_ok(a) for a in x.args if isinstance(a, sp.Basic))

    for num in e.atoms(sp.Number):
        if num.is_finite is False or _log10(abs(num)) > 308.25:
            return num, "is beyond the float range (+-1.8e308)"
    if fast_ok(e):
        return None
    return smallest(e) or (e, bad(e) or "is not a finite real number")


def parse(text, *, loc: Loc, key: str, names: dict[str, sp.Expr],
          resolve_ref: Callable[[str, str], sp.Expr] | None = None,
          values: dict | None = None) -> sp.Expr:
    """Parse ``text`` (a string or a YAML number) into a sympy expression.

    ``names`` maps bare names to sympy objects; ``resolve_ref(target, attr)`` turns
    ``target.attr`` into a symbol or raises ModelError. Errors name ``loc`` and ``key``.
    Every part that is constant (given the parameter ``values``: symbol -> float) must be
    a finite real number: 1/0, log(0), sqrt(-1), acos(2) are refused here, not at run time.
    """
    shown = text if not isinstance(text, str) or len(text) <= 60 else text[:57] + "..."
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        try:
            return number(text)
        except ValueError as exc:
            raise ModelError(f"expected a finite number: {exc}", loc=loc, key=key,
                             hint="write a finite number such as 1.5 or 2e-3") from None
    if not isinstance(text, str):
        kind = ("a mapping" if isinstance(text, dict) else "a list" if isinstance(text, list)
                else "nothing" if text is None else type(text).__name__)
        raise ModelError(f"expected a number or an expression string, got {kind}",
                         loc=loc, key=key, hint="write e.g. 2.5 or \"k*q + k3*q**3\"")
    hint_split = ("split it: sum blocks add its parts (blocks: {part_1: {type: sum, "
                  "inputs: [...]}}) and an expression reads their part_1.y; a constant "
                  "part can be a parameter, a function of time a signal")
    if len(text) > MAX_CHARS:
        raise ModelError(f"expression of {len(text)} characters is longer than bgc's limit "
                         f"of {MAX_CHARS}", loc=loc, key=key, hint=hint_split)
    try:
        tree = _parse_tree(text.strip())
    except SyntaxError as exc:
        raise ModelError(f"cannot parse expression {shown!r}: {exc.msg}", loc=loc, key=key,
                         hint="use Python syntax: + - * / ** and function calls") from None
    except (RecursionError, MemoryError):
        tree = None
    if tree is None or _depth(tree) > MAX_DEPTH:
        raise ModelError(f"expression {shown!r} nests operators or calls more than "
                         f"{MAX_DEPTH} deep", loc=loc, key=key, hint=hint_split)
    conv = _Converter(shown, loc, key, names, resolve_ref)
    e = sp.sympify(conv.expr(tree))
    found = check_finite(e, values or {})
    if found:
        part, why = found
        shown_names = {s: sp.Symbol(n) for n, s in names.items() if isinstance(s, sp.Symbol)}
        conv.fail(f"'{part.xreplace(shown_names)}' {why}" if part != e
                  else f"the value {why}",
                  hint="every constant must be a finite real number: check divisors, "
                       "log/sqrt/acos arguments and the parameters' values")
    return e


class _Converter:
    """One expression's Python syntax tree -> sympy, over the whitelist: numbers, the
    given ``names``, ``CONSTANTS``, references (``resolve_ref``), the operators of
    ``_BINOPS``, ``FUNCTIONS`` and ``ifelse``. Errors quote the expression (``shown``)."""

    def __init__(self, shown: str, loc: Loc, key: str, names: dict[str, sp.Expr],
                 resolve_ref: Callable[[str, str], sp.Expr] | None):
        self.shown, self.loc, self.key = shown, loc, key
        self.names, self.resolve_ref = names, resolve_ref

    def fail(self, msg: str, hint: str | None = None):
        raise ModelError(f"{msg} in expression {self.shown!r}", loc=self.loc, key=self.key,
                         hint=hint)

    def power(self, a, b):
        if b.is_Number and abs(b) > MAX_EXPONENT:
            self.fail(f"exponent {float(b):.6g} is larger than {MAX_EXPONENT}",
                      hint="a power this large is no float; rescale the quantity")
        if a.is_Number and b.is_Number and a != 0 and (
                float(abs(b)) * _log10(abs(a)) > 308.25):
            self.fail("a power beyond the float range (+-1.8e308)",
                      hint="rescale the quantity")
        return a ** b

    def expr(self, node):
        """The sympy value of ``node``, or a located ModelError."""
        if isinstance(node, ast.Expression):
            return self.expr(node.body)
        if isinstance(node, ast.Constant):
            return self.constant(node)
        if isinstance(node, ast.Name):
            return self.name(node)
        if isinstance(node, ast.Attribute):
            return self.reference(node)
        if _chain(node) is not None:
            return self.chain(node)
        if isinstance(node, ast.BinOp):
            if isinstance(node.op, ast.BitXor):
                self.fail("'^' is not a power", hint="write x**3 for a power")
            op = self.power if isinstance(node.op, ast.Pow) else _BINOPS.get(type(node.op))
            if op is None:
                self.fail(f"operator {type(node.op).__name__} is not allowed")
            return op(self.expr(node.left), self.expr(node.right))
        if isinstance(node, ast.UnaryOp):
            if isinstance(node.op, ast.USub):
                return -self.expr(node.operand)
            if isinstance(node.op, ast.UAdd):
                return self.expr(node.operand)
            self.fail(f"operator {type(node.op).__name__} is not allowed")
        if isinstance(node, ast.Call):
            return self.call(node)
        if isinstance(node, ast.Compare):
            self.fail("a comparison is only allowed as the first argument of ifelse",
                      hint="ifelse(x > 0, a, b)")
        self.fail(f"{type(node).__name__} is not allowed")

    def chain(self, node: ast.BinOp):
        """A sum or a product of any length, walked without recursion along the chain
        (``_depth`` counts it as one level) and built in one sympy call, not term by
        term (which is quadratic in the terms)."""
        ops, parts, todo = _chain(node), [], [(node, False)]
        while todo:                     # (node, inverted: subtracted or divided)
            n, inv = todo.pop()
            if _chain(n) is ops:
                todo.append((n.right, inv ^ isinstance(n.op, (ast.Sub, ast.Div))))
                todo.append((n.left, inv))
            else:
                parts.append((self.expr(n), inv))
        if ops[0] is ast.Add:
            return sp.Add(*[-v if inv else v for v, inv in parts])
        return sp.Mul(*[1 / v if inv else v for v, inv in parts])

    def constant(self, node: ast.Constant):
        if isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
            try:
                return number(node.value)
            except ValueError as exc:
                self.fail(f"the constant {exc}",
                          hint="write a finite number such as 1.5 or 2e-3")
        self.fail(f"constant {node.value!r} is not a number")

    def name(self, node: ast.Name):
        if node.id in self.names:
            return self.names[node.id]
        if node.id in CONSTANTS:
            return CONSTANTS[node.id]
        valid = sorted(set(self.names) | set(CONSTANTS))
        self.fail(f"unknown name '{node.id}'", hint="valid names here: " + ", ".join(valid))

    def reference(self, node: ast.Attribute):
        """``name.attr``, ``body.point.attr``, and the same in an instance
        (``leg_2.beater.x``): a dotted name the expression may read as it is (an
        instance's parameter, ``leg_2.k``) or a reference to resolve."""
        parts, target = [node.attr], node.value
        while isinstance(target, ast.Attribute):
            parts.append(target.attr)
            target = target.value
        if not isinstance(target, ast.Name):
            self.fail("references 'name.attr' are not allowed here")
        dotted = ".".join([target.id, *reversed(parts)])
        if dotted in self.names:
            return self.names[dotted]
        if self.resolve_ref is None:
            if dotted.rpartition(".")[0] in self.names or target.id in self.names:
                self.fail(f"'{dotted}' is not a name here",
                          hint="valid names here: " + ", ".join(sorted(self.names)))
            self.fail("references 'name.attr' are not allowed here")
        return self.resolve_ref(dotted.rpartition(".")[0], node.attr)

    def call(self, node: ast.Call):
        if not isinstance(node.func, ast.Name) or node.keywords:
            self.fail("only plain function calls like sin(x) are allowed")
        fname = node.func.id
        if fname == "ifelse":
            if len(node.args) != 3:
                self.fail("ifelse takes 3 arguments", hint="ifelse(x > 0, a, b)")
            cond = self.condition(node.args[0])
            return sp.Piecewise((self.expr(node.args[1]), cond),
                                (self.expr(node.args[2]), True))
        if fname not in FUNCTIONS:
            self.fail(f"unknown function '{fname}'",
                      hint="valid functions: " + ", ".join(sorted(FUNCTIONS) + ["ifelse"]))
        try:
            return FUNCTIONS[fname](*[self.expr(a) for a in node.args])
        except TypeError:
            self.fail(f"wrong number of arguments to {fname}")

    def condition(self, node):
        if (isinstance(node, ast.Compare) and len(node.ops) == 1
                and type(node.ops[0]) in _CMPS):
            return _CMPS[type(node.ops[0])](self.expr(node.left),
                                            self.expr(node.comparators[0]))
        self.fail("the condition of ifelse must be one comparison with < <= > >=")
