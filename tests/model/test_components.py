"""Components (bgc.model.components, bgc.model.library): an instance is its component's
parts written out with its prefix, placed and with its parameters; arrays; files and the
library; the errors, each naming the instance and the component's definition; the digest;
names in generated code; the SARIB assembled from the library's leg is the SARIB written
out."""

from __future__ import annotations

import json
import math
import re

import numpy as np
import pytest
from click.testing import CliRunner
from helpers import MODELS, ROOT

from bgc.errors import ModelError
from bgc.graph.causality import assign
from bgc.graph.expand import expand
from bgc.model import document, library, symbols
from bgc.model.load import load, loads

PENDULUM = """
components:
  pendulum:
    description: A rod on a hinge about the frame's y axis.
    parameters:
      m: {value: 1.0, unit: kg}
      c: 0.01
    constants:
      length: 0.5
    ports:
      base: {external: body}
      tip: {point: rod.T}
      arm: {body: rod}
      swing: {direction: hinge.rx}
    bodies:
      rod: {mass: m, com: [0, 0, "-length / 2"], inertia: [0.02, 0.02, 0.001],
            points: {T: [0, 0, "-length"]}}
    joints:
      hinge: {type: revolute, between: [base, rod], at: [0, 0, 0], axis: [0, 1, 0],
              spring: {k: 0, c: c}}
    outputs:
      angle: hinge.rx.q
"""


def model(instances: str, extra: str = "", name: str = "row") -> str:
    return f"name: {name}\ngravity: 9.81\nparameters:\n  m_rod: 0.3\n{PENDULUM}" \
           f"instances:\n{instances}{extra}"


def test_an_instance_is_its_parts_prefixed_placed_and_parameterized():
    m = loads(model("""
  p:
    component: pendulum
    origin: [1, 2, 3]
    rotate: {z: 90}
    parameters: {m: "2 * m_rod"}
    connect: {base: fixed_frame}
""", "outputs:\n  a: p.hinge.rx.q\n  x: p.rod.T.x\n"))
    assert list(m.bodies) == ["p.rod"] and list(m.joints) == ["p.hinge"]
    rod, hinge = m.bodies["p.rod"], m.joints["p.hinge"]
    # placed: the frame turned 90 deg about z, exactly (no 6e-17 from a float cosine)
    assert rod.com == (1.0, 2.0, 2.75)
    assert rod.frame == ((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))
    assert hinge.at == (1.0, 2.0, 3.0) and [r[0] for r in hinge.frame] == [-1.0, 0.0, 0.0]
    # m given by an expression of the model's parameters: that expression, no parameter
    assert str(rod.mass_expr) == "2*P_m_rod" and rod.mass == 0.6
    assert "p.c" in m.parameters and "p.m" not in m.parameters      # c kept its default
    assert "p.hinge__stiffness" in m.parameters
    assert [o.name for o in m.outputs] == ["a", "x", "p.angle"]
    assert m.instances["p"].component == "pendulum"


def test_an_array_makes_one_instance_per_index_used_in_every_key():
    m = loads(model("""
  p:
    component: pendulum
    for: {i: [1, 3]}
    origin: ["0.5 * i", 0, 0]
    rotate: {z: "90 * (i - 1)"}
    constants: {length: "0.1 * i"}
    parameters: {m: "m_rod * i", c: "0.01 * i"}
    connect: {base: fixed_frame}
  none:
    component: pendulum
    for: {k: [1, 0]}
    connect: {base: fixed_frame}
  grid:
    component: pendulum
    for: {i: [0, 1], j: [1, 2]}
    connect: {base: "p_{i + j}.arm"}
"""))
    assert list(m.instances) == ["p_1", "p_2", "p_3", "grid_0_1", "grid_0_2", "grid_1_1",
                                 "grid_1_2"]
    for i in (1, 2, 3):
        rod = m.bodies[f"p_{i}.rod"]
        assert rod.com == pytest.approx((0.5 * i, 0, -0.05 * i), abs=1e-15)
        assert str(rod.mass_expr) == f"{i}*P_m_rod" if i > 1 else "P_m_rod"
        assert m.parameters[f"p_{i}.c"].value == pytest.approx(0.01 * i)
        assert m.joints[f"p_{i}.hinge"].at[0] == 0.5 * i
    assert m.joints["grid_1_2.hinge"].body1 == "p_3.rod"


