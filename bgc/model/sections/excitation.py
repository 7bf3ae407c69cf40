"""The ``excitation:`` section, lowered to parameters (each direction's amplitude, each
kind's weight, the sine's frequency), the signal ``excitation`` (the weighted sum of the
kinds' g(t)) and an actuator term on each direction's joint, so that one compiled module
runs every kind in every direction (``Excitation.select`` sets the parameters)."""

from __future__ import annotations

import sympy as sp

from bgc.mechanics.joints import JOINT_KINDS
from bgc.model import signals as bsignals
from bgc.model import symbols
from bgc.model.document import YMap
from bgc.model.model import Excitation, Functional, Parameter, Signal
from bgc.model.sections.context import Context
from bgc.model.sections.joints import joint_params
from bgc.model.sections.parameters import signal
from bgc.model.values import IDENT, check_keys, fail, mapping, number


def excitation(cx: Context, sec: YMap, params, signals, tables) -> Excitation | None:
    """The model's Excitation (None without the section); adds to ``params``,
    ``signals`` (``tables``: as in ``parameters.signals``) and the joints' actuators."""
    if not sec:
        return None
    check_keys(sec, ("directions", "kinds", "description"), "excitation")
    for k in ("directions", "kinds"):
        if k not in sec:
            fail(f"missing 'excitation.{k}'", sec.loc, "excitation",
                 "directions: {name: {joint, amplitude}}, kinds: {name: signal}")
    kinds, freq = _kinds(cx, sec, params, signals, tables)
    directions = _directions(cx, sec, params, kinds)
    return Excitation(directions, kinds, freq, sec.loc)


def _kinds(cx: Context, sec: YMap, params, signals, tables) -> tuple[dict, float | None]:
    """Each kind's signal, weighted by its parameter into the signal ``excitation``;
    (kinds, the sine's frequency or None)."""
    names = {n: symbols.param(n) for n in params}
    ks = mapping(sec["kinds"], sec.val_locs["kinds"], "excitation.kinds",
                 "a mapping kind -> signal (constant, sine, chirp, ...)")
    kinds, freq, g, bps, freqs = {}, None, sp.S.Zero, set(), []
    for kind, v in ks.items():
        key = f"excitation.kinds.{kind}"
        if not isinstance(kind, str) or not IDENT.match(kind) or "__" in kind:
            fail(f"'{kind}' is not a valid kind name", ks.key_locs[kind], key)
        sig, vals = signal(cx, kind, v, ks.val_locs[kind], key, names, tables)
        if sig.kind == "sine":
            if freq is not None or not vals["frequency"].is_number:
                fail("one sine kind, with a numeric frequency (--frequency changes "
                     "it at run time)", ks.val_locs[kind], key)
            freq = float(vals["frequency"])
            params[Excitation.FREQUENCY] = Parameter(Excitation.FREQUENCY, freq, sig.loc,
                                                     "Hz")
            expr = bsignals.build("sine", {**vals, "frequency":
                                           symbols.param(Excitation.FREQUENCY)}, -1)[0]
            sig = Signal(kind, "sine", sp.sympify(expr), sig.loc,
                         frequency=symbols.param(Excitation.FREQUENCY))
        w = Excitation.param(kind)
        params[w] = Parameter(w, 0.0, sig.loc)
        g += symbols.param(w) * sig.expr
        if sig.frequency is not None:      # only the selected kind limits the step
            freqs.append(sp.Piecewise((sig.frequency, sp.Ne(symbols.param(w), 0)),
                                      (0, True)))
        bps.update(sig.breakpoints)
        kinds[kind] = sig
    cx.declare(Excitation.SIGNAL, "the excitation signal", sec.loc, "excitation")
    signals[Excitation.SIGNAL] = Signal(Excitation.SIGNAL, "excitation", g, sec.loc,
                                        tuple(sorted(bps)),
                                        frequency=sp.Max(*freqs) if freqs else None)
    return kinds, freq


def _directions(cx: Context, sec: YMap, params, kinds) -> dict[str, tuple[str, float]]:
    """Each direction: its joint's actuator gains amplitude parameter x ``excitation``;
    name -> (joint, amplitude)."""
    ds = mapping(sec["directions"], sec.val_locs["directions"],
                 "excitation.directions", "a mapping name -> {joint, amplitude}")
    directions = {}
    for d, v in ds.items():
        key = f"excitation.directions.{d}"
        if not isinstance(d, str) or not IDENT.match(d) or "__" in d or d in kinds:
            fail(f"'{d}' is not a valid direction name (or it names a kind)",
                 ds.key_locs[d], key)
        m = mapping(v, ds.val_locs[d], key, "a mapping {joint, amplitude}")
        check_keys(m, ("joint", "amplitude", "direction", "description"), key)
        for k in ("joint", "amplitude"):
            if k not in m:
                fail(f"missing '{k}'", m.loc, key,
                     "joint: the joint it acts in, amplitude: force [N] or torque [N m]")
        j = cx.joints.get(m["joint"]) if isinstance(m["joint"], str) else None
        if j is None:
            fail(f"unknown joint {m['joint']!r}", m.val_locs["joint"], f"{key}.joint",
                 "declared joints: " + ", ".join(cx.joints))
        free = JOINT_KINDS[j.kind].free
        if not free:
            fail(f"a {j.kind} joint has no free direction to excite",
                 m.val_locs["joint"], f"{key}.joint")
        label = m.get("direction", free[0])
        if label not in free:
            fail(f"'{label}' is not a free direction of a {j.kind} joint",
                 m.val_locs["direction"], f"{key}.direction",
                 "free directions: " + ", ".join(free))
        amp = number(m["amplitude"], m.val_locs["amplitude"], f"{key}.amplitude")
        a = Excitation.param(d)
        params[a] = Parameter(a, 0.0, m.loc)
        term = symbols.param(a) * symbols.signal(Excitation.SIGNAL)
        fun = j.functional.get(label, Functional(loc=m.loc))
        j.functional[label] = Functional(
            fun.k, fun.c, fun.preload, term if fun.actuator is None else fun.actuator + term,
            fun.loc)
        joint_params(j, params)
        directions[d] = (j.name, amp)
    return directions
