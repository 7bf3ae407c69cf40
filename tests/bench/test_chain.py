"""The chain of N spatial links (bgc.bench.chain), the model the compile-cost benchmark
sizes: well formed, the same link N times, and a mechanism that moves in space."""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import bgc as forked_bgc

from bgc.bench.chain import LINK, chain, write_chain
from bgc.model.load import load


def bgc(*args, cwd):
    """``bgc ARGS`` in its own process (``helpers.bgc``: forked from a server that has
    imported bgc; Python's start-up is tested where it is the subject)."""
    return forked_bgc(*map(str, args), cwd=cwd, timeout=600)


@pytest.mark.parametrize("n", [1, 4])
def test_each_link_hangs_from_the_previous_ones_tip(n):
    data = chain(n)
    assert len(data["bodies"]) == len(data["joints"]) == n
    top = np.zeros(3)
    for i in range(n):
        body, joint = data["bodies"][f"link_{i}"], data["joints"][f"joint_{i}"]
        assert np.allclose(joint["at"], top, atol=1e-9)
        frame = np.array([body["frame"][k] for k in "xyz"])
        assert np.allclose(frame @ frame.T, np.eye(3), atol=1e-9)
        axis = frame[2]
        assert np.allclose(body["com"], top + 0.5 * LINK * axis, atol=1e-9)
        assert axis[2] < -0.8                       # hangs, 30 deg off the vertical
        top = top + LINK * axis
    azimuths = [np.arctan2(data["bodies"][f"link_{i}"]["frame"]["z"][1],
                           data["bodies"][f"link_{i}"]["frame"]["z"][0]) for i in range(n)]
    assert len({round(a, 6) for a in azimuths}) == min(n, 4)   # a helix, not a plane


def test_a_chain_of_no_links_is_refused():
    with pytest.raises(ValueError):
        chain(0)


# the counts are the model's (the same under every method): the chain's check under the
# other methods is left to make test-all
@pytest.mark.parametrize("method", ["parasitic"] + [
    pytest.param(m, marks=pytest.mark.slow) for m in ("lagrange", "zcp")])
def test_the_written_chain_loads_and_has_three_dof_per_link(tmp_path, method):
    path = write_chain(3, tmp_path)
    assert load(path).name == "chain_3"
    proc = bgc("check", path, "--method", method, "--json", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    report = json.loads(proc.stdout)
    assert report["bodies"] == 3 and report["dof"] == 9 and report["constraints"] == 9


@pytest.mark.slow       # 3 s: make bench runs the chain in full
def test_the_chain_falls_in_space(tmp_path):
    path = write_chain(2, tmp_path)
    proc = bgc("simulate", path, "--t-end", 0.2, "-o", tmp_path / "gen", "--out",
               tmp_path / "r.csv", "--no-states", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    data = np.genfromtxt(tmp_path / "r.csv", delimiter=",", names=True)
    tip = np.stack([data["tip_x"], data["tip_y"], data["tip_z"]])
    moved = np.abs(tip[:, -1] - tip[:, 0])
    assert np.all(np.isfinite(tip)) and np.all(moved > 1e-3), moved   # every direction
