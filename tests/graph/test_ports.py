"""Power ports of the mechanism (issue 26, item 1): a scalar bond reaches a joint's free
direction (``slide.tx``) or a body point along a direction (``cart.P.z``, ``cart.P.d``).
What the load accepts and refuses, what expand makes of a port, how causality reports a
conflict through one, and the joint-direction sensors (``slide.tx.q``). No compile here:
the coupled runs are checked in tests/system/test_coupling.py."""

from __future__ import annotations

import pytest

from bgc.errors import CausalityError, ModelError
from bgc.graph import causality
from bgc.graph.expand import expand
from bgc.model.load import loads

CART = """
name: cart
parameters: {lead: 0.01}
bodies:
  cart: {mass: 2.0, com: [0, 0, 0], inertia: [1, 1, 1], points: {P: [0.1, 0, 0]},
         directions: {d: [1, 1, 0]}}
  arm: {mass: 0.5, com: [0, 0, 0.3], inertia: [0.01, 0.01, 0.001]}
joints:
  slide: {type: prismatic, between: [fixed_frame, cart], at: [0, 0, 0], axis: [1, 0, 0]}
  hinge: {type: revolute, between: [cart, arm], at: [0, 0, 0.2], axis: [0, 0, 1]}
elements:
  Jm: {type: I, I: 1.0e-5}
  screw: {type: TF, ratio: "lead/(2*pi)"}
  k: {type: C, k: 10}
  d: {type: R, R: 0.5}
bonds:
  - [Jm, screw]
  - [screw, slide.tx]
  - [cart.P.d, k]
  - [hinge.rx, d]
"""


def cart(replace=None, extra=""):
    text = CART.replace(*replace) if replace else CART
    return loads(text + extra, "cart.yaml")


def test_ports_load_and_expand_to_junctions():
    m = cart()
    assert set(m.ports) == {"slide.tx", "cart.P.d", "hinge.rx"}
    assert m.ports["slide.tx"].joint == "slide" and m.ports["hinge.rx"].rotational
    assert m.ports["cart.P.d"].body == "cart" and m.ports["cart.P.d"].point == "P"
    g = expand(m)
    # each port is a scalar 1-junction the model's bond now ends on
    assert g.port_junctions == {"slide__tx__1": "slide.tx", "hinge__rx__1": "hinge.rx",
                                "cart__P__d": "cart.P.d"}
    for junction in g.port_junctions:
        assert g.elements[junction].kind == "1"
        assert all(g.bonds[i].dim == 1 for i in g.ports[junction])
    ends = {(b.src, b.dst) for b in g.bonds if b.name in ("b2", "b3", "b4")}
    assert ends == {("screw", "slide__tx__1"), ("cart__P__d", "k"), ("hinge__rx__1", "d")}
    # the point port projects the point's velocity on the body-fixed direction: a row
    # turned by the body's rotation matrix, (1, 1, 0)/sqrt(2) at the initial pose
    row = g.elements["cart__P__d__u"].fields["ratio"]
    assert row.shape == (1, 3) and row.free_symbols
    at_rest = row.xreplace({s: int(s.name[-2] == s.name[-1]) for s in row.free_symbols})
    assert [float(x) for x in at_rest] == pytest.approx([0.5 ** 0.5, 0.5 ** 0.5, 0], abs=1e-16)


def test_port_causality_and_derivative_storage():
    """The screw imposes the mechanism's relative velocity on the rotor inertia: Jm takes
    derivative causality (its momentum follows the cart's), as in any rigid gear train."""
    cg = causality.assign(expand(cart()))
    assert cg.storage["Jm"] == "derivative" and cg.storage["cart__m"] == "integral"


@pytest.mark.parametrize("end, message", [
    ("slide.ty", "port 'slide.ty': a prismatic joint blocks ty"),
    ("slide.qq", "joint 'slide' has no direction 'qq'"),
    ("cart.Q.x", "body 'cart' has no point 'Q'"),
    ("cart.P.w", "no direction 'w' at a point of 'cart'"),
    ("cart.P", "unknown element or port 'cart.P'"),
    ("nowhere.tx", "unknown element or port 'nowhere.tx'"),
])
def test_bad_ports_are_refused_at_their_bond(end, message):
    with pytest.raises(ModelError) as e:
        cart(("[screw, slide.tx]", f"[screw, {end}]"))
    assert message in str(e.value)
    assert e.value.loc.line == CART.splitlines().index("  - [screw, slide.tx]") + 1
    assert e.value.key == "bonds[1]"


