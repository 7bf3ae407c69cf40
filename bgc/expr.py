"""Safe parsing of user expressions into sympy (a whitelist over Python's ast, never eval).

An expression may use numbers, the names it is given (parameters, signals, ``t``, local law
variables), references ``name.attr`` resolved by a callback, ``pi``, the arithmetic
operators, comparisons inside ``ifelse`` and the functions in ``FUNCTIONS``.
"""

from __future__ import annotations

import ast
from typing import Callable

import sympy as sp

from .errors import Loc, ModelError

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


def number(value) -> sp.Expr:
    """A YAML number as a sympy number (integers stay exact, floats become Float)."""
    if isinstance(value, bool):
        raise TypeError("bool is not a number")
    if isinstance(value, int):
        return sp.Integer(value)
    return sp.Float(value)


def parse(text, *, loc: Loc, key: str, names: dict[str, sp.Expr],
          resolve_ref: Callable[[str, str], sp.Expr] | None = None) -> sp.Expr:
    """Parse ``text`` (a string or a YAML number) into a sympy expression.

    ``names`` maps bare names to sympy objects; ``resolve_ref(target, attr)`` turns
    ``target.attr`` into a symbol or raises ModelError. Errors name ``loc`` and ``key``.
    """
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        return number(text)
    if not isinstance(text, str):
        raise ModelError(f"expected a number or an expression string, got {type(text).__name__}",
                         loc=loc, key=key, hint="write e.g. 2.5 or \"k*q + k3*q**3\"")
    try:
        tree = ast.parse(text.strip(), mode="eval")
    except SyntaxError as exc:
        raise ModelError(f"cannot parse expression {text!r}: {exc.msg}", loc=loc, key=key,
                         hint="use Python syntax: + - * / ** and function calls") from None

    def fail(msg: str, hint: str | None = None):
        raise ModelError(f"{msg} in expression {text!r}", loc=loc, key=key, hint=hint)

    def conv(node):
        if isinstance(node, ast.Expression):
            return conv(node.body)
        if isinstance(node, ast.Constant):
            if isinstance(node.value, (int, float)) and not isinstance(node.value, bool):
                return number(node.value)
            fail(f"constant {node.value!r} is not a number")
        if isinstance(node, ast.Name):
            if node.id in names:
                return names[node.id]
            if node.id in CONSTANTS:
                return CONSTANTS[node.id]
            valid = sorted(set(names) | set(CONSTANTS))
            fail(f"unknown name '{node.id}'", hint="valid names here: " + ", ".join(valid))
        if isinstance(node, ast.Attribute):
            target = node.value       # name.attr, or body.point.attr
            if (isinstance(target, ast.Attribute) and isinstance(target.value, ast.Name)):
                target_name = f"{target.value.id}.{target.attr}"
            elif isinstance(target, ast.Name):
                target_name = target.id
            else:
                target_name = None
            if target_name is None or resolve_ref is None:
                fail("references 'name.attr' are not allowed here")
            return resolve_ref(target_name, node.attr)
        if isinstance(node, ast.BinOp):
            if isinstance(node.op, ast.BitXor):
                fail("'^' is not a power", hint="write x**3 for a power")
            op = _BINOPS.get(type(node.op))
            if op is None:
                fail(f"operator {type(node.op).__name__} is not allowed")
            return op(conv(node.left), conv(node.right))
        if isinstance(node, ast.UnaryOp):
            if isinstance(node.op, ast.USub):
                return -conv(node.operand)
            if isinstance(node.op, ast.UAdd):
                return conv(node.operand)
            fail(f"operator {type(node.op).__name__} is not allowed")
        if isinstance(node, ast.Call):
            if not isinstance(node.func, ast.Name) or node.keywords:
                fail("only plain function calls like sin(x) are allowed")
            fname = node.func.id
            if fname == "ifelse":
                if len(node.args) != 3:
                    fail("ifelse takes 3 arguments", hint="ifelse(x > 0, a, b)")
                cond = conv_cond(node.args[0])
                return sp.Piecewise((conv(node.args[1]), cond), (conv(node.args[2]), True))
            if fname not in FUNCTIONS:
                fail(f"unknown function '{fname}'",
                     hint="valid functions: " + ", ".join(sorted(FUNCTIONS) + ["ifelse"]))
            try:
                return FUNCTIONS[fname](*[conv(a) for a in node.args])
            except TypeError:
                fail(f"wrong number of arguments to {fname}")
        if isinstance(node, ast.Compare):
            fail("a comparison is only allowed as the first argument of ifelse",
                 hint="ifelse(x > 0, a, b)")
        fail(f"{type(node).__name__} is not allowed")

    def conv_cond(node):
        if (isinstance(node, ast.Compare) and len(node.ops) == 1
                and type(node.ops[0]) in _CMPS):
            return _CMPS[type(node.ops[0])](conv(node.left), conv(node.comparators[0]))
        fail("the condition of ifelse must be one comparison with < <= > >=")

    return sp.sympify(conv(tree))
