"""The benchmark charts (PNG, matplotlib without a display)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bgc.analysis.results import panels, save_figure
from bgc.bench.rows import as_number as num

_MARKERS = {"parasitic": "o", "lagrange": "s", "zcp": "^", "augmented": "D"}
_LINES = {"native": "-", "bdf": "--", "radau": "-.", "lsoda": ":", "cvode": (0, (5, 1)),
          "ida": (0, (3, 1, 1, 1)), "rk4": (0, (1, 2))}


def work_precision(rows, path: Path, title: str, note: str = "",
                   xlabel: str = "error against the reference (largest relative output "
                                 "error)", limit: float | None = None) -> Path:
    """Wall time against error, log-log, one series per method x integrator (``limit``:
    a benchmark's limit on the error, drawn as a vertical line)."""
    fig, axes = panels(1, 5.2)
    ax = axes[0, 0]
    series = {}
    for r in rows:
        if r["status"] == "ok" and np.isfinite(r["error"]) and r["error"] > 0:
            series.setdefault((r["method"], r["integrator"]), []).append(
                (r["error"], r["wall_time"]))
    colours = {}
    # colour by integrator; by method where there is only one integrator
    by_method = len({i for _, i in series}) == 1
    for (method, integrator), pts in sorted(series.items()):
        c = colours.setdefault(method if by_method else integrator, f"C{len(colours)}")
        e, w = np.array(sorted(pts, key=lambda q: -q[0])).T
        ax.loglog(e, w, marker=_MARKERS.get(method, "o"), ls=_LINES.get(integrator, "-"),
                  color=c, ms=4, lw=1.1, label=f"{method} / {integrator}")
    if limit is not None:
        ax.axvline(limit, color="0.4", ls="--", lw=0.9, label=f"limit {limit:g}")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("wall time [s]")
    ax.invert_xaxis()
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=3, loc="upper left")
    if note:
        ax.set_title(note, fontsize=7)
    return save_figure(fig, path, title)


def stiffness(rows, path: Path, title: str) -> Path:
    """Parasitic stiffness sweep: error against time, one series per stiffness, each
    point labelled with its tolerance."""
    fig, axes = panels(1, 5.0)
    ax = axes[0, 0]
    by_k = {}
    for r in rows:
        if r["status"] == "ok" and np.isfinite(r["error"]):
            by_k.setdefault(r["stiffness"], []).append((r["error"], r["wall_time"],
                                                        r["setting"]))
    for i, (k, pts) in enumerate(sorted(by_k.items())):
        e, w, tol = np.array(sorted(pts, key=lambda q: -q[2])).T
        ax.loglog(e, w, marker="o", ms=4, color=f"C{i}", label=f"k = {k:.3g} N/m")
        for ei, wi, ti in zip(e, w, tol):
            ax.annotate(f"{ti:.0e}", (ei, wi), fontsize=6, xytext=(3, 2),
                        textcoords="offset points")
    ax.set_xlabel("error against the ideal-constraint reference")
    ax.set_ylabel("wall time [s]")
    ax.invert_xaxis()
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("each series levels off at its modelling error (falls as 1/k); the "
                 "tolerance is written by each point", fontsize=8)
    return save_figure(fig, path, title)


def rk4_map(rows, path: Path, title: str) -> Path:
    """Stable and unstable RK4 runs over (stiffness, step), with the predicted limits."""
    fig, axes = panels(1, 4.8)
    ax = axes[0, 0]
    k = np.array([r["stiffness"] for r in rows])
    h = np.array([r["step"] for r in rows])
    ok = np.array([r["stable"] for r in rows])
    ax.loglog(k[ok], h[ok], "o", color="C2", label="stable (measured)")
    ax.loglog(k[~ok], h[~ok], "x", color="C3", ms=7, label="unstable (measured)")
    ks = sorted(set(k))
    pred = [next(r["h_predicted"] for r in rows if r["stiffness"] == kk) for kk in ks]
    crude = [next(r["h_278"] for r in rows if r["stiffness"] == kk) for kk in ks]
    ax.loglog(ks, pred, "-", color="k", label="predicted: h lambda on |R(z)| = 1")
    ax.loglog(ks, crude, "--", color="0.5", label="h |lambda_max| = 2.78")
    ax.fill_between(ks, [min(h) / 2] * len(ks), pred, color="C2", alpha=0.08)
    ax.set_xlabel("parasitic stiffness [N/m]")
    ax.set_ylabel("RK4 step [s]")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    return save_figure(fig, path, title)


