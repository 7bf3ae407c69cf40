"""bgc report as its reader sees it: the tutorial's absorber under its chirp, the page
opened in headless chromium (Debian's, driven by playwright): no console error and no
request but the file itself; the 3D view drawn, moving while the run plays, changed by
choosing a mode; the numbers in the page against the run's CSV and bgc modes. The main
job's report (the SARIB): test_main_job_report (slow)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import TUTORIAL_MODEL, browser, open_page  # noqa: F401 (browser: a fixture)

from bgc.analysis.results import read_csv
from bgc.cli import main


def drawn(img: np.ndarray) -> float:
    """The share of pixels that are not background white."""
    return float(np.mean(np.any(img < 0.95, axis=-1)))


def changed(a: np.ndarray, b: np.ndarray) -> float:
    """The share of pixels that differ between two screenshots."""
    return float(np.mean(np.any(np.abs(a - b) > 0.02, axis=-1)))


def only_the_file(page, path) -> list[str]:
    """The requests that were neither the page itself nor data it holds."""
    return [u for u in page.requests if u != path.resolve().as_uri()
            and not u.startswith(("data:", "blob:"))]


@pytest.fixture(scope="module")
def tutorial_report(compiled, gen_dir, tmp_path_factory):
    """The tutorial's chirp run: its CSV (with the states) and its report, one run."""
    compiled(TUTORIAL_MODEL)
    d = tmp_path_factory.mktemp("report")
    r = CliRunner().invoke(main, ["simulate", str(TUTORIAL_MODEL), "--excitation", "chirp",
                                  "--direction", "rotor", "--out", str(d / "run.csv"),
                                  "--report", str(d / "run.html"), "-o", str(gen_dir),
                                  "--json", "-q"])
    assert r.exit_code == 0, r.output
    return d / "run.csv", d / "run.html", json.loads(r.output)


@pytest.fixture(scope="module")
def page(tutorial_report, browser):  # noqa: F811
    return open_page(browser, tutorial_report[1])


def test_the_page_works_offline_and_plays(tutorial_report, page):
    csv, html, rep = tutorial_report
    assert page.errors() == []
    assert only_the_file(page, html) == []
    p = page.page
    still = page.shot("#view3d")
    assert drawn(still) > 0.02                      # axes, bodies, joints: not blank
    # scrub into the chirp, then play at real time: the cabin and tuned mass move
    p.evaluate("s => { s.value = 3000; s.dispatchEvent(new Event('input')); }",
               p.locator("#scrub").element_handle())
    p.select_option("#speed", "1")
    before = page.shot("#view3d")
    t0 = p.evaluate("bgcView.state.simT")
    p.click("#play")
    p.wait_for_function("bgcView.state.draws > 8", timeout=30_000)
    p.click("#play")
    p.wait_for_function("!bgcView.state.busy")
    assert p.evaluate("bgcView.state.simT") > t0
    assert changed(before, page.shot("#view3d")) > 1e-4
    # a mode chosen in the table: its shape, away from the pose of the run
    run_pose = np.array(p.evaluate("bgcView.positions()"))
    p.locator("#modes-table tbody tr").nth(1).click()
    p.wait_for_function("bgcView.state.source === 'mode' && !bgcView.state.busy")
    assert p.input_value("#source") == "mode:1"
    assert changed(before, page.shot("#view3d")) > 1e-4
    assert np.abs(np.array(p.evaluate("bgcView.positions()")) - run_pose).max() > 1e-3
    assert page.errors() == [] and only_the_file(page, html) == []


