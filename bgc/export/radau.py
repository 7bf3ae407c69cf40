"""bgc's Radau IIA (``bgc.solvers.radau5``, the loop ``--solver native`` runs) as
position-independent object code for an FMU's co-simulation: the same numba function,
compiled for a generic x86-64 and linked into the FMU's shared library.

The loop is model-independent (it calls the model's rhs, Jacobian and guards through
their C addresses), so it is compiled once per machine and bgc version, in a child
process (numba compiles for the host CPU; the child sets ``NUMBA_CPU_NAME=generic`` and
an empty numba cache of its own, so that every function it links is compiled there, as
IR), and the object is kept in bgc's cache (``cache_dir``).

``step`` is the entry point: numba's calling convention (``int32 f(ret*, excinfo**,
args...)``, every argument a scalar or a pointer), renamed ``bgc_radau5_step`` with every
other symbol made internal. What the object then needs from outside is checked against
``EXTERNALS``: libm and libc, and four of numba's run-time functions that the FMU's C
layer defines (``runtime/numba_rt.c``): the allocator of numpy arrays
(``NRT_MemInfo_alloc_aligned``, ``NRT_MemInfo_call_dtor``), LAPACK's ``getrf`` as numba
calls it (``numba_xxgetrf``: the dense Newton matrices) and ``numba_nextafter``.
"""

from __future__ import annotations

import contextlib
import hashlib
import os
import subprocess
import sys
from pathlib import Path

from bgc.errors import BgcError

SYMBOL = "bgc_radau5_step"
# what the object may leave undefined: libm, libc and what runtime/numba_rt.c defines
EXTERNALS = frozenset({
    "NRT_MemInfo_alloc_aligned", "NRT_MemInfo_call_dtor", "numba_xxgetrf", "numba_nextafter",
    "sqrt", "pow", "fabs", "memcpy", "memset", "memmove", "exp", "log", "sin", "cos"})
# the sources the object is compiled from (with numba's and llvmlite's versions: its key)
_SOURCES = ("solvers/radau5.py", "solvers/radau5_lu.py", "solvers/native.py",
            "solvers/rank.py", "solvers/sparse_lu.py", "codegen/elimination.py",
            "export/radau.py")


def _step_function():
    """The numba function the FMU calls (defined here, imported only in the child)."""
    import numpy as np
    from numba import carray, njit, types

    from bgc.solvers import radau5, rank
    from bgc.solvers.native import N_STATS, Model

    @njit(no_cpython_wrapper=True, no_cfunc_wrapper=True)
    def step(rhs, jac, guards, n_guards, n, n_p, x_ptr, p_ptr, dae, mass_ptr, index2_ptr,
             sparse, perm_ptr, lptr_ptr, lidx_ptr, uptr_ptr, uidx_ptr, n_l, n_u, t0, t1,
             rtol, atol, max_step, h_start, max_steps, stats_ptr, diag_ptr, out_ptr,
             j_ptr, lu_ptr, lu_cplx_ptr, piv_ptr, piv_cplx_ptr, q_ptr, y_old_ptr, kept_ptr):
        """radau5 from (t0, x) towards t1 (x overwritten by the state reached); out =
        [t reached, next step size, guard index]; returns the status (native.REACHED,
        ...). ``dae``: M dx/dt = rhs with ``mass_ptr`` (n x n) and ``index2_ptr`` (n),
        else an ODE; ``sparse``: the Newton matrices factored along the plan (perm,
        lptr, lidx, uptr, uidx), else dense; ``j_ptr`` ... ``kept_ptr``: the loop's state
        across pauses (``radau5.Carry``)."""
        x = carray(x_ptr, (n,))
        p = carray(p_ptr, (n_p,))
        stats = carray(stats_ptr, (N_STATS,))
        diag = carray(diag_ptr, (n,))
        out = carray(out_ptr, (3,))
        if dae:
            mass = carray(mass_ptr, (n, n))
            index2 = carray(index2_ptr, (n,))
        else:
            mass = np.empty((0, 0))
            index2 = np.empty(0)
        if sparse:
            # dpos, lpos, upos (where the Jacobian's values go) are read only where the
            # loop takes the values (System.jacv), never here: the FMU passes a dense J;
            # no update table either (``sparse_lu.factor`` finds the targets in the lists)
            none = np.empty(0, dtype=np.int64)
            plan = (carray(perm_ptr, (n,)), carray(lptr_ptr, (n + 1,)),
                    carray(lidx_ptr, (n_l,)), carray(uptr_ptr, (n + 1,)),
                    carray(uidx_ptr, (n_u,)), none, none, none,
                    np.empty(0, dtype=np.int32), np.empty(0))
        else:
            none = np.empty(0, dtype=np.int64)
            plan = (none, none, none, none, none, none, none, none,
                    np.empty(0, dtype=np.int32), np.empty(0))
        ints, floats = np.empty(0, dtype=np.int64), np.empty(0)
        monitor = rank.Monitor(0, 0, 0, ints, ints, floats, floats, 0, 0.0,
                               np.empty((2, 0), dtype=np.int64), np.zeros(1, dtype=np.int64))
        none_i = np.empty(0, dtype=np.int64)
        system = radau5.System(Model(rhs, jac, guards, n_guards, p), mass, index2, plan,
                               monitor, 0, np.empty((0, 0)), 0, none_i, none_i)
        settings = radau5.Settings(rtol, atol, max_step, h_start, 1e-3, max_steps,
                                   np.empty(0, dtype=np.uint8))
        keep = radau5.Carry(carray(j_ptr, (n, n)), np.empty(1), carray(lu_ptr, (n, n)),
                            carray(lu_cplx_ptr, (n, n)), carray(piv_ptr, (n,)),
                            carray(piv_cplx_ptr, (n,)), carray(q_ptr, (n, 3)),
                            carray(y_old_ptr, (n,)), carray(kept_ptr, (11,)))
        res = radau5.radau5(system, settings, t0, t1, x, np.empty(0), stats, diag, keep)
        for i in range(n):
            x[i] = res.x[i]
        out[0], out[1], out[2] = res.t, res.h, res.guard
        return res.status

    i64, f64 = types.int64, types.float64
    dptr, iptr = types.CPointer(f64), types.CPointer(i64)
    i32ptr = types.CPointer(types.int32)
    sig = (i64, i64, i64, i64, i64, i64, dptr, dptr, i64, dptr, dptr, i64, iptr, iptr, iptr,
           iptr, iptr, i64, i64, f64, f64, f64, f64, f64, f64, i64, iptr, dptr, dptr,
           dptr, dptr, types.CPointer(types.complex128), i32ptr, i32ptr, dptr, dptr, dptr)
    return step, sig