def drift(history, grid, path: Path, title: str) -> Path:
    """Two panels: |g| against time for each Baumgarte rate (the drift limit, where bgc
    stops); the largest |g| over (alpha, rtol) against the limit."""
    fig, axes = panels(2, 3.6, sharex=False)
    ax = axes[0, 0]
    for i, a in enumerate(sorted({r["alpha"] for r in history})):
        rs = [r for r in history if r["alpha"] == a]
        t = np.array([r["t"] for r in rs])
        g = np.maximum([r["drift"] for r in rs], 1e-18)
        ax.semilogy(t, g, color=f"C{i}", label=f"alpha = {a:g} 1/s")
        stop = rs[0]["bgc_stop"]
        if stop == stop:
            ax.axvline(stop, color=f"C{i}", ls=":", lw=0.8)
    ax.axhline(history[0]["limit"], color="k", ls="--", lw=0.8, label="bgc's drift limit")
    ax.set_ylabel("position drift |g| (m, rad)")
    ax.set_xlabel("t [s]  (dotted: where bgc stops the run)")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    ax = axes[1, 0]
    for i, tol in enumerate(sorted({r["rtol"] for r in grid})):
        rs = sorted((r for r in grid if r["rtol"] == tol), key=lambda r: r["alpha"])
        a = np.array([max(r["alpha"], 0.03) for r in rs])
        ratio = np.array([r["drift"] / r["limit"] for r in rs])
        ax.loglog(a, np.maximum(ratio, 1e-12), "o-", color=f"C{i}", label=f"rtol {tol:g}")
    ax.axhline(1.0, color="k", ls="--", lw=0.8)
    ax.set_xlabel("Baumgarte rate alpha [1/s] (0 drawn at 0.03)")
    ax.set_ylabel("max |g| / drift limit")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path, title)


def growth(rows, path: Path, title: str) -> Path:
    """Operation counts of rhs and jac against the SARIB's legs, per method."""
    fig, axes = panels(1, 4.0)
    ax = axes[0, 0]
    for i, method in enumerate(sorted({r["method"] for r in rows})):
        rs = sorted((r for r in rows if r["method"] == method), key=lambda r: r["legs"])
        legs = [r["legs"] for r in rs]
        ax.plot(legs, [r["ops_rhs"] for r in rs], "o-", color=f"C{i}",
                label=f"{method}: rhs")
        ax.plot(legs, [r["ops_jac"] for r in rs], "s--", color=f"C{i}",
                label=f"{method}: jac")
    ax.set_xlabel("SARIB legs")
    ax.set_ylabel("operations in the generated function")
    ax.set_xticks([1, 2, 3, 4])
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, ncol=2)
    return save_figure(fig, path, title)


def zcp_map(rows, path: Path, title: str) -> Path:
    """Two panels against the tolerance: how far each integrator got into the run, and
    the error of those that finished."""
    fig, axes = panels(2, 3.2)
    for i, name in enumerate(dict.fromkeys(r["integrator"] for r in rows)):
        rs = [r for r in rows if r["integrator"] == name]
        tol = [r["rtol"] for r in rs]
        axes[0, 0].semilogx(tol, [r["fraction"] for r in rs], "o-", color=f"C{i}",
                            label=name)
        ok = [r for r in rs if r["status"] == "ran"]
        if ok:
            axes[1, 0].loglog([r["rtol"] for r in ok], [r["error"] for r in ok], "o-",
                              color=f"C{i}", label=name)
    axes[0, 0].set_ylabel("fraction of the run\ncompleted")
    axes[0, 0].set_ylim(-0.05, 1.05)
    axes[1, 0].set_ylabel("error against the\nopened loops")
    axes[1, 0].set_xlabel("rtol (atol = rtol / 100)")
    for ax in axes[:, 0]:
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    axes[1, 0].invert_xaxis()
    return save_figure(fig, path, title)


def compile_cost(rows, path: Path, title: str) -> Path:
    """Cold time to first result against the model's states, log-log, per method (chains
    joined, the SARIB a star, warm starts hollow), with a line of linear growth from each
    method's smallest chain; below, per method, the cold time of each model split into
    the stages its report gives (without any: the integrator's JIT time from its solver
    statistics), the rest unattributed (interpreter start, imports)."""
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, axes = panels(1 + len(methods), 3.4, sharex=False)
    _cold_against_states(axes[0, 0], rows, methods, num)
    stage_cols = [k for k in dict.fromkeys(k for r in rows for k in r)
                  if k.endswith("_s") and k not in ("cold_s", "warm_s", "cold_jit_s",
                                                    "warm_jit_s")]
    for j, m in enumerate(methods):
        _cold_by_stage(axes[1 + j, 0], [r for r in rows if r["method"] == m], m,
                       stage_cols, num)
    return save_figure(fig, path, title)


