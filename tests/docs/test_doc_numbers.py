"""The numbers the README, docs/tutorial.md and docs/main-job.md state are what the commands
print (issue 38, item 8): each is read from the document as written (``stated``) and
compared, to the precision it is written with (``agrees``), with the output of the command
the document shows (``doc_run``: the run its example test makes, once per session), or,
for a figure the documents derive (an error between two runs, a formula), with that
derivation from the commands' output files. Numbers that are inputs (a model's values, an
option given) are checked against the model or the code, and measured timings are not
tested (the documents say where they were measured). A last test reads every number in
the three documents' prose and requires each to be one of these: a number added to a
document without a check fails it.

The absorber's checks are cheap and run in ``make test``; the SARIB's take minutes and are
marked slow."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from doc_examples import agrees, stated
from helpers import PAPER_PUMPING_VERTICAL, ROOT, within_paper

README, TUTORIAL, MAIN_JOB = "README.md", "docs/tutorial.md", "docs/main-job.md"
ABSORBER = "docs/tutorial/absorber.yaml"

# The commands whose output the checks read: as the documents show them (docs/cli.md's,
# docs/tutorial.md's and docs/main-job.md's examples run the same, so each runs once).
FRF = f"bgc frf {ABSORBER} --input rotor --output a_cabin"
FRF_TUNED = f"bgc frf {ABSORBER} --input rotor --output x_tuned"
MODES = f"bgc modes {ABSORBER} --json"
CHIRP = (f"bgc simulate {ABSORBER} --excitation chirp --direction rotor --out chirp.csv "
         "--plot chirp.png")
TUNE = (f"bgc tune {ABSORBER} --target-frequency 17.5 --tune m_t --input rotor "
        "--output a_cabin")
SWEEP = (f"bgc sweep {ABSORBER} -p m_t=0.4:0.9:26 --frf rotor:a_cabin --out sweep.csv "
         "--plot sweep.png")
DWELL = (f"bgc sweep {ABSORBER} -p m_t=0.58:0.68:11 --metric rms:a_cabin:15:20 "
         "--excitation sine --direction rotor --frequency 17.5")
ERROR = f"bgc frf {ABSORBER} --input rotor --output nope --json"
LOAD_SARIB = "bgc check --stage load models/sarib.yaml --json"
SARIB_TUNE = ("bgc tune models/sarib.yaml --target-frequency 17.5 --tune beater_mass "
              "--input pumping --output a_OF_z")
MAIN = "bgc simulate"
REFERENCE = "bgc simulate --method lagrange --rtol 1e-9 --atol 1e-9"
LAGRANGE = "bgc simulate --method lagrange"
RTOL_1E3 = "bgc simulate --rtol 1e-3 --atol 1e-3"
RTOL_1E5 = "bgc simulate --rtol 1e-5 --atol 1e-5"
PARASITIC = "bgc simulate --method parasitic --rtol 1e-6 --atol 1e-6"
PARASITIC_AUTO = "bgc simulate --method parasitic --parasitic auto --rtol 1e-6 --atol 1e-6"
EQUATIONS = "bgc check --stage equations models/sarib.yaml --method {}"

# Each number a check reads from a document: name -> (document, the pattern that finds it,
# its one group the number as written). The last test counts these as covered.
CLAIMS = {
    # the absorber (make test)
    "suspension resonance": (TUTORIAL, r"suspension resonance near (\d+) Hz"),
    "chirp minimum": (TUTORIAL, r"falls to its minimum at ([\d.]+) Hz"),
    "frf anti-resonance": (TUTORIAL, r"([\d.]+) Hz: `sqrt"),
    "chirp transient": (TUTORIAL, r"It dips again at ([\d.]+) Hz"),
    "displacement peak 1": (TUTORIAL, r"peaks at ([\d.]+) and [\d.]+ Hz\)"),
    "displacement peak 2": (TUTORIAL, r"peaks at [\d.]+ and ([\d.]+) Hz\)"),
    "suspension damping": (TUTORIAL, r"\((\d+) % damped by its"),
    "parasitic modes": (TUTORIAL, r"\(([\d.]+) Hz and up, kind `parasitic`"),
    "undamped formula": (TUTORIAL, r"`sqrt\(7700 / 0\.6\) / 2 pi` = ([\d.]+) Hz"),
    "formula mass": (TUTORIAL, r"`7700 / \(2 pi 17\.5\)\^2` = ([\d.]+) kg"),
    "formula sensitivity": (TUTORIAL, r"`dF/dm = -F / 2m` = (-[\d.]+) Hz/kg"),
    "dwell least": (TUTORIAL, r"nearest the tuned mass, ([\d.]+) kg"),
    "dwell heavier": (TUTORIAL, r"at ([\d.]+) kg, \d+ % heavier"),
    "dwell percent": (TUTORIAL, r"at [\d.]+ kg, (\d+) % heavier"),
    "exit status": (README, r"exit status (\d+)"),
    "README bodies": (README, r"(\d+) bodies, \d+ joints"),
    "README joints": (README, r"\d+ bodies, (\d+) joints"),
    "tutorial bodies": (TUTORIAL, r"(\d+) bodies, \d+ joints"),
    "tutorial joints": (TUTORIAL, r"\d+ bodies, (\d+) joints"),
    "main-job bodies": (MAIN_JOB, r"(\d+) bodies and \d+ joints"),
    "main-job joints": (MAIN_JOB, r"\d+ bodies and (\d+) joints"),
    # the SARIB (slow)
    "README anti-resonance": (README, r"anti-resonance shows \(([\d.]+) Hz"),
    "main-job anti-resonance": (MAIN_JOB, r"anti-resonance of `a_OF_z` at ([\d.]+) Hz"),
    "tutorial rotor": (TUTORIAL, r"near (\d+) Hz on the SARIB rig"),
    "README error": (README, r"within ([\d.e-]+) of an ideal-joint reference"),
    "README steps": (README, r"reference in (\d+) steps"),
    "README parasitic error": (README, r"compliance alone is ([\d.e-]+) off"),
    "main-job zcp states": (MAIN_JOB, r"`--method zcp`, (\d+) states"),
    "error": (MAIN_JOB, r"within ([\d.e-]+) of ideal-joint behaviour"),
    "reference steps": (MAIN_JOB, r"rtol 1e-9, (\d+) steps"),
    "steps": (MAIN_JOB, r"The main job takes (\d+) steps"),
    "rhs calls": (MAIN_JOB, r"steps and (\d+) rhs calls"),
    "parasitic error": (MAIN_JOB, r"joints the outputs are ([\d.e-]+) off"),
    "auto error": (MAIN_JOB, r"brings that to ([\d.e-]+),"),
    "auto work": (MAIN_JOB, r"for (\d+) times the main job's rhs calls"),
    "lagrange error": (MAIN_JOB, r"Both are within ([\d.e-]+) of the reference"),
    "lagrange steps": (MAIN_JOB, r"same (\d+) steps, and take"),
    "zcp states": (MAIN_JOB, r"smaller system: (\d+) states"),
    "lagrange states": (MAIN_JOB, r"against lagrange's (\d+)"),
    "rtol 1e-3 steps": (MAIN_JOB, r"takes the same (\d+) steps and"),
    "rtol 1e-3 error": (MAIN_JOB, r"as close, within ([\d.e-]+)\."),
    "rtol 1e-5 steps": (MAIN_JOB, r"rtol 1e-5 takes (\d+) steps"),
    "rtol 1e-5 error": (MAIN_JOB, r"for an error of ([\d.e-]+) that"),
    "constraint block": (MAIN_JOB, r"constraint block, (\d+) unknowns"),
    "rhs a step": (MAIN_JOB, r"about ([\d.]+) rhs calls a step"),
    "parasitic tune": (TUTORIAL, r"puts it ([\d.e-]+) kg lower"),
}

# Numbers that are inputs (a model's values, options given, the settings of the main job),
# checked against the model or the code by test_the_inputs_the_documents_state; or, in
# main-job.md, measured timings (not tested: the page says where they were measured).
INPUTS = {
    README: {"5", "25", "1e-4", "2.0"},
    TUTORIAL: {"0", "3", "5", "25", "40", "11", "4", "17.5", "15", "20", "30", "2", "200",
               "0.3", "90"},
    MAIN_JOB: {"200", "5", "25", "28", "1e-4", "17.8", "18.2", "1e-9", "3e7", "1e-6", "1",
               "8", "0.005", "1e-3", "1e-5"},
}
MEASURED = {MAIN_JOB: {"2", "8", "9", "3.0", "3.4", "3.1", "3.6"}}
NUMBER = re.compile(r"(?<![\w])(?<!\d\.)-?\d+(?:\.\d+)?(?:e[-+]?\d+)?(?!\w)(?!\.\d)")


def claim(name: str) -> str:
    doc, pattern = CLAIMS[name]
    return stated(doc, pattern)


def check(name: str, value: float) -> None:
    written = claim(name)
    assert agrees(value, written), f"{CLAIMS[name][0]} says {written} ({name}); the " \
                                   f"command gives {value:.6g}"


def output_line(ran, pattern: str) -> tuple[str, ...]:
    """The groups of the one stdout line that matches ``pattern``."""
    found = [m.groups() for m in map(re.compile(pattern).match, ran.stdout.splitlines())
             if m]
    assert len(found) == 1, (pattern, ran.stdout)
    return found[0]


# -- the absorber (make test) ---------------------------------------------------------

def test_the_tutorials_frequency_response(doc_run):
    ran = doc_run(FRF)
    anti = [float(f) for f in output_line(ran, r"\s+anti-resonances: (.*) Hz")[0].split(",")]
    res = [float(f) for f in output_line(ran, r"\s+resonances: ([\d., ]+) Hz")[0].split(",")]
    check("frf anti-resonance", anti[0])
    check("suspension resonance", res[0])
    ran = doc_run(FRF_TUNED)
    peaks = output_line(ran, r"\s+resonances: ([\d., ]+) Hz \(.*, at ([\d., ]+) Hz\)")
    assert peaks[0] == output_line(doc_run(FRF), r"\s+resonances: ([\d., ]+) Hz")[0]
    for i, f in enumerate(peaks[1].split(","), 1):     # the same modes, other peaks
        check(f"displacement peak {i}", float(f))
    from bgc.model.load import load
    p = load(ROOT / ABSORBER).parameters
    undamped = math.sqrt(p["k_t"].value / p["m_t"].value) / (2 * math.pi)
    check("undamped formula", undamped)
    assert anti[0] < undamped                   # "lowered by the absorber's damper"


def test_the_tutorials_chirp(doc_run):
    ran = doc_run(CHIRP)
    minima = output_line(ran, r"\s+envelope minima of a_cabin over the chirp: (.*) Hz")[0]
    check("chirp minimum", float(minima.split(",")[0]))
    transient = output_line(ran, r"\s+envelope minima of a_cabin .*; ([\d.]+) the sweep's "
                                 r"transient$")[0]
    check("chirp transient", float(transient))
    assert (ran.cwd / "chirp_envelope.png").stat().st_size > 10_000


def two_mass_modes() -> list[tuple[float, float]]:
    """(natural frequency [Hz], damping ratio) of the absorber as the two-mass M, C, K
    system the tutorial says its modes are, from the model file's values."""
    import yaml
    model = yaml.safe_load((ROOT / ABSORBER).read_text())
    m1, m2 = model["bodies"]["cabin"]["mass"], model["parameters"]["m_t"]["value"]
    k1, c1 = (model["instances"]["mount"]["parameters"][k] for k in ("k", "c"))
    k2, c2 = model["parameters"]["k_t"]["value"], model["instances"]["absorber"]["parameters"]["c"]
    M = np.diag([m1, m2])
    K = np.array([[k1 + k2, -k2], [-k2, k2]])
    C = np.array([[c1 + c2, -c2], [-c2, c2]])
    A = np.block([[np.zeros((2, 2)), np.eye(2)],
                  [-np.linalg.solve(M, K), -np.linalg.solve(M, C)]])
    return sorted((abs(z) / (2 * np.pi), -z.real / abs(z)) for z in np.linalg.eigvals(A)
                  if z.imag > 0)


