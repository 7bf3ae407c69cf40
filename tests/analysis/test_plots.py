"""Plots that tell the truth (issue 27, item 6), on synthetic arrays and figures (no model,
no solver): which outputs are numerical noise, that noise has no envelope minima and is
stated rather than drawn, that minima labels cannot overlap, that every axis has a unit."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from bgc.analysis import noise
from bgc.analysis.envelope import analyse
from bgc.analysis.results import mark_minima, panels, plot, plot_envelopes
from bgc.model.signals import chirp_frequency
from bgc.simulate import Result

CHIRP = {"t1": 0.5, "t2": 1.0, "t3": 11.0, "f_start": 1.0, "f_end": 6.0}
UNITS = {"F_z": "N", "F_y": "N", "a_z": "m/s^2", "free": None}


def _run(scale: float = 1.0) -> Result:
    """A chirp response: F_z (N, 300 with a dip at 3 Hz), F_y (N, 5e-9 of round-off),
    a_z (m/s^2, alone in its unit, 1e-9), free (no unit, 1e-12); forces times ``scale``."""
    t = np.linspace(0.0, 11.0, 22001)
    f = chirp_frequency(t, CHIRP["t2"], CHIRP["t3"], CHIRP["f_start"], CHIRP["f_end"])
    s = np.sin(2 * np.pi * np.cumsum(f) * (t[1] - t[0]))
    rng = np.random.default_rng(0)
    y = np.column_stack([
        scale * 300.0 * (1 - 0.8 * np.exp(-((f - 3.0) / 0.3) ** 2)) * s,
        scale * 5e-9 * rng.standard_normal(len(t)),
        1e-9 * s, 1e-12 * s])
    return Result(t, np.zeros((len(t), 0)), y, (), tuple(UNITS), "synthetic")


def test_noise_is_below_rtol_times_the_largest_output_of_its_unit():
    r = _run()
    floor, quiet = noise.of_result(r, UNITS, 1e-5)
    assert floor["F_y"] == pytest.approx(3e-3, rel=1e-3) == floor["F_z"]
    assert set(quiet) == {"F_y"} and 4e-9 < quiet["F_y"] < 3e-8
    assert "free" not in floor          # no unit: compared with nothing, never noise
    assert floor["a_z"] == pytest.approx(1e-14, rel=1e-3)   # alone: only itself
    # free of units: forces in kN instead of N classify alike; a tighter rtol resolves more
    assert set(noise.of_result(_run(1e-3), UNITS, 1e-5)[1]) == {"F_y"}
    assert noise.of_result(r, UNITS, 1e-12)[1] == {}


def test_peaks_ignore_nan_and_empty_runs():
    y = np.array([[np.nan, 1.0], [2.0, -3.0]])
    assert list(noise.peaks(y)) == [2.0, 3.0]
    assert noise.peaks(np.zeros((0, 2))).tolist() == [0.0, 0.0]


def test_a_noise_output_has_no_envelope_minima():
    r = _run()
    floor, _ = noise.of_result(r, UNITS, 1e-5)
    curves = analyse(r, CHIRP, floor=floor)
    assert curves["F_y"][2] == []                   # the noise's minima: no anti-resonance
    assert abs(curves["F_z"][2][0] - 3.0) < 0.1     # the real dip is kept
    assert analyse(r, CHIRP)["F_y"][2]              # unfloored, noise shows "minima"


def test_noise_panels_say_so_and_every_axis_has_its_unit(tmp_path, figures):
    r = _run()
    floor, _ = noise.of_result(r, UNITS, 1e-5)
    plot(r, tmp_path / "x.png", units=UNITS, floor=floor)
    plot_envelopes(analyse(r, CHIRP, floor=floor), tmp_path / "e.png", units=UNITS,
                   floor=floor)
    time, env = figures
    assert time["ylabels"] == ["F_z [N]", "F_y [N]", "a_z [m/s^2]", "free"]
    assert time["xlabel"] == "t [s]" and "[Hz]" in env["xlabel"]
    assert env["ylabels"][:3] == ["|F_z| [N]", "|F_y| [N]", "|a_z| [m/s^2]"]
    for fig, what in ((time, "peak"), (env, "envelope at most")):
        [note] = fig["texts"][1]
        assert f"F_y: numerical noise, {what} " in note and " N" in note
        assert fig["lines"][1] == 1                 # the zero line only, no noise drawn
    assert env["texts"][0] and all("Hz" in t for t in env["texts"][0])


@pytest.mark.parametrize("mins", [[18.04, 17.47], [17.99, 18.0], [5.05, 5.1], [24.9, 6.0],
                                  [5.1, 24.97], [24.95, 24.9]])
def test_minima_labels_cannot_overlap(mins):
    fig, axes = panels(1, 2.2)
    ax = axes[0, 0]
    f = np.linspace(5.0, 25.0, 400)
    ax.semilogy(f, 1 + (f - 17.7) ** 2)
    labels = mark_minima(ax, mins)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    boxes = [a.get_window_extent(renderer) for a in labels]
    assert len(boxes) == 2
    for a, b in itertools.combinations(boxes, 2):
        assert not a.overlaps(b), (a, b)
    inside = ax.get_window_extent(renderer)       # near an end of the sweep too
    assert all(inside.x0 <= b.x0 and b.x1 <= inside.x1 for b in boxes), (boxes, inside)
    import matplotlib.pyplot as plt
    plt.close(fig)


def test_the_title_sits_above_every_panel(tmp_path):
    """The figure's title stays clear of every panel (frame, tick labels, axis labels):
    the main job's eight panels put tight_layout's title 2 px into the top one."""
    from bgc.analysis.results import save_figure
    fig, axes = panels(8, 1.9)
    for ax in axes[:, 0]:
        ax.plot([0, 1], [0, 1e4])
        ax.set_ylabel("F [N]")
    save_figure(fig, tmp_path / "t.png", "sarib (zcp, native, chirp pumping)")
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    canvas = FigureCanvasAgg(fig)           # the saved figure, closed: drawn again as saved
    canvas.draw()
    renderer = canvas.get_renderer()
    title = fig._suptitle.get_window_extent(renderer)
    assert title.y0 > max(ax.get_tightbbox(renderer).y1 for ax in axes[:, 0]) + 2


def test_a_dimensionless_unit_and_a_parameters_unit_are_named():
    from bgc.analysis.results import axis_label, parameter_unit
    from bgc.model.load import loads
    assert axis_label("g", "1") == "g [-]" and axis_label("x", None) == "x"
    m = loads("""
name: u
parameters: {m_t: {value: 0.6, unit: kg}, bare: 1.0}
bodies: {b: {mass: m_t, com: [0, 0, 0], inertia: [1, 1, 1]}}
joints:
  j: {type: revolute, between: [fixed_frame, b], at: [0, 0, 0], axis: [1, 0, 0],
      spring: {k: 5.0, c: 0.1}}
""", "u.yaml")
    assert [parameter_unit(m, n) for n in ("m_t", "bare", "j__stiffness", "j__rot_damping",
                                           "j__rx_k", "j__rx_c", "j__tx_load", "nope")] == \
        ["kg", None, "N/m", "N m s/rad", "N m/rad", "N m s/rad", "N", None]
