"""``bgc report`` (and ``bgc simulate --report``): one self-contained HTML page of a run.

The page holds the run's numbers and draws them with plotly.js, bundled inline from the
``plotly`` package (its offline bundle, ``package_data/plotly.min.js``; no CDN, no
network request): zoomable time histories, each chirp envelope with its minima, the
sweep's transients and the frequency response's anti-resonances, the FRF's magnitude and
phase, the modes, and the mechanism in 3D playing the run and each mode shape.

What the page embeds, ``collect``'s dict (``<script id="bgc-data">``, JSON):
- ``time``: every output time and every output at full precision (float64, base64): the
  page decimates what it draws to the visible window (min and max per pixel column),
  never the numbers; a test reads them back against the CSV.
- ``animation``: the drawn points' displacements from the reference pose at a subset of
  the output times (every ``stride``-th row, float32, base64: the picture, not numbers).
- ``mechanism``: the drawn points at the reference pose, which body each belongs to, the
  joints; ``modes``: each mode's frequency, damping, kind, bodies and its shape as the
  points' complex displacement (first order, ``mechanism.Mechanism.displacement``).
- ``envelopes``, ``frf``: the curves and the frequencies marked on them.
"""

from __future__ import annotations

import base64
import json
import math
from importlib import resources
from pathlib import Path

import numpy as np

from bgc.fileio import atomic_write

MAX_FRAMES = 6000       # animation frames at most (the SARIB's 28 s: every 5th ms)
MAX_MODES = 60          # rows of the modes table at most
RUN_SHARE = 0.08        # the run's largest displacement drawn at this share of the size
LARGE = 0.05            # a motion this large (share of the size) is drawn unmagnified
MODE_SHARE = 0.1        # a mode shape's largest displacement, share of the size


def plotly_js() -> str:
    """plotly.js, the offline bundle of the ``plotly`` package (no import of plotly's
    Python side), made safe to inline in a <script> element."""
    js = resources.files("plotly").joinpath("package_data", "plotly.min.js").read_text(
        encoding="utf-8")
    return js.replace("</script", "<\\/script")


def _plain(v):
    """A number for JSON: int or float (NaN and inf: None)."""
    if v is None or isinstance(v, (bool, np.bool_)):
        return None if v is None else bool(v)
    if isinstance(v, (int, np.integer)):
        return int(v)
    return float(v) if math.isfinite(v) else None


def _b64(a, dtype) -> str:
    return base64.b64encode(np.ascontiguousarray(a, dtype=dtype).tobytes()).decode("ascii")


def _sig(values, digits: int = 7) -> list:
    """Floats rounded to ``digits`` significant digits, for JSON (NaN/inf: None)."""
    out = []
    for v in np.asarray(values, dtype=float).ravel():
        out.append(float(f"{v:.{digits}g}") if math.isfinite(v) else None)
    return out


def collect(module, model, result, p, method: str, title: str, excitation: dict | None,
            curves: dict | None, view, linear_error: str | None, explained: dict | None,
            units: dict, floor: dict, noise: dict) -> dict:
    """The page's data (see the module's doc) for a run: its module and Model, Result,
    parameters ``p``, method, the excitation chosen, the chirp's envelopes (``curves``),
    the linear picture (``view``: ``linear.LinearView``, or None and why), the minima
    explained (``envelope.explain``), units, noise floors and the outputs that are
    noise."""
    from bgc.analysis import mechanism as mech_mod
    stats = result.stats.to_dict()
    data = {
        "title": title, "model": module.MODEL_NAME, "method": method,
        "solver": result.solver, "excitation": excitation,
        "t_end": float(result.t[-1]) if len(result.t) else 0.0,
        "stats": {k: _plain(v) for k, v in stats.items()
                  if v is None or isinstance(v, (int, float, np.integer, np.floating))},
        "message": getattr(result, "message", None),
        "linear_error": linear_error,
    }
    data["time"] = {
        "t": _b64(result.t, "<f8"), "n": int(len(result.t)),
        "outputs": [{"name": n, "unit": units.get(n), "noise": noise.get(n),
                     "floor": floor.get(n), "data": _b64(result.column(n), "<f8")}
                    for n in result.output_names]}
    mech = mech_mod.of_model(model, module, p) if model is not None and model.bodies \
        else None
    if mech is not None and mech.bodies:
        data["mechanism"], data["animation"] = _mechanism(mech, result)
    data["envelopes"] = _envelopes(curves, view, explained, excitation, model, units, floor,
                                   p, module) if curves is not None else []
    data["frf"] = _frf(view, units) if view is not None and view.direction else None
    data["modes"] = _modes(view, mech) if view is not None else []
    data["band"] = [float(view.f[0]), float(view.f[-1])] \
        if view is not None and len(view.f) else None
    return data


def _mechanism(mech, result) -> tuple[dict, dict]:
    """The drawn points at the reference pose (the run's start) and the run's frames."""
    ref = mech.points(result.x[0])[0]
    bodies, k = [], 0
    for b in mech.bodies:
        bodies.append({"name": b.name, "first": k, "count": len(b.offsets),
                       "labels": b.labels, "mass": b.mass})
        k += len(b.offsets)
    joints = []
    for j in mech.joints:
        ends = [e for e in (j["body2"], j["body1"]) if e is not None]
        joints.append({"name": j["name"], "kind": j["kind"],
                       "point": ends[0][1] if ends else None,
                       "at": _sig(j["at"]), "grounded": None in (j["body1"], j["body2"])})
    stride = max(1, math.ceil(len(result.t) / MAX_FRAMES))
    rows = np.arange(0, len(result.t), stride)
    disp = mech.points(result.x[rows]) - ref[None]
    size = mech.size()
    dmax = float(np.abs(disp).max(initial=0.0))
    magnify = 1.0 if dmax == 0 or dmax > LARGE * size else _nice(RUN_SHARE * size / dmax)
    return ({"ref": _sig(ref, 9), "bodies": bodies, "joints": joints, "size": size},
            {"stride": int(stride), "frames": int(len(rows)), "t": _b64(result.t[rows], "<f8"),
             "disp": _b64(disp, "<f4"), "dmax": dmax, "magnify": magnify})


