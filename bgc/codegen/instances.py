"""Instance loops: where many instances of one component compute the same thing, the
kernels compute it once per instance in a loop over a table instead of writing it out
once per instance (issue 40; DESIGN.md: "compile cost follows the number of component
kinds, not the model's size").

A program's straight-line steps (``steps.program_steps``: assignments, outputs, a
Jacobian's partials) are independent of each other within one *level* of the causal order (the
longest chain of assignments they are computed from), so any order within a level is
correct. ``schedule`` orders them level by level; at each level it groups the steps by the
instance they belong to (``owner``: the longest instance name in a symbol's name), and
the steps of one instance at one level by their structure: the expressions with every
symbol a placeholder ``T0, T1, ...`` in the order it is met, every number kept where the
group's instances agree on it and a placeholder ``C0, ...`` where they differ. A group of
at least ``MIN_COPIES`` instances with the same structure becomes a ``Loop``: one
template, written once in IR (``kernels.Module.loop``), and a table, a row per instance,
of where each placeholder lives (a state, a parameter, a workspace slot, an output) and of
the numbers that differ. The rest stays straight-line code, as before.

The values are the same as the straight-line code's up to the order of floating-point
operations within an expression where a number became a placeholder (round-off). A
model with fewer copies of any part than ``MIN_COPIES`` keeps its programs exactly as
they were (the SARIB's four legs: written out).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

import sympy as sp

from bgc.codegen.lowering import Function
from bgc.codegen.steps import STRAIGHT, Grad, LoopOver, Out, Set, Store
from bgc.model import symbols
from bgc.model.signals import table, table_slope
from bgc.symbolic.algorithms import reads

MIN_COPIES = 5           # the fewest instances of one structure that make a loop


@dataclass
class Loop:
    """One loop of a program: its template ``steps`` (``Set(T, e)``, ``Out(j, e)``,
    ``Store(j, e)`` and ``Grad(e, [(j, T)])`` in placeholders; ``j``: a row's entry, an
    output or a linear block's slot), where each placeholder and slot lives (``bases``:
    "x", "p", "w" or "out"), and per
    instance its ``rows`` (the index of each placeholder in its base) and ``consts`` (the
    numbers that differ between instances)."""
    steps: list
    placeholders: list[sp.Symbol]
    bases: list[str]
    constants: list[sp.Symbol]
    rows: list[list[int]] = field(default_factory=list)
    consts: list[list[float]] = field(default_factory=list)
    owners: list[str] = field(default_factory=list)


def owners(instances) -> callable:
    """symbol -> the instance it belongs to, or None: the first instance name (as
    ``symbols.ident`` writes it) in its name, followed by ``__0``, as deep as instances
    nest (``X_leg_1__0motor__0coil__p``: leg_1.motor); a bond between two instances'
    elements belongs to its first end's."""
    idents = {symbols.ident(n): n for n in instances}
    dot = symbols.DOT
    cache: dict = {}

    def owner(s) -> str | None:
        name = s.name           # (a name's hash is cached in C; a sympy object's is not)
        hit = cache.get(name, False)
        if hit is not False:
            return hit
        hit = None
        k = name.find(dot)
        while k >= 0 and hit is None:
            j = name.find("_")
            while 0 <= j < k:             # the longest name ending at k after an '_'
                if name[j + 1:k] in idents:
                    hit = name[j + 1:k]
                    break
                j = name.find("_", j + 1)
            if hit is None:
                k = name.find(dot, k + len(dot))
        while hit is not None:           # nested instances: as deep as they go
            rest = name[k + len(dot):]
            seg = rest.split("__", 1)[0]
            deeper = f"{hit}{dot}{seg}"
            if deeper not in idents:
                break
            hit, k = deeper, k + len(dot) + len(seg)
        hit = cache[name] = None if hit is None else idents[hit]
        return hit
    return owner