def test_the_tutorials_modes(doc_run):
    """The absorber's two functional modes are the M, C, K system's to the digits --json
    prints, the suspension's damping and where the parasitic joints' own modes start."""
    modes = doc_run(MODES).json()["modes"]
    functional = [m for m in modes if m["kind"] == "functional"]
    for m, (f, zeta) in zip(functional, two_mass_modes(), strict=True):
        assert m["frequency_hz"] == float(f"{f:.9g}") and \
            m["damping_ratio"] == float(f"{zeta:.9g}"), (m, f, zeta)
    check("suspension damping", 100 * functional[0]["damping_ratio"])
    check("parasitic modes", min(m["frequency_hz"] for m in modes
                                 if m["kind"] == "parasitic"))
    assert {m["kind"] for m in modes} == {"functional", "parasitic"}


def test_the_tutorials_tuning_against_its_formula(doc_run):
    ran = doc_run(TUNE)
    value = float(output_line(ran, r"absorber: m_t = ([\d.]+) kg puts")[0])
    mass = 7700 / (2 * math.pi * 17.5) ** 2
    check("formula mass", mass)
    check("formula sensitivity", -17.5 / (2 * mass))
    assert value < mass            # "the damper lowers the anti-resonance a little"


def test_the_tutorials_dwell_sweep(doc_run):
    rows = {float(m): float(v) for m, v in re.findall(
        r"^\s+m_t=([\d.]+): rms:a_cabin:15:20 ([\d.]+)$", doc_run(DWELL).stdout, re.M)}
    assert len(rows) == 11
    tuned = float(output_line(doc_run(TUNE), r"absorber: m_t = ([\d.]+) kg puts")[0])
    least = min(rows, key=rows.get)
    check("dwell least", least)
    assert least == min(rows, key=lambda m: abs(m - tuned))    # the point nearest tuned
    heavier = float(claim("dwell heavier"))
    check("dwell percent", 100 * (heavier / tuned - 1))
    assert rows[heavier] > 2 * rows[least]                     # "more than doubled"


