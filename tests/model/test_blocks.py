"""The ``blocks:`` section read and checked (issue 26, item 3), no compile: each kind's
input, values and limits as expressions of parameters; who may read ``block.y``; and
every mistake refused on one line naming its line and key."""

from __future__ import annotations

import pytest

from bgc.errors import ModelError
from bgc.model import symbols
from bgc.model.load import loads

MODEL = """\
name: loop
parameters:
  x_set: 1.0
  kp: 40.0
  ki: 300.0
  U: 24.0
  T_f: 0.01
elements:
  drive: {{type: MSe, effort: {effort}}}
  R: {{type: R, R: 2.0}}
  pos: {{type: C, k: 0}}
  node: {{type: "1"}}
bonds:
  - [drive, node]
  - [node, R]
  - [node, pos]
blocks:
{blocks}
outputs:
  volts: ctrl.y
"""
CTRL = '  ctrl: {type: PI, input: "x_set - pos.q", kp: kp, ki: ki, limits: [-U, U]}'
P, REF = symbols.param, symbols.ref


def _load(blocks=CTRL, effort="ctrl.y", **over):
    return loads(MODEL.format(blocks=blocks, effort=effort), "loop.yaml", over or None)


def _refused(blocks, effort="ctrl.y", line_of=None, **over) -> ModelError:
    """The error of a model whose ``blocks:`` lines are ``blocks``; its line is the one
    holding ``line_of`` (default: the last block's)."""
    text = MODEL.format(blocks=blocks, effort=effort)
    with pytest.raises(ModelError) as info:
        loads(text, "loop.yaml", over or None)
    err = info.value
    marker = line_of or blocks.splitlines()[-1]
    assert err.loc.line == next(i for i, ln in enumerate(text.splitlines(), 1)
                                if marker in ln), str(err)
    assert "\n" not in str(err)
    return err


def test_every_kind_read_with_its_values_as_expressions_of_parameters():
    m = _load(CTRL + """
  err: {type: sum, inputs: [x_set, -pos.q]}
  k1: {type: gain, input: err.y, k: 2 * kp}
  f1: {type: lag, input: k1.y, T: T_f, y0: 0.5}
  i1: {type: integrator, input: "f1.y - R.f", limits: [-1, 1]}
  pid: {type: PID, input: err.u, kp: kp, ki: ki, kd: 0.1, tt: 0.02, x0: U / 2}""")
    assert list(m.blocks) == ["ctrl", "err", "k1", "f1", "i1", "pid"]
    ctrl, err, k1, f1, i1, pid = m.blocks.values()
    assert ctrl.input == P("x_set") - REF("pos", "q")
    assert ctrl.values == {"kp": P("kp"), "ki": P("ki")}
    assert ctrl.limits == (-P("U"), P("U")) and ctrl.anti_windup
    assert err.input == P("x_set") - REF("pos", "q")
    assert k1.values["k"] == 2 * P("kp") and k1.input == REF("err", "y")
    assert f1.values == {"T": P("T_f"), "k": 1} and f1.initial == 0.5
    assert i1.values == {"k": 1} and i1.limits == (-1, 1) and i1.initial == 0
    assert pid.values == {"kp": P("kp"), "ki": P("ki"), "kd": 0.1, "n": 10, "tt": 0.02}
    assert pid.initial == P("U") / 2 and pid.input == REF("err", "u")
    assert m.elements["drive"].fields["effort"] == REF("ctrl", "y")
    assert m.outputs[0].expr == REF("ctrl", "y")


@pytest.mark.parametrize("kind", ["MSf", "MTF", "MGY"])
def test_modulated_elements_read_a_block(kind):
    key = {"MSf": "flow", "MTF": "ratio", "MGY": "r"}[kind]
    text = MODEL.format(blocks=CTRL, effort="1.0").replace(
        "  R: {type: R, R: 2.0}",
        f"  R: {{type: R, R: 2.0}}\n  m: {{type: {kind}, {key}: 1 + ctrl.y}}")
    if kind != "MSf":
        text = text.replace("  - [node, R]", "  - [node, m]\n  - [m, R]")
    else:
        text = text.replace("  - [node, R]", "  - [node, R]\n  - [m, node]")
    assert loads(text, "loop.yaml").elements["m"].fields[key] == 1 + REF("ctrl", "y")


@pytest.mark.parametrize("kind,key", [("Se", "effort"), ("Sf", "flow"), ("TF", "ratio"),
                                      ("GY", "r")])
def test_unmodulated_elements_refuse_a_block(kind, key):
    text = MODEL.format(blocks=CTRL, effort="1.0").replace(
        "  R: {type: R, R: 2.0}", f"  R: {{type: R, R: 2.0}}\n  s: {{type: {kind}, {key}: ctrl.y}}")
    with pytest.raises(ModelError, match="references 'name.attr' are not allowed here") as e:
        loads(text, "loop.yaml")
    assert e.value.key == f"elements.s.{key}"