def schedule(steps: list, instances, where, assigned: dict | None = None,
             min_copies: int | None = None, memo: dict | None = None) -> list:
    """``steps`` (``steps.program_steps``) with loops: the same steps, or, where some
    structure repeats in ``min_copies`` instances or more, level by level with ``LoopOver``
    steps in place of the instances' own. ``where(symbol)``: (base, index) of a symbol's
    value ("x" state, "p" parameter, "w" workspace slot); ``assigned``: expression -> the
    symbol it is assigned to (a Jacobian step's partials are of an assignment's
    expression, and belong where it does); ``memo``: the symbols each expression reads,
    shared by a module's programs. A program with no such repetition comes back as it
    is."""
    if not instances:
        return steps
    min_copies = MIN_COPIES if min_copies is None else min_copies
    by_symbol = owners(instances)
    assigned = assigned or {}

    def owner(s):
        return by_symbol(s)

    def own(step):
        if isinstance(step, Set):
            return by_symbol(step.v)
        e = step.e
        if isinstance(step, Grad) and e in assigned:
            return by_symbol(assigned[e])
        found = {o for o in map(by_symbol, reads(e, owner.memo)) if o is not None}
        return found.pop() if len(found) == 1 else None
    owner.step, owner.memo = own, memo if memo is not None else {}
    owner.of = by_symbol
    bases = sorted({m[1] for m in map(_INDEXED.match, instances) if m}, key=len, reverse=True)
    owner.arrays = re.compile(  # a mention of an array's instance in an identifier
        r"(?<![A-Za-z0-9])(" + "|".join(re.escape(symbols.ident(b)) for b in bases)
        + r")_(\d+)(?=" + symbols.DOT + ")") if bases else None
    out, segment = [], []
    for step in steps:
        if isinstance(step, STRAIGHT):
            segment.append(step)
            continue
        out += _segment(segment, owner, where, min_copies)
        segment = []
        out.append(step)
    out += _segment(segment, owner, where, min_copies)
    return out


def _segment(steps: list, owner, where, min_copies: int) -> list:
    """One stretch between solves and stores: level by level, with loops."""
    if len(steps) < 2 * min_copies:
        return steps
    level, defined = [], {}         # (by name: see owners)
    memo = owner.memo
    for step in steps:
        lv = 0
        for s in reads(step.e, memo):
            d = defined.get(s.name)
            if d is not None and d >= lv:
                lv = d + 1
        level.append(lv)
        if isinstance(step, Set):
            defined[step.v.name] = lv
    by_level: dict[int, list] = {}
    for lv, step in zip(level, steps):
        by_level.setdefault(lv, []).append(step)
    out, looped = [], False
    for lv in sorted(by_level):
        straight, loops = _level(by_level[lv], owner, where, min_copies)
        looped = looped or bool(loops)
        out += straight + [LoopOver(lp) for lp in loops]
    return out if looped else steps


def _level(steps: list, owner, where, min_copies: int) -> tuple[list, list[Loop]]:
    """One level's steps: those left straight, and the loops."""
    per: dict[str, list] = {}
    straight = []
    for step in steps:
        o = owner.step(step) if isinstance(step, STRAIGHT) else None
        if o is None:
            straight.append(step)
        else:
            per.setdefault(o, []).append(step)
    groups: dict = {}
    for o, block in per.items():
        key, canon = _canonical(block, _View(o, owner), where, owner.memo)
        groups.setdefault(key, []).append((o, block, canon))
    loops = []
    for key, members in groups.items():
        if len(members) < min_copies:
            straight += [s for _, block, _ in members for s in block]
            continue
        loops.append(_loop(members, where, _View(members[0][0], owner)))
    order = {id(s): i for i, s in enumerate(steps)}
    straight.sort(key=lambda s: order[id(s)])
    return straight, loops


_INDEXED = re.compile(r"^(.*)_(\d+)$")       # an array's instance: base_index
_DIGITS = re.compile(r"\d+")


def _padded(m) -> str:
    return m[0].zfill(12)