def _cold_against_states(ax, rows, methods, num) -> None:
    for i, m in enumerate(methods):
        rs = [r for r in rows if r["method"] == m]
        chains = sorted((r for r in rs if str(r["N"]) != "sarib"), key=lambda r: num(r["N"]))
        pts = [(num(r["states"]), num(r["cold_s"])) for r in chains]
        pts = [(x, y) for x, y in pts if np.isfinite(x) and np.isfinite(y)]
        if pts:
            x, y = np.array(pts).T
            ax.loglog(x, y, marker=_MARKERS.get(m, "o"), color=f"C{i}", label=f"{m}: chain")
            xs = np.array([x[0], max(num(r["states"]) for r in rs)])
            ax.loglog(xs, y[0] * xs / x[0], ":", color=f"C{i}", lw=0.9)
        warm = [(num(r["states"]), num(r["warm_s"])) for r in rs]
        warm = [(x, y) for x, y in warm if np.isfinite(x) and np.isfinite(y)]
        if warm:
            x, y = np.array(warm).T
            ax.loglog(x, y, _MARKERS.get(m, "o"), mfc="none", color=f"C{i}", ms=5,
                      label=f"{m}: warm")
        for r in rs:
            if str(r["N"]) == "sarib" and np.isfinite(num(r["cold_s"])):
                ax.loglog([num(r["states"])], [num(r["cold_s"])], "*", ms=12,
                          color=f"C{i}", label=f"{m}: SARIB")
    for r in rows:
        if str(r["N"]) != "sarib" and np.isfinite(num(r["states"])) and r["method"] == \
                methods[0]:
            ax.annotate(f"N={r['N']}", (num(r["states"]), 0.02), fontsize=6,
                        xycoords=("data", "axes fraction"), ha="center")
    ax.axhline(15.0, color="k", ls="--", lw=0.7)
    ax.axhline(10.0, color="0.5", ls="--", lw=0.7)
    ax.set_xlabel("states")
    ax.set_ylabel("time to first result [s]")
    ax.set_title("dotted: linear growth from the smallest chain; dashed: targets 15 s "
                 "(chain 40), 10 s (SARIB)", fontsize=8)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, ncol=3)


def _cold_by_stage(ax, rs, m, stage_cols, num) -> None:
    x = np.arange(len(rs))
    bottom = np.zeros(len(rs))
    for k, col in enumerate(stage_cols):
        h = np.array([num(r.get(col)) for r in rs])
        h = np.where(np.isfinite(h), h, 0.0)
        if h.any():
            ax.bar(x, h, bottom=bottom, color=f"C{k}", label=col[:-2].replace("_", " "))
            bottom += h
    # a report without stages: its solver statistics' JIT/cache-load time, at least
    jit = np.array([num(r.get("cold_jit_s")) if not bottom[i] else 0.0
                    for i, r in enumerate(rs)])
    jit = np.where(np.isfinite(jit), jit, 0.0)
    if jit.any():
        ax.bar(x, jit, bottom=bottom, color="0.45",
               label="JIT/cache load (solver statistics; no stages reported)")
        bottom += jit
    cold = np.array([num(r["cold_s"]) for r in rs])
    rest = np.where(np.isfinite(cold), np.maximum(cold - bottom, 0.0), 0.0)
    ax.bar(x, rest, bottom=bottom, color="0.8", hatch="//", edgecolor="0.6",
           label="unattributed")
    for xi, r in zip(x, rs):
        if r.get("status", "ok") != "ok":
            ax.annotate(str(r["status"])[:20], (xi, 0), fontsize=6, rotation=90,
                        ha="center", va="bottom")
    ax.set_xticks(x, [f"N={r['N']}" if str(r["N"]) != "sarib" else "SARIB" for r in rs])
    ax.set_ylabel(f"{m}: cold [s]")
    ax.grid(True, axis="y", alpha=0.3)
    ax.legend(fontsize=6, ncol=4)


def startup(row: dict, phases, path: Path, title: str, target: float) -> Path:
    """A small model's warm start to its first result: the phases (wall seconds) as one
    stacked bar beside the command's own median, with the ``target`` [s]."""
    fig, axes = panels(1, 3.4)        # room below the bar for the legend's three rows
    ax = axes[0, 0]
    left = 0.0
    for k, p in enumerate(phases):
        w = float(row.get(f"{p}_s", 0.0))
        ax.barh([1], [w], left=left, color=f"C{k}", label=f"{p.replace('_', ' ')} "
                f"{w:.2f} s")
        left += w
    ax.barh([0], [row["command_s"]], color="0.5",
            label=f"bgc simulate (the command) {row['command_s']:.2f} s")
    ax.axvline(target, color="k", ls="--", lw=0.8)
    ax.set_yticks([0, 1], ["command", "phases"])
    ax.set_xlabel(f"wall time [s] (dashed: target {target} s)")
    ax.grid(True, axis="x", alpha=0.3)
    ax.legend(fontsize=7, ncol=3, loc="upper center", bbox_to_anchor=(0.5, -0.3))
    return save_figure(fig, path, title)
