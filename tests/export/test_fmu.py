"""bgc export: FMUs checked as their users see them, by fmpy in a process that never
imports bgc (tests/export/run_fmpy.py): validated, run as Model Exchange (fmpy's CVode)
and as Co-Simulation (1 ms communication steps), compared with ``bgc simulate --solver
native`` at the same tolerance within 1e-6 of each output's peak (outputs that are
numerical noise at 1e-6 of the largest of their unit, ``bgc.analysis.noise``, left out), the
exact Jacobian through fmi2GetDirectionalDerivative, the library's dependencies and
exports, and the command's refusals."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from helpers import MODELS, ROOT, bgc

from bgc.analysis import noise
from bgc.analysis.results import output_units
from bgc.export import fmu as fmu_export
from bgc.simulate import simulate

pytest.importorskip("fmpy")
HERE = Path(__file__).resolve().parent
AGREE = 1e-6        # of each output's peak
# the tolerances of the comparison: fmpy's CVode (ME) needs a tighter one than bgc's
# Radau to be within 1e-6 of a stiff model's outputs (the SARIB's parasitic joints: 2e-6
# of a_OF_z's peak at 1e-10, 6e-7 at 1e-11)
RTOL_ME, RTOL_CS = 1e-11, 1e-9


def run_fmpy(jobs) -> list[dict]:
    """The jobs run by fmpy in a fresh process without bgc (no PYTHONPATH, nothing of bgc
    imported: checked)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH",)}
    proc = subprocess.run([sys.executable, str(HERE / "run_fmpy.py"), json.dumps(jobs)],
                          capture_output=True, text=True, env=env, cwd=HERE, timeout=1800)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])     # (after fmpy's warnings)
    assert out["bgc_imported"] is False
    return out["results"]


def reference(module, p, t_end, rtol):
    """bgc simulate --solver native at the FMU's tolerances (its atol in the model's ratio),
    on the 1 ms output grid."""
    st = module.SETTINGS
    return simulate(module, t_end=t_end, rtol=rtol, atol=rtol * st["atol"] / st["rtol"],
                    solver="native", params=p, points=int(round(t_end / 1e-3)) + 1)


def disagreement(module, ref, run: dict) -> tuple[float, dict]:
    """The largest difference over each output's peak, for the outputs that are not
    below 1e-6 (``AGREE``) of the largest of their unit: those are numerical noise at the
    agreement asked (``bgc.analysis.noise``: the SARIB's F_A1_y, round-off of a force
    that symmetry makes zero, 3e-9 N beside 226 N), and left out."""
    _, noisy = noise.of_result(ref, output_units(module), AGREE)
    t = np.array(run["time"])
    # fmpy's ME records a state event's time (off the grid) and a time event's twice,
    # before and after it: keep the grid's rows, the value after an event, as bgc's
    # output at a breakpoint is the next segment's
    on_grid = np.abs(t / 1e-3 - np.round(t / 1e-3)) < 1e-6
    keep = on_grid & np.append(t[1:] != t[:-1], True)
    run = {k: np.array(v)[keep] for k, v in run.items()}
    assert np.allclose(run["time"], ref.t, atol=1e-9), (run["time"][:3], ref.t[:3])
    errs = {}
    for k, name in enumerate(module.OUTPUT_NAMES):
        if name in noisy or name not in run:
            continue
        peak = np.abs(ref.y[:, k]).max()
        errs[name] = float(np.abs(np.array(run[name]) - ref.y[:, k]).max() / peak) \
            if peak > 0 else float(np.abs(run[name]).max())
    return max(errs.values(), default=0.0), errs


def check_runs(module, results, p, t_end, agree=None, skip=()):
    """ME and CS against bgc; the Jacobian against the module's. ``agree``: another
    bound per kind; ``skip``: outputs not compared."""
    for kind, rtol in (("ModelExchange", RTOL_ME), ("CoSimulation", RTOL_CS)):
        if kind not in results:
            continue
        ref = reference(module, p, t_end, rtol)
        worst, errs = disagreement(module, ref, {k: v for k, v in results[kind].items()
                                                 if k not in skip})
        bound = (agree or {}).get(kind, AGREE)
        print(f"{module.MODEL_NAME} {module.METHOD} {kind}: {worst:.2e} of the peak", errs)
        assert worst <= bound, (module.MODEL_NAME, module.METHOD, kind, errs)
    if "jacobian" in results:
        from bgc.simulate import prepare
        x0, q, _ = prepare(module, module.initial_state(p), p)
        assert np.allclose(results["x0"], x0, rtol=1e-12, atol=1e-14)
        J = module.jac(0.0, x0, q)
        assert np.allclose(results["jacobian"], J, rtol=1e-12,
                           atol=1e-12 * np.abs(J).max())


