"""The ``blocks:`` section: signal-flow control blocks (gain, sum, integrator, lag, PI,
PID). Read in two passes, as the elements are: their names and kinds first (``headers``,
so that an MSe's effort may read ``ctrl.y``), then their inputs, which may name
elements, bonds, bodies, joints and other blocks (``blocks``). Gains, time constants,
limits and initial values are expressions of parameters, checked at the parameters'
values; a cycle of blocks whose outputs read their inputs directly is refused here."""

from __future__ import annotations

import math

import sympy as sp

from bgc.symbolic.algorithms import is_cyclic, strongly_connected
from bgc.model import symbols
from bgc.model.document import YList, YMap
from bgc.model.model import BLOCK_KINDS, Block
from bgc.model.sections.context import Context
from bgc.model.values import check_keys, fail, text

ANTI_WINDUP = ("back_calculation", "none")
# the values that must be > 0 at the parameters' values: key -> what it is
_POSITIVE = {"T": "a time constant", "tt": "a tracking time constant",
          "n": "the derivative filter's n (Td/n is its time constant)"}


def headers(cx: Context, sec: YMap) -> dict[str, tuple[str, YMap]]:
    """Each block's name and kind: name -> (kind, its mapping). The blocks are known to
    ``cx`` from here on, so element laws and outputs may read ``name.y``."""
    out = cx.typed(sec, "blocks", "block", list(BLOCK_KINDS), "a mapping with type and input")
    cx.blocks = {n: k for n, (k, _) in out.items()}
    return out


def blocks(cx: Context, heads, params, signals, elements, bonds) -> dict[str, Block]:
    """Each block with its input, values, limits and initial value (``heads``: from
    ``headers``); a cycle of feedthrough blocks is refused with their names."""
    kinds = {n: e.kind for n, e in elements.items()}
    bond_names = {b.name for b in bonds}

    def resolver(key, loc):
        def resolve(target, attr):
            return cx.resolve_ref(target, attr, kinds, bond_names, key, loc)
        return resolve

    names = cx.expr_names(params, signals)
    pnames = {n: symbols.param(n) for n in params}
    out = {name: _block(cx, name, kind, v, names, pnames, resolver)
           for name, (kind, v) in heads.items()}
    _check_cycles(out, heads)
    return out


def _block(cx: Context, name, kind, v: YMap, names, pnames, resolver) -> Block:
    """One block from its mapping ``v``: keys, input, values (a kind's defaults where
    not given), limits, anti-windup and initial value, checked."""
    spec, key = BLOCK_KINDS[kind], f"blocks.{name}"
    allowed = (("type", "description", "input", "limits") + (("inputs",) if kind == "sum"
                                                            else ())
               + spec.required + tuple(spec.optional)
               + (("anti_windup",) if kind in ("PI", "PID") else ())
               + ((spec.initial,) if spec.initial else ()))
    check_keys(v, allowed, key)
    u = _input(cx, v, kind, key, names, resolver)
    values = {}
    for k in spec.required + tuple(spec.optional):
        if k in v:
            values[k] = _value(cx, v[k], v.val_locs[k], f"{key}.{k}", pnames)
        elif k in spec.required:
            fail(f"missing '{k}'", v.loc, key, f"a {kind} block needs "
                 + ", ".join(spec.required) + f": {spec.doc}")
        elif spec.optional[k] is not None:
            values[k] = sp.sympify(spec.optional[k])
    limits = _limits(cx, v, key, pnames) if "limits" in v else None
    aw = v.get("anti_windup", "back_calculation")
    if aw not in ANTI_WINDUP:
        fail(f"unknown anti_windup {aw!r}", v.val_locs["anti_windup"],
             f"{key}.anti_windup", "valid: " + ", ".join(ANTI_WINDUP))
    initial = (_value(cx, v[spec.initial], v.val_locs[spec.initial],
                      f"{key}.{spec.initial}", pnames) if spec.initial in v else sp.S.Zero)
    blk = Block(name, kind, v.loc, u, values, limits, initial, aw != "none",
                text(v.get("description"), v.val_locs.get("description"),
                     f"{key}.description"))
    _check_values(cx, blk, v, key)
    return blk


def _input(cx: Context, v: YMap, kind, key, names, resolver) -> sp.Expr:
    """The block's input: ``input`` (an expression), or a sum's ``inputs`` added."""
    def parse(text, loc, k):
        return cx.parse(text, loc=loc, key=k, names=names, resolve_ref=resolver(k, loc))

    if kind == "sum" and "inputs" in v:
        if "input" in v:
            fail("a sum takes 'inputs' or 'input', not both", v.val_locs["input"],
                 f"{key}.input", "inputs: [a, -b, ...] or input: \"a - b\"")
        items = v["inputs"]
        if not isinstance(items, YList) or not items:
            fail("'inputs' is a list of expressions", v.val_locs["inputs"], f"{key}.inputs",
                 "write inputs: [x_set, -mass.x]")
        return sp.Add(*[parse(x, items.item_locs[i], f"{key}.inputs[{i}]")
                        for i, x in enumerate(items)])
    if "input" not in v:
        fail(f"missing '{'inputs' if kind == 'sum' else 'input'}'", v.loc, key,
             "inputs: [a, -b]" if kind == "sum" else "input: an expression such as "
             "\"x_set - mass.x\"")
    return parse(v["input"], v.val_locs["input"], f"{key}.input")