def _nice(x: float) -> float:
    """``x`` rounded down to 1, 2 or 5 times a power of ten."""
    e = 10 ** math.floor(math.log10(x))
    return max(m for m in (1, 2, 5, 10) if m * e <= x * (1 + 1e-12)) * e


def _envelopes(curves, view, explained, exc, model, units, floor, p, module) -> list:
    """Each chirp envelope with its minima (explained or the sweep's transients), the
    FRF's anti-resonances and, where the linear picture exists, the steady state it
    predicts (amplitude times |H|)."""
    gain = _chirp_gain(model, exc, p, module) if view is not None else None
    out = []
    for name, (f, a, mins) in curves.items():
        quiet = name in floor and not a.max(initial=0.0) >= floor[name]
        item = {"name": name, "unit": units.get(name), "f": _sig(f), "amp": _sig(a),
                "minima": _sig(mins), "noise": float(a.max(initial=0.0)) if quiet else None}
        if explained and name in explained:
            item["anti"], item["transients"] = map(_sig, explained[name])
        if view is not None and name in view.anti:
            item["frf_anti"] = _sig(view.anti[name])
            k = list(view.lin.output_names).index(name)
            if gain is not None and len(view.f):
                item["steady"] = _sig(gain * np.interp(f, view.f, np.abs(view.H[:, k])))
        out.append(item)
    return out


def _chirp_gain(model, exc, p, module) -> float | None:
    """The excitation's amplitude times the chirp's own (|g| at full sweep): what |H|
    is multiplied by in the steady state; None where it cannot be read."""
    if not exc or model is None or model.excitation is None:
        return None
    try:
        import sympy as sp

        from bgc.model import symbols
        sig = model.excitation.kinds[exc["kind"]]
        t = sp.Symbol("t")
        expr = sig.expr.xreplace({symbols.param(n): float(v)
                                  for n, v in zip(module.PARAM_NAMES, p)})
        syms = [s for s in expr.free_symbols if s.name == "t"]
        fn = sp.lambdify(syms[0] if syms else t, expr, "numpy")
        n = sig.numbers
        ts = np.linspace(n["t2"], n["t2"] + 4.0 / min(n["f_start"], n["f_end"]), 4001)
        g = float(np.abs(np.asarray(fn(ts), dtype=float)).max())
        return float(exc["amplitude"]) * g if math.isfinite(g) else None
    except Exception:           # the overlay is a help, never a reason to fail the page
        return None


def _frf(view, units) -> dict:
    """Magnitude and phase of every output's response, its anti-resonances, the peaks of
    |H| and the resonances (the modes behind them)."""
    outs = []
    for k, name in enumerate(view.lin.output_names):
        if name not in view.anti:
            continue
        h = view.H[:, k]
        outs.append({"name": name, "unit": units.get(name), "mag": _sig(np.abs(h), 6),
                     "phase": _sig(np.degrees(np.unwrap(np.angle(h))), 6),
                     "anti": _sig(view.anti[name]), "res": _sig(view.res[name]),
                     "peaks": _sig(view.peaks[name])})
    return {"input": view.direction, "f": _sig(view.f), "outputs": outs}


def _modes(view, mech) -> list:
    """The modes table and shapes: the functional and overdamped modes, and the
    parasitic ones up to three times the band's top (MAX_MODES at most), lowest first;
    each shape as the drawn points' complex displacement, largest 1."""
    top = 3 * float(view.f[-1]) if len(view.f) else math.inf
    shown = [m for m in view.modal.modes if m.kind != "parasitic" or m.frequency_hz <= top]
    out = []
    for m in shown[:MAX_MODES]:
        item = {"frequency_hz": m.frequency_hz, "damping_ratio": m.damping_ratio,
                "kind": m.kind, "bodies": [{"name": n, "share": s} for n, s in m.bodies]}
        if mech is not None and mech.bodies:
            d = mech.displacement(m.shape)
            big = float(np.abs(d).max(initial=0.0))
            d = d / big if big > 0 else d
            item["re"], item["im"] = _sig(d.real, 6), _sig(d.imag, 6)
        out.append(item)
    return out


def write(path: str | Path, data: dict) -> Path:
    """The page: the template with plotly.js and the data inlined, written atomically."""
    import jinja2
    env = jinja2.Environment(
        loader=jinja2.PackageLoader("bgc.analysis", "templates"),
        autoescape=jinja2.select_autoescape(["html", "j2"]), keep_trailing_newline=True)
    # JSON inside <script>: no "<" that could close it (a model's name, a unit)
    payload = json.dumps(data, separators=(",", ":"), allow_nan=False).replace("<", "\\u003c")
    html = env.get_template("report.html.j2").render(
        title=data["title"], data=jinja2.utils.markupsafe.Markup(payload),
        plotly=jinja2.utils.markupsafe.Markup(plotly_js()))
    return atomic_write(path, lambda tmp: Path(tmp).write_text(html, encoding="utf-8"),
                        "report")