def pi_servo(tmp: Path):
    """docs/format.md's position servo: a PI loop whose voltage saturates at +-12 V (its
    two switching functions are the FMU's event indicators)."""
    text = (ROOT / "docs" / "format.md").read_text()
    start = text.index("name: pi_servo")
    path = tmp / "pi_servo.yaml"
    path.write_text(text[start:text.index("```", start)])
    return path


@pytest.fixture(scope="module")
def small_fmus(gen_dir, compiled, tmp_path_factory):
    """rlc (parasitic: a time event), the pendulum under lagrange (the projection and the
    rank set natively at initialization) and the PI servo (a saturation: event
    indicators), exported and run by fmpy in one process."""
    from bgc.codegen.emit import import_module
    from bgc.pipeline import compile_model
    out = gen_dir / "fmu"
    tmp = tmp_path_factory.mktemp("servo")
    servo = pi_servo(tmp)
    jobs, modules = [], []
    for name, method, t_end in (("rlc", "parasitic", 0.05), ("pendulum", "lagrange", 1.0),
                                ("pi_servo", "parasitic", 0.3)):
        path = out / f"{name}_{method}.fmu"
        model = servo if name == "pi_servo" else MODELS / f"{name}.yaml"
        done = fmu_export.export(model, path, method)
        assert done.interfaces == ["ModelExchange", "CoSimulation"]
        assert done.event_indicators == (2 if name == "pi_servo" else 0)
        jobs.append({"fmu": str(path), "t_end": t_end, "rtol_me": RTOL_ME, "rtol_cs": RTOL_CS})
        modules.append(import_module(compile_model(servo, tmp)[1]) if name == "pi_servo"
                       else compiled(name, method))
    return list(zip(jobs, modules, run_fmpy(jobs)))


def test_small_fmus_agree_with_bgc(small_fmus):
    for job, module, results in small_fmus:
        assert results["problems"] == []
        check_runs(module, results, module.PARAMS.copy(), job["t_end"])


def test_library_links_no_python_and_exports_fmi_only(small_fmus, tmp_path):
    job = small_fmus[0][0]
    with zipfile.ZipFile(job["fmu"]) as z:
        names = z.namelist()
        assert "modelDescription.xml" in names and "binaries/linux64/rlc.so" in names
        lib = tmp_path / "rlc.so"
        lib.write_bytes(z.read("binaries/linux64/rlc.so"))
    needed = subprocess.run(["readelf", "-d", str(lib)], capture_output=True, text=True).stdout
    libs = [ln.split("[")[1].rstrip("]") for ln in needed.splitlines() if "(NEEDED)" in ln]
    assert libs and all(not n.startswith("libpython") for n in libs), libs
    assert set(libs) <= {"libm.so.6", "libc.so.6"}, libs
    syms = subprocess.run(["nm", "-D", "--defined-only", str(lib)], capture_output=True,
                          text=True).stdout.split()
    exported = [s for s in syms[2::3]]
    assert exported and all(s.startswith("fmi2") for s in exported), exported


def test_model_description(small_fmus):
    from fmpy import read_model_description
    md = read_model_description(small_fmus[0][0]["fmu"])
    by = {v.name: v for v in md.modelVariables}
    assert float(md.defaultExperiment.stopTime) == 0.05
    assert float(md.defaultExperiment.tolerance) == 1e-6
    assert by["C"].causality == "parameter" and by["C"].variability == "tunable"
    assert by["C"].unit == "F" and float(by["C"].start) == 2e-5
    assert by["current"].causality == "output" and by["current"].unit == "A"
    states = [v.name for v in md.modelVariables if v.causality == "local"
              and v.derivative is None]
    assert [u.variable.name for u in md.derivatives] == [f"der({s})" for s in states]
    assert [u.variable.derivative.name for u in md.derivatives] == states
    md = read_model_description(small_fmus[1][0]["fmu"])
    by = {v.name: v for v in md.modelVariables}
    assert by["lagrange__rank"].causality == "calculatedParameter"
    assert by["lagrange__alpha"].variability == "tunable"


def test_same_model_same_fmu(gen_dir, small_fmus):
    """The same model and options give the same bytes (fixed zip times, a GUID from the
    content)."""
    again = gen_dir / "fmu" / "rlc_again.fmu"
    fmu_export.export(MODELS / "rlc.yaml", again)
    with zipfile.ZipFile(small_fmus[0][0]["fmu"]) as a, zipfile.ZipFile(again) as b:
        for name in ("modelDescription.xml", "binaries/linux64/rlc.so"):
            assert a.read(name) == b.read(name), name


