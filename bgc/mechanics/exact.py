"""Exact geometry: a model's frames, poses and offsets computed in exact arithmetic.

Generated code must be the same bytes on every machine (x86-64 of either vendor, aarch64,
any BLAS), and a value that is exact in the model (0, 1, 0.05, axes at right angles) must
stay exact in it. Floating-point geometry breaks both: numpy's BLAS and LAPACK round
differently from one CPU to the next (an exact zero became 5e-12, 0.05 became
0.05000000000933408), and even correctly rounded float steps add up to noise such as
1.0000000000000004. So every geometric constant that can reach an emitted expression is
computed here, with sympy's rationals and radicals, from the model's numbers read as the
decimals they were written as, and rounded to a double once, at the end, correctly
(``to_float``). Where a result has no closed form (the principal axes of a general inertia
tensor), it is computed with mpmath at high precision, which is software arithmetic and so
the same on every machine.

The canonical form of a number: ``rational(x)`` is the shortest decimal within two units
in the last place of ``x``. A double that was read from ``0.05`` or computed from it and
rounded correctly maps back to exactly 1/20, and a last-bit perturbation of an input (the
noise a numerical computation of another machine would leave) maps to the same value.
"""

from __future__ import annotations

import functools
import math
from fractions import Fraction

import mpmath
import sympy as sp

# digits of the evaluation that rounds an exact value to a double; an exact value whose
# evaluation stays below ZERO_TOL relative to its vector's scale is a zero that sympy
# could not prove structurally (a sum of radicals)
_DIGITS = 40
ZERO_TOL = 1e-30


def rational(x) -> sp.Rational:
    """The exact number a model value stands for: ints and sympy rationals as they are;
    a float as the shortest decimal within two units in its last place (0.05 -> 1/20,
    0.30000000000000004 -> 3/10)."""
    if isinstance(x, sp.Rational):
        return x
    if isinstance(x, sp.Basic):
        if x.is_Rational:
            return x
        x = float(x)
    if isinstance(x, int) and not isinstance(x, bool):
        return sp.Integer(x)
    return _shortest(float(x))


@functools.lru_cache(maxsize=4096)
def _shortest(x: float) -> sp.Rational:
    """``rational`` of a float (memoized: a model's few values are read many times)."""
    if not math.isfinite(x):
        raise ValueError(f"not a finite number: {x}")
    if x == 0.0:
        return sp.S.Zero
    exact, tol = Fraction(x), 2 * Fraction(math.ulp(x))
    for digits in range(1, 18):
        s = f"{x:.{digits - 1}e}"
        if abs(Fraction(s) - exact) <= tol:
            return sp.Rational(s)
    return sp.Rational(exact.numerator, exact.denominator)


def vector(xs) -> sp.Matrix:
    """A column of exact numbers."""
    return sp.Matrix([rational(x) for x in xs])


def matrix(rows) -> sp.Matrix:
    """A matrix of exact numbers from rows."""
    return sp.Matrix([[rational(x) for x in row] for row in rows])


def norm(v: sp.Matrix) -> sp.Expr:
    return sp.sqrt(sum(e ** 2 for e in v))


def unit(v: sp.Matrix) -> sp.Matrix:
    """``v`` scaled to unit length, exactly (a radical where the length is irrational)."""
    n = norm(v)
    return v / n if n != 0 else v


def cross(a: sp.Matrix, b: sp.Matrix) -> sp.Matrix:
    return sp.Matrix(a).cross(sp.Matrix(b))


def to_float(e, scale=None) -> float:
    """The double nearest to the exact value ``e`` (evaluated to 40 digits, so the rounding
    is correct but for exact ties). A value below ZERO_TOL of ``scale`` is an exact zero."""
    e = sp.sympify(e)
    if e.is_zero:
        return 0.0
    if e.is_Rational:
        return float(Fraction(int(e.p), int(e.q)))       # correctly rounded
    v = float(sp.N(e, _DIGITS))
    ref = abs(float(sp.N(scale, _DIGITS))) if scale is not None else 1.0
    return 0.0 if abs(v) < ZERO_TOL * max(ref, 1e-300) else v


def floats(M) -> tuple:
    """Correctly rounded doubles of an exact vector (a tuple) or matrix (a tuple of rows);
    tiny values that are unproven zeros are judged against the largest entry."""
    M = sp.Matrix(M)
    vals = [sp.N(e, _DIGITS) for e in M]
    scale = max((abs(v) for v in vals), default=sp.S.One) or sp.S.One
    out = [to_float(e, scale) for e in M]
    if M.shape[1] == 1:
        return tuple(out)
    return tuple(tuple(out[i * M.shape[1]:(i + 1) * M.shape[1]]) for i in range(M.shape[0]))


def canonical(M) -> sp.Matrix:
    """An exact vector or matrix in canonical form: each entry rounded correctly to a
    double and read back as the shortest decimal (``rational``). Keeps the numbers that
    flow on into the equations short, and every machine's the same."""
    M = sp.Matrix(M)
    f = floats(M)
    return vector(f) if M.shape[1] == 1 else matrix(f)


def principal_axes(M: sp.Matrix) -> tuple[sp.Matrix, sp.Matrix]:
    """Principal moments (ascending) and axes (columns, right-handed) of a symmetric 3x3
    inertia tensor given exactly. Exact where the tensor is diagonal; otherwise mpmath's
    symmetric eigensolver at 50 digits (software arithmetic: the same bits on every
    machine), each axis signed so that its largest component is positive."""
    M = sp.Matrix(M)
    if all(sp.simplify(M[i, j]).is_zero for i in range(3) for j in range(3) if i != j):
        order = sorted(range(3), key=lambda k: (float(sp.N(M[k, k], _DIGITS)), k))
        moments = sp.Matrix([M[k, k] for k in order])
        axes = sp.Matrix(3, 3, lambda i, j: sp.S.One if i == order[j] else sp.S.Zero)
        if axes.det() < 0:
            axes[:, 2] = -axes[:, 2]
        return moments, axes
    with mpmath.workdps(50):
        A = mpmath.matrix([[mpmath.mpf(str(sp.N(M[i, j], 60))) for j in range(3)]
                           for i in range(3)])
        A = (A + A.T) / 2
        w, Q = mpmath.eigsy(A)
        cols = []
        for k in sorted(range(3), key=lambda k: w[k]):
            c = [Q[i, k] for i in range(3)]
            if c[max(range(3), key=lambda i: abs(c[i]))] < 0:
                c = [-x for x in c]
            cols.append((w[k], c))
        if mpmath.det(mpmath.matrix([[c[i] for _, c in cols] for i in range(3)])) < 0:
            cols[2] = (cols[2][0], [-x for x in cols[2][1]])

        def num(x):
            return sp.Float(mpmath.nstr(x, _DIGITS), _DIGITS)
        return (sp.Matrix([num(m) for m, _ in cols]),
                sp.Matrix(3, 3, lambda i, j: num(cols[j][1][i])))
