"""Instance loops (bgc.codegen.instances): many instances of one component are one
template and a table in the generated code, computing what the code written out per
instance computes; the code grows with the kinds of parts, not with their copies."""

from __future__ import annotations

import ctypes
import re

import numpy as np
from helpers import ROOT

from bgc.codegen import emit, instances
from bgc.codegen.module_file import import_module
from bgc.model.load import loads
from bgc.pipeline import build

CHAIN = [b for b in re.findall(r"```yaml\n(.*?)```", (ROOT / "docs" / "format.md").read_text(),
                               re.S) if b.startswith("name: spring_chain")][0]


def system(n: int):
    return build(loads(CHAIN, str(ROOT / "docs" / "format.md"), constants={"N": n})).system


def kernel_ir(source: str) -> str:
    return "".join(re.findall(r'^_KERNEL_IR(?:_STRAIGHT)? = """\\\n(.*?)"""', source,
                              re.S | re.M))


def code(ir: str) -> str:
    """IR without its constant tables (data, a row per instance)."""
    return "\n".join(line for line in ir.splitlines() if not line.startswith("@"))


def entry(mod, name: str, n_out: int):
    """The module's C entry point ``name`` (t, x, p, out) through ctypes: no numba."""
    fn = ctypes.CFUNCTYPE(None, ctypes.c_double, *[ctypes.POINTER(ctypes.c_double)] * 3)(
        mod._ENGINE.get_function_address(f"{mod._KERNEL_PREFIX}_{name}"))

    def call(t, x, p):
        out = np.zeros(n_out)
        x, p = np.ascontiguousarray(x, float), np.ascontiguousarray(p, float)
        ptr = ctypes.POINTER(ctypes.c_double)
        fn(t, x.ctypes.data_as(ptr), p.ctypes.data_as(ptr), out.ctypes.data_as(ptr))
        return out
    return call


def test_loops_compute_what_the_code_written_out_computes(tmp_path, monkeypatch):
    s = system(12)
    looped = emit.write(s, tmp_path / "loops")
    monkeypatch.setattr(instances, "MIN_COPIES", 10 ** 9)
    straight = emit.write(s, tmp_path / "straight")
    a, b = looped.read_text(), straight.read_text()
    assert "_rhs_loop" in a and "_jac_loop" in a and "_loop" not in b
    ma, mb = import_module(looped), import_module(straight)
    n = len(ma.STATE_NAMES)
    rng = np.random.default_rng(3)
    for _ in range(3):
        x = rng.standard_normal(n) * 1e-3
        p = ma.PARAMS * rng.uniform(0.5, 1.5, len(ma.PARAMS))
        for name, size in (("rhs_entry", n), ("jac_entry", n * n)):
            ya, yb = entry(ma, name, size)(0.1, x, p), entry(mb, name, size)(0.1, x, p)
            assert np.abs(ya - yb).max() <= 1e-14 * np.abs(yb).max(), name


def test_the_code_follows_the_kinds_of_parts_not_their_copies():
    """12 and 48 cells: the same loops (one template per program and level), and kernel
    code of the same size; the tables (data) grow by a row per cell."""
    sizes, loops = {}, {}
    for n in (12, 48):
        ir = kernel_ir(emit.render(system(n)))
        sizes[n] = len(code(ir))
        loops[n] = sorted(re.findall(r"define void @\w+_(\w+_tmpl\d+)\(", ir))
    assert loops[12] == loops[48] and loops[12]
    assert sizes[48] < 1.05 * sizes[12], sizes


def test_fewer_instances_than_min_copies_are_written_out():
    """Four cells (the SARIB's four legs: the same): the code as without components."""
    assert instances.MIN_COPIES > 4
    assert "_loop" not in emit.render(system(4))