def test_an_instances_parts_are_connected_through_its_ports_only():
    text = model("""
  a: {component: pendulum, connect: {base: fixed_frame}}
  b: {component: pendulum, origin: [0, 0, -0.5], connect: {base: a.rod}}
""")
    with pytest.raises(ModelError, match="'a.rod': instance 'a' .* has no port 'rod'"):
        loads(text)
    m = loads(text.replace("base: a.rod", "base: a.arm"))
    assert m.joints["b.hinge"].body1 == "a.rod"
    # a point port with an axis, and a direction port, as bond ends
    m = loads(model("  a: {component: pendulum, connect: {base: fixed_frame}}\n",
                    "elements:\n  d: {type: R, R: 0.5}\n  s: {type: C, k: 2.0}\n"
                    "bonds:\n  - [a.tip.x, d]\n  - [a.swing, s]\n"))
    assert set(m.ports) == {"a.rod.T.x", "a.hinge.rx"}
    assign(expand(m))


def test_library_components_are_working_parts():
    """Every component the library ships, instanced in a host that binds its external
    ports (bodies to the fixed frame, signals to 0) and bonds its element ports (a source
    into those that take power in, a resistor out of the others): it loads, expands and
    gets its causality."""
    for entry in library.listing():
        name, host = entry["name"], []
        connect = {p["name"]: ("fixed_frame" if p["kind"] == "external body" else 0)
                   for p in entry["ports"] if p["kind"].startswith("external")}
        elements, bonds = [], []
        for p in entry["ports"]:
            if p["kind"] == "element":
                e = f"e_{p['name']}"
                if p.get("power") == "out":
                    elements.append(f"  {e}: {{type: R, R: 1.0}}")
                    bonds.append(f"  - [x.{p['name']}, {e}]")
                else:
                    elements.append(f"  {e}: {{type: Se, effort: 1.0}}")
                    bonds.append(f"  - [{e}, x.{p['name']}]")
        host.append(f"name: host\ngravity: 9.81\ninstances:\n  x: {{component: {name}, "
                    f"connect: {json.dumps(connect)}}}")
        if elements:
            host += ["elements:", *elements, "bonds:", *bonds]
        if not any(p["kind"] == "external body" for p in entry["ports"]) and not elements:
            host += ["elements:\n  e: {type: C, C: 1.0}\n  s: {type: Se, effort: 1.0}",
                     "bonds:\n  - [s, e]"]
        m = loads("\n".join(host) + "\n", "host.yaml")
        assert m.instances["x"].library and entry["description"], name
        cg = assign(expand(m))
        assert cg.effort_in and None not in cg.effort_in, name


def test_a_component_from_another_file_and_the_digest_of_what_is_used(tmp_path):
    (tmp_path / "parts").mkdir()
    parts = tmp_path / "parts" / "pend.yaml"
    parts.write_text(PENDULUM)
    path = tmp_path / "row.yaml"
    text = ("name: row\ngravity: 9.81\nuses:\n  swing: {file: parts/pend.yaml, component: "
            "pendulum}\n  pendulum: parts/pend.yaml\ninstances:\n"
            "  a: {component: swing, connect: {base: fixed_frame}}\n"
            "  b: {component: pendulum, origin: [1, 0, 0], connect: {base: fixed_frame}}\n")
    path.write_text(text)
    m = load(path)
    assert set(m.bodies) == {"a.rod", "b.rod"}
    assert m.bodies["a.rod"].loc.file == str(tmp_path / "parts" / "pend.yaml")
    doc = document.read(path)
    d1 = library.digest(doc, str(path))
    assert d1 == m.digest and d1 != document.digest(doc)
    parts.write_text(PENDULUM.replace("c: 0.01", "c: 0.02"))     # the used file changed
    assert library.digest(doc, str(path)) != d1
    assert library.digest(doc, str(path), {"N": 2}) != library.digest(doc, str(path))


def test_a_compile_time_constant_changes_the_structure_and_the_digest(tmp_path):
    path = MODELS / "n_four_bar.yaml"
    doc = document.read(path)
    assert doc["constants"]["N"] == 2          # the model's default (-p N=40 for more)
    m = load(path, constants={"N": 3})
    assert len(m.bodies) == 7 and len(m.joints) == 10 and list(m.instances) == [
        "w_1", "w_2", "w_3"]
    assert m.joints["w_3.left_end"].body1 == "w_2.crank"
    assert m.bodies["w_3.crank"].com == (3.0, 0.5, 0.0)
    assert m.digest == library.digest(doc, str(path), {"N": 3}) != library.digest(
        doc, str(path))
    one = load(path, constants={"N": 1})            # the array w_2 ... w_N is empty
    assert list(one.instances) == ["w_1"]
    with pytest.raises(ModelError, match="declares no constant 'M'"):
        load(path, constants={"M": 3})


