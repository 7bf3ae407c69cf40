"""What a run may plan: the step an input signal allows and the most steps bgc will take
(light: read by the warm path of ``bgc simulate``, which loads no sympy)."""

from __future__ import annotations

# An adaptive step is at most a period / STEPS_PER_PERIOD of the fastest input signal
# (``max_step`` of a generated module, whose template holds the same number); a run whose
# plan alone needs more than MAX_PLANNED_STEPS steps (a 1e12 Hz sine over 1 s: 8e12) is
# refused before it starts: at ~1 us a step it would take more than a minute and a
# result that never resolves the signal is no answer.
STEPS_PER_PERIOD = 8
MAX_PLANNED_STEPS = 10 ** 8


def too_fast(frequency: float, t_span: float) -> str | None:
    """Why a signal of ``frequency`` [Hz] cannot be followed over ``t_span`` [s], or None."""
    steps = frequency * t_span * STEPS_PER_PERIOD
    if steps > MAX_PLANNED_STEPS:
        return (f"{frequency:g} Hz over {t_span:g} s needs {steps:.3g} steps "
                f"({STEPS_PER_PERIOD} a period), more than bgc's limit of "
                f"{MAX_PLANNED_STEPS:.0e}")
    return None