def test_the_tutorials_sweep_has_no_failed_point(doc_run):
    ran = doc_run(SWEEP)
    assert "bgc: sweep: 26 points on 2 workers, 0 with an error" in ran.stderr
    assert "26 points on 2 workers, 0 with an error" in (ROOT / TUTORIAL).read_text()


def test_a_mistake_exits_with_status_2(doc_run):
    check("exit status", doc_run(ERROR).exit_code)


def test_the_sarib_counts(doc_run):
    counts = doc_run(LOAD_SARIB).json()["counts"]
    for doc in ("README", "tutorial", "main-job"):
        check(f"{doc} bodies", counts["bodies"])
        check(f"{doc} joints", counts["joints"])


def test_the_inputs_the_documents_state():
    """The main job's chirp, amplitude, duration, tolerances and zoom, the limit of the
    step and parasitic auto's accuracy, as the documents give them, are the model's and
    the code's."""
    from bgc.cli.simulate import MAIN_JOB as JOB
    from bgc.cli.simulate import MAIN_ZOOM
    from bgc.methods.parasitic import ACCURACY
    from bgc.model.limits import STEPS_PER_PERIOD
    from bgc.model.load import load
    sarib = load(ROOT / "models" / "sarib.yaml")
    chirp = sarib.excitation.kinds["chirp"].numbers
    main_job = re.sub(r"\s+", " ", (ROOT / MAIN_JOB).read_text())
    readme = re.sub(r"\s+", " ", (ROOT / README).read_text())
    g = f"{chirp['f_start']:g} to {chirp['f_end']:g} Hz over {chirp['t2']:g}..{chirp['t3']:g} s"
    assert f"a force of {sarib.excitation.directions['pumping'][1]:g} N" in main_job
    assert f"sweeps from {g}, {sarib.settings.t_end:g} s in all" in main_job
    assert f"pumping chirp from {chirp['f_start']:g} to {chirp['f_end']:g} Hz" in readme
    rtol = f"{JOB['rtol']:.0e}".replace("e-0", "e-")
    assert JOB["rtol"] == JOB["atol"] and JOB["method"] == "zcp"
    assert f"native Radau at rtol = atol = {rtol}" in main_job
    assert f"(ideal joints under `zcp`, rtol {rtol})" in readme
    assert f"{MAIN_ZOOM[0]:g}..{MAIN_ZOOM[1]:g} s" in main_job
    assert f"with the model's {_k(sarib):.0e} N/m joints".replace("e+0", "e") in main_job
    assert f"moves by more than {ACCURACY:.0e}".replace("e-0", "e-") in main_job
    assert f"{STEPS_PER_PERIOD} steps a period of the fastest input" in main_job
    assert f"({chirp['f_end']:g} Hz: {1 / (STEPS_PER_PERIOD * chirp['f_end']):g} s)" in main_job
    absorber = load(ROOT / ABSORBER)
    c = absorber.excitation.kinds["chirp"].numbers
    tutorial = re.sub(r"\s+", " ", (ROOT / TUTORIAL).read_text())
    assert (f"from {c['f_start']:g} to {c['f_end']:g} Hz in {c['t3'] - c['t2']:g} s"
            in tutorial)
    import yaml
    damper = yaml.safe_load((ROOT / ABSORBER).read_text())["instances"]["mount"]["parameters"]
    assert f"damped by its {damper['c']:g} N s/m" in tutorial
    model = yaml.safe_load((ROOT / ABSORBER).read_text())
    assert f"its frame {model['instances']['absorber']['origin'][2]:g} m above it" in tutorial
    legs = yaml.safe_load((ROOT / "models" / "sarib.yaml").read_text())["instances"]
    assert "instanced at 90 degree steps" in tutorial and any(
        "90 * (i - 1)" in str(v) or "90*(i-1)" in str(v).replace(" ", "")
        for v in legs.values()), legs
    from bgc.export.fmu import FMI_VERSIONS
    assert FMI_VERSIONS == (2,) and "an FMU (FMI 2.0, " in readme


