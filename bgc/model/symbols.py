"""The one place that names sympy symbols after model objects.

Every symbol's name is also its identifier in the generated code, so the emitter can
print expressions as they are. Display names (``spring.q``, ``L1.f``) are kept beside.

The names of an instance's parts carry its prefix with dots (``leg_2.beater``, a
component's part; ``bgc.model.components``), which no identifier may hold: ``ident``
writes each dot as ``__0``, here, for every symbol. A name bgc accepts has no ``__`` and
never starts with a digit, so a dot's ``__0`` is always followed by a name's first
character (a letter or one ``_``), and ``ident`` is one-to-one on dotted names; the names
bgc generates from them join parts with ``__`` and a name (``hinge__rx``, ``box__P``) or
end a part in ``__0`` followed by ``__`` (a point's 0-junction, ``box__P__0__x``) or in
numbers (``ROT_box__01``). So ``name`` reads a reference's target (which is a model's
name, never a generated one) back exactly, and no two names share an identifier.
"""

from __future__ import annotations

import functools

import sympy as sp

t = sp.Symbol("t", real=True)

# Local names inside a constitutive law: the element's own port variables and state.
LOCAL = {name: sp.Symbol(f"LOCAL_{name}", real=True) for name in ("e", "f", "q", "p")}


DOT = "__0"       # an instance's dot in an identifier (module doc)


def ident(name: str) -> str:
    """A (flat, dotted) name as an identifier: each ``.`` as ``__0``."""
    return name.replace(".", DOT)


def name(identifier: str) -> str:
    """The name ``ident`` made ``identifier`` from."""
    return identifier.replace(DOT, ".")


@functools.lru_cache(maxsize=1 << 16)
def _sym(name: str) -> sp.Symbol:
    """The real symbol of ``name`` (its ``ident``; memoized: the same object sympy would
    return from its cache, without re-checking the assumptions on every one of the many
    calls)."""
    return sp.Symbol(ident(name), real=True)


def param(name: str) -> sp.Symbol:
    return _sym(f"P_{name}")


def signal(name: str) -> sp.Symbol:
    return _sym(f"U_{name}")


def ref(target: str, attr: str) -> sp.Symbol:
    """A reference such as ``spring.e`` in a user expression, resolved after causality."""
    return _sym(f"REF_{target}__{attr}")


AXES = "xyz"


def effort(bond: str, comp: int | None = None) -> sp.Symbol:
    """Effort of a bond; ``comp`` names one component of a multibond (0, 1, 2 -> x, y, z)."""
    return _sym(f"E_{bond}" if comp is None else f"E_{bond}__{AXES[comp]}")


def flow(bond: str, comp: int | None = None) -> sp.Symbol:
    return _sym(f"F_{bond}" if comp is None else f"F_{bond}__{AXES[comp]}")


def rotation(body: str, i: int, j: int) -> sp.Symbol:
    """Entry (i, j) of a body's rotation matrix (body frame -> R0), from its Cardan angles."""
    return _sym(f"ROT_{body}__{i}{j}")


def unknown(element: str, comp: int) -> sp.Symbol:
    """An algebraic unknown (the twist of a body of negligible mass)."""
    return _sym(f"W_{element}__{AXES[comp]}")


def acceleration(element: str, comp: int) -> sp.Symbol:
    """Method lagrange: the rate of the twist of a body of negligible mass, an unknown of
    the constraint block next to the multipliers."""
    return _sym(f"ACC_{element}__{AXES[comp]}")


def multiplier(joint: str, label: str) -> sp.Symbol:
    """The Lagrange multiplier of a joint's blocked direction (method ``lagrange``): the
    effort of its constraint element L."""
    return _sym(f"LAM_{joint}__{label}")


def state(element: str, kind: str) -> sp.Symbol:
    return _sym(f"X_{element}__{kind}")


def dstate(element: str, kind: str) -> sp.Symbol:
    return _sym(f"DX_{element}__{kind}")


def algebraic(element: str, kind: str) -> sp.Symbol:
    """A storage variable that is not a state (derivative causality), e.g. q of a C."""
    return _sym(f"V_{element}__{kind}")


def modulus(element: str, i: int, j: int) -> sp.Symbol:
    """Entry (i, j) of a modulated transformer's matrix, given its own assignment."""
    return _sym(f"M_{element}__{i}{j}")


def output(name: str) -> sp.Symbol:
    return _sym(f"Y_{name}")


def block(name: str, attr: str) -> sp.Symbol:
    """A control block's signal: its input ``u``, output ``y``, unsaturated output ``v``."""
    return _sym(f"BLK_{name}__{attr}")


# What a symbol stands for, from the prefix this module gave it: the one inverse of the
# naming above, so that no other stage reads meaning into a symbol's name.
_KINDS = {"DX_": "rate", "X_": "state", "LAM_": "multiplier", "ACC_": "acceleration",
          "W_": "unknown", "P_": "parameter", "U_": "signal", "REF_": "reference",
          "E_": "effort", "F_": "flow", "V_": "algebraic", "Y_": "output", "ROT_": "rotation",
          "BLK_": "block"}


def kind(s: sp.Symbol) -> str | None:
    """``rate`` (a state's derivative), ``multiplier``, ``acceleration`` (a massless
    body's twist rate under an ideal method), ``unknown`` (a massless body's twist),
    ``state``, ``parameter``, ... or None for a symbol not named here."""
    prefix = s.name.split("_", 1)[0] + "_"
    return _KINDS.get(prefix)


def is_ref(s: sp.Symbol) -> bool:
    return kind(s) == "reference"


def split_ref(s: sp.Symbol) -> tuple[str, str]:
    """(target, attr) of a reference symbol, the target in model names (dotted)."""
    target, attr = s.name[4:].rsplit("__", 1)
    return name(target), attr


def renamed(e, rename: dict, memo: dict):
    """``e`` with its symbols renamed (``rename``: symbol -> symbol), its form kept: a sum
    or product is rebuilt from its renamed terms as they stand (``_from_args``: no
    re-sorting, no combining), about 25 times faster than ``xreplace``, which evaluates
    each node again. ``memo``: shared subexpressions, renamed once."""
    if e.is_Symbol:
        return rename.get(e, e)
    if not e.args:
        return e
    hit = memo.get(e)
    if hit is None:
        args = tuple(renamed(a, rename, memo) for a in e.args)
        hit = memo[e] = (e.func._from_args(args) if e.is_Add or e.is_Mul
                         else e.func(*args))
    return hit
