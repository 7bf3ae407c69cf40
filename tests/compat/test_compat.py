"""What ran keeps running (issue 38, item 1). tests/compat holds model files in every form
an earlier bgc accepted, each saying in its header which forms it exercises and since
(and until) which commit each was the documented one; here every file is loaded, built
and run briefly with its own ``simulation:`` settings, and its outputs checked against
closed forms. A form that was retired on purpose (tests/compat/retired/) gets bgc's
one-line error, which must say what to write instead."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
from helpers import bgc, one_line_error

from bgc.codegen.emit import import_module
from bgc.model import load
from bgc.pipeline import compile_model
from bgc.scene import scenes
from bgc.simulate import simulate

COMPAT = Path(__file__).resolve().parent
RETIRED = COMPAT / "retired"
CHAIN = "chain40_flat_energy.yaml"
MODEL_FILES = sorted(p.name for p in COMPAT.glob("*.yaml")
                     if p.name not in ("scene.yaml", CHAIN))
COMMIT = re.compile(r"\b[0-9a-f]{7}\b")
G = 9.81


def header(path: Path) -> str:
    """The comment lines a file starts with."""
    lines = path.read_text().splitlines()
    return "\n".join(ln for ln in lines[:next(i for i, ln in enumerate(lines)
                                             if not ln.startswith("#"))])


def run(tmp_path, name, *, method="parasitic"):
    """Compile tests/compat/NAME under ``method`` and run it with its own simulation
    settings; (module, result)."""
    _, path = compile_model(COMPAT / name, tmp_path / "gen", method)
    mod = import_module(path)
    s = mod.SETTINGS
    r = simulate(mod, t_end=s["t_end"], rtol=s["rtol"], atol=s["atol"], solver=s["solver"],
                 points=s["points"])
    assert r.success, r.message
    assert len(r.t) == s["points"] and r.t[-1] == pytest.approx(s["t_end"])
    return mod, r


def close(actual, expected, tol, scale=None):
    """|actual - expected| <= tol * scale (scale: the largest |expected|, at least 1e-300)."""
    expected = np.broadcast_to(np.asarray(expected, dtype=float), np.shape(actual))
    scale = scale if scale is not None else max(float(np.abs(expected).max()), 1e-300)
    err = float(np.abs(np.asarray(actual) - expected).max())
    assert err <= tol * scale, f"error {err:.3g} > {tol:g} x {scale:.3g}"


# ------------------------------------------------------------------ every file loads
@pytest.mark.parametrize("name", MODEL_FILES)
def test_every_compat_file_loads_and_says_what_it_exercises(name):
    assert COMMIT.search(header(COMPAT / name)), "the header names no commit"
    model = load.load(COMPAT / name)
    assert model.outputs


def test_every_scene_and_retired_file_says_since_when():
    for path in [COMPAT / "scene.yaml", *sorted(RETIRED.glob("*.yaml"))]:
        assert COMMIT.search(header(path)), path.name


def test_yaml_variants_of_a_file_load_as_it(tmp_path):
    """A byte order mark (as Windows editors save), CRLF line ends, document markers
    (--- and ...) and aliases: read as plain YAML since 3419412; without name: the file's
    stem names the model (3419412, documented 133ee83)."""
    text = (COMPAT / "scalar_network.yaml").read_text()
    variant = tmp_path / "variant.yaml"
    variant.write_bytes(b"\xef\xbb\xbf" + ("---\n" + text + "...\n").replace(
        "\n", "\r\n").encode())
    assert load.load(variant).digest == load.load(COMPAT / "scalar_network.yaml").digest
    aliased = tmp_path / "aliased.yaml"
    aliased.write_text(text.replace("  Rd: 50.0", "  Rd: &rd 50.0\n  Rd2: *rd"))
    assert load.load(aliased).parameters["Rd2"].value == 50.0
    unnamed = tmp_path / "my_circuit.yaml"          # no name: the file's stem names it
    unnamed.write_text(text.replace("name: compat_scalar\n", ""))
    assert load.load(unnamed).name == "my_circuit"


# ------------------------------------------------------------------ runs, closed forms
def test_scalar_network(tmp_path):
    _, r = run(tmp_path, "scalar_network.yaml")
    t, y = r.t, r.column
    w = np.sqrt(400.0 / 0.5)
    close(y("x"), 0.01 * np.cos(w * t), 1e-6)
    close(y("v"), -0.01 * w * np.sin(w * t), 1e-6)
    close(y("v_spring"), y("v"), 1e-12)
    close(y("p_mass"), 0.5 * y("v"), 1e-12)
    close(y("v_cap"), np.where(t > 0.01, 5.0 * (1 - np.exp(-(t - 0.01) / 2e-3)), 0.0), 1e-5)
    close(y("v_store"), 0.2 * 50.0 * (1 - np.exp(-t / 0.05)), 1e-6)
    wave = 2.0 * np.sin(2 * np.pi * 20.0 * t + np.pi / 2) + 0.5      # phase: 90 deg
    close(y("wave_out"), wave, 1e-12)
    close(y("i_tf"), wave / (2.0 ** 2 * 4.0), 1e-12)
    close(y("q_gy"), 3.0 * t ** 2 / (2 * 0.5), 1e-6)
    close(y("i_mtf"), 1.0 / ((1 + t) ** 2 * 2.0), 1e-12)
    close(y("i_mgy"), 3.0 / (2 + t) ** 2, 1e-12)
    close(y("i_mse"), 1.5 * np.exp(-t / 0.02) / 10.0, 1e-12)
    close(y("e_msf"), 8.0 * 0.5 * np.interp(t, [0, 0.02, 0.05], [0, 1, 1]), 1e-12)
    close(y("p_free"), 0.0, 1e-12, scale=1.0)
    close(y("trig"), np.sin(3 * t) + np.cos(3 * t) - np.tan(0.1 * t), 1e-12)
    close(y("inverse"), np.arcsin(0.5 * t) + np.arccos(0.5 * t) + np.arctan(t)
          + np.arctan2(1 + t, 2), 1e-12)
    close(y("hyper"), np.sinh(t) - np.cosh(t) + np.tanh(2 * t), 1e-12)
    close(y("exp_log"), np.exp(-t) * np.log(2 + t) + np.sqrt(1 + t ** 2), 1e-12)
    close(y("pieces"), np.abs(t - 0.02) + np.sign(t - 0.02) + np.minimum(t, 0.02)
          - np.maximum(-t, -0.01), 1e-12)
    close(y("arith"), -(1 + t) ** 2 / (2 - t) * 3 - 4 / 5 + 0.5, 1e-12)
    q = y("cubic_q")
    close(y("cubic_e"), 100.0 * q + 2.0e4 * q ** 3, 1e-12)
    close(y("diode_f"), 1e-9 * (np.exp(y("diode_e") / 0.025) - 1), 1e-9)


def test_bodies_and_joints(tmp_path):
    _, r = run(tmp_path, "bodies_joints.yaml")
    t, y = r.t, r.column
    close(y("ball_x"), 1.5 * t, 1e-9, scale=1.0)
    close(y("ball_z"), 1 + 4.0 * t - G / 2 * t ** 2, 1e-9, scale=1.0)
    close(y("ball_vz"), 4.0 - G * t, 1e-9, scale=1.0)
    close(y("ball_az"), -G, 1e-9)
    close(y("P_x"), 0.5 + 1.5 * t, 1e-9, scale=1.0)
    close(y("P_vz"), y("ball_vz"), 1e-9, scale=1.0)
    close(y("ball_angle"), 0.0, 1e-9, scale=1.0)
    for axis, w in (("x", 3.0), ("y", -3.0), ("z", 0.0)):     # a principal axis: kept
        close(y(f"top_w{axis}"), w, 1e-8, scale=3.0)
    # the carriage drops onto its preloaded spring (parasitic compliance 1e-8 m/N)
    close(y("carriage_z"), (3.0 - 1.0 * G) / 400.0 * (1 - np.cos(20.0 * t)), 1e-5)
    close(y("wheel_w"), 0.3 * t / 0.08, 1e-6)
    # a screw of lead l: z'' = -m g l^2 / (J + m l^2); the coupled row's parasitic
    # compliance (1e8 N/m: k l^2 = 250 N m/rad on the nut's turn) shifts it by 4e-4
    lead = 0.01 / (2 * np.pi)
    close(y("nut_z"), -0.5 * 0.5 * G * lead ** 2 / (0.002 + 0.5 * lead ** 2) * t ** 2, 1e-3)
    w = np.sqrt(32.0 / 0.8)
    close(y("slider_x"), 3.0 + 0.2 / w * np.sin(w * t), 1e-6, scale=0.2 / w)
    late = t >= 0.1                     # the joints have settled on their parasitic springs
    close(y("axle_Fz")[late], 2.0 * G, 1e-6)
    close(y("cardan_Fz")[late], 1.2 * G, 1e-6)
    for joint in ("weld", "table", "socket", "floor", "rod", "guide", "gimbal"):
        close(y(f"{joint}_Fz")[late], 1.0 * G, 1e-6)
    close(y("bob2_z"), 0.0, 1e-6, scale=1.0)        # at rest below the yoke
    close(y("cardan_Mx"), 0.0, 1e-9, scale=1.0)
    assert 0 < y("axle_gap")[late].max() < 1e-6 and y("axle_tilt").max() < 1e-9


def test_multibonds(tmp_path):
    _, r = run(tmp_path, "multibonds.yaml")
    t, y = r.t, r.column
    for c, q0, w in (("x", 0.01, 10.0), ("y", -0.02, 20.0), ("z", 0.03, 5.0)):
        close(y(f"q{c}"), q0 * np.cos(w * t), 1e-7, scale=0.03)
    close(y("fx"), 200.0 * y("qx"), 1e-12)
    for c, f in (("x", 2.0), ("y", 3.0), ("z", 1.0)):          # [[0,1,0],[0,0,1],[1,0,0]]
        close(y(f"coil_q{c}"), f * t, 1e-9, scale=1.0)
    close(y("push_fz"), 3.0, 1e-12)
    close(y("lever_qy"), 2.0 * 0.5 * t, 1e-9, scale=1.0)        # (w x r)_y t
    close(y("torque_z"), 0.5 * 10.0 * y("lever_qy"), 1e-9, scale=1.0)


def test_mechanism_ports_and_blocks(tmp_path):
    _, r = run(tmp_path, "mechanism_ports_blocks.yaml")
    t, y = r.t, r.column
    w = np.sqrt(2 * 100.0 / 0.5)
    close(y("lift"), 0.01 * np.cos(w * t), 1e-6, scale=0.01)
    close(y("lift_rate"), -0.01 * w * np.sin(w * t), 1e-6, scale=0.01 * w)
    close(y("spin"), 0.4 / 2.0 * t / 0.02, 1e-7, scale=1.0)
    close(y("turn"), 0.5 * 0.4 / 2.0 / 0.02 * t ** 2, 1e-7, scale=1.0)
    close(y("force_z"), 0.0, 1e-9, scale=1.0)      # the tip moves in the xy plane
    close(y("force_n"), 0.0, 1e-9, scale=1.0)
    close(y("ramp_y"), 0.5 + 2.0 * t, 1e-9)
    close(y("lag_y"), 1 - np.exp(-t / 0.01), 1e-7, scale=1.0)
    close(y("gain_y"), 1.5 + 6.0 * t, 1e-9)
    close(y("sum_y"), 1.0 + 4.0 * t, 1e-9)
    close(y("pi_y"), 2.0 + 0.5 + 5.0 * t, 1e-9)
    close(y("pi_u"), 1.0, 0.0)
    tf = 0.1 / (1.0 * 10)                           # the PID's filter: kd/(kp n)
    close(y("pid_y"), 1.0 + t + 0.1 / tf * np.exp(-t / tf), 1e-7)
    close(y("tacho_y"), 10.0 * (t - 0.005 * (1 - np.exp(-t / 0.005))), 1e-6, scale=1.0)
    close(y("current"), y("pi_y") / 4.0, 1e-12)
    close(y("unity"), 1.0, 0.0)


def test_excitation_every_kind_and_direction(tmp_path):
    _, path = compile_model(COMPAT / "excitation.yaml", tmp_path / "gen")
    mod = import_module(path)
    model = load.load(COMPAT / "excitation.yaml")
    names = list(mod.PARAM_NAMES)

    def excite(kind, direction):
        p = np.array(mod.PARAMS, dtype=np.float64)
        for k, v in model.excitation.select(kind, direction).items():
            p[names.index(k)] = v
        r = simulate(mod, t_end=0.1, rtol=1e-9, atol=1e-12, points=11, params=p)
        assert r.success, r.message
        return r.t, r.column
    t, y = excite("constant", "push")
    close(y("x"), 4.0 / 800.0 * (1 - np.cos(20.0 * t)), 1e-6)
    close(y("spin"), 0.0, 1e-12, scale=1.0)
    close(y("g"), 1.0, 0.0)
    t, y = excite("constant", "twist")             # direction: rx of the cylindrical joint
    close(y("spin"), 0.1 * t / 0.05, 1e-7)
    close(y("x"), 0.0, 1e-12, scale=1.0)
    t, y = excite("sine", "push")
    close(y("g"), np.sin(2 * np.pi * 5.0 * t), 1e-12, scale=1.0)
    t, y = excite("chirp", "twist")                # the paper's envelope: 2 t^2/t1^2 first
    early = t <= 0.025
    close(y("g")[early], (2 * t ** 2 / 0.05 ** 2 * np.sin(2 * np.pi * 2.0 * t))[early],
          1e-12, scale=1.0)


def test_scene(tmp_path):
    scene = scenes.load_scene(COMPAT / "scene.yaml")
    assert (scene.name, scene.method, scene.merge_relays) == ("compat_push", "lagrange", False)
    mod, _ = scenes.ensure_scene_module(scene, tmp_path / "gen")
    p = np.array(mod.PARAMS, dtype=np.float64)
    names = list(mod.PARAM_NAMES)
    for k, v in scenes.scene_values(scene, load.load(scene.model)).items():
        if k in names:
            p[names.index(k)] = v
    r = simulate(mod, t_start=scene.t_start, t_end=scene.t_end, rtol=scene.rtol,
                 atol=scene.atol, solver=scene.solver, points=scene.points, params=p)
    assert r.success, r.message
    close(r.column("x"), 3.0 / 800.0 * (1 - np.cos(20.0 * r.t)), 1e-6)


def test_ifelse(tmp_path):
    _, r = run(tmp_path, "expr_ifelse.yaml")
    t, y = r.t, r.column
    close(y("u"), np.where(t < 0.01, t / 0.01, 1.0), 1e-12)
    close(y("late"), np.where(t >= 0.02, 1.0, 0.0), 0.0)
    close(y("twice"), np.where(t <= 0.03, 2 * t, t), 1e-12)
    e = y("valve_e")
    close(y("valve_f"), np.where(e > 0, e / 2.0, e / 1e6), 1e-12)
    assert e.max() > 0.1                            # the valve opened


def test_float_zero(tmp_path):
    _, r = run(tmp_path, "expr_float_zero.yaml")
    t, y = r.t, r.column
    close(y("rectified"), np.maximum(0.0, np.sin(2 * np.pi * 5 * t)), 1e-12)
    for name in ("zero", "minus_zero", "tiny", "sink_f"):
        close(y(name), 0.0, 0.0, scale=1.0)
    assert y("v_cap")[0] == 0.0 and y("v_cap").max() > 0.1


def test_flat_sums(tmp_path):
    _, r = run(tmp_path, "expr_flat_sum.yaml")
    t, y = r.t, r.column
    close(y("v_cap"), 1.5 * (1 - np.exp(-t / 0.1)), 1e-6)
    close(y("taylor"), np.exp(t), 1e-14)
    close(y("product"), (1 + t / 110) ** 110, 1e-12)
    close(y("difference"), 4.0, 1e-12)


# ------------------------------------------------------------------ the 40-link chain
def test_chain40_loads_with_its_energy_one_flat_sum():
    assert COMMIT.search(header(COMPAT / CHAIN))
    outs = {o.name: o.expr for o in load.load(COMPAT / CHAIN).outputs}
    assert len(outs["kinetic"].args) == 240 and len(outs["potential"].args) == 40
    assert outs["energy"] == outs["kinetic"] + outs["potential"]


@pytest.mark.slow
@pytest.mark.parametrize("method", ["lagrange", "zcp"])
def test_chain40_conserves_energy(tmp_path, method):
    """Ideal spherical joints: the falling chain's energy stays what it was to the
    integration tolerance while joules turn from potential into kinetic. (Slow: the
    40-link build and compile take ~25 s a method.)"""
    mod, r = run(tmp_path, CHAIN, method=method)
    y = r.column
    close(y("energy"), y("kinetic") + y("potential"), 1e-12)
    kinetic = y("kinetic")
    assert kinetic[0] == pytest.approx(0.0, abs=1e-12) and kinetic[-1] > 1.0
    drift = np.abs(y("energy") - y("energy")[0]).max()
    assert drift < 10 * mod.SETTINGS["rtol"] * kinetic.max(), drift


# ------------------------------------------------------------------ retired forms
# file -> (key of the error, what its message must tell the user to write instead)
RETIRED_FORMS = {
    "dunder_name.yaml": ("parameters.k__s", "single '_'"),
    "point_dunder.yaml": ("bodies.b.points", "single '_'"),
    "points_one.yaml": ("simulation.points", "1001"),
    "scene_points_one.yaml": ("time.points", "1001"),
    "module_name.yaml": ("name", "name: wave_model"),
}


def test_a_number_written_as_a_unit_or_a_description_is_its_text():
    """unit: 1 and description: 2024 were refused for a while (36037d0): read again as
    the text they are."""
    assert load.load(COMPAT / "unit_number.yaml").parameters["gain"].unit == "1"
    assert load.load(COMPAT / "description_number.yaml").description == "2024"


@pytest.mark.parametrize("name", sorted(RETIRED_FORMS))
def test_retired_form_says_what_to_write(tmp_path, name):
    key, instead = RETIRED_FORMS[name]
    m = one_line_error(bgc("check", RETIRED / name, cwd=tmp_path))
    assert m["key"] == key
    assert instead in m["msg"] + " (hint: " + m["hint"], m.group(0)


def long_expression_model(tmp_path, terms: int) -> Path:
    """A model whose output ``big`` is a sum of ``terms`` terms of ~25 characters."""
    big = " + ".join(f"{i}.125*(c.e - 0.5)**2" for i in range(terms))
    path = tmp_path / "long.yaml"
    path.write_text(f"""name: long
