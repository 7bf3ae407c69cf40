"""Writing output files atomically, with the permissions the user's umask asks for.

Every file bgc writes (generated modules, CSV, PNG, JSON, bench results) goes through
``atomic_write``: a temporary file in the same directory, flushed to disk, given the mode
``0o666 & ~umask`` (``tempfile.mkstemp`` alone gives 0600), then renamed over the target.
A failure at any point, Ctrl-C included, removes the temporary file and leaves an existing
target unchanged.
"""

from __future__ import annotations

import os
import tempfile
import threading
from pathlib import Path
from typing import Callable

from bgc.errors import BgcError

_UMASK_LOCK = threading.Lock()


def umask() -> int:
    """The process's umask (os.umask only reads it by setting it: set it back at once)."""
    with _UMASK_LOCK:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def output_dir(path: str | Path, what: str = "output") -> Path:
    """The directory ``path`` is to be written in, created if missing (with its parents);
    a BgcError naming the path if it cannot be (under a regular file, /proc, read-only)."""
    parent = Path(path).parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise unwritable(path, e, what) from None
    return parent


def check_writable(path: str | Path | None, what: str = "output",
                   directory: bool = False) -> None:
    """Refuse, before any work is done, an output path bgc could not write: under a
    regular file, an existing directory where a file is wanted (or a file where a
    directory is: ``directory``), or in a directory that does not take new files (read-only,
    /proc). Probes with a temporary file in the nearest existing directory, removed at
    once; missing directories are fine (they are created when written). Nothing is left
    behind."""
    if path is None:
        return
    path = Path(path)
    if path.exists() and path.is_dir() != directory:
        kind = "a directory" if path.is_dir() else "not a directory"
        raise BgcError(f"cannot write {what} {str(path)!r}: it is {kind}",
                       hint="give a " + ("directory" if directory else "file") + " path "
                            "in a writable directory")
    probe = path if directory else path.parent
    probe = probe if str(probe) else Path(".")
    while not probe.exists() and probe != probe.parent:
        probe = probe.parent
    if not probe.is_dir():
        raise BgcError(f"cannot write {what} {str(path)!r}: {str(probe)!r} is not a "
                       "directory", hint="give a path in a writable directory (missing directories are created)")
    try:
        fd, tmp = tempfile.mkstemp(dir=probe, prefix=".bgc-probe.", suffix=".tmp")
        os.close(fd)
        os.unlink(tmp)
    except OSError as e:
        raise BgcError(f"cannot write {what} {str(path)!r}: directory {str(probe)!r} does "
                       f"not take new files ({e.strerror or type(e).__name__})",
                       hint="give a path in a writable directory (missing directories are created)") from None


def unwritable(path: str | Path, e: OSError, what: str = "output") -> BgcError:
    """The one-line error for an output path bgc cannot write."""
    reason = e.strerror or type(e).__name__
    return BgcError(f"cannot write {what} {str(path)!r}: {reason}",
                    hint="give a path in a writable directory (missing directories are "
                         "created)")


def atomic_write(path: str | Path, data: str | bytes | Callable[[str], None],
                 what: str = "output") -> Path:
    """Write ``data`` (text, written as UTF-8 with '\\n' line ends; bytes; or a function
    that writes the file at the temporary path it is given) to ``path`` atomically. The
    directory is created if missing. An OSError becomes a one-line BgcError naming the
    path (``what`` says which file it is)."""
    path = Path(path)
    output_dir(path, what)
    tmp = None
    try:
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
        try:
            os.fchmod(fd, 0o666 & ~umask())
            if callable(data):
                os.close(fd)
                fd = -1
                data(tmp)
                fd = os.open(tmp, os.O_RDONLY)
            else:
                with os.fdopen(fd, "wb", closefd=False) as fh:
                    fh.write(data.encode("utf-8") if isinstance(data, str) else data)
            os.fsync(fd)
        finally:
            if fd >= 0:
                os.close(fd)
        os.replace(tmp, path)
        tmp = None
    except OSError as e:
        raise unwritable(path, e, what) from None
    finally:
        if tmp is not None:
            try:
                os.unlink(tmp)
            except OSError:
                pass
    return path
