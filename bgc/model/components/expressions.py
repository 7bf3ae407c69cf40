"""Components: the expressions and geometry of an instance written in flat names
(its constants, indices and inlined parameters put in, its names prefixed, its
vectors and frames placed in R0 exactly): the ``Expressions`` part of the assembler."""

from __future__ import annotations

import ast
import copy

import sympy as sp

from bgc.errors import Loc, ModelError
from bgc.mechanics import exact
from bgc.model import expr as bexpr
from bgc.model.components.scope import (
    LITERAL,
    Scope,
    _chain,
    _const_node,
    _dotted,
    _exact,
    _names,
    _number,
    _ylist,
    _ymap,
)
from bgc.model.document import YList, YMap
from bgc.model.values import fail, kind_of


class Expressions:
    """Expressions, vectors and frames of a scope in flat names (a part of
    ``assembler.Assembler``)."""

    # -- expressions -----------------------------------------------------------------
    def _node(self, text: str, scope: Scope, loc, key) -> ast.AST:
        """An expression of ``scope`` as a node in flat names."""
        rewritten = self._rewrite(text, scope, loc, key)
        if not isinstance(rewritten, str):
            return _const_node(rewritten)
        try:
            return ast.parse(rewritten.strip(), mode="eval").body
        except SyntaxError:
            fail(f"cannot parse expression {text!r}", scope.loc(loc), key,
                 "use Python syntax: + - * / ** and function calls")

    def _rewrite(self, text, scope: Scope, loc, key, numeric: bool = True):
        """An expression text in flat names: the scope's constants, indices, inlined
        parameters and signal inputs put in, its local names prefixed, instances' signal
        ports replaced by their expressions. Text that is not an expression, or that
        names nothing of the scope, comes back as it is (its reader judges it); one that
        reads no name once rewritten is its value (a number) where ``numeric``."""
        if not isinstance(text, str) or len(text) > bexpr.MAX_CHARS:
            return text
        if "{" in text:         # no expression holds braces: names made of constants
            text = self._interpolate(text, scope, loc, key)
        try:
            tree = ast.parse(text.strip(), mode="eval")
        except (SyntaxError, RecursionError, MemoryError, ValueError):
            return text
        changed = [False]

        def visit(node):
            if isinstance(node, ast.Call):
                node.args = [visit(a) for a in node.args]
                return node
            parts = _chain(node) if isinstance(node, (ast.Name, ast.Attribute)) else None
            if parts is not None:
                new = self._ref(parts, scope, loc, key)
                if new is not None:
                    changed[0] = True
                    return new
                return node
            for name, value in ast.iter_fields(node):
                if isinstance(value, ast.AST):
                    setattr(node, name, visit(value))
                elif isinstance(value, list):
                    setattr(node, name, [visit(x) if isinstance(x, ast.AST) else x
                                         for x in value])
            return node

        try:
            body = visit(tree.body)
        except RecursionError:
            return text
        if not changed[0]:
            return text
        if numeric and not (_names(body) - {"pi"}):
            value = self._try_value(body)
            if value is not None:
                return value
        return ast.unparse(body)

    def _try_value(self, node):
        """A constant expression's number (a float), or None if it has none."""
        try:
            e = bexpr.parse(ast.unparse(node), loc=Loc(self.file, 1), key="value", names={})
            v = float(e)
        except (ModelError, TypeError, ValueError, OverflowError):
            return None
        return int(v) if v.is_integer() and abs(v) < 2 ** 53 and \
            isinstance(e, sp.Integer) else v

    def _ref(self, parts: list[str], scope: Scope, loc, key) -> ast.AST | None:
        """The flat form of a name or reference ``parts`` in ``scope`` (None: as is)."""
        head = parts[0]
        if head in scope.subst:
            if len(parts) == 1:
                return copy.deepcopy(scope.subst[head])
            return None
        if head in scope.insts:
            inst = scope.insts[head]
            if len(parts) >= 2 and parts[1] in inst.ports and (
                    parts[1] not in inst.names or inst.ports[parts[1]].kind == "signal"):
                p = inst.ports[parts[1]]
                if p.kind == "signal":
                    if p.expr is None:
                        fail(f"'{head}.{parts[1]}': the signal port of {inst.where()} is "
                             "read before the instance is written out", scope.loc(loc), key,
                             "instances are written out in file order; read another's "
                             "signal port after it")
                    return copy.deepcopy(p.expr) if len(parts) == 2 else None
                if p.target is not None:
                    return _dotted(".".join([p.target, *parts[2:]]))
            if scope.prefix:
                return _dotted(".".join([inst.name, *parts[1:]]))
            return None
        if head in scope.rename:
            return _dotted(".".join([scope.rename[head], *parts[1:]]))
        return None

    def _exprs(self, x, scope: Scope, loc, key):
        """A value that is an expression, or a list (vector, matrix) or mapping of
        them, rewritten."""
        if isinstance(x, str):
            return self._rewrite(x, scope, loc, key)
        if isinstance(x, YList):
            return _ylist([self._exprs(y, scope, x.item_locs[i], f"{key}[{i}]")
                           for i, y in enumerate(x)],
                          [scope.loc(lc) for lc in x.item_locs], scope.loc(x.loc))
        if isinstance(x, YMap):
            return self._map_exprs(x, scope, key)
        return x

    def _map_exprs(self, m: YMap, scope: Scope, key, skip=()) -> YMap:
        out = self._copy(m, scope)
        for k in m:
            if k in LITERAL or k in skip:
                continue
            out[k] = self._exprs(m[k], scope, m.val_locs[k], f"{key}.{k}")
        return out

    def _copy(self, m: YMap, scope: Scope) -> YMap:
        """A shallow copy of a mapping with its locations as the scope shows them."""
        out = _ymap(scope.loc(m.loc))
        for k, v in m.items():
            out[k] = v
            out.key_locs[k] = scope.loc(m.key_locs[k])
            out.val_locs[k] = scope.loc(m.val_locs[k])
        return out

    # -- geometry ----------------------------------------------------------------------
    def _exact_vector(self, v, loc, key, scope: Scope) -> sp.Matrix:
        """[x, y, z] of numbers or expressions of constants and indices, exact."""
        if not isinstance(v, YList) or len(v) != 3:
            fail(f"expected [x, y, z], got {kind_of(v)}", scope.loc(loc), key)
        out = []
        for i, x in enumerate(v):
            k, xl = f"{key}[{i}]", v.item_locs[i]
            if isinstance(x, bool) or not isinstance(x, (int, float, str)):
                fail(f"expected a number, got {kind_of(x)}", scope.loc(xl), k)
            if isinstance(x, str):
                text = self._rewrite(x, scope, xl, k, numeric=False)
                hit = self.geometry.get(text)       # the instances of an array: one text
                if hit is None:
                    try:
                        e = bexpr.parse(text, loc=scope.loc(xl), key=k, names={})
                    except ModelError as exc:
                        raise ModelError(exc.message, loc=exc.loc, key=k,
                                         hint="positions, axes and angles are compile-time: "
                                              "numbers, constants and indices (not "
                                              "parameters)") from None
                    hit = self.geometry[text] = _exact(sp.sympify(e))
                out.append(hit)
            else:
                out.append(exact.rational(x))
        return sp.Matrix(out)

    def _text_vector(self, m: sp.Matrix, loc=None) -> YList:
        """An exact vector as the values a reader takes: a rational as itself (a number,
        or its text where its decimal does not end), an irrational as its correctly
        rounded double (``exact.to_float``: canonical, the same on every machine; the
        readers keep a body's and a joint's geometry as such doubles anyway)."""
        scale = max((abs(exact.to_float(e)) for e in m), default=1.0) or 1.0
        items = [_number(e) if e.is_Rational else exact.to_float(e, scale) for e in m]
        return _ylist(items, [loc] * 3, loc)

    def _vector(self, v, loc, key, scope: Scope, kind: str):
        """A position (``point``: R x + o), a direction (``direction``: R x) or a vector
        of R0 (``turn``: a velocity; expressions of parameters allowed) of a component,
        in R0; as it is where nothing changes it."""
        if not isinstance(v, YList) or len(v) != 3:
            return self._exprs(v, scope, loc, key)      # the reader reports it
        has_text = any(isinstance(x, str) for x in v)
        if kind == "expr":
            return self._exprs(v, scope, loc, key)
        if not scope.placed and not has_text:
            return v
        if kind == "turn":
            items = [self._rewrite(x, scope, v.item_locs[i], f"{key}[{i}]")
                     if isinstance(x, str) else x for i, x in enumerate(v)]
            if not scope.placed:
                return _ylist(items, [scope.loc(lc) for lc in v.item_locs], scope.loc(loc))
            if all(not isinstance(x, str) for x in items):
                return self._text_vector(scope.R * sp.Matrix([exact.rational(x)
                                                              for x in items]),
                                         scope.loc(loc))
            rows = []
            for r in range(3):
                terms = [f"({sp.sstr(scope.R[r, c])})*({items[c]})" for c in range(3)
                         if scope.R[r, c] != 0 and items[c] != 0]
                rows.append(" + ".join(terms) if terms else 0)
            return _ylist(rows, [scope.loc(loc)] * 3, scope.loc(loc))
        x = self._exact_vector(v, loc, key, scope)
        w = scope.R * x + (scope.o if kind == "point" else sp.zeros(3, 1))
        return self._text_vector(w, scope.loc(loc))

    def _frame(self, v, loc, key, scope: Scope):
        if not isinstance(v, YMap):
            return v
        out = self._copy(v, scope)
        for a in v:
            out[a] = self._vector(v[a], v.val_locs[a], f"{key}.{a}", scope, "direction")
        return out

    def _axes(self, scope: Scope, loc) -> YMap:
        """The component frame's axes in R0, as a body's ``frame``."""
        out = _ymap(scope.loc(loc))
        for j, a in enumerate("xyz"):
            out[a] = self._text_vector(scope.R[:, j], scope.loc(loc))
            out.key_locs[a] = out.val_locs[a] = scope.loc(loc)
        return out
