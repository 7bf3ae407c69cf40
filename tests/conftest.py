"""Shared fixtures: shipped models compiled once per session into a temporary directory
(tests never write into the repository's generated/). Shared plain helpers: helpers.py."""

from __future__ import annotations

import contextlib
import fcntl
import os
import signal
import sys

# One BLAS thread per process: `make test` runs a pytest-xdist worker per core, and
# OpenBLAS's own threads on top of them oversubscribe the cores (a 152-state complex solve,
# the SARIB's frequency response: 1.2 ms on one thread, 40 ms on two beside a busy
# worker). Set before numpy is imported; subprocesses inherit it.
if "numpy" not in sys.modules:
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import pytest
from helpers import MODELS

from bgc.codegen import emit
from bgc.codegen.emit import import_module
from bgc.model import load
from bgc.pipeline import compile_model


@pytest.fixture(scope="session")
def gen_dir(tmp_path_factory):
    """One directory for the whole run, shared by pytest-xdist workers (their base temp
    directories are siblings), so each model is compiled and JIT-compiled once."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent
    path = root / "bgcgen"
    path.mkdir(exist_ok=True)
    return path


class _Compiled:
    """A step loop another worker's child process compiles into numba's cache: ``wait``
    (``native.await_precompiled``, before the loop's first call) blocks on its lock."""

    def __init__(self, lock):
        self.lock = lock

    def wait(self) -> bool:
        fcntl.flock(self.lock, fcntl.LOCK_EX)
        fcntl.flock(self.lock, fcntl.LOCK_UN)
        return True


_COMPILES = pytest.StashKey[list]()


def pytest_configure(config):
    """hypothesis is no dependency of bgc and no test uses it, but where it is installed its
    pytest plugin's terminal summary imports it at the end of every process of the run
    (0.7 to 1.2 s each, measured: the workers' then the controller's, one after the
    other): not loaded here."""
    config.pluginmanager.set_blocked("hypothesispytest")


def pytest_sessionstart(session):
    """In the controller of a distributed run (``make test``: ``pytest -n 2``), before any
    test: bgc's one-time compiles (the native Radau and RK4 step loops into numba's cache,
    the FMU's Radau object into bgc's; 27 + 4 + 28 s of CPU cold) started in children of
    their own while the workers start. Every process of the run, the CLI's children among
    them, then finds the step loops cached: none compiles them again beside a worker that
    is still compiling them (``native.precompile`` cannot see another process's compile).
    The FMU's object, which only ``bgc export`` needs and whose compile holds a lock that
    every other caller waits on (``radau.object_code``), is compiled at the lowest
    priority until the tests start (``_FmuObject``): the Radau loop, which every test
    waits for, keeps a core to itself meanwhile."""
    config = session.config
    if hasattr(config, "workerinput") or not config.pluginmanager.has_plugin("dsession"):
        return
    from bgc.solvers import native, radau5, rk4
    jobs = [native.Precompile(name) for name, mod in (("radau5", radau5), ("rk4", rk4))
            if not native.cached(getattr(mod, name))]
    config.stash[_COMPILES] = [*jobs, _FmuObject()]


@pytest.hookimpl(tryfirst=True)
def pytest_runtestloop(session):
    """The controller waits for the step loops before it hands out the first test (the
    workers import and collect meanwhile), then lets the FMU's object compile at the
    tests' priority (the tests that export an FMU wait for it on its lock); a compile
    that failed is done again, and its error shown, where a test needs it."""
    jobs = session.config.stash.get(_COMPILES, [])
    try:
        for job in jobs:
            if not isinstance(job, _FmuObject):
                job.wait()
    except BaseException:           # Ctrl-C: no compiler left behind
        for job in jobs:
            job.stop()
        raise
    for job in jobs:
        if isinstance(job, _FmuObject):
            job.hurry()


def pytest_sessionfinish(session):
    """No compile outlives the run (the FMU's object, if no test needed it, is left
    for the next run to compile)."""
    for job in session.config.stash.get(_COMPILES, []):
        job.stop()


class _FmuObject:
    """``bgc.export.radau.object_code()`` in a child (which compiles in a child of its
    own, hence a session of their own, stopped together), at the lowest priority from
    just before it takes the object's lock until ``hurry``; ``wait``/``stop`` as
    ``native.Precompile``'s."""

    def __init__(self):
        import subprocess
        self.proc = subprocess.Popen(
            [sys.executable, "-c", "import os; from bgc.export import radau; os.nice(19); "
             "radau.object_code()"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            start_new_session=True)

    def hurry(self):
        """Back to the tests' priority (the child's group: its compiler too), where this
        user may raise it again; else it goes on at the lowest, in the cores' idle time."""
        with contextlib.suppress(OSError):      # not this user's to raise: it stays low
            os.setpriority(os.PRIO_PGRP, self.proc.pid, os.getpriority(os.PRIO_PROCESS, 0))

    def wait(self) -> bool:
        return self.proc.wait() == 0

    def stop(self):
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()


@pytest.fixture(scope="session", autouse=True)
def native_loops_once(gen_dir):
    """The native step loops (16 s of CPU for Radau's) compiled once for the run, by one
    child process beside the tests (``native.Precompile``), not once per worker: the first
    worker starts it and holds a lock until it is done; every worker's first native run
    waits for that (``native.await_precompiled``) and then loads the loop from the cache."""
    import threading

    from bgc.solvers import native, radau5, rk4
    for name, mod in (("radau5", radau5), ("rk4", rk4)):
        if native.cached(getattr(mod, name)):
            continue
        lock = open(gen_dir / f"{name}.lock", "a+")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:             # another worker's child compiles it
            native._started[name] = _Compiled(lock)
            continue
        job = native.Precompile(name)
        native._started[name] = job

        def release(job=job, lock=lock):
            job.wait()
            fcntl.flock(lock, fcntl.LOCK_UN)
        threading.Thread(target=release, daemon=True).start()
    # bgc export's Radau object (21 s of CPU), compiled in a child beside the tests as
    # well: object_code's lock makes every other caller wait for it, then read it
    from bgc.export import radau
    threading.Thread(target=_radau_object, args=(radau,), daemon=True).start()
    yield


def _radau_object(radau):
    """The FMU's Radau object into bgc's cache (an error shows in the tests that use it)."""
    try:
        radau.object_code()
    except Exception:           # noqa: BLE001 - reported where it is used
        pass


@pytest.fixture(scope="session")
def compiled(gen_dir):
    """compiled(name, method) -> generated module of models/<name>.yaml, or of the model
    file ``name`` (a Path), in ``gen_dir`` (cached per session)."""
    cache = {}

    def get(name, method: str = "parasitic"):
        """``name``: a shipped model's, or the path of another model file."""
        if (name, method) not in cache:
            # one worker compiles (source and machine code, cached on disk) while the
            # others wait, then load it
            file = MODELS / f"{name}.yaml" if isinstance(name, str) else name
            with open(gen_dir / f"{file.stem}_{method}.lock", "w") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                model = load.load(file)
                path = emit.module_path(model.name, gen_dir, method)
                if emit.is_stale(path, model.digest, method):
                    compile_model(model, gen_dir, method)
                mod = import_module(path)
                for f in (mod.rhs, mod.jac, mod.outputs):
                    f(0.0, mod.X0, mod.PARAMS)
                fcntl.flock(lock, fcntl.LOCK_UN)
            cache[name, method] = mod
        return cache[name, method]
    return get


@pytest.fixture
def figures(monkeypatch):
    """What each figure the plot functions save holds (per axes: y label, lines, texts;
    the x label), read from the figure object before it is written: what tests inspect
    instead of pixels."""
    kept = []
    from bgc.analysis import results
    save = results.save_figure

    def keep(fig, path, title):
        fig.canvas.draw()
        kept.append({"ylabels": [ax.get_ylabel() for ax in fig.axes],
                     "xlabel": fig.axes[-1].get_xlabel(),
                     "lines": [len(ax.get_lines()) for ax in fig.axes],
                     "texts": [[t.get_text() for t in ax.texts] for ax in fig.axes]})
        return save(fig, path, title)
    monkeypatch.setattr(results, "save_figure", keep)
    return kept
