"""What the compile stages share (``bgc.symbolic``), on its own: the strongly connected
components in dependency order and which are loops, iteratively (a 20 000-long chain);
a linear block's symbols and its aliases replaced."""

from __future__ import annotations

import sympy as sp

from bgc.symbolic.algorithms import is_cyclic, strongly_connected
from bgc.symbolic.linear import LinearBlock, Regularized


def test_components_come_dependencies_first_and_loops_are_found():
    deps = {"a": ["b"], "b": ["c"], "c": ["b"], "d": ["d"], "e": []}
    comps = strongly_connected(["a", "b", "c", "d", "e"], deps)
    assert comps.index(["b", "c"]) < comps.index(["a"])
    assert [is_cyclic(c, deps) for c in comps] == [c in (["b", "c"], ["d"]) for c in comps]


def test_a_long_chain_needs_no_recursion():
    n = 20_000
    deps = {i: [i + 1] if i + 1 < n else [] for i in range(n)}
    comps = strongly_connected(range(n), deps)
    assert len(comps) == n and comps[0] == [n - 1]


def test_a_linear_blocks_free_symbols_and_aliases():
    u, v, w, k, a = sp.symbols("u v w k a", real=True)
    blk = LinearBlock(0, (u,), ((0, 0, k),), None, (w - k * u,), chain=((v, 2 * u),),
                      pre=((w, a + 1),), regularize=Regularized((k,), (0,)))
    assert blk.free_symbols == {k, a}           # its unknowns, chain and pre are its own
    rep = blk.xreplace({k: a, v: u})
    assert rep.A == ((0, 0, a),) and rep.chain == () and rep.regularize.weights == (a,)
