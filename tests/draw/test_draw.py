"""``bgc draw``: the SVG parses; every element and bond of the graph is in it; each causal
stroke sits at the end of its bond that the causality stage says receives the effort, and
each half-arrow at the end the power flows to (both read back from the SVG's geometry);
the marks (constraint elements, algebraic loops, zero-order causal paths, a conflict);
``--only``; bad input as one line. Causality only: nothing is compiled."""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET

import pytest
from click.testing import CliRunner
from helpers import MODELS

from bgc.cli import main
from bgc.draw import diagram, layout, render
from bgc.pipeline import build

SVG = "{http://www.w3.org/2000/svg}"


def run(*args):
    return CliRunner().invoke(main, [str(a) for a in args])


def svg_parts(path):
    """(element -> its label's anchor, bond -> its two ends, stroke -> its centre,
    half-arrow -> its tip, multibond -> its dimension) read from the ids of the SVG's
    groups."""
    root = ET.parse(path).getroot()
    els, bonds, strokes, arrows, dims = {}, {}, {}, {}, {}
    for g in root.iter(f"{SVG}g"):
        kind, _, name = (g.get("id") or "").partition("-")
        if kind in ("el", "dim"):
            text = g.find(f"{SVG}text")
            if kind == "dim":
                dims[name] = int(text.text)
                continue
            els[name] = (float(text.get("x")), float(text.get("y")))
            assert g.find(f"{SVG}title").text.endswith(f" {name}")     # its tooltip
        elif kind in ("bond", "stroke", "arrow"):
            nums = [float(v) for v in re.findall(r"-?\d+(?:\.\d+)?",
                                                 g.find(f"{SVG}path").get("d"))]
            a, b = (nums[0], nums[1]), (nums[2], nums[3])
            if kind == "bond":
                bonds[name] = (a, b)
            elif kind == "stroke":
                strokes[name] = ((a[0] + b[0]) / 2, (a[1] + b[1]) / 2)
            else:
                arrows[name] = a
    return els, bonds, strokes, arrows, dims


def end_element(point, bond_ends, src, dst, els):
    """The element at the end of a bond that ``point`` sits on (within 0.5 pt)."""
    near = min(bond_ends, key=lambda p: math.dist(p, point))
    assert math.dist(near, point) < 0.5, (point, bond_ends)
    return min((src, dst), key=lambda n: math.dist(els[n], near))


def check_drawing(path, graph, effort_in, elements):
    """Every element of ``elements`` and every bond touching one is drawn, with its
    stroke at the end receiving the effort, its half-arrow at its dst and, a multibond,
    its dimension."""
    els, bonds, strokes, arrows, dims = svg_parts(path)
    assert elements <= set(els)
    drawn = [(b, bd) for b, bd in enumerate(graph.bonds)
             if bd.src in elements or bd.dst in elements]
    assert {bd.name for _, bd in drawn} == set(bonds) == set(strokes) == set(arrows)
    assert dims == {bd.name: bd.dim for _, bd in drawn if bd.dim > 1}
    for b, bd in drawn:
        ends = bonds[bd.name]
        assert end_element(strokes[bd.name], ends, bd.src, bd.dst, els) == effort_in[b]
        assert end_element(arrows[bd.name], ends, bd.src, bd.dst, els) == bd.dst
    return els


def test_small_model_strokes_match_the_causality_report(tmp_path):
    out = tmp_path / "dc_motor.svg"
    r = run("draw", MODELS / "dc_motor.yaml", "--out", out, "--quiet")
    assert r.exit_code == 0, r.output
    c = build(MODELS / "dc_motor.yaml")
    g = c.causal.graph
    check_drawing(out, g, c.causal.effort_in, set(g.elements))
    # a stroke on each side occurs: the supply's bond (effort into the junction) and
    # the inductor's (integral causality: effort into the I)
    names = {bd.name: c.causal.effort_in[b] for b, bd in enumerate(g.bonds)}
    assert {names[bd.name] for bd in g.bonds if "L_a" in (bd.src, bd.dst)} == {"L_a"}
    assert {names[bd.name] for bd in g.bonds if "supply" in (bd.src, bd.dst)} == {"armature"}
    png = tmp_path / "dc_motor.png"      # the format by the suffix
    assert run("draw", MODELS / "dc_motor.yaml", "--out", png, "-q").exit_code == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def sarib():
    return build(MODELS / "sarib.yaml")


