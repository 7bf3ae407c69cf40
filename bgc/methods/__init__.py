"""The ways of handling a blocked joint direction (paper 11.2.5) behind one interface
(``base.ConstraintMethod``): parasitic, lagrange, zcp; and the run-time side of
constraints (``consistent``: consistent initial conditions, drift, rank).

``REGISTRY`` names each method's class; a method's module is imported only when asked
for (``get``), so the run-time side loads no sympy.
"""

from __future__ import annotations

import importlib

from bgc.errors import BgcError

# name -> "module:class", in the order the CLI lists them; the first is the default
REGISTRY = {
    "parasitic": "bgc.methods.parasitic:Parasitic",
    "lagrange": "bgc.methods.lagrange:Lagrange",
    "zcp": "bgc.methods.zcp:Zcp",
    "augmented": "bgc.methods.augmented:Augmented",
}
NAMES = tuple(REGISTRY)
DEFAULT = NAMES[0]
# methods that can keep kinematic loops closed (an index-2 DAE) instead of opening them:
# such a module is a variant of its own, ``<method>_closed`` (known without importing the
# method, for the run-time side that finds modules)
CLOSES_LOOPS = ("zcp",)

_made: dict = {}


def get(name: str):
    """The method called ``name`` (a ``base.ConstraintMethod``)."""
    if name not in _made:
        if name not in REGISTRY:
            raise BgcError(f"unknown constraint method {name!r}", key="method",
                           hint="valid methods: " + ", ".join(NAMES))
        module, cls = REGISTRY[name].split(":")
        _made[name] = getattr(importlib.import_module(module), cls)()
    return _made[name]


def variant(name: str, open_loops: bool = True) -> str:
    """What a module of method ``name`` is named and hashed by: the method, or
    ``<method>_closed`` for one that keeps its kinematic loops closed."""
    return f"{name}_closed" if not open_loops and name in CLOSES_LOOPS else name
