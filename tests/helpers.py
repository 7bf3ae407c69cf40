"""Helpers shared by test files in several folders: paths, the shipped models as pytest
parameters, LLVM IR JIT-compiled, error measures, the parsed form of bgc's error line, a
forked ``bgc`` run, and the few model-specific references more than one stage's tests
check against. Test files import these from here, never from each other (pytest imports
each folder's files by bare name, so a test file is not importable from another folder)."""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path

import forked_cli
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models"
# the tutorial's model: a cabin on its suspension and a tuned mass (Den Hartog's absorber)
TUTORIAL_MODEL = ROOT / "docs" / "tutorial" / "absorber.yaml"
# models whose numba compilation and runs take minutes: their tests are marked slow (the
# one-leg SARIB is checked against the rig in test_sarib and in bench's symmetry part at
# CI scale; the A02 N-four-bar's 20 s through its singular positions)
SLOW_MODELS = {"sarib", "sarib_one_leg", "sarib_semiactive", "n_four_bar"}
# the integrator of a test that checks a model against a closed form or an invariant:
# bgc's native Radau in make test, scipy's Radau (the independent implementation, tens of
# times the CPU on parasitic joints' stiffness) in make test-all as well
REFERENCE_SOLVERS = ["native", pytest.param("radau", marks=pytest.mark.slow)]


# the shipped models whose parasitic module make test compiles in any case (the session's,
# ``compiled``: test_codegen's Jacobian checks, the SARIB's main job, its one leg's sweep)
SESSION_MODELS = {"dc_motor", "double_pendulum", "duffing", "four_bar", "geared_inertias",
                  "isosceles_slider_crank", "msd_forced", "msd_free", "pendulum", "rc_table",
                  "rectifier", "rlc", "rr_loop", "sarib", "sarib_one_leg", "servo",
                  "slider_crank", "tumbling_box"}


def rendered(compiled, name: str) -> bytes:
    """What ``bgc compile models/<name>.yaml`` writes now (parasitic), as bytes: the
    session's module where make test compiles it in any case (``emit.write`` wrote it,
    this run, from the very render), else rendered here."""
    if name in SESSION_MODELS:
        return Path(compiled(name).__file__).read_bytes()
    from bgc.codegen import emit
    from bgc.pipeline import build
    return emit.render(build(MODELS / f"{name}.yaml").system).encode()


def model_params(names=None):
    """pytest parameters for the shipped models (all by default), slow ones marked."""
    names = names or sorted(p.stem for p in MODELS.glob("*.yaml"))
    return [pytest.param(n, marks=pytest.mark.slow) if n in SLOW_MODELS else n for n in names]


def jit(ir: str):
    """An execution engine holding ``ir`` (parsed and verified by LLVM), compiled for this
    machine: ``engine.get_function_address(name)`` for ctypes. Keep it alive while its
    functions are called."""
    import llvmlite.binding as llvm
    llvm.initialize_native_target()
    llvm.initialize_native_asmprinter()
    module = llvm.parse_assembly(ir)
    module.verify()
    machine = llvm.Target.from_default_triple().create_target_machine()
    engine = llvm.create_mcjit_compiler(module, machine)
    engine.finalize_object()
    return engine


# ------------------------------------------------------------------ measures of error
def rel_err(actual, expected) -> float:
    """Largest deviation relative to the largest magnitude of the expected trajectory."""
    actual, expected = np.asarray(actual), np.asarray(expected)
    return float(np.max(np.abs(actual - expected)) / np.max(np.abs(expected)))


def fd_jacobian(mod, t, x, p):
    """Central differences of a generated module's rhs, to check its analytic jac."""
    fd = np.empty((len(x), len(x)))
    for j in range(len(x)):
        h = 1e-6 * max(abs(x[j]), 1e-2)
        xp, xm = x.copy(), x.copy()
        xp[j] += h
        xm[j] -= h
        fd[:, j] = (mod.rhs(t, xp, p) - mod.rhs(t, xm, p)) / (2 * h)
    return fd


def dwell_amplitude(t, y, f, periods: int = 10) -> float:
    """Amplitude of the component at ``f`` over the last ``periods`` periods (least
    squares on sine, cosine and offset)."""
    sel = t >= t[-1] - periods / f
    tt = t[sel]
    M = np.column_stack([np.sin(2 * np.pi * f * tt), np.cos(2 * np.pi * f * tt),
                         np.ones_like(tt)])
    c = np.linalg.lstsq(M, y[sel], rcond=None)[0]
    return float(np.hypot(c[0], c[1]))