def _k(model) -> float:
    """The SARIB joints' translational stiffness, the same for every joint."""
    ks = {p.value for n, p in model.parameters.items() if n.endswith("__stiffness")}
    assert len(ks) == 1, ks
    return ks.pop()


def prose_numbers(doc: str) -> list[str]:
    """The numbers of a document's prose: code blocks and spans, headings and link
    targets left out."""
    text = (ROOT / doc).read_text()
    text = re.sub(r"^```.*?^```", "", text, flags=re.S | re.M)
    text = re.sub(r"`[^`]*`", "", text)
    text = re.sub(r"^#.*$", "", text, flags=re.M)
    text = re.sub(r"\]\([^)]*\)", "]", text)
    return NUMBER.findall(text)


@pytest.mark.parametrize("doc", [README, TUTORIAL, MAIN_JOB])
def test_every_number_of_the_prose_is_checked(doc):
    covered = {claim(n) for n, (d, _) in CLAIMS.items() if d == doc}
    known = covered | INPUTS[doc] | MEASURED.get(doc, set())
    unchecked = sorted(set(prose_numbers(doc)) - known)
    assert not unchecked, f"{doc}: numbers no test checks: {unchecked}"


# -- the SARIB (slow) -----------------------------------------------------------------

RUN_LINE = r"sarib: native to t = ([\d.]+) s: (\d+) steps, (\d+) rhs"