@pytest.mark.slow       # drawing an instance and the other models stay in make test
def test_sarib_leg_and_whole(sarib, tmp_path):
    """A leg (--only leg_1, the instance: the beater, the bar and their three joints, with
    the fuselage's and MGB's elements they bond to, marked outside), and the whole SARIB."""
    cg = sarib.causal
    g = cg.graph
    group = diagram.groups_of(g)
    leg = {"leg_1.beater", "leg_1.bar", "leg_1.hinge", "leg_1.bar_bottom", "leg_1.bar_top"}
    d = diagram.build_diagram(g, cg.effort_in, {}, "leg_1", "sarib")
    kept = {n for n in g.elements if group[n] in leg}
    assert {n for n, node in d.nodes.items() if "outside" not in node.marks} == kept
    assert {group[n] for n, node in d.nodes.items() if "outside" in node.marks} == \
        {"fuselage", "mgb"}
    path = render.render(layout.layout(d), tmp_path / "leg.svg")
    check_drawing(path, g, cg.effort_in, kept)
    whole = diagram.build_diagram(g, cg.effort_in, {}, None, "sarib")
    assert len(whole.nodes) == len(g.elements) and len(whole.edges) == len(g.bonds)
    path = render.render(layout.layout(whole), tmp_path / "sarib.svg")
    check_drawing(path, g, cg.effort_in, set(g.elements))
    # every blocked direction's spring and damper are constraint elements (18 joints)
    marked = {n for n, node in whole.nodes.items() if "constraint" in node.marks}
    assert len(marked) == 2 * 74 and all(n.endswith(("__L", "__Lc")) for n in marked)


def test_marks_loops_zcps_and_constraint_sources():
    d, err = diagram.of_model(MODELS / "rr_loop.yaml", "parasitic")
    assert err is None
    assert {"r1", "r2", "r3"} <= {n for n, node in d.nodes.items() if "loop" in node.marks}
    d, err = diagram.of_model(MODELS / "pendulum.yaml", "zcp")
    assert err is None
    marked = {n for n, node in d.nodes.items() if "constraint" in node.marks}
    assert marked == {f"hinge__{a}__L" for a in ("tx", "ty", "tz", "ry", "rz")}
    assert any("zcp" in e.marks for e in d.edges)


CONFLICT = """\
name: clash
elements:
  s1: {type: Se, effort: 1.0}
  s2: {type: Se, effort: 2.0}
  node: {type: "0"}
  r: {type: R, R: 1.0}
bonds:
  - [s1, node]
  - [s2, node]
  - [node, r]
"""


def test_conflict_is_drawn_marked_then_reported(tmp_path):
    model = tmp_path / "clash.yaml"
    model.write_text(CONFLICT)
    out = tmp_path / "clash.svg"
    r = run("draw", model, "--out", out, "--quiet")
    assert r.exit_code == 2
    [line] = r.output.strip().splitlines()
    assert line.startswith("error: ") and "causality conflict" in line
    els, bonds, strokes, _, _ = svg_parts(out)
    assert set(els) == {"s1", "s2", "node", "r"} and len(bonds) == 3 and not strokes
    d, err = diagram.of_model(model, "parasitic")
    assert {n for n, node in d.nodes.items() if "conflict" in node.marks} == {"node"}
    assert {e.name for e in d.edges if "conflict" in e.marks} == {"b1", "b2"}


@pytest.mark.parametrize("args, key", [
    (("--out", "{tmp}/x.svg", "--only", "leg_9"), "--only"),
    (("--out", "{tmp}/x.jpg"), "--out"),
    (("--out", "{tmp}/file/x.svg"), "drawing"),
    (("-o", "{tmp}/x.svg"), "-o"),
])
def test_bad_input_is_one_line(tmp_path, args, key):
    (tmp_path / "file").write_text("")
    r = run("draw", MODELS / "rlc.yaml", "--quiet",
            *[a.format(tmp=tmp_path) for a in args])
    assert r.exit_code == 2
    [line] = r.output.strip().splitlines()
    assert line.startswith("error: ") and key in line, line
