"""Algebraic loops solved numerically at run time (LU in the generated kernels) agree with
the symbolic solution, and the Jacobian is carried through the factorization."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import MODELS

from bgc.codegen.emit import import_module
from bgc.codegen.equations import LinearBlock
from bgc.pipeline import build, compile_model
from bgc.simulate import simulate


@pytest.fixture(scope="module")
def both(tmp_path_factory, compiled):
    """both(name) -> [(system, module) solved symbolically, (system, module) numerically]:
    the symbolic one is the default build (loops up to ``MAX_SYMBOLIC_LOOP`` tearing
    variables solved symbolically), the session's module."""
    root, cache = tmp_path_factory.mktemp("loops"), {}

    def get(name):
        if name not in cache:
            model = MODELS / f"{name}.yaml"
            c, path = compile_model(model, root / "num", max_symbolic_loop=0)
            cache[name] = [(build(model).system, compiled(name)),
                           (c.system, import_module(path))]
        return cache[name]
    return get


@pytest.mark.parametrize("name", ["rr_loop", "geared_inertias"])
def test_numeric_block_matches_symbolic_solution(name, both):
    (sym_sys, sym), (num_sys, num) = both(name)
    assert not any(isinstance(a, LinearBlock) for a in sym_sys.assignments)
    assert sum(isinstance(a, LinearBlock) for a in num_sys.assignments) == 1
    assert "_lu(i64" in open(num.__file__).read()       # solved by LU in the kernels
    t_end = sym_sys.model.settings.t_end
    r1 = simulate(sym, t_end=t_end, rtol=1e-10, atol=1e-12, solver="radau")
    r2 = simulate(num, t_end=t_end, rtol=1e-10, atol=1e-12, solver="radau")
    assert np.abs(r1.y - r2.y).max() <= 1e-9 * np.abs(r1.y).max()


@pytest.mark.parametrize("name", ["rr_loop", "geared_inertias"])
def test_jacobian_through_numeric_block(name, both):
    (_, sym), (_, num) = both(name)
    rng = np.random.default_rng(3)
    p = num.PARAMS
    for _ in range(3):
        x = num.X0 + rng.uniform(-1, 1, len(num.X0))
        t = float(rng.uniform(0, 1))
        J = num.jac(t, x, p)
        fd = np.empty_like(J)
        for j in range(len(x)):
            h = 1e-6 * max(1.0, abs(x[j]))
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            fd[:, j] = (num.rhs(t, xp, p) - num.rhs(t, xm, p)) / (2 * h)
        assert np.abs(J - fd).max() <= 1e-6 * max(np.abs(fd).max(), 1e-12)
        assert np.allclose(J, sym.jac(t, x, p), rtol=1e-12, atol=1e-14)
