"""The compiler digest covers what determines the generated code, and only that (issue 25,
item 6): a compile imports nothing of bgc outside ``CODEGEN_SOURCES`` but the cross-cutting
helpers, and editing the CLI, a solver or the analysis leaves every module fresh."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

from helpers import MODELS, ROOT

from bgc.codegen import module_file

# bgc's modules a compile may import outside the digest: none of them writes code
CROSS_CUTTING = {"bgc", "bgc.errors", "bgc.fileio", "bgc.progress"}

# what writes a module: the stages to its source (its machine code is the template's)
SCRIPT = """
import json, sys
from bgc.codegen import emit
from bgc.pipeline import build
for method in ("parasitic", "lagrange", "zcp"):
    emit.write(build(sys.argv[1], method).system, sys.argv[2])
print(json.dumps({n: m.__file__ for n, m in sys.modules.items()
                  if n.split(".")[0] == "bgc" and getattr(m, "__file__", None)}))
"""


def test_a_compile_imports_only_digested_code(tmp_path):
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(MODELS / "pendulum.yaml"),
                           str(tmp_path)], capture_output=True, text=True, timeout=600,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)), check=False)
    assert proc.returncode == 0, proc.stderr[-2000:]
    loaded = json.loads(proc.stdout.strip().splitlines()[-1])
    digested = {str(f) for f in module_file.codegen_files()}
    outside = {n for n, f in loaded.items() if f not in digested} - CROSS_CUTTING
    assert not outside, sorted(outside)
    assert any(n.startswith("bgc.methods.") for n in loaded)      # it did run the methods


def test_the_digest_moves_with_codegen_code_only(tmp_path):
    root = tmp_path / "bgc"
    shutil.copytree(ROOT / "bgc", root, ignore=shutil.ignore_patterns("__pycache__"))
    base = module_file.compiler_digest(root)
    assert base == module_file.compiler_digest(ROOT / "bgc")      # by content, not place
    digested = set(module_file.codegen_files(root))
    outside = [f for f in root.rglob("*.py") if f not in digested]
    assert {"cli", "simulate", "radau5", "frf", "scenes"} <= {f.stem for f in outside} | {
        f.parent.name for f in outside}
    for path in outside:            # every file outside: CLI, solvers, analysis, scenes, bench
        path.write_text(path.read_text() + "\n# edited\n")
    assert module_file.compiler_digest(root) == base
    for inside in ("codegen/emit.py", "methods/lagrange.py", "graph/causality.py",
                   "model/load.py", "mechanics/joints.py", "codegen/templates/module.py.j2",
                   "pipeline.py", "scene/reduce.py"):
        path = root / inside
        before = module_file.compiler_digest(root)
        path.write_text(path.read_text() + "\n# edited\n")
        assert module_file.compiler_digest(root) != before, inside
