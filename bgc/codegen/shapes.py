"""Element equations derived once per shape (issue 40: compile cost follows the parts).

The instances of one component (and any other repeated structure: the joints of a chain,
the point junctions of like bodies) hold elements whose equations differ only in the
names of their bonds' variables and of the symbols in their laws: junctions, transformers
modulated by a body's rotation, cross-product transformers. ``RuleMemo`` derives an
element's equations by its rule (``elements.RULES``) the first time its **shape** is met
(kind, law, the causal stroke, direction and dimension of each bond, its laws with every
symbol numbered in the order met and every number as it is) and, for every later element
of that shape, renames the recorded equations onto the element's own symbols (and its own
modulus variables, ``symbols.modulus``) by ``symbols.renamed``, which keeps their form:
every element of one shape gets its equations in one form (what the instance loops of
``instances`` look for). The equations are those the rule would write, the
terms of a sum or product in the order of the shape's first element
(``tests/codegen/test_shapes.py`` compares whole systems).
"""

from __future__ import annotations

import itertools

import sympy as sp

from bgc.model import symbols

# the kinds whose rule only defines its bonds' variables (and a modulated transformer's
# moduli): no states, displays of its own or method hooks
KINDS = ("0", "1", "TF", "MTF", "XTF")


def _place(s, ph: dict) -> int:
    i = ph.get(s)
    if i is None:
        i = ph[s] = len(ph)
    return i


def _shape(e, ph: dict):
    """``e``'s structure: symbols numbered in ``ph``, numbers as they are."""
    if isinstance(e, sp.MatrixBase):
        return ("Matrix", e.rows, e.cols) + tuple(_shape(x, ph) for x in e)
    if e.is_Symbol:
        return _place(e, ph)
    if e.is_Number or not e.args:
        return e
    return (type(e).__name__,) + tuple(_shape(a, ph) for a in e.args)


class RuleMemo:
    """The equations of ``Builder``'s elements, by shape (module doc)."""

    def __init__(self, bld):
        self.bld = bld
        self.cache: dict = {}
        self.bond_symbols: dict = {}

    def symbols_of(self, b: int) -> list:
        """A bond's effort and flow symbols (components of a multibond's), once."""
        hit = self.bond_symbols.get(b)
        if hit is None:
            bond = self.bld.g.bonds[b]
            ks = [None] if bond.dim == 1 else range(bond.dim)
            hit = self.bond_symbols[b] = ([symbols.effort(bond.name, k) for k in ks]
                                          + [symbols.flow(bond.name, k) for k in ks])
        return hit

    def signature(self, name: str, el) -> tuple[tuple, dict]:
        """(the element's shape, its symbols by number)."""
        g, cg = self.bld.g, self.bld.cg
        ph: dict = {}
        ports = []
        cut = self.bld.cut      # the terms a junction leaves out shape it too
        for b in g.ports[name]:
            comps = [None] if g.bonds[b].dim == 1 else range(g.bonds[b].dim)
            gone = tuple(k for k in comps if (name, b, k) in cut) if cut else ()
            ports.append((g.bonds[b].dim, g.points_into(b, name), cg.receives_effort(b, name),
                          gone, tuple(_place(s, ph) for s in self.symbols_of(b))))
        fields = tuple((k, _shape(el.fields[k], ph)) for k in sorted(el.fields))
        return (el.kind, el.law, el.orthogonal, tuple(ports), fields), ph

    def apply(self, name: str, el, rule):
        """Define the element's equations: recorded, or renamed from a recording."""
        if el.kind not in KINDS:
            rule(self.bld, name, el)
            return
        key, ph = self.signature(name, el)
        hit = self.cache.get(key)
        if hit is None:
            self.cache[key] = self.record(name, el, rule, ph)
        else:
            self.replay(name, el, hit, ph)

    def record(self, name: str, el, rule, ph: dict):
        bld = self.bld
        n_eqs, n_display = len(bld.eqs), len(bld.display)
        rule(bld, name, el)
        defined = list(itertools.islice(reversed(bld.eqs), len(bld.eqs) - n_eqs))[::-1]
        shown = list(itertools.islice(reversed(bld.display), len(bld.display) - n_display))
        ports = {bld.g.bonds[b].name: k for k, b in enumerate(bld.g.ports[name])}
        every = {symbols.modulus(name, i, j): (i, j) for i in range(3) for j in range(3)}
        moduli = {v: every[v] for v in defined if v in every}
        steps = [(v, bld.eqs[v], ports.get(bld.origin[v][1])) for v in defined]
        return name, {s: i for s, i in ph.items()}, steps, moduli, set(shown)

    def replay(self, name: str, el, hit, ph: dict):
        bld = self.bld
        first, first_ph, steps, moduli, shown = hit
        by_number = {i: s for s, i in ph.items()}
        rename = {s: by_number[i] for s, i in first_ph.items()}
        for m, (i, j) in moduli.items():
            rename[m] = symbols.modulus(name, i, j)
        bonds = bld.g.ports[name]
        was, now = first.replace("__", "."), name.replace("__", ".")
        memo: dict = {}
        for v, e, port in steps:
            w = rename.get(v, v)
            bld.define(w, symbols.renamed(e, rename, memo), name,
                       None if port is None else bonds[port])
            if v in shown:
                bld.display[w] = bld.display[v].replace(was, now, 1)
