"""A run's energy as pictures (issue 42, item 2): ``bgc draw --energy RUN.json`` draws
each element's bond as wide as its activity share, ``bgc energy --sankey`` the mean
power from what fed the run to where it went. Both read back from their SVG."""

from __future__ import annotations

import json
import re
import xml.etree.ElementTree as ET

import pytest
from click.testing import CliRunner
from helpers import MODELS

from bgc.cli import main

SVG = "{http://www.w3.org/2000/svg}"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


@pytest.fixture(scope="module")
def rlc_run(gen_dir, tmp_path_factory):
    out = tmp_path_factory.mktemp("energy") / "rlc.json"
    r = run("energy", MODELS / "rlc.yaml", "-o", gen_dir, "--out", out, "--rtol", "1e-6",
            "-q")
    assert r.exit_code == 0, r.output
    return out, json.loads(out.read_text())


def widths(path) -> dict[str, float]:
    """bond name -> the width of its activity underlay (``activity-BOND`` groups)."""
    out = {}
    for g in ET.parse(path).getroot().iter(f"{SVG}g"):
        kind, _, name = (g.get("id") or "").partition("-")
        if kind == "activity":
            style = g.find(f"{SVG}path").get("style")
            out[name] = float(re.search(r"stroke-width: ?([\d.]+)", style).group(1))
    return out


def test_bonds_are_as_wide_as_their_elements_activity(rlc_run, tmp_path):
    path, data = rlc_run
    svg = tmp_path / "rlc.svg"
    r = run("draw", MODELS / "rlc.yaml", "--out", svg, "--energy", path, "-q")
    assert r.exit_code == 0, r.output
    w = widths(svg)
    share = {e["name"]: e["share"] for e in data["elements"]}
    bond = {"source": "b1", "resistor": "b2", "inductor": "b3", "capacitor": "b4"}
    assert set(w) == set(bond.values())
    order = sorted(share, key=share.get)
    assert [w[bond[n]] for n in order] == sorted(w.values())
    assert w[bond[order[0]]] < w[bond[order[-1]]]
    assert "activity share" in svg.read_text()


def test_a_run_of_another_model_is_refused(rlc_run, tmp_path):
    path, _ = rlc_run
    r = run("draw", MODELS / "msd_free.yaml", "--out", tmp_path / "x.svg", "--energy",
            path, "-q")
    assert r.exit_code == 2
    [line] = r.output.strip().splitlines()
    assert line.startswith("error: --energy: ") and "none of its 4 elements" in line, line
    assert not (tmp_path / "x.svg").exists()


@pytest.mark.parametrize("text", ["{", '{"elements": [{"name": "x"}]}', "[]",
                                  '{"elements": [{"name": "x", "share": 2}]}'])
def test_a_file_that_is_not_a_run_is_one_line(tmp_path, text):
    (tmp_path / "bad.json").write_text(text)
    r = run("draw", MODELS / "rlc.yaml", "--out", tmp_path / "x.svg", "--energy",
            tmp_path / "bad.json", "-q")
    assert r.exit_code == 2
    [line] = r.output.strip().splitlines()
    assert line.startswith("error: --energy: "), line


def test_sankey_from_what_fed_the_run_to_where_it_went(gen_dir, tmp_path):
    """The forced mass-spring-damper msd_forced over its steady state: the drive feeds
    the damper (and what the storage holds more at the end), both sides labelled in W."""
    svg = tmp_path / "s.svg"
    r = run("energy", MODELS / "msd_forced.yaml", "-o", gen_dir, "--sankey", svg,
            "--t-end", "8", "--since", "6", "--rtol", "1e-7", "--json", "-q")
    assert r.exit_code == 0, r.output
    data = json.loads(r.output)
    text = svg.read_text()
    assert "drive (supplied)" in text and "damper (dissipated)" in text
    assert "fed by" in text and "went to" in text
    els = {e["name"]: e for e in data["elements"]}
    # mean steady-state power of a forced m-c-k: 1/2 c w^2 |X|^2 = 1/2 F0^2 c w^2 /
    # ((k - m w^2)^2 + (c w)^2), supplied = dissipated over whole periods (2 s = 6 of 3 Hz;
    # the transient decays as e^(-c t / 2m), e^(-12) by 6 s)
    import math
    m, k, c, F0, w = 1.5, 600.0, 6.0, 10.0, 2 * math.pi * 3.0
    mean = 0.5 * F0 ** 2 * c * w ** 2 / ((k - m * w ** 2) ** 2 + (c * w) ** 2)
    assert els["damper"]["dissipated"] / 2.0 == pytest.approx(mean, rel=1e-3)
    assert els["drive"]["supplied"] / 2.0 == pytest.approx(mean, rel=1e-3)


def test_a_failed_run_keeps_its_balance_so_far(gen_dir, tmp_path):
    """The step budget spent part way: exit 2, one error line, and --out holds the
    balance up to there as JSON (not the partial CSV other commands write there)."""
    out = tmp_path / "part.json"
    r = CliRunner().invoke(main, ["energy", str(MODELS / "rlc.yaml"), "-o", str(gen_dir),
                                  "--max-steps", "200", "--out", str(out), "-q"])
    assert r.exit_code == 2, r.output
    data = json.loads(out.read_text())
    bal = data["balance"]
    assert bal["supplied"] > 0 and abs(bal["residual"]) <= 1e-3 * bal["supplied"]
    assert "the balance up to t = " in r.output and "step budget" in r.output
