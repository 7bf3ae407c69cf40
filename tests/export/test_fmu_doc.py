"""docs/fmu.md's worked example, run as a reader would: its shell blocks with bgc, its
Python block in a process that has fmpy and never imports bgc (slow: the SARIB)."""

from __future__ import annotations

import os
import re
import shlex
import subprocess
import sys

import pytest
from helpers import ROOT, bgc

pytest.importorskip("fmpy")


def blocks(kind: str) -> list[str]:
    text = (ROOT / "docs" / "fmu.md").read_text()
    return re.findall(rf"```{kind}\n(.*?)```", text, re.S)


@pytest.mark.slow
def test_the_worked_example_runs(tmp_path):
    (tmp_path / "models").symlink_to(ROOT / "models")
    export, simulate = blocks("sh")
    for cmd in (export, simulate):
        args = shlex.split(cmd.strip())
        assert args[0] == "bgc"
        proc = bgc(*args[1:], "-q", cwd=tmp_path, timeout=1200)
        assert proc.returncode == 0, proc.stderr
    code, = blocks("python")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run([sys.executable, "-c", code + "\nimport sys\nassert 'bgc' not in "
                           "sys.modules\n"], cwd=tmp_path, env=env, capture_output=True,
                          text=True, timeout=1200)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "ME - CS" in proc.stdout