def where(err) -> set[tuple[str, int]]:
    """The (file name, line) pairs an error's line names."""
    return {(f.rsplit("/", 1)[-1], int(n))
            for f, n in re.findall(r"([\w./-]+\.yaml):(\d+)", str(err))}


@pytest.mark.parametrize("case, change, message", [
    ("unknown port", ("connect: {base: fixed_frame}", "connect: {base: fixed_frame, top: x}"),
     "no external port 'top'"),
    ("unconnected port", ("connect: {base: fixed_frame}", "connect: {}"),
     "external port 'base' \\(external body\\) is not connected"),
    ("wrong parameter", ("parameters: {m: 1.0}", "parameters: {mass: 1.0}"),
     "has no parameter 'mass'"),
    ("wrong constant", ("parameters: {m: 1.0}", "constants: {len: 1.0}"),
     "has no constant 'len'"),
    ("bond to a body port", ("outputs:\n  y: t\n",
                             "elements:\n  r: {type: R, R: 1}\nbonds:\n  - [p.base, r]\n"),
     "port 'base' of instance 'p' .* is a external body port"),
])
def test_an_instance_error_names_the_instance_and_the_definition(case, change, message):
    text = model("  p:\n    component: pendulum\n    parameters: {m: 1.0}\n"
                 "    connect: {base: fixed_frame}\n", "outputs:\n  y: t\n")
    lines = text.splitlines()
    instance, definition = lines.index("  p:") + 1, lines.index("  pendulum:") + 1
    with pytest.raises(ModelError, match=message) as err:
        loads(text.replace(*change), "row.yaml")
    assert "\n" not in str(err.value)
    assert {("row.yaml", instance), ("row.yaml", definition)} <= where(err.value), case


def test_a_clash_and_an_unknown_component_name_where():
    text = model("  p:\n    component: pendulum\n    connect: {base: fixed_frame}\n",
                 "outputs:\n  p_1: t\n")
    lines = text.splitlines()
    with pytest.raises(ModelError, match="duplicate name 'p_1'") as err:
        loads(text.replace("  p:\n", "  p:\n    for: {i: [1, 2]}\n"), "row.yaml")
    assert {("row.yaml", lines.index("  p:") + 1),
            ("row.yaml", lines.index("  p_1: t") + 2)} <= where(err.value)
    with pytest.raises(ModelError, match="unknown component 'pendula'.*the library's: "
                                         "ball_screw, dc_motor"):
        loads(text.replace("component: pendulum", "component: pendula"), "row.yaml")


def test_a_missing_file_and_a_cycle_name_both_places(tmp_path):
    path = tmp_path / "m.yaml"
    path.write_text("name: m\nuses:\n  strut: parts.yaml\ninstances:\n"
                    "  s: {component: strut}\n")
    with pytest.raises(ModelError, match="no such component file") as err:
        load(path)
    assert {("m.yaml", 3), ("m.yaml", 5)} <= where(err.value)
    path.write_text("name: m\ncomponents:\n  a:\n    instances:\n      x: {component: b}\n"
                    "  b:\n    instances:\n      y: {component: a}\ninstances:\n"
                    "  top: {component: a}\n")
    with pytest.raises(ModelError, match=r"a cycle of components: a \(.*m.yaml:3\) -> "
                                         r"b \(.*m.yaml:6\) -> a"):
        load(path)


def test_a_bond_must_draw_power_the_way_a_port_says():
    text = ("name: m\ninstances:\n  motor: {component: dc_motor}\nelements:\n"
            "  u: {type: Se, effort: 12}\n  load: {type: R, R: 0.1}\n"
            "bonds:\n  - [u, motor.electric]\n  - [motor.shaft, load]\n")
    assign(expand(loads(text)))
    with pytest.raises(ModelError, match="port 'motor.shaft' takes power out, but this "
                                         "bond draws it in"):
        loads(text.replace("[motor.shaft, load]", "[load, motor.shaft]"))


def test_a_value_a_reader_refuses_in_a_component_names_the_instance_too():
    with pytest.raises(ModelError) as err:
        loads(model("  p:\n    component: pendulum\n    parameters: {m: -1.0}\n"
                    "    connect: {base: fixed_frame}\n"), "row.yaml")
    assert "(in p (row.yaml:" in str(err.value) and str(err.value).startswith("row.yaml:")


