"""The model's excitation as FMU inputs: a Model pass (as ``scene.merge_relays``
is one) that adds to each excitation direction's actuator a parameter of its own,
``excitation__<direction>_input``, the force (N) or moment (N m) a tool applies along that
direction on top of the model's own g(t). The FMU lists these as inputs; at 0 the model
is the one ``bgc simulate`` runs."""

from __future__ import annotations

from dataclasses import replace

from bgc.model import symbols
from bgc.model.model import Excitation, Model, Parameter


def input_name(direction: str) -> str:
    return f"{Excitation.param(direction)}_input"


def add_inputs(model: Model) -> dict[str, tuple[str, str, str]]:
    """Add the inputs to ``model`` (in place); parameter name -> (the FMU's variable
    name, unit, description)."""
    exc = model.excitation
    if exc is None:
        return {}
    out = {}
    for d, (joint, _) in exc.directions.items():
        j = model.joints[joint]
        amplitude = symbols.param(Excitation.param(d))
        label = next(lb for lb, f in j.functional.items()
                     if f.actuator is not None and f.actuator.has(amplitude))
        name = input_name(d)
        f = j.functional[label]
        j.functional[label] = replace(f, actuator=f.actuator + symbols.param(name))
        unit = "N" if label.startswith("t") else "N m"
        model.parameters[name] = Parameter(name, 0.0, exc.loc, unit)
        what = "force along" if label.startswith("t") else "moment about"
        out[name] = (f"excitation.{d}", unit,
                     f"{what} {label} of joint {joint}, added to the excitation's")
    return out
