"""Prints sympy expressions as Python that uses only numpy (``np``) and the standard
library's ``math``: the few plain-Python parts of a generated module (its initial state
and largest step as functions of the parameters). The equations themselves are LLVM IR
(``bgc.codegen.kernels``)."""

from __future__ import annotations

import math

import sympy as sp
from sympy.printing.numpy import NumPyPrinter

from bgc.errors import BgcError
from bgc.model.signals import table

_MATH = {f"numpy.{np_name}": f"math.{name}" for np_name, name in (
    ("sin", "sin"), ("cos", "cos"), ("tan", "tan"), ("arcsin", "asin"), ("arccos", "acos"),
    ("arctan", "atan"), ("arctan2", "atan2"), ("sinh", "sinh"), ("cosh", "cosh"),
    ("tanh", "tanh"), ("arcsinh", "asinh"), ("arccosh", "acosh"), ("arctanh", "atanh"),
    ("exp", "exp"), ("expm1", "expm1"), ("log", "log"), ("log1p", "log1p"),
    ("log10", "log10"), ("log2", "log2"), ("sqrt", "sqrt"), ("hypot", "hypot"))}


class NumbaPrinter(NumPyPrinter):
    printmethod = "_numbacode"

    def __init__(self):
        super().__init__({"fully_qualified_modules": True, "strict": True})

    def _module_format(self, fqn, register=True):
        return super()._module_format(_MATH.get(fqn, fqn), register).replace("numpy.", "np.")

    def _print_Piecewise(self, expr):
        pieces = list(expr.args)
        out = "np.nan"
        if pieces[-1].cond == True:  # noqa: E712  (sympy's true, not Python's)
            out = self._print(pieces.pop().expr)
        for piece in reversed(pieces):
            out = f"({self._print(piece.expr)} if {self._print(piece.cond)} else {out})"
        return out

    def _print_Relational(self, expr):
        return f"({self._print(expr.lhs)} {expr.rel_op} {self._print(expr.rhs)})"

    def _print_Heaviside(self, expr):
        x = self._print(expr.args[0])
        return f"(1.0 if {x} > 0 else (0.5 if {x} == 0 else 0.0))"

    def _print_DiracDelta(self, expr):
        return "0.0"   # zero almost everywhere; a Jacobian cannot use the impulse

    def _print_Min(self, expr):
        return self._minmax("min", expr.args)

    def _print_Max(self, expr):
        return self._minmax("max", expr.args)

    def _minmax(self, fn, args):
        out = self._print(args[0])
        for a in args[1:]:
            out = f"{fn}({out}, {self._print(a)})"
        return out

    def _print_Rational(self, expr):
        return repr(float(expr))

    def parenthesize(self, item, level, strict=False):
        """A positive rational prints as a float literal, an atom: no parentheses."""
        if isinstance(item, sp.Rational) and item > 0:
            return self._print(item)
        return super().parenthesize(item, level, strict)

    def _print_Float(self, expr):
        v = float(expr)
        if not math.isfinite(v):       # 'inf' would be a NameError in the module
            raise BgcError(f"a constant of the model, {sp.Float(expr, 4)}, is beyond the "
                           "float range (+-1.8e308): nothing was written",
                           hint="rescale the values whose product it is (masses, "
                                "velocities, gravity, preloads)")
        return repr(v)

    def _print_Integer(self, expr):
        return f"{int(expr)}.0" if abs(int(expr)) < 2**53 else repr(float(expr))

    def _print_Pow(self, expr, rational=False):
        base, exp = expr.as_base_exp()
        if exp.is_Integer and abs(int(exp)) <= 8:
            n = int(exp)
            b = self.parenthesize(base, sp.printing.precedence.PRECEDENCE["Pow"])
            if n == -1:
                return f"(1.0/{b})"
            if n < 0:
                return f"(1.0/{b}**{-n})"
            return f"{b}**{n}"
        if exp == sp.Rational(1, 2):
            return f"math.sqrt({self._print(base)})"
        if exp == -sp.Rational(1, 2):
            return f"(1.0/math.sqrt({self._print(base)}))"
        return super()._print_Pow(expr, rational)

    def _print_Function(self, expr):
        if isinstance(expr, table):
            k = int(expr.args[0])
            return f"np.interp({self._print(expr.args[1])}, TABLE_T{k}, TABLE_Y{k})"
        return super()._print_Function(expr)

    def _print_Symbol(self, expr):
        return expr.name


def code(expr) -> str:
    return NumbaPrinter().doprint(expr)
