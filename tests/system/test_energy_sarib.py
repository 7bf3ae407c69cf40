"""The SARIB's energy balance (``bgc energy``, issue 42) under each constraint method
that takes it: pumping excitation (a sine at 10 Hz) over 0.5 s at rtol 1e-6. The balance
closes within 1e-4 of the energy the actuator supplies, the constraints of lagrange and
zcp do no work beyond that, parasitic's springs and dampers have their own lines, the
shares sum to 1, and the methods agree on where the power goes. (Method augmented does
not take the SARIB's bodies of negligible mass: ``tests/analysis/test_energy.py`` checks
its balance on the pendulum.)"""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner
from helpers import MODELS

from bgc.cli import main

SARIB = MODELS / "sarib.yaml"
RUN = ["--excitation", "sine", "--direction", "pumping", "--frequency", "10",
       "--t-end", "0.5", "--rtol", "1e-6", "--atol", "1e-9", "--json", "-q"]


@pytest.fixture(scope="module")
def balances(gen_dir):
    out = {}

    def get(method):
        if method not in out:
            r = CliRunner().invoke(main, ["energy", str(SARIB), "-o", str(gen_dir),
                                          "--method", method, *RUN])
            assert r.exit_code == 0, r.output
            out[method] = json.loads(r.output)
        return out[method]
    return get


@pytest.mark.slow
@pytest.mark.parametrize("method", ["parasitic", "lagrange", "zcp"])
def test_sarib_balance_closes_under_each_method(balances, method):
    data = balances(method)
    els = {e["name"]: e for e in data["elements"]}
    bal = data["balance"]
    supplied = els["attach_pumping.tx.actuator"]["supplied"]
    assert supplied > 0
    assert abs(bal["residual"]) <= 1e-4 * supplied
    assert sum(e["share"] for e in data["elements"]) == pytest.approx(1.0, abs=1e-9)
    sources = [e for e in data["elements"] if e["kind"] == "source" and e["supplied"]]
    assert [e["name"] for e in sources] == ["attach_pumping.tx.actuator"]
    kinds = {e["kind"] for e in data["elements"]}
    if method == "parasitic":
        assert {"parasitic spring", "parasitic damper"} <= kinds
    else:
        work = sum(abs(e["supplied"]) for e in data["elements"] if e["kind"] == "constraint")
        assert work <= 1e-4 * supplied
    groups = {(g["kind"], g["name"]) for g in data["groups"]}
    for body in ("mgb", "fuselage", "leg_1.beater", "leg_4.bar"):   # (the legs: instances)
        assert ("body", body) in groups
    for joint in ("leg_1.hinge", "attach_pumping", "membrane_pumping"):
        assert ("joint", joint) in groups
    assert ("component", "leg_2") in groups


@pytest.mark.slow
def test_sarib_methods_agree_on_where_the_power_goes(balances):
    """The ideal methods within 1e-3 of each other; parasitic within 6 % on the large
    flows: its joints' compliance, at the stiffness the model gives them, moves the
    dampers' shares (the pumping damper's by 5 % at 10 Hz, the membrane's small one by
    8 %; the actuator's supply by 1 %)."""
    ref = {e["name"]: e for e in balances("zcp")["elements"]}
    large = ["attach_pumping.tx.actuator", "attach_pumping.tx.damper", "leg_1.hinge.rx.damper"]
    for method, tol, names in (("lagrange", 1e-3, large + ["membrane_pumping.tx.damper"]),
                               ("parasitic", 6e-2, large)):
        els = {e["name"]: e for e in balances(method)["elements"]}
        for name in names:
            for col in ("supplied", "dissipated"):
                assert els[name][col] == pytest.approx(ref[name][col], rel=tol,
                                                       abs=1e-9), (method, name, col)