class _View:
    """Symbols and expressions as seen from instance ``o``: in a symbol's name, ``o``
    as '@' and every instance of ``o``'s array by its offset (``w[+1]``: what
    ``w_{i+1}`` is to ``w_i`` for every i), any other name as it is. Sympy orders the
    terms of a sum or product by the symbols' names, and names order ``w_9`` after
    ``w_10``: the steps of a level and the commutative arguments are put in the order of
    their relative form (``name``, ``key``) instead, so that every instance's steps have
    one structure."""

    def __init__(self, o: str, owner):
        self.o, self.memo, self.arrays = o, owner.memo, owner.arrays
        # what is seen from o, memoized per instance (the programs of a module share it)
        self.names = owner.memo.setdefault(("name", o), {})
        self.keys = owner.memo.setdefault(("key", o), {})
        self.shapes = owner.memo.setdefault(("shape", o), {})
        self.mark = symbols.ident(o) + symbols.DOT
        mine = _INDEXED.match(o)
        self.base, self.index = (symbols.ident(mine[1]), int(mine[2])) if mine else (None, 0)

    def _offset(self, m) -> str:
        if m[1] != self.base:
            return m[0]
        return f"{m[1]}[{int(m[2]) - self.index:+d}]"

    def name(self, s) -> str:
        """``s``'s name with ``o`` as '@' and its array's instances by offset."""
        name = s.name
        hit = self.names.get(name)
        if hit is None:
            hit = name.replace(self.mark, "@" + symbols.DOT)
            if self.arrays is not None and self.base is not None:
                hit = self.arrays.sub(self._offset, hit)
            hit = _DIGITS.sub(_padded, hit)      # counters (x__99, x__100) in number order
            self.names[name] = hit
        return hit

    def key(self, e) -> str:
        """``e`` with relative names and its numbers as '#' (they may differ between
        instances), commutative arguments sorted: the same for every instance's step."""
        k = id(e)
        hit = self.keys.get(k)
        if hit is not None and hit[0] is e:
            return hit[1]
        if e.is_Symbol:
            out = "t" if e is symbols.t else self.name(e)
        elif e.is_Number:
            out = "#"
        elif e.is_Pow and e.exp.is_Number:
            out = f"Pow({self.key(e.base)},{e.exp})"
        elif isinstance(e, (table, table_slope)):
            out = f"{type(e).__name__}({e.args[0]},{self.key(e.args[1])})"
        elif not e.args:
            out = f"{type(e).__name__}:{e}"
        else:
            keys = [self.key(a) for a in e.args]
            if e.is_Add or e.is_Mul:
                keys.sort()
            out = f"{type(e).__name__}({','.join(keys)})"
        self.keys[k] = (e, out)
        return out

    def args(self, e) -> tuple:
        """``e``'s arguments, a sum's or product's in the order of their ``key``."""
        if e.is_Add or e.is_Mul:
            return tuple(sorted(e.args, key=self.key))
        return e.args


def _canonical(block: list, view: _View, where, memo: dict):
    """The structure of one instance's steps at one level: a hashable key (the steps in
    a canonical order, their expressions with numbered placeholders and the numbers left
    out) and what the template and the table need (the ordered steps, a Jacobian step's
    partials in the order of their placeholders, the placeholders' symbols and bases,
    the numbers in order)."""
    def sort_key(step):
        if isinstance(step, Set):
            return ("set", view.name(step.v))
        if isinstance(step, Out):
            return ("out", view.key(step.e))
        if isinstance(step, Store):
            return ("store", view.key(step.e))
        return ("grad", view.key(step.e),
                tuple(sorted(view.name(w) for _, w in step.partials)))
    ordered = sorted(block, key=sort_key)
    ph: dict = {}           # placeholder numbers by symbol name (see owners)
    syms: list = []         # the symbols in that order
    nums: list = []
    key = []
    for i, step in enumerate(ordered):
        if isinstance(step, Set):
            lhs = _place(step.v, ph, syms)
            key.append(("set", lhs) + _shape(step.e, ph, syms, nums, view))
        elif isinstance(step, Out):
            key.append(("out",) + _shape(step.e, ph, syms, nums, view))
        elif isinstance(step, Store):
            key.append(("store",) + _shape(step.e, ph, syms, nums, view))
        else:
            shape = _shape(step.e, ph, syms, nums, view)
            partials = sorted(step.partials, key=lambda jw: _place(jw[1], ph, syms))
            ordered[i] = step = Grad(step.e, partials)
            key.append(("grad",) + shape + (tuple(ph[w.name] for _, w in partials),))
    bases = tuple(_where(s, where, memo)[0] for s in syms)
    return (tuple(key), bases), (ordered, syms, nums)


