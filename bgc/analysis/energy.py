"""Where the power goes: a run of a module's energy variant (``codegen.energy``) read as
an energy balance (``bgc energy``).

For every element the module's ``ENERGY`` table lists: the energy it supplied (sources,
and the work of a method's constraint elements, which ideal joints keep at zero), the
energy stored at the end minus the start (C, I, the bodies' kinetic energy, gravity's
potential energy, parasitic springs: the element's energy function where the module has
one, ``stored[NAME]``, else its power integrated), the energy dissipated (R, parasitic
dampers), its activity A = int |P| dt and its share of the total activity. The same summed
per body, per joint and per component instance (every dotted prefix of an owner's name:
``leg_2.beater`` is in ``leg_2``), and the balance supplied = stored + dissipated with its
residual. No sympy: this reads the run's final and first states and outputs only.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

COLUMNS = ("supplied", "stored", "dissipated")


@dataclass
class Line:
    """One element's or one group's energies [J] and activity [J] over the run."""
    name: str
    kind: str
    supplied: float = 0.0
    stored: float = 0.0
    dissipated: float = 0.0
    activity: float = 0.0
    share: float = 0.0
    elements: list[str] = field(default_factory=list)   # a group's elements

    def to_dict(self, group: bool = False) -> dict:
        out = {"name": self.name, "kind": self.kind, "supplied": self.supplied,
               "stored": self.stored, "dissipated": self.dissipated,
               "activity": self.activity, "share": self.share}
        if group:
            out["elements"] = list(self.elements)
        return out


@dataclass
class Balance:
    elements: list[Line]
    groups: list[Line]
    supplied: float
    stored: float
    dissipated: float
    t0: float
    t1: float
    owner: dict[str, str] = field(default_factory=dict)     # element -> body or joint

    @property
    def residual(self) -> float:
        return self.supplied - self.stored - self.dissipated

    @property
    def scale(self) -> float:
        """What the residual is measured against: the energy the sources supplied, or
        where they supplied none (a free motion; the constraints' work is not a supply),
        the largest element's activity (the largest energy that moved)."""
        sources = abs(sum(ln.supplied for ln in self.elements if ln.kind == "source"))
        return sources if sources > 0 else max([ln.activity for ln in self.elements]
                                               or [0.0])

    @property
    def measured_by(self) -> str:
        sources = any(ln.kind == "source" and ln.supplied for ln in self.elements)
        return "the sources' supply" if sources else "the largest activity"

    @property
    def relative_residual(self) -> float:
        return abs(self.residual) / self.scale if self.scale > 0 else 0.0

    def to_dict(self) -> dict:
        return {"elements": [ln.to_dict() for ln in self.elements],
                "groups": [g.to_dict(group=True) for g in self.groups],
                "balance": {"supplied": self.supplied, "stored": self.stored,
                            "dissipated": self.dissipated, "residual": self.residual}}


def is_energy_module(module) -> bool:
    return bool(getattr(module, "ENERGY", ()))


def account(module, result, since: float | None = None) -> Balance:
    """The balance of a run (``simulate.Result``) of an energy variant: each element's
    line from its quadrature states at the run's end less at its start, its stored
    energy from its energy function at the end and the start where it has one. With
    ``since``: from the first output time at or after it (the quadratures are exact at
    the output times, not between), e.g. the steady state after a transient."""
    names, outs = list(result.state_names), list(result.output_names)
    k0 = 0 if since is None else int(np.searchsorted(result.t, since - 1e-12 * abs(since)))
    k0 = min(k0, len(result.t) - 1)
    x_end, x_start = result.x[-1], result.x[k0]
    lines, owner = [], {}
    for name, kind, column, body, joint in module.ENERGY:
        work = float(x_end[names.index(f"energy[{name}]")]
                     - x_start[names.index(f"energy[{name}]")])
        activity = float(x_end[names.index(f"activity[{name}]")]
                         - x_start[names.index(f"activity[{name}]")])
        stored_out = f"stored[{name}]"
        if column == "stored" and stored_out in outs and result.y.size:
            k = outs.index(stored_out)
            work = float(result.y[-1, k] - result.y[k0, k])
        ln = Line(name, kind, activity=activity)
        setattr(ln, column, work)
        lines.append(ln)
        owner[name] = body or joint or name
    total = sum(ln.activity for ln in lines)
    for ln in lines:
        ln.share = ln.activity / total if total > 0 else 0.0
    groups = _groups(lines, module.ENERGY, total)
    return Balance(lines, groups, *(float(sum(getattr(ln, c) for ln in lines))
                                    for c in COLUMNS),
                   float(result.t[k0]), float(result.t[-1]), owner)


def _groups(lines: list[Line], table, total: float) -> list[Line]:
    """Per body, per joint and per component instance (every dotted prefix of the
    element's owner: its body, its joint or itself), in order of first appearance."""
    groups: dict[tuple[str, str], Line] = {}

    def add(kind, name, ln):
        g = groups.setdefault((kind, name), Line(name, kind))
        for c in COLUMNS + ("activity",):
            setattr(g, c, getattr(g, c) + getattr(ln, c))
        g.elements.append(ln.name)

    for ln, (name, kind, column, body, joint) in zip(lines, table):
        if body:
            add("body", body, ln)
        if joint:
            add("joint", joint, ln)
        parts = (body or joint or name).split(".")
        for k in range(1, len(parts)):
            add("component", ".".join(parts[:k]), ln)
    out = list(groups.values())
    for g in out:
        g.share = g.activity / total if total > 0 else 0.0
    return out


def describe(bal: Balance, top: int | None = None) -> list[str]:
    """The balance as lines of text: the elements by activity (the ``top`` most active,
    all if None), the groups, the balance and its residual."""
    w = max([len(ln.name) for ln in bal.elements + bal.groups] + [7])
    head = f"  {'':{w}s}  {'kind':16s} {'supplied':>11s} {'stored':>11s} " \
        f"{'dissipated':>11s} {'activity':>11s} {'share':>7s}"

    def row(ln):
        return (f"  {ln.name:{w}s}  {ln.kind:16s} {ln.supplied:11.4g} {ln.stored:11.4g} "
                f"{ln.dissipated:11.4g} {ln.activity:11.4g} {100 * ln.share:6.2f}%")
    ranked = sorted(bal.elements, key=lambda ln: -ln.activity)
    shown = ranked if top is None else ranked[:top]
    out = [f"energy over t = {bal.t0:g} .. {bal.t1:g} s [J]", head]
    out += [row(ln) for ln in shown]
    if len(shown) < len(ranked):
        rest = ranked[len(shown):]
        out.append(f"  ... {len(rest)} more elements, "
                   f"{100 * sum(ln.share for ln in rest):.3g}% of the activity")
    if bal.groups:
        out += ["groups (body, joint, component):", head]
        out += [row(g) for g in sorted(bal.groups, key=lambda g: -g.activity)]
    out.append(f"balance: supplied {bal.supplied:.6g} J = stored {bal.stored:.6g} J + "
               f"dissipated {bal.dissipated:.6g} J; residual {bal.residual:.3g} J "
               f"({bal.relative_residual:.2g} of {bal.measured_by})")
    return out
