"""A chain of N spatial links: the model whose size a compile-cost benchmark chooses.

Link i (a thin rod, 0.2 m, 0.5 kg) hangs from the previous one (link 0: from the fixed
frame at the origin) on a spherical joint. Each rod starts 30 deg off the vertical, its
azimuth turned 90 deg from the previous one's, so the chain is a helix whose motion
under gravity is spatial from the start and no link is at rest. Every link is the same,
so a compiler that rerolls repeated structure sees one kind of body and one kind of joint
N times; a straight-line one sees N times the code. Written as decimals of 10 significant
digits, as a user would write them (bgc reads frames and poses exactly from those).
"""

from __future__ import annotations

import math
from pathlib import Path

import yaml

from bgc.fileio import atomic_write

LINK, MASS, RADIUS, TILT_DEG = 0.2, 0.5, 0.01, 30.0


def _dec(v: float) -> float:
    """``v`` to 10 significant digits (an exact zero stays 0)."""
    return 0.0 if abs(v) < 1e-15 else float(f"{v:.10g}")


def chain(n: int) -> dict:
    """The model (as YAML data) of a chain of ``n`` >= 1 links."""
    if not (isinstance(n, int) and n >= 1):
        raise ValueError(f"a chain has at least one link, got {n!r}")
    a = math.radians(TILT_DEG)
    bodies, joints = {}, {}
    top = (0.0, 0.0, 0.0)
    for i in range(n):
        phi = math.radians(90.0 * i)
        d = (math.sin(a) * math.cos(phi), math.sin(a) * math.sin(phi), -math.cos(a))
        x = (-d[1], d[0], 0.0)                       # horizontal, normal to the rod
        norm = math.hypot(*x)
        x = tuple(c / norm for c in x)
        y = (d[1] * x[2] - d[2] * x[1], d[2] * x[0] - d[0] * x[2], d[0] * x[1] - d[1] * x[0])
        lateral = MASS * LINK ** 2 / 12.0
        bodies[f"link_{i}"] = {
            "mass": MASS,
            "com": [_dec(top[k] + 0.5 * LINK * d[k]) for k in range(3)],
            "frame": {"x": [_dec(c) for c in x], "y": [_dec(c) for c in y],
                      "z": [_dec(c) for c in d]},
            "inertia": [_dec(lateral), _dec(lateral), _dec(0.5 * MASS * RADIUS ** 2)],
        }
        joints[f"joint_{i}"] = {"type": "spherical",
                                "between": ["fixed_frame" if i == 0 else f"link_{i - 1}",
                                            f"link_{i}"],
                                "at": [_dec(c) for c in top]}
        top = tuple(top[k] + LINK * d[k] for k in range(3))
    tip = f"link_{n - 1}"
    return {
        "name": f"chain_{n}",
        "description": f"A chain of {n} spatial links on spherical joints, a helix at the "
                       f"start, falling under gravity (bgc.bench.chain).",
        "gravity": 9.81,
        "bodies": bodies,
        "joints": joints,
        "outputs": {"tip_x": f"{tip}.x", "tip_y": f"{tip}.y", "tip_z": f"{tip}.z"},
        "simulation": {"t_end": 1.0, "rtol": 1.0e-6, "atol": 1.0e-8, "solver": "native"},
    }


def write_chain(n: int, out_dir: str | Path) -> Path:
    """Write ``chain_<n>.yaml`` into ``out_dir`` (made if missing); its path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"chain_{n}.yaml"
    atomic_write(path, yaml.safe_dump(chain(n), sort_keys=False))
    return path