def resolved_rates(system) -> dict:
    """State name -> its rate as one expression in states and parameters: an
    EquationSystem's assignments substituted, after checking that each reads only what is
    defined before it (causal order) and none is a numeric block."""
    from bgc.codegen.equations import LinearBlock
    known = {st.sym for st in system.states} | {sym for sym, _, _ in system.params}
    defs = {}
    for item in system.assignments:
        assert not isinstance(item, LinearBlock), "a loop left to a numeric block"
        var, expr = item
        assert var not in defs and expr.free_symbols <= known | set(defs), var
        defs[var] = expr
    out = {}
    for st in system.states:
        e = defs[st.dsym]
        while e.free_symbols & set(defs):
            e = e.xreplace(defs)
        out[st.name] = e
    return out


# ----------------------------------------------------------------- what bgc answers
ERROR_LINE = re.compile(
    r"^error: (?P<file>.+?):(?P<line>\d+):(?P<col>\d+): (?P<key>[^\s:]+): (?P<msg>.+) "
    r"\(hint: (?P<hint>.+)\)$")


def error_lines(stderr: str) -> list[str]:
    """stderr's lines without bgc's progress lines (``bgc: STAGE: ... (TIME)``, one per
    finished stage when stderr is not a terminal): what a failing run says."""
    from bgc.progress import PREFIX
    return [ln for ln in stderr.splitlines() if not ln.startswith(PREFIX)]


def one_line_error(proc) -> re.Match:
    """What a refused input gets from the CLI (``proc``: a finished ``bgc`` run): exit
    status 2, no traceback, one or two lines on stderr besides progress lines, the first in
    bgc's form ``error: FILE:LINE:COL: KEY: message (hint: ...)`` with a hint. Returns
    that line's parts (``ERROR_LINE``'s groups)."""
    detail = f"\nstdout: {proc.stdout[-2000:]!r}\nstderr: {proc.stderr[-2000:]!r}"
    assert "Traceback" not in proc.stderr + proc.stdout, detail
    assert proc.returncode == 2, f"exit {proc.returncode}" + detail
    lines = error_lines(proc.stderr)
    assert 1 <= len(lines) <= 2, detail
    m = ERROR_LINE.match(lines[0])
    assert m, "not bgc's error form" + detail
    assert m["hint"].strip(), detail
    return m


def snapshot(root: Path) -> dict:
    """Every file under ``root`` with its bytes and mode (directories by name)."""
    return {str(p.relative_to(root)): (p.read_bytes(), stat.S_IMODE(p.stat().st_mode))
            if p.is_file() else "dir" for p in sorted(root.rglob("*"))}


def bgc(*args, cwd: Path, umask: int = -1, timeout: float = 10):
    """``bgc ARGS`` in its own process (forked from a server that has imported bgc:
    ``forked_cli``)."""
    return forked_cli.run(*args, cwd=cwd, umask=umask, timeout=timeout,
                          env=dict(os.environ, PYTHONPATH=str(ROOT)))


# ------------------------------------------------------------------- small models
def body_model(tmp_path, name, body, extra=""):
    """The generated module of a model holding one free body ``box`` (``body``: its YAML
    flow mapping; ``extra``: YAML lines before ``bodies:``), compiled under tmp_path."""
    from bgc.codegen.emit import import_module
    from bgc.pipeline import compile_model
    f = tmp_path / f"{name}.yaml"
    f.write_text(f"name: {name}\n{extra}bodies:\n  box: {body}\n")
    _, path = compile_model(f, tmp_path / "gen")
    return import_module(path)


# the smallest model with a body and a joint: a rod hung on a revolute joint (axis y, the
# rod's own y axis) from the fixed frame
HINGE = """\
name: hinge
gravity: 9.81
bodies:
  rod: {mass: 2.0, com: [0, 0, -0.5], inertia: [0.2, 0.2, 0.01]}
joints:
  hinge: {type: revolute, between: [fixed_frame, rod], at: [0, 0, 0], axis: [0, 1, 0]}
"""


# -------------------------------------------------- the benchmark mechanisms' references
T_SINGULAR = 0.1575     # the isosceles slider-crank's crank reaches 90 deg (slider at x = 0)