def test_a_multibond_cannot_reach_a_port():
    with pytest.raises(ModelError, match="a port of the mechanism is scalar"):
        cart(("  - [screw, slide.tx]", "  - {from: screw, to: slide.tx, dim: 3}"))


def test_a_flow_source_on_a_port_is_the_conflict_reported():
    text = ("  d: {type: R, R: 0.5}", "  d: {type: R, R: 0.5}\n  vs: {type: Sf, flow: 0.1}")
    m = cart(text, "  - [vs, slide.tx]\n")
    with pytest.raises(CausalityError) as e:
        causality.assign(expand(m))
    assert "while assigning source 'vs'" in str(e.value)
    assert "(port slide.tx)" in str(e.value)


def test_a_port_on_a_direction_another_joint_blocks_is_refused():
    extra_joint = ("  hinge:", "  lock: {type: prismatic, between: [fixed_frame, cart], "
                   "at: [0, 0, 0], axis: [0, 1, 0]}\n  hinge:")
    with pytest.raises(ModelError, match="port on direction tx of joint 'slide'"):
        expand(cart(extra_joint))


def test_direction_sensors():
    """slide.tx.q is the geometric displacement (no state); hinge.rx.q integrates the
    rate (a state); .v is the rate; a blocked or unknown direction is refused."""
    from bgc.codegen.equations import derive
    m = cart(extra="outputs:\n  xs: slide.tx.q\n  vs: slide.tx.v\n  th: hinge.rx.q\n"
                   "  om: hinge.rx.v\n")
    system = derive(causality.assign(expand(m)))
    names = [st.name for st in system.states]
    assert "hinge.rx" in names and "slide.tx" not in names
    outs = dict(system.outputs)
    assert "X_cart__x" in {s.name for s in outs["xs"].free_symbols}
    for bad, msg in (("slide.ty.q", "not a free direction of joint 'slide'"),
                     ("slide.tx.e", "joint direction 'slide.tx' has no '.e'")):
        with pytest.raises(ModelError, match=msg):
            cart(extra=f"outputs:\n  y: {bad}\n")


@pytest.mark.parametrize("sensor, message", [
    ("nothing.tx.q", "'nothing.tx' names no point of a body nor a joint's direction"),
    ("cart.Q.x", "'cart.Q' names no point of a body nor a joint's direction"),
    ("hinge.ry.q", "'hinge.ry' is not a free direction of joint 'hinge'"),
    ("hinge.rx.f", "joint direction 'hinge.rx' has no '.f'"),
])
def test_a_sensor_of_nothing_is_refused_at_its_line(sensor, message):
    with pytest.raises(ModelError) as e:
        cart(extra=f"outputs:\n  y: {sensor}\n")
    assert message in str(e.value)
    assert e.value.key == "outputs.y" and e.value.loc.line == len(CART.splitlines()) + 2


def test_two_ports_at_one_point_and_a_direction_named_like_bgcs_parts():
    """A direction called 'point' or 'v' is the model's to name: its port's junction is
    not the point's velocity junction; names with '__' are refused."""
    text = CART.replace("directions: {d: [1, 1, 0]}",
                        "directions: {point: [1, 1, 0], v: [0, 0, 1]}").replace(
        "  - [cart.P.d, k]", "  - [cart.P.point, k]\n  - [cart.P.v, d2]").replace(
        "  d: {type: R, R: 0.5}", "  d: {type: R, R: 0.5}\n  d2: {type: R, R: 0.2}")
    g = expand(loads(text, "cart.yaml"))
    junctions = {port: j for j, port in g.port_junctions.items()}
    assert len({junctions["cart.P.point"], junctions["cart.P.v"]}) == 2
    for j in ("cart.P.point", "cart.P.v"):
        assert g.elements[junctions[j]].kind == "1" and len(g.ports[junctions[j]]) == 2
    causality.assign(g)
    for good, bad in (("directions: {d: [1, 1, 0]}", "directions: {a__b: [1, 0, 0]}"),
                      ("points: {P: [0.1, 0, 0]}", "points: {P__Q: [0.1, 0, 0]}")):
        with pytest.raises(ModelError, match="is not a valid (direction|point) name"):
            cart((good, bad))
