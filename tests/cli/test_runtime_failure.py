"""Loud failure at run time (issue 23, item 4), through the CLI as a user meets it.

Before integrating, rhs and Jacobian are evaluated at the initial state and non-finite
values are refused, naming what is responsible. Ctrl-C stops a run within a second and
keeps the results so far. A step budget (``--max-steps``) and a collapsing step size stop
a run with the time and the states involved. The millimetre four-bar with redundant
constraints, which used to start with NaN in its rhs (native Radau hung for more than 37
minutes, scipy BDF raised a raw ValueError), is refused at once naming them.

The modules are the session's (``compiled``, in ``gen_dir``), which each run is given with
``-o``: the runs load them warm; their files go to a directory of this module's.
Subprocess timeouts guard against hangs; they are not performance targets.
"""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import forked_cli
import pytest
from helpers import ROOT, error_lines

MSD = ROOT / "models" / "msd_forced.yaml"
MICRO = Path(__file__).with_name("micro_four_bar.yaml")


def bgc_args(*args) -> list[str]:
    return [sys.executable, "-m", "bgc.cli", *map(str, args)]


def env() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT))


def run(*args, cwd, timeout=120) -> subprocess.CompletedProcess:
    """``bgc ARGS`` in its own process, forked from a server that has imported bgc
    (``forked_cli``; Ctrl-C is sent to a fresh ``python -m bgc.cli``)."""
    return forked_cli.run(*args, cwd=cwd, timeout=timeout, env=env())


def rows(path: Path) -> list[list[float]]:
    with open(path) as fh:
        reader = csv.reader(fh)
        next(reader)
        return [[float(v) for v in r] for r in reader]


@pytest.fixture(scope="module")
def gen(tmp_path_factory, compiled):
    """The runs' working directory; msd_forced (parasitic) and micro_four_bar (lagrange)
    compiled into the session's ``gen_dir``."""
    compiled("msd_forced")
    compiled(MICRO, "lagrange")
    return tmp_path_factory.mktemp("runtime")


def test_non_finite_start_names_the_parameter(gen, gen_dir):
    """m = 0 makes dp/dt = p/m - ... = 0/0 at the start. The CLI refuses -p m=0 with the
    model's own check (tests/model/test_hostile_input.py); a script that sets it in the
    parameter array meets the check of the start instead: refused before any step,
    naming the parameter."""
    import numpy as np

    from bgc.errors import SimulationError
    from bgc.pipeline import ensure_module
    from bgc.simulate import simulate
    module = ensure_module(MSD, gen_dir, "parasitic")[0]
    p = np.array(module.PARAMS)
    p[list(module.PARAM_NAMES).index("m")] = 0.0
    with pytest.raises(SimulationError) as err:
        simulate(module, t_end=1.0, params=p, solver="native")
    msg = str(err.value)
    assert msg.startswith("d/dt of mass.p, spring.q not finite at the initial state "
                          "(t = 0)"), msg
    assert "parameter(s) m make it so" in msg and "nothing was run" in msg
    assert err.value.result is None


@pytest.mark.parametrize("solver", ["native", "bdf"])
def test_step_budget_stops_the_run_and_keeps_its_results(gen, gen_dir, solver):
    out = gen / f"budget_{solver}.csv"
    proc = run("simulate", MSD, "-o", gen_dir, "--solver", solver, "--max-steps", 25,
               "--out", out, cwd=gen)
    lines = error_lines(proc.stderr)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr, proc.stderr
    assert "the step budget (25 steps) is spent at t = " in lines[0], lines[0]
    assert "fastest states there: " in lines[0], lines[0]
    t_stop = float(lines[0].split("is spent at t = ")[1].split(";")[0])
    assert 0 < t_stop < 2.0
    assert "partial results up to t = " in proc.stderr
    data = rows(out)
    assert len(data) >= 2 and data[-1][0] <= t_stop + 1e-12


@pytest.mark.parametrize("value", ["0", "-5", "1.5", "many"])
def test_step_budget_must_be_a_whole_positive_number(gen, gen_dir, value):
    proc = run("simulate", MSD, "-o", gen_dir, "--max-steps", value, cwd=gen)
    lines = error_lines(proc.stderr)
    assert proc.returncode == 2 and len(lines) == 1, proc.stderr
    assert lines[0].startswith("error: --max-steps: "), lines[0]


