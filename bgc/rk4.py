"""The classical fixed-step Runge-Kutta method of order 4, the paper's explicit
alternative (11.2.5.2: the parasitic method makes an explicit ODE, so RK4 can run it, as
far as its stability region allows: h |lambda| <= 2.78 on the real axis, 2.83 on the
imaginary). The step loop runs in numba and calls the model through its C entry points
(``bgc.native``)."""

from __future__ import annotations

import numpy as np
from numba import njit

from .native import (GUARD, NOT_FINITE, REACHED, ST_RHS, ST_STEPS, evaluate, guard_min)

# the stability region's reach along the negative real axis (2.785) and the imaginary
# axis (2.828), rounded down: a step beyond h |lambda_max| = LIMIT is refused
LIMIT = 2.78


@njit(cache=True)
def rk4(rhs, guards, n_guards, t0, t1, x0, t_eval, p, step, guard_tol, stats):
    """Steps of ``step`` from t0 to t1 (the last one shortened to land on t1); states at
    ``t_eval`` by cubic Hermite interpolation. Stops where the state becomes non-finite
    (beyond the stability limit) or a guard margin reaches ``guard_tol``.

    Returns (states at t_eval, how many were reached, t reached, state there, status,
    guard index, the step)."""
    n = x0.shape[0]
    out = np.empty((t_eval.shape[0], n))
    k_out = 0
    while k_out < t_eval.shape[0] and t_eval[k_out] <= t0:
        out[k_out] = x0
        k_out += 1
    t, y = t0, x0.copy()
    f = evaluate(rhs, t, y, p, n)
    stats[ST_RHS] += 1
    while t < t1:
        h = min(step, t1 - t)
        if t1 - (t + h) < 1e-9 * step:
            h = t1 - t
        k2 = evaluate(rhs, t + 0.5 * h, y + 0.5 * h * f, p, n)
        k3 = evaluate(rhs, t + 0.5 * h, y + 0.5 * h * k2, p, n)
        k4 = evaluate(rhs, t + h, y + h * k3, p, n)
        y_new = y + h / 6.0 * (f + 2.0 * k2 + 2.0 * k3 + k4)
        t_new = t + h if t1 - (t + h) >= 1e-9 * step else t1
        stats[ST_STEPS] += 1
        stats[ST_RHS] += 3
        if not np.all(np.isfinite(y_new)):
            return out, k_out, t, y, NOT_FINITE, -1, step
        f_new = evaluate(rhs, t_new, y_new, p, n)
        stats[ST_RHS] += 1
        while k_out < t_eval.shape[0] and t_eval[k_out] <= t_new:
            s = (t_eval[k_out] - t) / h
            out[k_out] = ((1.0 + 2.0 * s) * (1.0 - s) ** 2 * y + s * s * (3.0 - 2.0 * s)
                          * y_new + s * (1.0 - s) ** 2 * h * f - s * s * (1.0 - s) * h * f_new)
            k_out += 1
        t, y, f = t_new, y_new, f_new
        if guard_tol > 0.0 and n_guards > 0:
            kg, low = guard_min(guards, n_guards, t, y, p, guard_tol)
            if low <= 0.0:
                return out, k_out, t, y, GUARD, kg, step
    return out, k_out, t, y, REACHED, -1, step