elements:
  src: {{type: Se, effort: 1.0}}
  loop: {{type: "1"}}
  c: {{type: C, C: 0.5}}
  r: {{type: R, R: 2.0}}
bonds:
  - [src, loop]
  - [loop, c]
  - [loop, r]
outputs:
  big: "{big}"
""")
    return path


def test_retired_expression_longer_than_the_limit_says_what_to_write(tmp_path):
    """An expression over expr.MAX_CHARS (10 000) characters: accepted from 3419412 until
    d3ba890, refused since 613381a (the limit stays). Outputs cannot read other outputs,
    so the hint 'give its parts names as parameters, signals or outputs' does not say how;
    sum blocks can hold the parts (blocks: {part: {type: sum, inputs: [...]}}, their
    .y added by the output), and that form loads."""
    m = one_line_error(bgc("check", long_expression_model(tmp_path, 600), cwd=tmp_path))
    assert m["key"] == "outputs.big" and "10000" in m["msg"]
    assert "sum" in m["hint"] and "block" in m["hint"], m.group(0)
    terms = [f"{i}.125*(c.e - 0.5)**2" for i in range(600)]
    split = (tmp_path / "long.yaml").read_text().split("outputs:")[0] + (
        "blocks:\n"
        f"  part_a: {{type: sum, inputs: [{', '.join(terms[:300])}]}}\n"
        f"  part_b: {{type: sum, inputs: [{', '.join(terms[300:])}]}}\n"
        "outputs:\n  big: part_a.y + part_b.y\n")
    (tmp_path / "split.yaml").write_text(split)
    assert load.load(tmp_path / "split.yaml").outputs[0].name == "big"


def table_model(tmp_path, samples: int, wide: bool = False) -> Path:
    """A model whose source follows a table signal of ``samples`` samples (``wide``:
    written with 10 decimals, as a measured profile is, else as short integers)."""
    def num(x):
        return f"{x:.10f}" if wide else str(int(x))
    t = ", ".join(num(i / 1000 if wide else i) for i in range(samples))
    v = ", ".join(num(np.sin(i / 100)) if wide else "0" for i in range(samples))
    path = tmp_path / "table.yaml"
    path.write_text("name: table\nsignals:\n  profile: {type: table, t: [" + t
                    + "], values: [" + v + "]}\n"
                    "elements:\n  src: {type: Se, effort: profile}\n"
                    "  loop: {type: \"1\"}\n  r: {type: R, R: 2.0}\n"
                    "bonds:\n  - [src, loop]\n  - [loop, r]\n")
    return path


def test_retired_model_file_over_the_size_limit_says_what_to_write(tmp_path):
    """A model file over document.MAX_FILE_BYTES (1 MiB), in practice a long table
    signal (here 45 000 samples at 0.001 s, 10 decimals): accepted until b02f8f7, refused since
    d3ba890. Today's hint says the limit, not what to write instead."""
    path = table_model(tmp_path, 45_000, wide=True)
    assert path.stat().st_size > load.MAX_FILE_BYTES
    m = one_line_error(bgc("check", path, cwd=tmp_path))
    assert "table" in m["hint"], m.group(0)


@pytest.mark.slow
def test_retired_table_over_the_node_limit_says_what_to_write(tmp_path):
    """A table of 55 000 samples (110 000 YAML values, a 540 kB file): accepted until
    b02f8f7, refused since d3ba890 by document.MAX_NODES, whose hint blames aliases the
    file does not have. (Slow: composing it takes ~2.5 s of CPU before the refusal.)"""
    m = one_line_error(bgc("check", table_model(tmp_path, 55_000), cwd=tmp_path,
                           timeout=60))
    assert "alias" not in m["hint"] and "table" in m["hint"], m.group(0)