# Andrews' squeezing mechanism at t = 0.03: the IVP test set's reference (PSIDE, tol 1e-14)
ANDREWS_REF = {"beta": 15.81077119629904, "Theta": -15.75637105984298,
               "gamma": 0.04082224013073101, "Phi": -0.5347301163226948,
               "delta": 0.5244099658805304, "Omega": 0.5347301163226948,
               "epsilon": 1.048080741042263}


def stiffer(mod, factor):
    """Parameters with every parasitic stiffness x factor and damping x sqrt(factor)."""
    p = mod.PARAMS.copy()
    for i, name in enumerate(mod.PARAM_NAMES):
        if name.endswith(("__stiffness", "__rot_stiffness")):
            p[i] *= factor
        elif name.endswith(("__damping", "__rot_damping")):
            p[i] *= np.sqrt(factor)
    return p


def slider_closure(r):
    """|x_slider - (r cos th + sqrt(l^2 - r^2 sin^2 th))| with th read off the crank pin."""
    rc, rl = 0.1, 0.3
    th = np.arctan2(r.column("A_z"), r.column("A_x"))
    x = rc * np.cos(th) + np.sqrt(rl ** 2 - (rc * np.sin(th)) ** 2)
    return np.abs(r.column("slider_x") - x).max(), th


# ------------------------------------------------------------ the paper's SARIB figures
# Anti-resonances the paper reports for its rig (section 11.5.2) [Hz], each with the
# accuracy its text states it to: half a unit of the last digit given. The rig's numbers
# are not published; models/sarib.yaml holds the project's data set (tests/system/
# test_sarib.py says where bgc meets these on it, and why not where it does not).
PAPER_PUMPING_VERTICAL = (18.0, 0.5)   # a_OF_z, Fig. 11.27: "observed at 18 Hz"; F_A1_z,
                                       # Fig. 11.28: "an anti-resonance at about 18 Hz"
PAPER_PUMPING_X = (16.8, 0.05)         # F_A1_x, Fig. 11.29: "around 16.8 Hz"


def within_paper(value: float, figure: tuple[float, float]) -> bool:
    """``value`` within the paper's ``figure`` (value, stated accuracy)."""
    return abs(value - figure[0]) <= figure[1]


# ------------------------------------------------------------------ a real browser
CHROMIUM = "/usr/bin/chromium"      # Debian's, installed by .ci/run
# headless without a GPU: WebGL (plotly's 3D and scattergl) through SwiftShader, which
# chromium no longer falls back to unless told; no network, no profile of the user's
CHROMIUM_FLAGS = ["--headless=new", "--no-sandbox", "--disable-gpu", "--disable-quic",
                  "--no-first-run", "--disable-background-networking",
                  "--disable-component-update", "--disable-sync",
                  "--enable-unsafe-swiftshader", "--use-angle=swiftshader"]


class Page:
    """A page opened in headless chromium (playwright, driving Debian's chromium, never a
    browser of its own): what it logged and every request it made, kept from the start."""

    def __init__(self, page):
        self.page = page
        self.console: list[tuple[str, str]] = []
        self.requests: list[str] = []
        page.on("console", lambda m: self.console.append((m.type, m.text)))
        page.on("pageerror", lambda e: self.console.append(("pageerror", str(e))))
        page.on("request", lambda r: self.requests.append(r.url))

    def errors(self) -> list[str]:
        return [f"{k}: {t}" for k, t in self.console if k in ("error", "pageerror")]

    def shot(self, selector: str) -> np.ndarray:
        """The element's screenshot as an RGB array."""
        import io

        import matplotlib.image as mpimg
        png = self.page.locator(selector).screenshot()
        return mpimg.imread(io.BytesIO(png), format="png")[..., :3]


def open_page(browser, path, width: int = 1400, height: int = 1000) -> Page:
    """``path`` (a local HTML file) opened in a fresh context of ``browser``, waited for
    until the page says it is drawn (``body[data-ready]``)."""
    ctx = browser.new_context(viewport={"width": width, "height": height})
    page = Page(ctx.new_page())
    page.page.goto(Path(path).resolve().as_uri())
    page.page.wait_for_selector("body[data-ready='1']", timeout=120_000)
    return page


@pytest.fixture(scope="module")
def browser():
    """Headless chromium for a test module (playwright gives it a fresh profile); a
    missing chromium fails, naming the fix."""
    if not os.path.exists(CHROMIUM):
        pytest.fail(f"{CHROMIUM} is missing: apt-get install -y chromium (.ci/run does)")
    from playwright.sync_api import sync_playwright
    with sync_playwright() as pw:
        chromium = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_FLAGS)
        yield chromium
        chromium.close()
