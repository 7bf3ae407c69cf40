"""The ``parameters:`` and ``signals:`` sections: named values (changeable without
recompiling) and the time functions built from them (``bgc.model.signals``)."""

from __future__ import annotations

import sympy as sp

from bgc.model import limits, symbols
from bgc.model import signals as bsignals
from bgc.model.document import YMap
from bgc.model.model import Parameter, Signal, Table
from bgc.model.sections.context import Context
from bgc.model.values import check_keys, fail, mapping, number, number_list, text


def parameters(cx: Context, sec: YMap) -> dict[str, Parameter]:
    """Each parameter, a number or ``{value, unit, description}`` (``unit: deg`` is
    turned into radians); their values are known to ``cx`` from here on."""
    out = {}
    for name, v in sec.items():
        key, loc = f"parameters.{name}", sec.val_locs[name]
        cx.declare(name, f"parameter '{name}'", sec.key_locs[name], key)
        unit = None
        if isinstance(v, YMap):
            check_keys(v, ("value", "unit", "description"), key)
            if "value" not in v:
                fail("missing 'value'", v.loc, key, "write {value: 1.0, unit: kg}")
            unit = text(v.get("unit"), v.val_locs.get("unit"), f"{key}.unit")
            loc = v.val_locs["value"]
            v = v["value"]
        value = number(v, loc, key)
        if unit == "deg":
            value = value * 3.141592653589793 / 180.0
        out[name] = Parameter(name, value, loc, unit)
        cx.pvals[symbols.param(name)] = value
    return out


def signals(cx: Context, sec: YMap, params, tables: list[Table]) -> dict[str, Signal]:
    """Each named signal (a table signal's samples are appended to ``tables``)."""
    out = {}
    names = {n: symbols.param(n) for n in params}
    for name, v in sec.items():
        key = f"signals.{name}"
        cx.declare(name, f"signal '{name}'", sec.key_locs[name], key)
        out[name] = signal(cx, name, v, sec.val_locs[name], key, names, tables)[0]
    return out


def signal(cx: Context, name, v, loc, key, names, tables: list[Table]) -> tuple[Signal, dict]:
    """One signal and its parsed fields (``names``: what its expressions may name)."""
    v = mapping(v, loc, key, "a mapping with 'type'")
    kind = v.get("type")
    if not isinstance(kind, str) or kind not in bsignals.SIGNAL_TYPES:
        fail(f"unknown signal type {kind!r}", v.val_locs.get("type", v.loc),
             f"{key}.type", "valid types: " + ", ".join(bsignals.SIGNAL_TYPES))
    required, optional = bsignals.SIGNAL_TYPES[kind]
    check_keys(v, ("type", "description") + required + tuple(optional), key)
    vals = {}
    for k in required:
        if k not in v:
            fail(f"missing '{k}' for a {kind} signal", v.loc, key,
                 "needs: " + ", ".join(required))
    for k in required + tuple(optional):
        kk, kloc = f"{key}.{k}", v.val_locs.get(k, v.loc)
        if kind == "table":
            vals[k] = number_list(v[k], kloc, kk)
        elif k in bsignals.NUMBER_FIELDS:
            vals[k] = number(v.get(k, optional.get(k)), kloc, kk)
        elif k == "expr":
            vals[k] = cx.parse(v[k], loc=kloc, key=kk, names={**names, "t": symbols.t})
        else:
            vals[k] = cx.parse(v.get(k, optional.get(k)), loc=kloc, key=kk, names=names)
    if kind == "table":
        tt, yy = vals["t"], vals["values"]
        if len(tt) != len(yy) or len(tt) < 2:
            fail(f"'t' and 'values' must have the same length >= 2 "
                 f"(got {len(tt)} and {len(yy)})", v.loc, key)
        if any(b <= a for a, b in zip(tt, tt[1:])):
            fail("'t' must be strictly increasing", v.val_locs["t"], f"{key}.t")
        tables.append(Table(len(tables), tuple(tt), tuple(yy)))
    _check_frequencies(cx, v, key, vals)
    if kind == "chirp":
        t1, t2, t3 = vals["t1"], vals["t2"], vals["t3"]
        if not 0 < t1 <= t2 < t3:
            fail(f"chirp times must satisfy 0 < t1 <= t2 < t3, got t1 = {t1:g}, "
                 f"t2 = {t2:g}, t3 = {t3:g}", v.loc, key,
                 "t1: end of the ramp-up, t2/t3: start/end of the sweep")
    expr, bps = bsignals.build(kind, vals, len(tables) - 1)
    numbers = {k: float(x) for k, x in vals.items() if k in bsignals.NUMBER_FIELDS}
    return Signal(name, kind, sp.sympify(expr), v.loc, bps, numbers,
                  bsignals.frequency(kind, vals)), vals


def _check_frequencies(cx: Context, v: YMap, key, vals):
    """A signal's constant frequencies are > 0 and slow enough for the model's t_end
    (``limits.too_fast``)."""
    for k in ("frequency", "f_start", "f_end"):
        f = (sp.sympify(sp.sympify(vals[k]).xreplace(cx.pvals)) if k in vals
             else None)
        if f is None or not f.is_number:
            continue
        if float(f) <= 0:
            fail(f"must be > 0, got {float(f)}", v.val_locs.get(k, v.loc),
                 f"{key}.{k}", "a frequency in Hz, > 0")
        why = limits.too_fast(float(f), cx.t_end)
        if why:
            fail(why, v.val_locs.get(k, v.loc), f"{key}.{k}",
                 "lower the frequency or shorten simulation.t_end")
