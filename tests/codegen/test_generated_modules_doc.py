"""docs/generated-modules.md works as written (issue 23, item 7): its shell blocks (``bgc``
in a process of its own, ``helpers.bgc``) and then its Python blocks, in order, as one
script in a fresh interpreter and an empty directory; the numbers it prints are checked
here."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys

from helpers import ROOT, bgc

DOC = ROOT / "docs" / "generated-modules.md"


def blocks(lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", DOC.read_text(), flags=re.S | re.M)


def test_the_documented_example_runs_and_its_numbers_hold(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    (tmp_path / "models").symlink_to(ROOT / "models")
    shell = blocks("sh")
    assert shell, "the doc shows how to generate the module"
    for block in shell:
        for line in filter(None, (ln.strip() for ln in block.splitlines())):
            argv = shlex.split(line)
            assert argv[0] == "bgc", line
            proc = bgc(*argv[1:], cwd=tmp_path, timeout=600)
            assert proc.returncode == 0, proc.stderr
    script = "\n\n".join(blocks("python"))
    assert "solve_ivp(" in script and "project(" in script
    (tmp_path / "example.py").write_text(script)
    proc = subprocess.run([sys.executable, "example.py"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    checks = {}
    for line in proc.stdout.splitlines():
        if line.startswith("CHECK "):
            key, *values = line.split()[1:]
            checks[key] = values
    assert checks["residual_before"] and float(checks["residual_before"][0]) > 1e-4
    assert float(checks["residual_after"][0]) < 1e-10
    assert checks["rank"] == ["17", "of", "20"]
    assert float(checks["energy_change"][0]) < 1e-7
    assert float(checks["max_constraint_residual"][0]) < 1e-7
    assert float(checks["agreement"][0]) < 1e-7
    assert "3 redundant constraint(s)" in proc.stdout