@pytest.mark.parametrize("blocks,key,message,hint", [
    ("  c: {type: PIDD, input: x_set}", "blocks.c.type", "unknown block type 'PIDD'",
     "valid types: gain, sum, integrator, lag, PI, PID"),
    ("  c: {type: gain, k: 2}", "blocks.c", "missing 'input'", "input:"),
    ("  c: {type: sum}", "blocks.c", "missing 'inputs'", "inputs:"),
    ("  c: {type: gain, input: x_set}", "blocks.c", "missing 'k'", "needs k"),
    ("  c: {type: gain, input: nope.y, k: 1}", "blocks.c.input", "'nope.y' names no element",
     "block.y"),
    ("  c: {type: sum, inputs: [x_set, -nope.y]}", "blocks.c.inputs[1]",
     "'nope.y' names no element", "block.y"),
    ("  c: {type: gain, input: ctrl.x, k: 1}", "blocks.c.input", "block 'ctrl' has no '.x'",
     "ctrl.y"),
    ("  c: {type: gain, input: x_set, k: 1, gain: 2}", "blocks.c.gain", "unknown key 'gain'",
     "valid keys"),
    ("  c: {type: lag, input: x_set, T: 0}", "blocks.c.T", "T = 0: a time constant must be > 0",
     "gain block"),
    ("  c: {type: lag, input: x_set, T: -T_f}", "blocks.c.T", "T = -0.01", "positive"),
    ("  c: {type: PI, input: x_set, kp: 1, ki: 1, tt: -1, limits: [0, 1]}", "blocks.c.tt",
     "tt = -1", "positive"),
    ("  c: {type: PI, input: x_set, kp: 1, ki: 1, limits: [U, -U]}", "blocks.c.limits",
     "limits [24, -24]", "lo < hi"),
    ("  c: {type: PI, input: x_set, kp: 1, ki: 1, limits: [1, 1]}", "blocks.c.limits",
     "lower limit must be below", "lo < hi"),
    ("  c: {type: PI, input: x_set, kp: 1, ki: 1, limits: [1]}", "blocks.c.limits",
     "'limits' is a list [lo, hi]", "limits:"),
    ("  c: {type: PI, input: x_set, kp: 0, ki: 1, limits: [0, 1]}", "blocks.c.ki",
     "tracking time Ti = kp/ki", "tt"),
    ("  c: {type: PI, input: x_set, kp: 1, ki: 1, anti_windup: clamp}",
     "blocks.c.anti_windup", "unknown anti_windup 'clamp'", "back_calculation, none"),
    ("  c: {type: PID, input: x_set, kp: 1, ki: 1, kd: 0}", "blocks.c.kd",
     "time constant kd/(kp n)", "PI block"),
    ("  c: {type: gain, input: x_set, k: 1, x0: 1}", "blocks.c.x0", "unknown key 'x0'",
     "valid keys"),
    ("  c: {type: integrator, input: x_set, k: kq}", "blocks.c.k", "unknown name 'kq'", "kp"),
    ("  R: {type: gain, input: x_set, k: 1}", "blocks.R", "duplicate name 'R'", "element"),
])
def test_mistakes_are_refused_on_one_line(blocks, key, message, hint):
    err = _refused(CTRL + "\n" + blocks)
    assert err.key == key and message in err.message and hint in err.hint


def test_a_cycle_of_blocks_without_state_is_refused_naming_them():
    err = _refused(CTRL + """
  s: {type: sum, inputs: [x_set, -g.y]}
  g: {type: gain, input: s.y, k: 2}""", line_of="  s: {type: sum")
    assert err.message.startswith("algebraic loop through blocks s, g")
    assert "lag or an integrator" in err.hint
    # a PI reads its input directly too; a lag between them breaks the loop
    _refused(CTRL + "\n  c2: {type: PI, input: 'x_set - c2.y', kp: 1, ki: 1}",
             line_of="  c2:")
    assert "c3" in _load(CTRL + """
  c3: {type: PI, input: "x_set - lp.y", kp: 1, ki: 1}
  lp: {type: lag, input: c3.y, T: 0.1}""").blocks


def test_minus_p_values_are_checked_as_the_file_s():
    assert _load(CTRL + "\n  lp: {type: lag, input: x_set, T: T_f}", T_f=0.5).blocks
    err = _refused(CTRL + "\n  lp: {type: lag, input: x_set, T: T_f}", T_f=0.0)
    assert err.key == "blocks.lp.T"
    assert _refused(CTRL, U=-1.0).key == "blocks.ctrl.limits"


def test_a_clamping_integrator_starts_within_its_limits():
    ok = "\n  i1: {type: integrator, input: x_set, limits: [-1, 1], y0: 0.5}"
    assert _load(CTRL + ok).blocks["i1"].initial == 0.5
    err = _refused(CTRL + ok.replace("y0: 0.5", "y0: 2"))
    assert err.key == "blocks.i1.y0" and "outside the limits" in err.message
