"""Object code for an FMU's shared library: a model's LLVM IR kernels compiled by
llvmlite for a generic x86-64 (the FMU runs on other machines than the one that built
it: no CPU features beyond the baseline) as position-independent code.

The passes are those a generated module runs when it is first imported
(``codegen/templates/module.py.j2``, ``_load_kernels``: the loops' module at
``kernels.IR_OPT`` with its module passes, the straight-line chunks by local passes
only), which a generated module must hold itself because it imports nothing of bgc.
"""

from __future__ import annotations

import llvmlite.binding as llvm

from bgc.codegen import kernels
from bgc.errors import BgcError

# the FMU's platform (FMI 2.0: binaries/linux64; FMI 3.0: binaries/x86_64-linux)
TRIPLE = "x86_64-unknown-linux-gnu"
CPU = "x86-64"
# what the kernels may call that is not in the IR: libm, libc and the LAPACK routine a
# redundant constraint block calls (``<prefix>_dgesdd``, defined by the FMU's C layer)
LIBM = frozenset({"sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh",
                  "tanh", "exp", "log", "pow", "sqrt", "fabs", "malloc", "free", "memcpy",
                  "memset", "memmove"})


def target_machine():
    """The FMU's target: generic x86-64 Linux, position-independent code."""
    llvm.initialize_all_targets()
    llvm.initialize_all_asmprinters()
    target = llvm.Target.from_triple(TRIPLE)
    return target.create_target_machine(cpu=CPU, features="", opt=2, reloc="pic",
                                        codemodel="default")


def kernels_object(ir: str, ir_straight: str, prefix: str) -> bytes:
    """The kernels' object code; refused if they call anything but ``LIBM`` and the
    module's own ``<prefix>_dgesdd`` (nothing of Python's or numba's run time)."""
    machine = target_machine()
    module, straight = llvm.parse_assembly(ir), llvm.parse_assembly(ir_straight)
    for m in (module, straight):
        m.triple, m.data_layout = machine.triple, str(machine.target_data)
        m.verify()
    passes = llvm.create_pass_builder(
        machine, llvm.create_pipeline_tuning_options(speed_level=kernels.IR_OPT))
    passes.getModulePassManager().run(module, passes)
    local = llvm.create_new_module_pass_manager()
    for p in kernels.STRAIGHT_PASSES:
        getattr(local, f"add_{p}_pass")()
    local.run(straight, passes)
    module.link_in(straight)
    undefined = {f.name for f in module.functions
                 if f.is_declaration and not f.name.startswith("llvm.")}
    unknown = undefined - LIBM - {f"{prefix}_dgesdd"}
    if unknown:
        raise BgcError(f"internal: the model's kernels call {', '.join(sorted(unknown))}, "
                       "which an FMU cannot provide")
    return machine.emit_object(module)
