"""The mechanism's constraints at its initial configuration: numerical rank, mobility and
a minimal redundant set (``bgc check``), from the joints' blocked directions alone, so the
same for every constraint method.

Each blocked direction's rate is a row on the bodies' twists (``joints.Direction.rows``:
on the velocities of the joint's points and the angular velocities, R0, of its two
bodies), evaluated at the initial pose and moved to each body's centre of mass (a point
P: v_P = v_G + omega x (P - G)). Written on the
coordinates whose rates the simulator's projection measures (v in R0, omega in the body
frame: the momenta's, up to the masses and principal inertias, which the column
equilibration takes out), the rows are scaled and their rank and redundant set taken by
``consistent`` as the projection of a run takes them, so both name the same directions.
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from bgc.graph.expand import position, rotation_matrix
from bgc.mechanics import exact
from bgc.solvers import consistent


def constraint_rows(graph, system) -> tuple[np.ndarray, list[str], int]:
    """The blocked directions' rows at the initial state (one per direction, model order,
    method zcp's imposed directions first: held independent, as the simulator holds
    them), their names, and how many are imposed."""
    bodies = list(graph.bodies)
    col = {b: 6 * k for k, b in enumerate(bodies)}
    env = {}
    for st in system.states:
        try:
            env[st.sym] = sp.Float(float(st.initial.xreplace(
                {s: v for s, _, v in system.params})), 30)
        except (TypeError, ValueError):
            env[st.sym] = sp.Float(0.0)
    frames = {}
    for b in bodies:
        F0 = exact.matrix(graph.bodies[b].frame)
        frames[b] = np.array(F0.tolist(), dtype=np.float64)
        env.update(dict(zip(rotation_matrix(b), F0)))
    centre = {b: np.array([float(env.get(sym, 0.0)) for sym in position(b)])
              for b in bodies}
    rows, names, first = [], [], []
    imposed = set(system.imposed)
    for joint, dirs in graph.joints.items():
        j = graph.model.joints[joint]
        for d in dirs:
            if not d.blocked:
                continue
            name = f"{joint}.{d.label}"
            row = np.zeros(6 * len(bodies))
            for key, vec in d.rows.items():
                body = j.body1 if key.endswith("1") else j.body2
                if body not in col:         # the fixed frame
                    continue
                v = np.array([float(e.xreplace(env)) for e in vec], dtype=np.float64)
                if key.startswith("w"):     # omega in R0 = R omega_body
                    row[col[body] + 3:col[body] + 6] += v @ frames[body]
                else:                       # the point's velocity: v_G + omega x r
                    row[col[body]:col[body] + 3] += v
                    r = np.asarray(j.at, dtype=np.float64) - centre[body]
                    row[col[body] + 3:col[body] + 6] += np.cross(r, v) @ frames[body]
            (first if name in imposed else rows).append((row, name))
    both = first + rows
    J = np.array([r for r, _ in both]).reshape(len(both), 6 * len(bodies))
    return J, [n for _, n in both], len(first)


def analyse(graph, system) -> dict:
    """``rank``, ``mobility`` (coordinates minus rank), ``redundant`` (a minimal set:
    constraints - rank names) and the counts, at the initial configuration."""
    J, names, imposed = constraint_rows(graph, system)
    Je = consistent.equilibrate(J)
    rank = consistent._rank(Je)
    coords = 6 * len(graph.bodies)
    return {"coordinates": coords, "constraints": len(names), "rank": rank,
            "mobility": coords - rank,
            "redundant": consistent._dependent(Je, names, rank, imposed)}