def key() -> str:
    """What the object depends on: the sources above, numba's and llvmlite's versions."""
    import llvmlite
    import numba
    root = Path(__file__).resolve().parent.parent
    h = hashlib.sha256(f"{numba.__version__}|{llvmlite.__version__}".encode())
    for name in _SOURCES:
        h.update(name.encode())
        h.update((root / name).read_bytes())
    return h.hexdigest()[:24]


def cache_dir() -> Path:
    """Where compiled objects are kept: $NUMBA_CACHE_DIR/bgc if set (as the generated
    modules' kernels), else the user's cache directory."""
    root = os.environ.get("NUMBA_CACHE_DIR")
    if root:
        return Path(root) / "bgc"
    user = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(user) / "bgc"


def _cached(path: Path) -> bytes | None:
    try:
        data = path.read_bytes()
    except OSError:
        return None
    return data[32:] if data[:32] == hashlib.sha256(data[32:]).digest() else None


def object_code() -> bytes:
    """The loop's object code, compiled (in a child process) if not cached yet; two
    processes that both miss the cache compile it once (a lock beside the cache)."""
    path = cache_dir() / f"radau5_fmu.{key()}.o"
    obj = _cached(path)
    if obj is not None:
        return obj
    import fcntl
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        lock = open(path.parent / "radau5_fmu.lock", "a+")
    except OSError:             # no cache directory: compile here, unshared
        return _compile(path)
    with lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        obj = _cached(path)     # compiled by another process meanwhile
        return obj if obj is not None else _compile(path)


def _compile(path: Path) -> bytes:
    """Compile the object in a child process and keep it at ``path`` (if it can)."""
    import tempfile
    with tempfile.TemporaryDirectory(prefix="bgc-radau-") as tmp:
        env = dict(os.environ, NUMBA_CPU_NAME="generic", NUMBA_CPU_FEATURES="",
                   NUMBA_CACHE_DIR=tmp)
        out = Path(tmp) / "radau5.o"
        proc = subprocess.run(
            [sys.executable, "-c", f"from bgc.export import radau; radau.build({str(out)!r})"],
            env=env, stdin=subprocess.DEVNULL, capture_output=True, text=True)
        if proc.returncode != 0 or not out.exists():
            last = (proc.stderr.strip().splitlines() or ["no message"])[-1]
            raise BgcError(f"compiling bgc's Radau for the FMU failed: {last}",
                           hint="this numba/llvmlite may be unsupported; see docs/fmu.md")
        obj = out.read_bytes()
    from bgc.fileio import atomic_write
    with contextlib.suppress(BgcError):     # no cache here: compiled again next time
        atomic_write(path, hashlib.sha256(obj).digest() + obj, "Radau object cache")
    return obj


def build(path: str):
    """In the child: compile ``step``, keep only it (renamed ``SYMBOL``) and what it
    calls, check its externals and write its object code to ``path``."""
    import llvmlite.binding as llvm

    from bgc.export.objects import target_machine
    step, sig = _step_function()
    step.compile(sig)
    cres = step.overloads[sig]
    mod = llvm.parse_assembly(cres.library.get_llvm_str())
    entry = cres.fndesc.llvm_func_name
    for f in mod.functions:
        if f.name == entry:
            f.name = SYMBOL
        elif not f.is_declaration:
            f.linkage = "internal"
    for g in mod.global_variables:
        if not g.is_declaration:
            g.linkage = "internal"
    machine = target_machine()
    mod.triple, mod.data_layout = machine.triple, str(machine.target_data)
    pb = llvm.create_pass_builder(machine, llvm.create_pipeline_tuning_options(speed_level=2))
    pb.getModulePassManager().run(mod, pb)
    mod.verify()
    undefined = {f.name for f in mod.functions if f.is_declaration
                 and not f.name.startswith("llvm.")}
    unknown = undefined - EXTERNALS
    if unknown:
        raise SystemExit(f"the Radau object needs {', '.join(sorted(unknown))}, which the "
                         "FMU does not provide")
    Path(path).write_bytes(machine.emit_object(mod))