def _where(s, where, memo: dict) -> tuple[str, int]:
    """``where(s)``, memoized."""
    hit = memo.get(s)
    if hit is None:
        hit = memo[s] = where(s)
    return hit


def _shape(e, ph: dict, syms: list, nums: list, view: _View) -> tuple:
    """``e``'s shape (``_walk``, its symbols numbered within it; memoized on the
    expression and the instance it is seen from) and its symbols as placeholders of the
    block (``ph``, ``syms``: ``_place``); its numbers appended to ``nums``."""
    k = id(e)
    hit = view.shapes.get(k)
    if hit is None or hit[0] is not e:
        local: dict = {}
        order: list = []
        found: list = []
        shape = _walk(e, local, order, found, view)
        hit = view.shapes[k] = (e, shape, order, found)
    _, shape, order, found = hit
    nums.extend(found)
    return shape, tuple([_place(s, ph, syms) for s in order])


def _place(s, ph: dict, syms: list) -> int:
    """``s``'s number among the placeholders ``ph`` (by name), a new one at the end."""
    name = s.name
    i = ph.get(name)
    if i is None:
        i = ph[name] = len(syms)
        syms.append(s)
    return i


def _walk(e, ph: dict, syms: list, nums: list, view: _View):
    """``e``'s shape: symbols by placeholder number, numbers out (into ``nums``), but
    those that are structure (integer exponents, a table's index); a sum's or product's
    arguments in ``view``'s order."""
    if e.is_Symbol:
        return _place(e, ph, syms) if e is not symbols.t else "t"
    if e.is_Number:
        nums.append(e)
        return "#"
    if e.is_Pow and e.exp.is_Number:
        return ("Pow", _walk(e.base, ph, syms, nums, view), str(e.exp))
    if isinstance(e, (table, table_slope)):
        return (type(e).__name__, str(e.args[0]), _walk(e.args[1], ph, syms, nums, view))
    if not e.args:
        return (type(e).__name__, str(e))        # pi, E, true, false, nan ...
    return (type(e).__name__,) + tuple(_walk(a, ph, syms, nums, view)
                                       for a in view.args(e))


def _loop(members: list, where, view: _View) -> Loop:
    """The loop of instances whose steps have one structure: the template from the
    first (numbers that all agree kept, the others placeholders), a row per instance: the
    index of each symbol placeholder in its base, then the output slot of each partial
    of its Jacobian steps, then (in ``consts``) its numbers that differ."""
    first_steps, first_syms, first_nums = members[0][2]
    differ = [k for k in range(len(first_nums))
              if any(m[2][2][k] != first_nums[k] for m in members[1:])]
    T = [sp.Symbol(f"T{j}", real=True) for j in range(len(first_syms))]
    C = [sp.Symbol(f"C{k}", real=True) for k in range(len(differ))]
    sym_map = dict(zip(first_syms, T))
    num_map = {k: C[i] for i, k in enumerate(differ)}
    counter = [0]

    def rebuild(e):         # the same traversal as _walk (``view``'s): numbers in one order
        if e.is_Symbol:
            return sym_map.get(e, e)
        if e.is_Number:
            k = counter[0]
            counter[0] += 1
            return num_map.get(k, e)
        if e.is_Pow and e.exp.is_Number:
            return sp.Pow(rebuild(e.base), e.exp, evaluate=False)
        if isinstance(e, (table, table_slope)):
            return type(e)(e.args[0], rebuild(e.args[1]))
        if not e.args:
            return e
        if e.is_Add or e.is_Mul:    # numbered in view's order, summed in sympy's (the
            built = {id(a): rebuild(a) for a in view.args(e)}   # first instance's code
            return type(e)(*[built[id(a)] for a in e.args], evaluate=False)   # bitwise)
        return e.func(*[rebuild(a) for a in e.args])

    steps, slots = [], []               # slots: the base of each row entry after T's
    for step in first_steps:
        if isinstance(step, Set):
            steps.append(Set(sym_map[step.v], rebuild(step.e)))
        elif isinstance(step, (Out, Store)):
            steps.append(type(step)(len(T) + len(slots), rebuild(step.e)))
            slots.append("out" if isinstance(step, Out) else "w")
        else:
            e = rebuild(step.e)
            steps.append(Grad(e, [(len(T) + len(slots) + k, sym_map[w])
                                  for k, (_, w) in enumerate(step.partials)]))
            slots += ["out"] * len(step.partials)
    bases = [_where(s, where, view.memo)[0] for s in first_syms] + slots
    lp = Loop(steps, T, bases, C)
    for o, _, (ordered, syms, nums) in members:
        row = [_where(s, where, view.memo)[1] for s in syms]
        row += [slot for step in ordered if not isinstance(step, Set)
                for slot in ([step.slot] if isinstance(step, (Out, Store))
                             else [m for m, _ in step.partials])]
        lp.rows.append(row)
        lp.consts.append([float(nums[k]) for k in differ])
        lp.owners.append(o)
    return lp


