"""The C toolchain that links an FMU's shared library: the system's C compiler ($CC, else
gcc, cc or clang on PATH) or, without one, zig's (the ``ziglang`` package from PyPI:
``pip install ziglang``), else a one-line error saying what to install."""

from __future__ import annotations

import importlib.util
import os
import shlex
import shutil
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from bgc.errors import BgcError

FLAGS = ("-std=c99", "-O2", "-fPIC", "-fvisibility=hidden", "-shared")


@dataclass(frozen=True)
class Compiler:
    name: str
    command: tuple[str, ...]
    target: tuple[str, ...] = ()        # zig: the glibc the library needs at least

    def link(self, out: Path, sources, objects, includes, exports: Path):
        """Compile ``sources`` and link them with ``objects`` into the shared library
        ``out``, exporting only what the version script ``exports`` lists; nothing left
        undefined but libc's and libm's."""
        cmd = [*self.command, *self.target, *FLAGS, "-o", str(out),
               *(f"-I{i}" for i in includes), *map(str, sources), *map(str, objects),
               f"-Wl,--version-script={exports}", "-Wl,-z,defs", "-lm"]
        proc = subprocess.run(cmd, capture_output=True, text=True, stdin=subprocess.DEVNULL)
        if proc.returncode != 0:
            lines = (proc.stderr or proc.stdout).strip().splitlines() or ["no message"]
            first = next((ln for ln in lines if "error" in ln), lines[0])
            raise BgcError(f"linking the FMU's library with {self.name} failed: {first}",
                           hint="see docs/fmu.md (toolchain)")


def find() -> Compiler:
    """The toolchain to use, or a BgcError saying what to install."""
    cc = os.environ.get("CC")
    if cc:
        cmd = tuple(shlex.split(cc))
        if cmd and shutil.which(cmd[0]):
            return Compiler(Path(cmd[0]).name, cmd)
        raise BgcError(f"$CC is {cc!r}, which is not an executable on PATH",
                       hint="unset CC to use gcc, cc or clang, or set it to a C compiler")
    for name in ("gcc", "cc", "clang"):
        path = shutil.which(name)
        if path:
            return Compiler(name, (path,))
    if importlib.util.find_spec("ziglang") is not None:     # zig's wheel: pip install ziglang
        return Compiler("zig cc", (sys.executable, "-m", "ziglang", "cc"),
                        ("-target", "x86_64-linux-gnu.2.17"))
    raise BgcError("no C compiler found to link the FMU's library (gcc, cc, clang or $CC)",
                   hint="install one (apt-get install gcc) or zig's: pip install ziglang")