@pytest.mark.parametrize("args, message", [
    (["--fmu", "x.zip"], "--fmu: an FMU's file name ends in .fmu"),
    (["--fmu", "x.fmu", "--fmi", "3"], "--fmi: FMI 3 export is not available"),
    (["--fmu", "x.fmu", "-p", "nope=1"], "--param: unknown parameter 'nope'"),
    (["--fmu", "x.fmu", "-p", "C=-1"], "--param: C=-1: capacitance C"),
    (["--fmu", "x.fmu", "-p", "C=abc"], "--param"),
    (["--fmu", "/proc/x.fmu"], "cannot write --fmu"),
])
def test_refusals_are_one_line_and_write_nothing(tmp_path, args, message):
    args = [a if a != "x.fmu" else str(tmp_path / "x.fmu") for a in args]
    proc = bgc("export", str(MODELS / "rlc.yaml"), "-q", *args, cwd=tmp_path, timeout=60)
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_no_compiler_says_what_to_install(tmp_path, monkeypatch):
    from bgc.errors import BgcError
    from bgc.export import toolchain
    monkeypatch.delenv("CC", raising=False)
    monkeypatch.setattr(toolchain.shutil, "which", lambda name: None)
    monkeypatch.setitem(sys.modules, "ziglang", None)
    with pytest.raises(BgcError, match="no C compiler found") as e:
        toolchain.find()
    assert "pip install ziglang" in e.value.hint


# ---- the models under each method, with an excitation where the model has one

SLOW = [("dc_motor", "parasitic", {}), ("pendulum", "parasitic", {}),
        ("pendulum", "zcp", {})] + [
    ("sarib", m, {"excitation__sine": 1.0, "excitation__pumping": 200.0})
    for m in ("parasitic", "lagrange", "zcp")]


@pytest.mark.slow
@pytest.mark.parametrize("name, method, start", SLOW)
def test_models_agree_with_bgc(gen_dir, compiled, name, method, start):
    """The FMU's start values set by the importer (the SARIB's sine along pumping): the
    start (static loads, projection) computed natively after them."""
    path = gen_dir / "fmu" / f"{name}_{method}.fmu"
    fmu_export.export(MODELS / f"{name}.yaml", path, method)
    module = compiled(name, method)
    results = run_fmpy([{"fmu": str(path), "t_end": 1.0, "rtol_me": RTOL_ME,
                         "rtol_cs": RTOL_CS, "start": start}])[0]
    assert results["problems"] == []
    p = module.PARAMS.copy()
    for k, v in start.items():
        p[module.PARAM_NAMES.index(k)] = v
    check_runs(module, results, p, 1.0)


@pytest.mark.slow
def test_excitation_as_input(gen_dir, compiled):
    """The SARIB's excitation directions are inputs (N, N m): 200 N held on
    excitation.pumping is bgc simulate --excitation constant --direction pumping (but
    for the output g, the model's own g(t), which the input leaves at 0). The load
    applied at once rings the parasitic joints: fmpy's CVode (ME) is within 1.2e-6 of
    a_OF_z's peak at rtol 1e-11, bgc's Radau (CS) within 2e-7."""
    path = gen_dir / "fmu" / "sarib_input.fmu"
    fmu_export.export(MODELS / "sarib.yaml", path)
    module = compiled("sarib")
    results = run_fmpy([{"fmu": str(path), "t_end": 1.0, "rtol_me": RTOL_ME,
                         "rtol_cs": RTOL_CS, "input": {"excitation.pumping": 200.0}}])[0]
    p = module.PARAMS.copy()
    p[module.PARAM_NAMES.index("excitation__constant")] = 1.0
    p[module.PARAM_NAMES.index("excitation__pumping")] = 200.0
    results.pop("jacobian")
    check_runs(module, results, p, 1.0, agree={"ModelExchange": 2e-6}, skip=("g",))


@pytest.mark.slow
def test_loops_kept_closed(gen_dir, tmp_path):
    """zcp with --keep-loops: an index-2 DAE, Co-Simulation only (bgc's Radau takes its
    mass matrix), equal to bgc's run; a model whose closed loops are redundant (Bricard's
    linkage) is refused at export, as bgc simulate refuses it."""
    from bgc.errors import BgcError
    from bgc.pipeline import ensure_module
    path = gen_dir / "fmu" / "four_bar_zcp_closed.fmu"
    done = fmu_export.export(MODELS / "four_bar.yaml", path, "zcp", open_loops=False,
                             out_dir=tmp_path)
    assert done.interfaces == ["CoSimulation"] and done.notes
    module, _, _ = ensure_module(MODELS / "four_bar.yaml", tmp_path, "zcp", open_loops=False)
    results = run_fmpy([{"fmu": str(path), "t_end": 1.0, "rtol_me": RTOL_ME,
                         "rtol_cs": RTOL_CS}])[0]
    assert results["problems"] == [] and "ModelExchange" not in results
    check_runs(module, results, module.PARAMS.copy(), 1.0)
    with pytest.raises(BgcError, match="redundant constraints"):
        fmu_export.export(MODELS / "bricard.yaml", tmp_path / "b.fmu", "zcp",
                          open_loops=False, out_dir=tmp_path)
    assert not (tmp_path / "b.fmu").exists()