TEMPLATE_ARGS = ("double %t, double* noalias %x, double* noalias %p, double* noalias %w, "
                 "double* noalias %out, i64* noalias %row, double* noalias %crow")


def template_ir(lp: Loop, name: str, layout, decls: set) -> str:
    """``@name(t, x, p, w, out, row, crow)``: the loop's template for one instance, each
    placeholder read and written at ``base[row[j]]``, each differing number ``crow[k]``;
    lowered as the straight-line chunks are (``lowering.Function``)."""
    slot = {s: j for j, s in enumerate(lp.placeholders)}
    const = {c: k for k, c in enumerate(lp.constants)}
    base = {"x": "%x", "p": "%p", "w": "%w", "out": "%out"}

    class Template(Function):
        def index(self, j: int) -> str:
            at = self.op(f"getelementptr inbounds i64, i64* %row, i64 {j}")
            return self.op(f"load i64, i64* {at}, align 8")

        def symbol(self, s) -> str:
            if s in self.env:
                return self.env[s]
            if s is symbols.t:
                v = "%t"
            elif s in slot:
                v = self.load(base[lp.bases[slot[s]]], self.index(slot[s]))
            elif s in const:
                v = self.load("%crow", const[s])
            else:
                return super().symbol(s)
            self.env[s] = v
            return v

        def assign(self, v, e):
            value = self.val(e)
            self.env[v] = value
            self.store("%w", self.index(slot[v]), value)

    fn = Template(name, layout, {}, {}, decls)
    for step in lp.steps:
        if isinstance(step, Set):
            fn.assign(step.v, step.e)
        elif isinstance(step, Out):
            fn.store("%out", fn.index(step.slot), fn.val(step.e))
        elif isinstance(step, Store):       # an entry of a linear block's region
            fn.store("%w", fn.index(step.slot), fn.val(step.e))
        else:
            d = fn.grad(step.e, [w for _, w in step.partials])
            for j, w in step.partials:
                fn.store("%out", fn.index(j), d[w])
    return "\n".join([f"define void @{name}({TEMPLATE_ARGS}) noinline nounwind {{",
                      "entry:", *fn.body, "  ret void", "}"])


def driver_ir(name: str, template: str, n: int, width: int, rows: str, consts: str,
              args: str) -> str:
    """``@name(t, x, p, w, out)``: the template called for each of the ``n`` instances,
    with its row of the table ``rows`` (``width`` entries a row) and of ``consts`` (a
    pointer and its row's length); ``rows`` and ``consts[0]`` typed pointers
    (``kernels.Module.array``)."""
    return "\n".join([
        f"define internal void @{name}({args}) nounwind {{",
        "entry:",
        "  br label %head",
        "head:",
        "  %i = phi i64 [ 0, %entry ], [ %i1, %body ]",
        f"  %more = icmp slt i64 %i, {n}",
        "  br i1 %more, label %body, label %exit",
        "body:",
        f"  %ro = mul i64 %i, {width}",
        f"  %row = getelementptr inbounds i64, {rows}, i64 %ro",
        f"  %co = mul i64 %i, {consts[1]}",
        f"  %crow = getelementptr inbounds double, {consts[0]}, i64 %co",
        f"  call void @{template}(double %t, double* %x, double* %p, double* %w, "
        "double* %out, i64* %row, double* %crow)",
        "  %i1 = add i64 %i, 1",
        "  br label %head",
        "exit:",
        "  ret void",
        "}"])
