"""Stage **run**: a ``Job`` and its ``Plan`` -> one ``Point`` per row, computed on a Dask
cluster (``dask.distributed``): a ``LocalCluster`` of one single-threaded worker process per
core by default, or the cluster of a running scheduler.

The compiled module reaches each worker once: the client compiles it (``ensure_module``)
and registers a worker plugin (``ShipModule``) that carries its source and the Job; the
scheduler hands the plugin to every worker, including one that joins later or replaces a
worker that died. On its worker the plugin uses the client's file if it is there (same
machine or a shared file system: its machine code is cached beside it already), else
writes the source once per machine under the temporary directory, and imports the
module at the first point, once per worker process. A task then carries one row of
parameter values and returns its Point.

Nothing is lost with a worker: a task whose worker dies is run again on another (the
nanny starts a new worker, which the plugin reaches too), and a task that raises is
retried (``RETRIES``); a point that fails after that is a row with its message.
"""

from __future__ import annotations

import fcntl
import logging
import os
import tempfile
import threading
import time
import uuid
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from distributed import Client, LocalCluster, WorkerPlugin, as_completed, get_worker

from bgc.errors import BgcError
from bgc.sweep.metrics import Metrics, evaluate

# a task raising (not a metric failing: that is its row's error) is tried again this often
RETRIES = 2


@dataclass(frozen=True)
class Job:
    """What every point shares: the module (where the client has it and its MODEL_HASH),
    the Model for what reads it (the FRF's excitation; None otherwise), the parameter
    vector before the swept values, the swept parameters' names and where their values
    go in it, and the metrics."""
    module_path: str
    module_hash: str
    model: object
    base: np.ndarray
    names: tuple[str, ...]
    swept: tuple[int, ...]
    metrics: Metrics


@dataclass
class Point:
    """One point's result: its parameter values, its metrics (``evaluate``), the
    failures' messages (None if none), the seconds its worker spent on it and the CPU
    seconds of that worker's thread (the module's import, once per worker, not counted;
    on a shared machine the CPU time is the one that does not depend on the load)."""
    index: int
    params: dict[str, float]
    values: dict
    error: str | None
    seconds: float = 0.0
    cpu: float = 0.0


class ShipModule(WorkerPlugin):
    """The worker plugin that brings a Job's module to a worker once and keeps it
    imported there."""

    def __init__(self, job: Job, source: bytes):
        self.job, self.source = job, source
        self.path: Path | None = None
        self._module = None
        self._lock = None

    def setup(self, worker=None) -> None:
        """On the worker: the module's file placed (``place``); imported at first use."""
        self.path = place(self.job, self.source)
        self.source = None              # on disk now: not kept in the worker's memory
        self._lock = threading.Lock()

    def module(self):
        """The Job's module, imported once in this worker process."""
        with self._lock:
            if self._module is None:
                from bgc.codegen.module_file import import_module
                self._module = import_module(self.path)
        return self._module

    def point(self, index: int, values: np.ndarray) -> Point:
        """The metrics at one row of swept values."""
        module = self.module()
        start, cpu = time.perf_counter(), time.thread_time()
        p = self.job.base.copy()
        p[list(self.job.swept)] = values
        metrics, error = evaluate(self.job.metrics, module, self.job.model, p)
        return Point(index, dict(zip(self.job.names, map(float, values))), metrics, error,
                     time.perf_counter() - start, time.thread_time() - cpu)


def place(job: Job, source: bytes) -> Path:
    """Where a worker imports the module from: the client's own file if this machine sees
    it unchanged, else a copy written once per machine (``<tmp>/bgc-sweep/<hash>/``),
    written by one worker while the others on the machine wait, and never rewritten
    while it is whole (numba's cache beside it stays valid)."""
    from bgc.codegen.module_file import stored_hash
    from bgc.fileio import atomic_write
    own = Path(job.module_path)
    if stored_hash(own) == job.module_hash:
        return own
    copy = Path(tempfile.gettempdir()) / "bgc-sweep" / job.module_hash[:16] / own.name
    copy.parent.mkdir(parents=True, exist_ok=True)
    with open(copy.parent / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        if stored_hash(copy) != job.module_hash:
            atomic_write(copy, lambda tmp: Path(tmp).write_bytes(source), "module")
    return copy


def _point(plugin: str, index: int, values: np.ndarray) -> Point:
    """A task: one point, on the worker, through the plugin registered as ``plugin``."""
    return get_worker().plugins[plugin].point(index, values)


@contextmanager
def connect(scheduler: str | None = None, workers: int | None = None):
    """A Dask client: of the running scheduler at ``scheduler`` (tcp://HOST:PORT), else of
    a LocalCluster of ``workers`` single-threaded worker processes (default: one per
    core), its logs quiet and without a dashboard."""
    if scheduler is not None:
        try:
            client = Client(scheduler, timeout="10s")
        except (OSError, ValueError) as exc:
            raise BgcError(f"cannot reach the Dask scheduler at {scheduler}: {exc}",
                           key="--scheduler", hint="start one (dask scheduler; dask worker "
                           "tcp://HOST:PORT on each machine) or leave --scheduler out for "
                           "the local cores") from None
        with client:
            yield client
        return
    with LocalCluster(n_workers=workers or os.cpu_count() or 1, threads_per_worker=1,
                      processes=True, dashboard_address=None,
                      silence_logs=logging.ERROR) as cluster, Client(cluster) as client:
        yield client


def run(client, job: Job, rows: np.ndarray, source: bytes, on_point=None) -> list[Point]:
    """Every row's Point (``rows[i]``: the values of ``job.names``), in the rows' order;
    ``on_point(point)`` is called in the caller's thread as each arrives (the progress
    bar). A point whose task failed for good (its worker killed again and again, an error
    outside the metrics) is a row with the reason."""
    name = f"bgc-sweep-{uuid.uuid4().hex[:12]}"
    client.register_plugin(ShipModule(job, source), name=name)
    try:
        futures = client.map(_point, [name] * len(rows), range(len(rows)), list(rows),
                             retries=RETRIES, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        points: list[Point | None] = [None] * len(rows)
        for fut in as_completed(futures):
            i = index[fut.key]
            try:
                points[i] = fut.result()
            except Exception as exc:    # noqa: BLE001 - the point is lost, not the sweep
                points[i] = Point(i, dict(zip(job.names, map(float, rows[i]))),
                                  {label: None for label in job.metrics.labels},
                                  f"lost: {type(exc).__name__}: {exc}")
            if on_point is not None:
                on_point(points[i])
        return points
    finally:
        client.unregister_worker_plugin(name)
