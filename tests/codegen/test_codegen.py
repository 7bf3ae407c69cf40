"""The generated module: analytic Jacobian vs finite differences, determinism, atomic and
fresh output, standalone import, parameters as an array."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from helpers import MODELS, ROOT, model_params, rendered

from bgc.codegen import emit
from bgc.codegen.kernels import program_functions
from bgc.model import load
from bgc.pipeline import build, compile_model
from bgc.simulate import simulate

ALL_MODELS = sorted(p.stem for p in MODELS.glob("*.yaml"))


# models whose default method cannot integrate them over their own run: the IFToMM
# flyball governor (A05) under parasitic, unstable (+4.3e4 1/s: its spring-dampers'
# actuator law reads body velocities across the parasitic joints) and stopped within
# 1 ms (tests/system/test_iftomm.py): its Jacobian is checked under zcp
METHOD = {"flyball_governor": "zcp"}
# make test checks one model of each kind (scalar networks, a table, events, loops and
# derivative causality, control blocks, a free body, revolute and spherical joints, closed
# loops: the four-bar, the slider-crank and its isosceles variant); these the same kinds
# again (Andrews' and Bricard's loops as the four-bar's, the heavy top's spherical joint
# as the double pendulum's, A01's revolute as the pendulum's, the zcp loops of A05 as the
# slider-crank's in test_zcp), in make test-all
ALSO = {"andrews", "bricard", "heavy_top", "simple_pendulum", "flyball_governor"}


@pytest.mark.parametrize("name", model_params([n for n in ALL_MODELS if n not in ALSO]) + [
    pytest.param(n, marks=pytest.mark.slow) for n in sorted(ALSO)])
def test_jacobian_matches_finite_differences(compiled, name):
    mod = compiled(name, METHOD.get(name, "parasitic"))
    rng = np.random.default_rng(7)
    p = mod.PARAMS
    n = len(mod.STATE_NAMES)
    # states at their initial value plus a perturbation of the size the model works at
    st = load.load(MODELS / f"{name}.yaml").settings
    run = simulate(mod, t_end=st.t_end, points=50, solver=st.solver, rtol=st.rtol, atol=st.atol)
    scale = np.maximum(np.abs(run.x).max(0), 1e-3)
    for _ in range(3):
        x = mod.X0 + scale * rng.uniform(-0.5, 0.5, n)
        t = float(rng.uniform(0, st.t_end))
        J = mod.jac(t, x, p)
        fd = np.empty((n, n))
        for j in range(n):
            h = 1e-6 * scale[j]
            xp, xm = x.copy(), x.copy()
            xp[j] += h
            xm[j] -= h
            fd[:, j] = (mod.rhs(t, xp, p) - mod.rhs(t, xm, p)) / (2 * h)
        norm = np.maximum(np.abs(fd).max(), 1e-12)
        assert np.abs(J - fd).max() / norm < 1e-5, (name, J, fd)


# the semi-active SARIB's code paths are the SARIB's plus ports and blocks that smaller
# models exercise, the A02 N-four-bar's those of the chains and instance loops of
# test_instances; their builds are left to `make test-all`
@pytest.mark.parametrize("name", [pytest.param(n, marks=pytest.mark.slow)
                                  if n in ("sarib_semiactive", "n_four_bar") else n
                                  for n in ALL_MODELS])
def test_committed_generated_module_is_fresh(name, compiled):
    """generated/<model>.py in the repository is exactly what `bgc compile` writes now
    (its source, as emit renders it: the machine code, which the source determines, is
    left to the tests that import modules): ``helpers.rendered``, the session's module
    where make test compiles it in any case."""
    committed = ROOT / "generated" / f"{name}.py"
    assert committed.exists(), f"run `make generated`: {committed} is missing"
    assert rendered(compiled, name) == committed.read_bytes(), (
        f"{committed} is stale: run `make generated`")
    model = load.load(MODELS / f"{name}.yaml")
    assert not emit.is_stale(committed, model.digest, "parasitic")


def test_compiling_twice_is_byte_identical_across_hash_seeds(tmp_path):
    """The module's source is the same bytes whatever the interpreter's hash seed (set
    and dict orders): rendered in two processes (the machine code, which the source
    determines, left out)."""
    script = ("import sys; from bgc.codegen import emit; from bgc.pipeline import build; "
              "sys.stdout.write(emit.render(build(sys.argv[1], 'lagrange').system))")
    outs = []
    for seed in ("0", "12345"):
        env = dict(os.environ, PYTHONHASHSEED=seed)
        outs.append(subprocess.run([sys.executable, "-c", script,
                                    str(MODELS / "geared_inertias.yaml")],
                                   check=True, env=env, capture_output=True).stdout)
    assert outs[0] == outs[1] and b"def rhs" in outs[0]


def test_stale_module_is_detected_and_rebuilt(tmp_path, compiled):
    src = (MODELS / "msd_free.yaml").read_text()
    model_file = tmp_path / "msd_free.yaml"
    model_file.write_text(src)
    out = tmp_path / "gen"
    out.mkdir()
    # the module bgc compile writes for this document: the session's (the same text, so
    # the same digest), copied
    path = out / "msd_free.py"
    shutil.copyfile(compiled("msd_free").__file__, path)
    m1 = load.load(model_file)
    assert not emit.is_stale(path, m1.digest, "parasitic")
    # a comment does not change the model ...
    model_file.write_text(src + "\n# a comment\n")
    assert not emit.is_stale(path, load.load(model_file).digest, "parasitic")
    # ... a value does
    model_file.write_text(src.replace("value: 800.0", "value: 900.0"))
    m2 = load.load(model_file)
    assert emit.is_stale(path, m2.digest, "parasitic")
    from bgc.pipeline import ensure_module
    mod, _, recompiled = ensure_module(model_file, out)
    assert recompiled is not None
    assert mod.PARAMS[mod.PARAM_NAMES.index("k")] == 900.0
    assert not emit.is_stale(path, m2.digest, "parasitic")


def test_write_is_atomic_and_leaves_no_temp_files(tmp_path):
    compile_model(MODELS / "rlc.yaml", tmp_path)
    compile_model(MODELS / "rlc.yaml", tmp_path)
    names = sorted(p.name for p in tmp_path.iterdir() if p.is_file())
    assert names == ["__init__.py", "rlc.py"]


def test_generated_module_imports_standalone(tmp_path):
    """`from generated import <model>` works in a fresh interpreter that has no bgc on
    its path, and the module imports only numpy, numba (with llvmlite, which compiles its
    kernels) and the standard library (ctypes: the functions on the kernels' C entry
    points); its C entry points for the native integrators are there too."""
    out = tmp_path / "generated"
    _, path = compile_model(MODELS / "dc_motor.yaml", out)
    text = path.read_text()
    imports = [ln for ln in text.splitlines() if ln.startswith(("import ", "from "))]
    assert imports == ["import ctypes", "import hashlib", "import math", "import os",
                       "import sys",
                       "from types import ModuleType", "import llvmlite",
                       "import llvmlite.binding as llvm", "import numpy as np",
                       "from llvmlite import ir", "from numba import njit, types",
                       "from numba.core import cgutils", "from numba.extending import intrinsic"]
    code = ("import sys; sys.modules['bgc'] = None\n"
            "from generated import dc_motor as m\n"
            "dx = m.rhs(0.0, m.X0, m.PARAMS); J = m.jac(0.0, m.X0, m.PARAMS)\n"
            "y = m.outputs(0.5, m.X0, m.PARAMS)\n"
            "assert all(a > 0 for a in m.native_entry_points())\n"
            "assert len(m.guards(0.0, m.X0, m.PARAMS)) == 0\n"   # (through ctypes)
            "assert len(m.constraints(0.0, m.X0, m.PARAMS)) == 0\n"
            "print(len(dx), J.shape, len(y), m.STATE_NAMES, m.MODEL_HASH, m.BGC_VERSION)")
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True,
                         text=True, env=dict(os.environ, PYTHONPATH=""))
    assert res.returncode == 0, res.stderr
    assert "2 (2, 2) 5 ('L_a.p', 'J.p')" in res.stdout


def test_parameters_change_without_recompiling(compiled):
    mod = compiled("msd_free")
    h = mod.MODEL_HASH
    p = mod.PARAMS.copy()
    p[mod.PARAM_NAMES.index("k")] = 3200.0          # four times stiffer: twice the frequency
    p[mod.PARAM_NAMES.index("x0")] = 0.02           # initial conditions follow parameters
    r = simulate(mod, t_end=0.5, rtol=1e-10, atol=1e-12, solver="radau", params=p)
    assert r.x[0, mod.STATE_NAMES.index("spring.q")] == 0.02
    wn, zeta = np.sqrt(3200 / 2.0), 4.0 / (2 * np.sqrt(3200 * 2.0))
    wd = wn * np.sqrt(1 - zeta ** 2)
    x = 0.02 * np.exp(-zeta * wn * r.t) * (np.cos(wd * r.t) + zeta * wn / wd * np.sin(wd * r.t))
    assert np.abs(r.column("position") - x).max() < 1e-8
    assert mod.MODEL_HASH == h


def test_emitted_code_keeps_causal_assignments(compiled):
    """The rhs is a sorted list of assignments, not one substituted expression: each
    assignment of its cone is stored to the workspace once, in short instructions."""
    mod = compiled("rr_loop")
    bodies = program_functions(Path(mod.__file__).read_text(), "rhs")
    stores = sum(b.count("store double") for b in bodies)
    assert stores >= 5 + len(mod.STATE_NAMES)       # the assignments, then dx
    assert all(len(ln) < 200 for b in bodies for ln in b.splitlines())


def test_fourteen_body_model_stays_lean(compiled):
    """The SARIB suspension (14 bodies, 18 joints, closed loops, 4 bodies of negligible
    mass) compiles to causal assignments that grow with the graph, not with its depth:
    no long substituted expressions, a bounded number of statements per state, and a
    Jacobian tape whose compressed width is the densest row of the Jacobian (its module:
    the session's)."""
    from bgc.codegen.emit import cone
    from bgc.codegen.jacobian import tape
    c, path = build(MODELS / "sarib.yaml"), Path(compiled("sarib").__file__)
    assert len(c.model.bodies) == 14 and len(c.model.joints) == 18
    s = c.system
    n = len(s.states)
    assert n == 10 * 12 + 4 * 6 + 8   # massive bodies (pose, momenta), massless (pose), springs
    text = path.read_text()
    rhs = [ln for b in program_functions(text, "rhs") for ln in b.splitlines()]
    # about 90 instructions a state (each read of a slot or state is two); a substituted
    # expression would be many times that
    assert len(rhs) < 150 * n, len(rhs)
    assert max(map(len, rhs)) < 200
    assert len(text) < 4_500_000
    rhs_asg, _ = cone(s.assignments, [st.dsym for st in s.states])
    jt = tape(rhs_asg, s.states)
    densest = np.bincount([i for i, _, _ in jt.pattern]).max()
    assert jt.n_colours <= densest + 5, (jt.n_colours, densest)
    assert len(jt.pattern) < 0.25 * n * n           # the Jacobian is sparse


def test_a_module_carries_its_outputs_units(compiled):
    """OUTPUT_UNITS beside OUTPUT_NAMES (issue 27), as models/rlc.yaml declares them."""
    m = compiled("rlc")
    assert m.OUTPUT_NAMES == ("current", "v_C", "v_R")
    assert m.OUTPUT_UNITS == ("A", "V", "V")
