"""``python -m bgc.cli ARGS`` as a separate process forked from an interpreter that has
already imported bgc, so that a test of what the CLI answers does not pay Python's and
bgc's start-up (about 1.5 s) each time.

One server per test process (started on first use, ended with it) imports the CLI and what
loading a model pulls in lazily (sympy: 0.3 s a child otherwise), then
for each request forks a child that runs ``bgc.cli`` as ``__main__`` (``runpy``, as
``python -m`` does) in the request's directory, with its umask, stdin from /dev/null and
stdout/stderr to files; an uncaught exception prints its traceback and exits 1, as the
interpreter would; ``atexit`` handlers run. The server waits for the child, killing it at
the timeout. Start-up itself is tested by the tests that run ``python -m bgc.cli``
directly (``test_import_orders``, ``test_runtime_failure``, ``test_warm_start`` ...)."""

from __future__ import annotations

import atexit
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

SERVER = r"""
import atexit, json, os, runpy, signal, sys, time, traceback
import bgc.cli, bgc.pipeline, bgc.simulate          # what the CLI's commands import,
import bgc.model.load, bgc.graph.expand, bgc.graph.causality, bgc.codegen.equations, bgc.scene.scenes  # and, lazily,
import sympy, scipy.integrate                        # what a model's load pulls in
print(json.dumps(dict(os.environ)), flush=True)     # as these imports left it


def child(req):
    null = os.open(os.devnull, os.O_RDONLY)
    out = os.open(req["out"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    err = os.open(req["err"], os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    for fd, to in ((null, 0), (out, 1), (err, 2)):
        os.dup2(fd, to)
        os.close(fd)
    os.chdir(req["cwd"])
    if req["umask"] >= 0:
        os.umask(req["umask"])
    sys.argv = ["bgc.cli", *req["args"]]
    del sys.modules["bgc.cli"]          # as in `python -m bgc.cli`: run as __main__ only
    code = 0
    try:
        runpy.run_module("bgc.cli", run_name="__main__", alter_sys=True)
    except SystemExit as e:
        if e.code is None:
            code = 0
        elif isinstance(e.code, int):
            code = e.code
        else:
            print(e.code, file=sys.stderr)
            code = 1
    except BaseException:
        traceback.print_exc()
        code = 1
    try:
        atexit._run_exitfuncs()
    finally:
        sys.stdout.flush()
        sys.stderr.flush()
        os._exit(code)


for line in sys.stdin:
    req = json.loads(line)
    sys.stdout.flush()
    pid = os.fork()
    if pid == 0:
        child(req)
    deadline = time.monotonic() + req["timeout"]
    timed_out = False
    while True:
        done, status = os.waitpid(pid, os.WNOHANG)
        if done:
            break
        if time.monotonic() > deadline:
            os.kill(pid, signal.SIGKILL)
            _, status = os.waitpid(pid, 0)
            timed_out = True
            break
        time.sleep(0.005)
    print(json.dumps({"code": os.waitstatus_to_exitcode(status), "timeout": timed_out}),
          flush=True)
"""

_server: subprocess.Popen | None = None
_env: dict | None = None            # the server's environment, as the caller's would be
_own: set = {"PYTEST_CURRENT_TEST"}  # variables not compared: pytest's per-test one, and
                                    # those the server's imports set (bgc sets some)


def _key(env: dict) -> dict:
    return {k: v for k, v in env.items() if k not in _own}


def _stop():
    if _server is not None and _server.poll() is None:
        _server.stdin.close()
        _server.wait(timeout=30)


def run(*args, cwd: Path, umask: int = -1, timeout: float = 10,
        env: dict | None = None) -> subprocess.CompletedProcess:
    """What ``subprocess.run([python, -m, bgc.cli, *args], capture_output=True,
    text=True, timeout=timeout, umask=umask)`` returns, from a forked child (see the
    module's docstring). The server is started with ``env``; a call with another ``env``
    than the server's runs a fresh interpreter instead."""
    global _server, _env
    env = dict(env if env is not None else os.environ)
    argv = [str(a) for a in args]
    if _server is not None and _key(env) != _env:
        return subprocess.run([sys.executable, "-m", "bgc.cli", *argv], check=False, cwd=cwd,
                              capture_output=True, text=True, timeout=timeout, env=env,
                              umask=umask)
    if _server is None:
        _server = subprocess.Popen([sys.executable, "-c", SERVER], stdin=subprocess.PIPE,
                                   stdout=subprocess.PIPE, text=True, env=env)
        atexit.register(_stop)
        imported = json.loads(_server.stdout.readline())
        _own.update(k for k in imported.keys() | env.keys() if imported.get(k) != env.get(k))
        _env = _key(env)
    with tempfile.TemporaryDirectory(prefix="bgc-cli-") as tmp:
        out, err = Path(tmp) / "stdout", Path(tmp) / "stderr"
        _server.stdin.write(json.dumps({"args": argv, "cwd": str(cwd), "umask": umask,
                                        "timeout": timeout, "out": str(out),
                                        "err": str(err)}) + "\n")
        _server.stdin.flush()
        reply = _server.stdout.readline()
        if not reply:
            raise RuntimeError("the forked-CLI server ended")
        reply = json.loads(reply)
        stdout, stderr = out.read_text(), err.read_text()
    cmd = [sys.executable, "-m", "bgc.cli", *argv]
    if reply["timeout"]:
        raise subprocess.TimeoutExpired(cmd, timeout, stdout, stderr)
    return subprocess.CompletedProcess(cmd, reply["code"], stdout, stderr)