def run_stats(ran) -> tuple[int, int]:
    """Steps and rhs calls of a SARIB run, as its line says."""
    t_end, steps, rhs = output_line(ran, RUN_LINE)
    assert float(t_end) == 28.0
    return int(steps), int(rhs)


def outputs(ran) -> dict[str, np.ndarray]:
    """The CSV a main-job run wrote (t and the outputs)."""
    path = ran.cwd / "results" / "sarib_pumping_chirp.csv"
    data = np.genfromtxt(path, delimiter=",", names=True)
    return {n: data[n] for n in data.dtype.names}


def error(ran, reference, noise) -> float:
    """main-job.md's error: over 5..28 s, the largest deviation of each output from the
    reference relative to that output's peak, the largest over the outputs that are not
    numerical noise."""
    y, ref = outputs(ran), outputs(reference)
    assert np.array_equal(y["t"], ref["t"])
    window = ref["t"] >= 5.0
    return max(np.abs(y[n] - ref[n])[window].max() / np.abs(ref[n][window]).max()
               for n in ref if n != "t" and n not in noise)


@pytest.mark.slow
def test_the_main_jobs_figures(doc_run):
    main, reference = doc_run(MAIN), doc_run(REFERENCE)
    noise = set(re.findall(r"^\s+(\w+): numerical noise", main.stdout, re.M))
    assert noise == {"F_A1_y", "F_A2_y"}
    minima = output_line(main, r"\s+envelope minima of a_OF_z over the chirp: (.*) Hz")[0]
    for name in ("README anti-resonance", "main-job anti-resonance", "tutorial rotor"):
        check(name, float(minima.split(",")[0]))
    # and the paper's, on its pumping chirp (Fig. 11.27a): "observed at 18 Hz"
    assert within_paper(float(minima.split(",")[0]), PAPER_PUMPING_VERTICAL), minima
    steps, rhs = run_stats(main)
    for name in ("steps", "README steps", "lagrange steps", "rtol 1e-3 steps"):
        check(name, steps)
    check("rhs calls", rhs)
    check("rhs a step", rhs / steps)
    check("reference steps", run_stats(reference)[0])
    for name in ("error", "README error"):
        check(name, error(main, reference, noise))
    lagrange = doc_run(LAGRANGE)
    assert run_stats(lagrange)[0] == steps
    check("lagrange error", error(lagrange, reference, noise))
    loose, tight = doc_run(RTOL_1E3), doc_run(RTOL_1E5)
    check("rtol 1e-3 steps", run_stats(loose)[0])
    check("rtol 1e-3 error", error(loose, reference, noise))
    check("rtol 1e-5 steps", run_stats(tight)[0])
    check("rtol 1e-5 error", error(tight, reference, noise))
    parasitic, auto = doc_run(PARASITIC), doc_run(PARASITIC_AUTO)
    for name in ("parasitic error", "README parasitic error"):
        check(name, error(parasitic, reference, noise))
    check("auto error", error(auto, reference, noise))
    check("auto work", run_stats(auto)[1] / rhs)


