"""What a symmetric shortcut costs: the one-leg SARIB (``models/sarib_one_leg.yaml``, the
rig reduced by its four-fold symmetry under pumping) against the full 3D rig, both
parasitic and native Radau over the same tolerances, each error measured against the full
rig at a tight tolerance. The one-leg series falls with the tolerance until it meets its
modelling error (what the symmetry reduction changes: one leg's forces held by stiff
parasitic joints where the rig's legs cancel them); the gap between the series' times is
the speed gain at that accuracy."""

from __future__ import annotations

from dataclasses import replace

from bgc.bench.cases import MODELS, Bench, Scenario
from bgc.bench.precision import work_precision_series

ONE_LEG = MODELS / "sarib_one_leg.yaml"
# the outputs the one-leg model has (leg 1 stands for every leg)
OUTPUTS = ("a_OF_z", "F_A1_x", "F_A1_z")


def one_leg(full: Scenario) -> Scenario:
    """The same question of the one-leg model."""
    return replace(full, name=f"{full.name}_one_leg", model=ONE_LEG, outputs=OUTPUTS,
                   title=f"{full.title}, one leg")


def symmetry(bench: Bench, full: Scenario, tolerances, budget: float) -> list[dict]:
    """Rows (``model`` = the model's name) of the full rig's and the one-leg model's
    series against the full rig's reference (parasitic, rtol = atol = ``full.ref_tol``)."""
    full = replace(full, outputs=OUTPUTS)
    ref, _ = bench.reference(full, "parasitic")
    full_names = list(bench.module(full, "parasitic").OUTPUT_NAMES)
    rows = []
    for scn in (full, one_leg(full)):
        names = bench.module(scn, "parasitic").OUTPUT_NAMES
        # the reference's columns in this model's output order (every one-leg output is
        # one of the rig's)
        scn_ref = ref[:, [full_names.index(k) for k in names]]
        rows += work_precision_series(bench, scn, "parasitic", "native", tolerances, budget,
                                      scn_ref, model=scn.model.stem)
    return rows