def test_the_pages_numbers_are_the_runs(tutorial_report, page, gen_dir):
    """Every output time and value in the page is the CSV's (full precision: the page
    decimates only what it draws); the animation's frames are rows of the run, each
    body's centre where its pose states put it; the modes are bgc modes'; the envelope
    minima are classified as bgc simulate reports them."""
    csv, html, rep = tutorial_report
    names, data = read_csv(csv)
    col = {n: data[:, k] for k, n in enumerate(names)}
    p = page.page
    t = np.array(p.evaluate("bgcReport.t()"))
    assert t == pytest.approx(col["t"], rel=1e-11, abs=1e-12)
    for name in ("a_cabin", "x_tuned"):
        y = np.array(p.evaluate(f"bgcReport.output({name!r})"))
        assert y == pytest.approx(col[name], rel=1e-10, abs=1e-12 * np.abs(col[name]).max())
    D = p.evaluate("bgcReport.data")
    frames = np.array(p.evaluate("bgcReport.frames()"))
    stride = D["animation"]["stride"]
    assert frames == pytest.approx(col["t"][::stride], rel=1e-12, abs=1e-12)
    disp = np.array(p.evaluate("bgcReport.disp()"), dtype=float).reshape(len(frames), -1, 3)
    ref = np.array(D["mechanism"]["ref"]).reshape(-1, 3)
    for b in D["mechanism"]["bodies"]:
        g = ref[b["first"]] + disp[:, b["first"]]
        for c, axis in enumerate("xyz"):
            assert g[:, c] == pytest.approx(col[f"{b['name']}.{axis}"][::stride], abs=1e-6)
    r = CliRunner().invoke(main, ["modes", str(TUTORIAL_MODEL), "--json", "-q",
                                  "-o", str(gen_dir)])
    modes = json.loads(r.output)["modes"]
    page_modes = D["modes"]
    assert [m["frequency_hz"] for m in page_modes] == \
        pytest.approx([m["frequency_hz"] for m in modes[:len(page_modes)]], rel=1e-8)
    env = {e["name"]: e for e in D["envelopes"]}
    assert env["a_cabin"]["transients"] == pytest.approx(
        rep["envelope_transients_hz"]["a_cabin"], abs=0.006)
    assert env["a_cabin"]["transients"]
    assert env["a_cabin"]["frf_anti"] == pytest.approx(
        rep["frf_antiresonances_hz"]["a_cabin"], abs=0.006)
    rows = p.locator("#modes-table tbody tr")
    assert rows.count() == len(page_modes)
    assert rows.nth(0).locator("td").nth(1).inner_text() == f"{modes[0]['frequency_hz']:.4f}"


def test_the_chirp_ripples_are_not_anti_resonances(tutorial_report):
    """The tutorial's absorber (issue 44): its a_cabin envelope dips at 17.95 Hz, the
    FRF's anti-resonance (17.94), and again at 19.32 Hz after the resonance, where the
    FRF has none: the second is the sweep's transient, reported and drawn as such."""
    _, _, rep = tutorial_report
    mins = rep["envelope_minima_hz"]["a_cabin"]
    trans = rep["envelope_transients_hz"]["a_cabin"]
    assert 19.32 in mins and trans == [19.32]
    assert rep["frf_antiresonances_hz"]["a_cabin"] == [17.94]
    assert [f for f in mins if f not in trans][0] == pytest.approx(17.95, abs=0.02)
    assert rep["envelope_transients_hz"]["x_tuned"]     # 19.29: its ripple too


@pytest.mark.slow
def test_main_job_report(compiled, gen_dir, tmp_path, monkeypatch, browser):  # noqa: F811
    """make run's report: the SARIB's pumping chirp under zcp, under 20 MB, opened with no
    error and no request; its outputs are the CSV's, its 3D view drawn and moving, its
    modes the pumping one among them; the envelope's 17.53 Hz dip is the sweep's
    transient, its 18.04 Hz one the anti-resonance (the FRF's 18.06)."""
    compiled("sarib", "zcp")
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(main, ["simulate", "--excitation", "chirp", "-o", str(gen_dir),
                                  "--json", "-q"])
    assert r.exit_code == 0, r.output
    rep = json.loads(r.output)
    html = tmp_path / rep["files"]["report"]
    assert html.name == "sarib_pumping_chirp.html" and html.stat().st_size < 20e6
    assert rep["envelope_transients_hz"]["a_OF_z"] == [17.53]
    assert 18.04 in rep["envelope_minima_hz"]["a_OF_z"]
    page = open_page(browser, html)
    assert page.errors() == [] and only_the_file(page, html) == []
    p = page.page
    names, data = read_csv(tmp_path / rep["files"]["csv"])
    for k, name in enumerate(names[1:], 1):
        y = np.array(p.evaluate(f"bgcReport.output({name!r})"))
        assert y == pytest.approx(data[:, k], rel=1e-10, abs=1e-12 * np.abs(data[:, k]).max())
    still = page.shot("#view3d")
    assert drawn(still) > 0.02
    p.evaluate("bgcView.seek(16.5)")
    p.wait_for_function("!bgcView.state.busy")
    a = page.shot("#view3d")
    p.evaluate("bgcView.seek(16.52)")
    p.wait_for_function("!bgcView.state.busy")
    assert changed(a, page.shot("#view3d")) > 1e-4
    modes = p.evaluate("bgcReport.data.modes")
    assert any(abs(m["frequency_hz"] - 16.22) < 0.01 for m in modes)