@pytest.mark.slow
def test_the_main_jobs_systems(doc_run):
    zcp, lagrange = doc_run(EQUATIONS.format("zcp")), doc_run(EQUATIONS.format("lagrange"))
    states = int(output_line(zcp, r"sarib \(zcp\): (\d+) states")[0])
    for name in ("zcp states", "main-job zcp states"):
        check(name, states)
    check("lagrange states", int(output_line(lagrange, r"sarib \(lagrange\): (\d+) states")[0]))
    blocks = [int(n) for n in re.findall(r"^\s+linear block \d+: (\d+) unknowns", zcp.stdout,
                                         re.M)]
    check("constraint block", max(blocks))


@pytest.mark.slow
@pytest.mark.parametrize("method", ["lagrange", "zcp"])
def test_the_tutorials_modes_under_ideal_joints(doc_run, method):
    """'to the digits --json prints, under every method': the ideal joints' too (slow:
    two more modules of the absorber)."""
    modes = doc_run(f"{MODES} --method {method}").json()["modes"]
    assert len(modes) == 2
    for m, (f, zeta) in zip(modes, two_mass_modes(), strict=True):
        assert m["frequency_hz"] == float(f"{f:.9g}") and \
            m["damping_ratio"] == float(f"{zeta:.9g}"), (method, m, f, zeta)


@pytest.mark.slow
def test_the_sarib_tuning_under_parasitic_joints(doc_run):
    """The tutorial's tune of the ideal-joint model, and the parasitic model's value
    below it."""
    pattern = r"sarib: beater_mass = ([\d.]+) kg puts"
    ideal = float(output_line(doc_run(SARIB_TUNE + " --method lagrange"), pattern)[0])
    parasitic = float(output_line(doc_run(SARIB_TUNE), pattern)[0])
    check("parasitic tune", ideal - parasitic)