def _wait_for_integration(proc: subprocess.Popen, timeout: float = 120) -> None:
    """Until the run has armed its Ctrl-C handler (``solver.Interrupt`` maps a memfd
    named bgc-interrupt just before the integration starts)."""
    fd_dir = Path(f"/proc/{proc.pid}/fd")
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        assert proc.poll() is None, proc.communicate()
        try:
            if any("bgc-interrupt" in os.readlink(fd) for fd in fd_dir.iterdir()):
                return
        except OSError:         # an fd closed while listing
            pass
        time.sleep(0.02)
    raise AssertionError("the integration did not start")


@pytest.mark.skipif(not Path("/proc/self/fd").is_dir() or not hasattr(os, "memfd_create"),
                    reason="needs Linux's /proc and memfd")
@pytest.mark.parametrize("solver", ["native", "bdf"])
def test_ctrl_c_stops_within_a_second_and_writes_the_results_so_far(gen, gen_dir, solver):
    out = gen / f"interrupted_{solver}.csv"
    t_end = 1e6                  # 3 Hz forcing: tens of millions of steps
    proc = subprocess.Popen(bgc_args("simulate", MSD, "-o", gen_dir, "--solver", solver,
                                     "--t-end", t_end, "--max-steps", 10 ** 9,
                                     "--points", 100_001, "--out", out),
                            cwd=gen, env=env(), stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    try:
        _wait_for_integration(proc)
        time.sleep(0.5)
        sent = time.monotonic()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=30)
        took = time.monotonic() - sent
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr, stderr
    assert took < 1.0, f"{took:.2f} s from Ctrl-C to exit"
    assert error_lines(stderr)[0].startswith("interrupted: Ctrl-C at t = "), stderr
    assert "partial results up to t = " in stderr, stderr
    data = rows(out)
    assert len(data) >= 2 and 0 < data[-1][0] < t_end
    assert all(b[0] > a[0] for a, b in zip(data, data[1:]))


@pytest.mark.parametrize("solver", ["native", "bdf"])
def test_redundant_constraints_at_millimetre_scale_end_at_once_naming_them(gen, gen_dir,
                                                                        solver):
    """The projection finds rank 17 of 20 on the equilibrated constraint rows, but the
    generated block solve keeps only the singular values of J M^-1 J^T above 1e-10 of the
    largest, fewer at this scale: the rhs is NaN at the start. Refused before any step,
    under every solver, naming the redundant constraints and what to do."""
    out = gen / f"micro_{solver}.csv"
    proc = run("simulate", MICRO, "--method", "lagrange", "-o", gen_dir, "--solver", solver,
               "--t-end", 0.1, "--out", out, cwd=gen, timeout=60)
    lines = error_lines(proc.stderr)
    assert proc.returncode == 2, proc.stderr
    assert "Traceback" not in proc.stderr and len(lines) == 1, proc.stderr
    assert "not finite at the initial state (t = 0)" in lines[0], lines[0]
    assert "its 20 constraints have rank 17, 3 redundant (" in lines[0]
    assert "nothing was run" in lines[0] and "--method parasitic" in lines[0]
    assert not out.exists()


@pytest.mark.parametrize("solver", ["bdf", "radau"])
def test_collapsing_step_size_stops_a_scipy_run_at_once(solver):
    """dx/dt = -sign(x) from x = 1e-13 chatters about x = 0 from t = 1e-13 on: scipy's
    own test (a step below the spacing of t) does not fire that close to t = 0, and BDF
    crawled on in steps of 1e-29 s. A thousand steps in a row below 1e-10 of the segment
    stop it, with the time and the state."""
    import types

    import numpy as np

    from bgc.simulate import SOLVERS
    from bgc.solvers.base import Problem
    module = types.SimpleNamespace(rhs=lambda t, x, p: -np.sign(x),
                                   jac=lambda t, x, p: np.zeros((1, 1)), STATE_NAMES=("x",))
    start = time.monotonic()
    seg = SOLVERS[solver](Problem(module, np.zeros(0), rtol=1e-6, atol=1e-8)).integrate(
        0.0, 1.0, np.array([1e-13]), np.linspace(0.0, 1.0, 11))
    assert time.monotonic() - start < 30       # a hang guard; it takes well under a second
    assert not seg.ok and seg.t_reached < 1e-6
    assert seg.message.startswith("the step size collapsed to "), seg.message
    assert f"at t = {seg.t_reached:.6g}; fastest states there: x" in seg.message
