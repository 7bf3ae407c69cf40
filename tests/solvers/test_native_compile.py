"""Compiling the native step loops (issue 24, cold time to first result): ``compile_loop``
compiles exactly the specialization the solver runs, so that ``native.Precompile`` (a
separate process filling numba's cache while the model is built) leaves the run nothing to
compile; and that process never outlives the run."""

from __future__ import annotations

import os

import numpy as np
import pytest

from bgc.simulate import simulate
from bgc.solvers import native, radau5, rk4


@pytest.mark.parametrize("loop, kw", [(radau5, {"solver": "native"}),
                                      (rk4, {"solver": "rk4", "step": 1e-4})])
def test_compile_loop_is_the_specialization_a_run_uses(compiled, loop, kw):
    """After ``compile_loop`` a run (with its Ctrl-C flag, events and output times) adds
    no specialization of the loop: the cache the child fills is the one the run loads."""
    loop.compile_loop()
    dispatcher = getattr(loop, loop.__name__.split(".")[-1])
    before = set(dispatcher.signatures)
    assert before
    r = simulate(compiled("msd_forced"), t_end=0.05, points=11, **kw)
    assert r.success and len(r.t) == 11 and np.isfinite(r.x).all()
    assert set(dispatcher.signatures) == before
    assert native.cached(dispatcher)


def test_loops_return_at_once_with_nothing_to_integrate():
    """t1 = t0: no entry point is called (the addresses may be anything), the state comes
    back as it was (``compile_loop`` relies on this)."""
    x0 = np.array([1.0, 2.0])
    counts = np.zeros(native.N_STATS, dtype=np.int64)
    flag = np.zeros(0, dtype=np.uint8)
    from bgc.solvers import rank, sparse_lu
    model = native.Model(0, 0, 0, 0, np.zeros(1))
    system = radau5.System(model, np.empty((0, 0)), np.empty(0), sparse_lu.DENSE, rank.none(),
                           0, np.empty((0, 0)), 0, np.empty(0, dtype=np.int64),
                           np.empty(0, dtype=np.int64))
    r = radau5.radau5(system, radau5.settings(1e-6, 1e-6, np.inf, 0.25, 1e-3, 0, flag),
                      1.0, 1.0, x0, np.array([1.0]), counts, np.zeros(2), radau5.carry(2))
    out, k, t, x, status, _, h = r
    assert (k, t, status, h) == (1, 1.0, native.REACHED, 0.25)
    assert np.array_equal(out[0], x0) and np.array_equal(x, x0)
    r = rk4.rk4(model, rk4.settings(0.1, 1e-3, 0, 0, flag), 1.0, 1.0, x0, np.array([1.0]),
                counts)
    assert r.n_eval == 1 and r.status == native.REACHED and np.array_equal(r.x_eval[0], x0)
    assert not counts.any()


def test_precompile_child_is_stopped_and_leaves_no_process(tmp_path, monkeypatch):
    """A run that ends before the child is done (an error in the model, Ctrl-C) kills it:
    no stray compiler process; a new one is started only when the cache lacks the loop."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))     # cold: the child has work
    job = native.Precompile("rk4")
    pid = job.proc.pid
    assert job.proc.poll() is None
    job.stop()
    assert job.proc.returncode is not None
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)


def test_precompile_is_skipped_when_the_cache_has_the_loop():
    native.await_precompiled("rk4")      # the session's own compile (conftest), if any
    rk4.compile_loop()                   # this process's cache (cache=True): present now
    assert native.cached(rk4.rk4)
    native.precompile("rk4")
    assert "rk4" not in native._started
    native.await_precompiled("rk4")      # nothing to wait for


def test_precompile_child_fills_the_cache(tmp_path, monkeypatch):
    """The child compiles into the NUMBA_CACHE_DIR it inherits and exits 0."""
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert native.Precompile("rk4").wait()
    assert any(f.suffix == ".nbi" and "rk4" in f.name for f in tmp_path.rglob("*"))