def _value(cx: Context, text, loc, key, pnames) -> sp.Expr:
    """A gain, time constant, limit or initial value: a number or an expression of the
    model's parameters (read as it is by the generated code, so ``-p`` changes it)."""
    return cx.parse(text, loc=loc, key=key, names=pnames)


def _limits(cx: Context, v: YMap, key, pnames) -> tuple[sp.Expr, sp.Expr]:
    """``limits: [lo, hi]``, with lo < hi at the parameters' values."""
    lim, loc = v["limits"], v.val_locs["limits"]
    if not isinstance(lim, YList) or len(lim) != 2:
        fail("'limits' is a list [lo, hi]", loc, f"{key}.limits",
             "write limits: [-24, 24] (numbers or expressions of parameters)")
    lo, hi = (_value(cx, x, lim.item_locs[i], f"{key}.limits[{i}]", pnames)
              for i, x in enumerate(lim))
    vlo, vhi = _at(cx, lo), _at(cx, hi)
    if not vlo < vhi:
        fail(f"limits [{vlo:g}, {vhi:g}]: the lower limit must be below the upper", loc,
             f"{key}.limits", "write limits: [lo, hi] with lo < hi")
    return lo, hi


def _at(cx: Context, e: sp.Expr) -> float:
    """An expression of parameters at their values (``-p`` included)."""
    return float(e.xreplace(cx.pvals))


def _check_values(cx: Context, blk: Block, v: YMap, key):
    """Time constants > 0 (T = 0 is no lag); a clamping integrator's y0 within its
    limits; PID's derivative filter time kd/(kp n) > 0; the default tracking time of
    back-calculation (Ti = kp/ki for PI, sqrt(Ti Td) for PID) defined where the output
    is limited."""
    for k, what in _POSITIVE.items():
        if k in blk.values and k in v:
            val = _at(cx, blk.values[k])
            if not (math.isfinite(val) and val > 0):
                fail(f"{k} = {val:g}: {what} must be > 0", v.val_locs[k], f"{key}.{k}",
                     "use a gain block for no lag" if k == "T" and val == 0 else
                     "write a positive value")
    if blk.kind == "integrator" and blk.limits and "y0" in v and not (
            _at(cx, blk.limits[0]) <= _at(cx, blk.initial) <= _at(cx, blk.limits[1])):
        fail(f"y0 = {_at(cx, blk.initial):g} is outside the limits", v.val_locs["y0"],
             f"{key}.y0", "a clamping integrator starts within [lo, hi]")
    p = {k: _at(cx, e) for k, e in blk.values.items()}
    if blk.kind == "PID" and not (p["kp"] * p["n"] != 0 and p["kd"] / (p["kp"] * p["n"]) > 0):
        fail(f"the derivative filter's time constant kd/(kp n) = {p['kd']:g}/"
             f"({p['kp']:g} * {p['n']:g}) must be > 0", v.val_locs["kd"], f"{key}.kd",
             "kp and kd of one sign, not 0 (use a PI block for no derivative)")
    if blk.kind in ("PI", "PID") and blk.limits and blk.anti_windup and "tt" not in v:
        over = p["kp"] if blk.kind == "PI" else p["kd"]     # 1/Tt = ki/kp, sqrt(ki/kd)
        if over == 0 or p["ki"] / over < 0:
            fail("the default tracking time " + ("Ti = kp/ki" if blk.kind == "PI" else
                                                 "sqrt(Ti Td) = sqrt(kd/ki)")
                 + f" is not a positive time (kp {p['kp']:g}, ki {p['ki']:g})",
                 v.val_locs["ki"], f"{key}.ki",
                 "give 'tt' (the anti-windup tracking time) or anti_windup: none")


def _check_cycles(out: dict[str, Block], heads):
    """Refuse a cycle of blocks that read their inputs directly (gain, sum, PI, PID): an
    algebraic loop with no state to break it. A block's ``.u`` reads what its input names;
    its ``.y`` reads its ``.u`` unless a state stands between (integrator, lag)."""
    deps: dict = {}
    for name, blk in out.items():
        read = set()
        for s in blk.input.free_symbols:
            if symbols.is_ref(s):
                target, attr = symbols.split_ref(s)
                if target in out:
                    read.add((target, attr))
        deps[(name, "u")] = read
        deps[(name, "y")] = {(name, "u")} if BLOCK_KINDS[blk.kind].feedthrough else set()
    for comp in strongly_connected(list(deps), deps):
        if is_cyclic(comp, deps):
            names = list(dict.fromkeys(n for n, _ in comp))
            first = heads[names[0]][1]
            fail("algebraic loop through blocks " + ", ".join(names) + ": each output "
                 "reads the next one's input directly", first.val_locs.get(
                     "input", first.val_locs.get("inputs", first.loc)),
                 f"blocks.{names[0]}", "break it with a lag or an integrator, or write "
                 "the loop's closed form")
