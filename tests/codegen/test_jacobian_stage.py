"""The Jacobian tape on its own (``jacobian.tape``: sorted assignments -> compressed
forward-mode tape), on a small nonlinear two-mass chain: the tape, played back in Python
(each partial differentiated by sympy at the point, accumulated along the tape's edges),
gives sympy's Jacobian of the substituted rates; its pattern holds every non-zero entry,
and its colouring gives no two columns that share a row one colour."""

from __future__ import annotations

import numpy as np
import sympy as sp
from helpers import resolved_rates

from bgc.codegen.equations import derive
from bgc.codegen.jacobian import tape
from bgc.graph.causality import assign
from bgc.graph.expand import expand
from bgc.model.load import loads

# m1 with a cubic damper, a hardening spring to m2, m2 on a linear spring to ground
TWO_MASSES = """\
name: two_masses
parameters: {M1: 1.5, M2: 0.5, c: 0.3, k: 40.0, k3: 900.0, k2: 25.0}
elements:
  m1: {type: I, I: M1}
  v1: {type: "1"}
  damper: {type: R, effort: "c*f + c*f**3"}
  n12: {type: "0"}
  spring: {type: C, effort: "k*q + k3*q**3"}
  v2: {type: "1"}
  m2: {type: I, I: M2}
  ground: {type: C, k: k2}
bonds: [[v1, m1], [v1, damper], [v1, n12], [n12, spring], [n12, v2], [v2, m2], [v2, ground]]
"""


def play(jt, values: dict) -> np.ndarray:
    """The tape's rows at a point: row r = sum over its edges of d e/d w * (the row of w,
    or w's colour if w is a state)."""
    entry = {m: (e, w) for e, edges in jt.partials for m, w in edges}
    d = np.zeros((jt.n_rows, jt.n_colours))
    for r in range(jt.n_rows):
        for m in range(jt.ptr[r], jt.ptr[r + 1]):
            e, w = entry[m]
            pv = float(sp.diff(e, w).xreplace(values))
            s = jt.src[m]
            d[r] += pv * (d[s] if s >= 0 else np.eye(jt.n_colours)[-1 - s])
    return d


def test_played_tape_is_sympys_jacobian_and_its_colouring_is_valid():
    s = derive(assign(expand(loads(TWO_MASSES))))
    states = [st.sym for st in s.states]
    n = len(states)
    assert n == 4
    rng = np.random.default_rng(5)
    values = {sym: sp.Float(v) for sym, _, v in s.params}
    values |= {x: sp.Float(rng.uniform(-0.5, 0.5)) for x in states}
    for var, expr in s.assignments:
        values[var] = expr.xreplace(values)
    jt = tape(s.assignments, s.states)
    d = play(jt, values)
    J = np.zeros((n, n))
    for i, j, r in jt.pattern:
        J[i, j] = d[r, jt.colours[j]]
    rates = resolved_rates(s)
    ref = sp.Matrix([rates[st.name] for st in s.states]).jacobian(states)
    ref = np.array(ref.xreplace(values), dtype=float)
    assert np.abs(J - ref).max() <= 1e-12 * np.abs(ref).max()
    # the pattern holds every non-zero entry (a chain: sparse), and is no denser than it
    nonzero = {(i, j) for i in range(n) for j in range(n) if ref[i, j] != 0}
    assert nonzero == {(i, j) for i, j, _ in jt.pattern}
    assert len(nonzero) < n * n
    # columns sharing a row never share a colour, and the compression saves a column
    for i in range(n):
        cols = [j for (k, j) in nonzero if k == i]
        assert len({jt.colours[j] for j in cols}) == len(cols)
    assert jt.n_colours < n
