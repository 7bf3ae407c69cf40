"""Stage **load**, between the YAML and the section readers: a model that is an assembly
of components -> the flat document the readers take (issue 40; the paper's "assembly of
modules ... with a well-structured library of components", 11.6).

A **component** is a named part of a model: parameters (defaults, units), compile-time
``constants``, declared ``ports`` and its own bodies, joints, signals, elements, bonds,
blocks, outputs and nested ``instances``. An **instance** places it (``origin``, ``rotate``:
its frame in the frame of what contains it), overrides its parameters and constants, and
``connect``s its external ports (the bodies its joints attach to, the signals it reads);
the outside joins its exported ports with ordinary joints and bonds. An instance array
(``for: {i: [1, 4]}``) makes ``leg_1`` ... ``leg_4``, the index usable in every key of the
instance.

``flatten`` writes every instance out as if its contents were in the model with their
names prefixed (``leg_2.beater``, ``leg_2.hinge``), placed (positions, axes and frames in
R0, exact: ``bgc.mechanics.exact``), its parameters either its own model parameters
(``leg_2.k_hinge``, changeable by ``-p``) or, where the instance gives an expression of the
outer model's parameters, that expression (so ``-p beater_mass`` reaches every leg without
recompiling). Constants, indices and placements are compile-time: they are in the model's
digest (``bgc.model.library.digest``), numeric parameters are not. The readers then check
everything as in a flat model; a value that came from a component carries an
``InstanceLoc``: its own file:line and the instance's.
"""

from __future__ import annotations

from bgc.model.components.assembler import Assembler
from bgc.model.components.scope import (  # noqa: F401 (the package's interface)
    COMPONENT_KEYS,
    INSTANCE_KEYS,
    MAX_INSTANCES,
    PORT_KINDS,
    Instance,
    InstanceLoc,
    Port,
    QName,
    Scope,
)
from bgc.model.document import YMap
from bgc.model.library import is_assembly


def flatten(doc, file: str, constants: dict | None = None) -> tuple[YMap, dict]:
    """The flat document of a model document and its instances (flat name ->
    Instance); a document without components (and no ``constants`` given) comes back as
    it is. ``constants``: compile-time values given on the command line (``-p N=40``)."""
    if not is_assembly(doc) and not constants:
        return doc, {}
    a = Assembler(file, doc)
    return a.model(doc, constants or {}), a.instances
