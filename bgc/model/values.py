"""Stage **load**: checks of one located YAML value (``document.YMap``/``YList`` and
scalars) that turn it into a Python value or raise a ModelError naming its
``file:line:col``, key path and a hint.

Used by every reader of the load stage (``bgc.model.sections``) and by the scene reader
(``bgc.scene.scenes``), so a mistake reads the same in a model and in a scene file. Each
function is stateless: what depends on the rest of the model (names already declared,
parameter values) is ``sections.context.Context``'s.
"""

from __future__ import annotations

import contextlib
import re
import sys

from bgc.errors import ModelError
from bgc.model import expr as bexpr
from bgc.model.document import YList, YMap, plain
from bgc.model.model import MAX_POINTS

IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\Z")     # a name bgc accepts (no keywords check)


def fail(msg, loc, key, hint=None):
    """Raise the located error ``msg`` at ``loc`` under the key path ``key``."""
    raise ModelError(msg, loc=loc, key=key, hint=hint)


def kind_of(v) -> str:
    """What a YAML value is, as a message says it: 'a mapping', 'a list', 'nothing', 'int'."""
    if isinstance(v, dict):
        return "a mapping"
    if isinstance(v, list):
        return "a list"
    if v is None:
        return "nothing"
    return type(v).__name__


def short(v) -> str:
    """A value shown after its kind in a message: ' ' and its repr, cut to 40
    characters ('' for nothing)."""
    if v is None:
        return ""
    text = " " + repr(plain(v))
    return text if len(text) <= 40 else text[:37] + "..."


def mapping(v, loc, key, what="a mapping") -> YMap:
    """``v`` itself if it is a mapping."""
    if not isinstance(v, YMap):
        fail(f"expected {what}, got {kind_of(v)}", loc, key,
             "write a mapping such as {name: value}" if what == "a mapping"
             else f"write {what}")
    return v


def string(v, loc, key, what="a name") -> str:
    """A plain string (a name, a path), not a number, list or mapping."""
    if not isinstance(v, str):
        fail(f"expected {what}, got {kind_of(v)}{short(v)}", loc, key,
             f"write {what} as plain text")
    return v


def text(v, loc, key, what="a text"):
    """A description or a unit: text, or a number written as one (``unit: 1`` for a
    dimensionless quantity, ``description: 2024``: earlier bgc took these, and they are
    read as the text they are); None stays None."""
    if v is None or isinstance(v, str):
        return v
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return str(v)
    return string(v, loc, key, what)


# an output's unit (``outputs: {a: {expr: ..., unit: m/s^2}}``) goes into generated code and
# into plot labels: a short text of letters, digits and a few signs, nothing that a string
# literal, a docstring or matplotlib's mathtext ($, \\) would read as syntax
UNIT = re.compile(r"[A-Za-z0-9 /*^.()%+_-]{1,32}")


def unit(v, loc, key) -> str:
    """An output's unit: ``UNIT`` text, e.g. m/s^2, N m, kg m^2, 1 (dimensionless)."""
    written = text(v, loc, key, "a unit text")
    if not UNIT.fullmatch(written) or not written.strip():
        fail(f"unit {written[:40]!r} is not a unit text", loc, key,
             "up to 32 letters, digits, spaces and / * ^ . ( ) % + _ -, e.g. m/s^2, N m, 1")
    return written.strip()


def strings(v, loc, key, what="names") -> list[str]:
    """A list of plain strings."""
    if not isinstance(v, YList):
        fail(f"expected a list of {what}, got {kind_of(v)}{short(v)}", loc, key,
             "write [a, b, ...]")
    return [string(x, v.item_locs[i], f"{key}[{i}]", "a " + what.rstrip("s"))
            for i, x in enumerate(v)]


def check_keys(m: YMap, allowed, key):
    """Every key of ``m`` is one of ``allowed``; a description or unit is text."""
    for k in m:
        if k not in allowed:
            fail(f"unknown key '{k}'", m.key_locs[k], f"{key}.{k}",
                 "valid keys: " + ", ".join(allowed))
        if k in ("description", "unit") and m[k] is not None:
            text(m[k], m.val_locs[k], f"{key}.{k}", f"a {k} text")


def number(v, loc, key, *, positive=False, nonneg=False, divisor=False) -> float:
    """A finite plain number; ``positive``/``nonneg`` bound it; ``divisor``: it divides
    in the equations, so it must be a normal float (a subnormal one such as 5e-324 has
    a reciprocal beyond the float range)."""
    if isinstance(v, str):      # YAML 1.1 reads 1e-3 and 4.0e6 as strings
        with contextlib.suppress(ValueError):
            v = float(v)
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        fail(f"expected a number, got {kind_of(v)} {v!r}", loc, key,
             "write a plain number such as 1.5 or 2e-3")
    try:
        bexpr.number(v)
    except ValueError as exc:
        fail(f"expected a finite number: {exc}", loc, key,
             "write a finite number such as 1.5 or 2e-3")
    v = float(v)
    if positive and v <= 0:
        fail(f"must be > 0, got {v}", loc, key, "write a positive number")
    if nonneg and v < 0:
        fail(f"must be >= 0, got {v}", loc, key, "write a number >= 0")
    if divisor and 0 < abs(v) < sys.float_info.min:
        fail(f"{v:g} is a subnormal float: its reciprocal is beyond the float range",
             loc, key, f"a divisor is at least {sys.float_info.min:.4g} in size; "
                       "rescale the units if the value is really this small")
    return v


def points(v, loc, key) -> int:
    """A number of output times: an integer from 2 to ``MAX_POINTS``."""
    n = number(v, loc, key)
    if n != int(n) or not 2 <= n <= MAX_POINTS:
        fail(f"expected a whole number of output times from 2 to {MAX_POINTS}, got "
             f"{n:g}", loc, key, "e.g. 1001; each point is a row of the result")
    return int(n)


def number_list(v, loc, key) -> list[float]:
    """A list of plain numbers."""
    if not isinstance(v, YList):
        fail(f"expected a list of numbers, got {kind_of(v)}", loc, key)
    return [number(x, v.item_locs[i], f"{key}[{i}]") for i, x in enumerate(v)]


def vector(v, loc, key) -> tuple[float, float, float]:
    """Three plain numbers [x, y, z]."""
    vals = number_list(v, loc, key)
    if len(vals) != 3:
        fail(f"expected 3 numbers [x, y, z], got {len(vals)}", loc, key)
    return tuple(vals)