def test_dotted_names_become_identifiers_and_back_without_collisions():
    names = ["a", "a.b", "a_.b", "a._b", "a_0.b", "leg_1.hinge__rx", "x.y.z", "a__x", "_",
             "a_b", "a.b_c", "ab.c", "a.bc"]
    idents = [symbols.ident(n) for n in names]
    assert len(set(idents)) == len(names)
    assert all(re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", i) for i in idents)
    assert all(symbols.name(symbols.ident(n)) == n for n in names)
    s = symbols.ref("leg_1.hinge__rx", "q")
    assert s.name == "REF_leg_1__0hinge__rx__q"
    assert symbols.split_ref(s) == ("leg_1.hinge__rx", "q")


def test_bgc_library_lists_components_with_ports_and_parameters():
    from bgc.cli import main
    r = CliRunner().invoke(main, ["library", "--json"])
    assert r.exit_code == 0, r.output
    comps = {c["name"]: c for c in json.loads(r.output)["components"]}
    assert {"dc_motor", "gear", "ball_screw", "pi_servo", "pid_servo", "spring_damper",
            "strut", "sarib_leg", "sarib_leg_semiactive", "four_bar_window"} <= set(comps)
    for c in comps.values():
        assert set(c) >= {"name", "ports", "parameters", "description"}
    assert {p["name"]: p["kind"] for p in comps["dc_motor"]["ports"]} == {
        "electric": "element", "shaft": "element"}
    assert {p["name"] for p in comps["dc_motor"]["parameters"]} == {
        "R_a", "L_a", "k_t", "J_m", "b_m"}
    r = CliRunner().invoke(main, ["library", "nope"])
    assert r.exit_code == 2 and "no component 'nope'" in r.output


def _leg_names(name: str) -> str:
    """A name of the SARIB written out as the assembly names it."""
    for old, new in (("beater_", "leg_{}.beater"), ("bar_bottom_", "leg_{}.bar_bottom"),
                     ("bar_top_", "leg_{}.bar_top"), ("bar_", "leg_{}.bar"),
                     ("hinge_", "leg_{}.hinge")):
        if name.startswith(old) and name[len(old):].isdigit():
            return new.format(name[len(old):])
    return name


def test_the_sarib_assembled_from_the_library_leg_is_the_sarib_written_out():
    """Bodies (mass, moments, frame, centre of mass), joints (kind, bodies, point,
    frame, output frame, springs) and outputs: equal to the digits of the file written
    out (1e-9 m), every leg at its azimuth."""
    flat = load(ROOT / "tests" / "model" / "sarib_written_out.yaml")
    asm = load(MODELS / "sarib.yaml")
    assert {_leg_names(n) for n in flat.bodies} == set(asm.bodies)
    assert {_leg_names(n) for n in flat.joints} == set(asm.joints)
    for n, b in flat.bodies.items():
        a = asm.bodies[_leg_names(n)]
        assert (a.mass, *a.inertia) == pytest.approx((b.mass, *b.inertia), rel=1e-12)
        assert str(a.mass_expr) == str(b.mass_expr)
        assert np.allclose(a.com, b.com, atol=1e-9) and np.allclose(a.frame, b.frame,
                                                                     atol=1e-9), n
    for n, j in flat.joints.items():
        k = asm.joints[_leg_names(n)]
        assert (k.kind, k.body1, k.body2) == (j.kind, j.body1 and _leg_names(j.body1),
                                              j.body2 and _leg_names(j.body2))
        assert np.allclose(k.at, j.at, atol=1e-9), n
        # a spherical joint measures its blocked translations along R0 and has no free
        # direction with an element: its frame (the leg's, in the assembly; R0's written
        # out) is in no equation
        assert k.kind == "spherical" or np.allclose(k.frame, j.frame, atol=1e-9), n
        assert (k.output_frame is None) == (j.output_frame is None)
        if j.output_frame is not None:
            assert np.allclose(k.output_frame, j.output_frame, atol=1e-9)
        for lab, f in j.functional.items():
            g = k.functional[lab]
            assert str(g.preload) == str(f.preload) and (g.k, g.c) != (None, None)
    assert [o.name for o in asm.outputs] == [o.name for o in flat.outputs]
    # the psi_i azimuth, exactly: leg 2's hinge at 0.30 (cos 135, sin 135) + 0.05 e_z
    c = 0.3 * math.cos(math.radians(135))
    assert asm.joints["leg_2.hinge"].at == pytest.approx((c, -c, 0.05), abs=1e-16)
