"""What bgc's native integrators (``radau5``, ``rk4``) share: calling a generated module's
functions through their C entry points, the statistics layout and the guard search.

The step loops are compiled once per machine (numba's cache beside this package), not
once per model: they take the addresses of the module's ``rhs``, ``jac`` and ``guards``
as C functions ``void f(double t, double *x, double *p, double *out)`` (the module's
``native_entry_points()``) and call them through a pointer. A call costs tens of
nanoseconds; a model's cold compile no longer includes a step loop.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.extending import intrinsic

# statistics array layout (int64): what every native loop counts
ST_STEPS, ST_RHS, ST_JAC, ST_LU, ST_REJECTED = 0, 1, 2, 3, 4
N_STATS = 5

# status a loop returns (PAUSED: after its ``max_steps`` steps, for Python to look at
# the state before it goes on; UNSTABLE: rk4's step beyond the stability limit there;
# INTERRUPTED: its ``stop`` flag was set, by Ctrl-C: ``solver.Interrupt``)
REACHED, STEP_TOO_SMALL, GUARD, NOT_FINITE, SINGULAR, PAUSED, UNSTABLE, INTERRUPTED = \
    range(8)
# (MINOR: the rank monitor's minor crossed zero where the constraints may have lost rank,
# ``bgc.solvers.rank``; the loop returns at the crossing)
MINOR = 8


class Model(NamedTuple):
    """A generated module at parameter values ``p`` as the loops call it: the addresses
    of its C entry points (``native_entry_points()``) and how many guards it has."""
    rhs: int
    jac: int
    guards: int
    n_guards: int
    p: np.ndarray


class Outcome(NamedTuple):
    """What a native loop returns: the states at the output times reached (the first
    ``n_eval`` rows of ``x_eval``), the time reached ``t`` and the state ``x`` there, the
    status (above), the guard that stopped it (-1: none) and the step size to go on
    with."""
    x_eval: np.ndarray
    n_eval: int
    t: float
    x: np.ndarray
    status: int
    guard: int
    h: float


# a function called only from compiled code: no Python or C wrapper to lower and optimize
# (a few % of a loop's cold compile); not callable from Python
inner = njit(cache=True, no_cpython_wrapper=True, no_cfunc_wrapper=True)


def _call_codegen(context, builder, signature, args):
    """f(t, a.data, b.data, ...) for the C function at address args[0] (float64 arrays)."""
    dbl = ir.DoubleType()
    fnty = ir.FunctionType(ir.VoidType(), [dbl] + [dbl.as_pointer()] * (len(args) - 2))
    fptr = builder.inttoptr(args[0], fnty.as_pointer())
    ptrs = [context.make_array(ty)(context, builder, v).data
            for ty, v in zip(signature.args[2:], args[2:])]
    builder.call(fptr, [args[1]] + ptrs)
    return context.get_dummy_value()


@intrinsic
def call_entry(typingctx, addr, t, x, p, out):
    """Call the C function at ``addr`` as f(t, x.data, p.data, out.data) (contiguous
    float64 arrays; ``out`` may be 2-D, filled in C order)."""
    return types.void(addr, t, x, p, out), _call_codegen


@intrinsic
def call_kernel(typingctx, addr, t, x, p, w, out):
    """Call a generated module's kernel at ``addr`` as f(t, x.data, p.data, w.data,
    out.data), ``w`` its workspace (the constraints kernel, which has no entry point)."""
    return types.void(addr, t, x, p, w, out), _call_codegen


@njit(cache=True)
def evaluate(addr, t, x, p, n):
    """A fresh length-``n`` array filled by the entry point at ``addr``."""
    out = np.empty(n)
    call_entry(addr, t, x, p, out)
    return out


@njit(cache=True)
def guard_min(addr, n_guards, t, x, p, tol):
    """The guard whose margin is lowest above ``tol`` (index, margin - tol)."""
    g = evaluate(addr, t, x, p, n_guards)
    k, low = -1, np.inf
    for i in range(n_guards):
        if g[i] - tol < low:
            k, low = i, g[i] - tol
    return k, low


@intrinsic
def load_flag(typingctx, flag):
    """``flag[0]`` (a uint8 array) read by an atomic load, so that a loop sees it change:
    the flag is written by the kernel (``solver.Interrupt``), and a plain load could be
    hoisted out of the loop by the compiler."""
    sig = types.int64(flag)

    def codegen(context, builder, signature, args):
        data = context.make_array(signature.args[0])(context, builder, args[0]).data
        value = builder.load_atomic(data, ordering="monotonic", align=1)
        return builder.zext(value, ir.IntType(64))

    return sig, codegen


@njit(cache=True)
def stopped(flag) -> bool:
    """Whether the loop was asked to stop (an empty ``flag``: never)."""
    return flag.shape[0] > 0 and load_flag(flag) != 0


def cached(dispatcher) -> bool:
    """Whether numba's cache holds ``dispatcher`` compiled from its current source (through
    numba's cache index; False when it cannot tell)."""
    try:
        return bool(dispatcher._cache._cache_file._load_index())
    except Exception:                       # noqa: BLE001 - a private API: no answer
        return False


class Precompile:
    """A step loop compiled into numba's cache by a separate process, started while this
    one still works on the model (sympy, emit, the model's machine code): on two cores the
    loop's cold compile runs beside the front end instead of after it. ``wait`` before
    the loop's first call, then it loads from the cache; if the child failed, the loop
    compiles here as it would have. The child has its own session (Ctrl-C reaches this
    process only), no output, and is killed when this process exits before it is done."""

    def __init__(self, module: str):
        import atexit
        import subprocess
        import sys
        self.proc = subprocess.Popen(
            [sys.executable, "-c", f"from bgc.solvers import {module}; {module}.compile_loop()"],
            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL, start_new_session=True)
        atexit.register(self.stop)

    def wait(self) -> bool:
        """Wait for the child; whether it compiled the loop."""
        try:
            return self.proc.wait() == 0
        except BaseException:               # Ctrl-C while waiting: no orphan
            self.stop()
            raise

    def stop(self):
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait()


_started: dict[str, Precompile] = {}


def precompile(module: str):
    """Start compiling the step loop of ``module`` (``radau5``, ``rk4``: its
    ``compile_loop``) in a separate process, unless numba's cache has it already."""
    import importlib
    mod = importlib.import_module(f"bgc.solvers.{module}")
    if module not in _started and not cached(getattr(mod, module)):
        _started[module] = Precompile(module)


def await_precompiled(module: str):
    """Before the loop's first call: wait for the compile ``precompile`` started."""
    job = _started.pop(module, None)
    if job is not None:
        job.wait()
