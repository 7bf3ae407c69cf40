"""The models, scenes and components bgc ships: the repository's ``models/``, ``scenes/``
and ``library/``, which an installed bgc carries as the packages ``bgc.data.models``,
``bgc.data.scenes`` and ``bgc.data.library`` (pyproject.toml maps them with
``package-dir``; one copy of each file). They let the main job (``bgc simulate`` without
MODEL) run from any directory after a plain ``pip install``, and a model use the
library's components (``bgc.model.library``).

A scene names its model by a path relative to the scene file (``../models/sarib.yaml``):
in the repository, in an editable install and in an installed wheel alike, the two
folders are siblings, so a shipped scene finds its shipped model.
"""

from __future__ import annotations

from importlib.util import find_spec
from pathlib import Path

FOLDERS = ("models", "scenes", "library")


def folder(name: str) -> Path:
    """The shipped folder ``name`` ("models", "scenes" or "library") on disk: importlib finds it in
    an installed wheel and in an editable install; a source checkout on PYTHONPATH, not
    installed, has it beside the ``bgc`` package."""
    if name not in FOLDERS:
        raise ValueError(f"no shipped folder {name!r}: {', '.join(FOLDERS)}")
    spec = find_spec(f"{__name__}.{name}")      # a namespace package: no __init__.py
    if spec is None or not spec.submodule_search_locations:
        return Path(__file__).resolve().parents[2] / name
    return Path(next(iter(spec.submodule_search_locations)))


def path(folder_name: str, name: str) -> Path:
    """The shipped file ``name`` of ``folder_name`` (``path("models", "sarib.yaml")``)."""
    return folder(folder_name) / name


def names(folder_name: str) -> list[str]:
    """The shipped YAML files of ``folder_name``, by name (``sarib.yaml``, ...)."""
    return sorted(p.name for p in folder(folder_name).glob("*.yaml"))


def find(folder_name: str, given: str | Path) -> Path:
    """``given`` if that file exists, else the shipped file of ``folder_name`` it names
    (``pumping_chirp`` or ``pumping_chirp.yaml``), else ``given`` as is (for its reader to
    report missing): so that ``bgc run pumping_chirp`` runs from any directory."""
    p = Path(given)
    if p.exists() or p.parent != Path("."):
        return p
    name = p.name if p.suffix == ".yaml" else p.name + ".yaml"
    return path(folder_name, name) if name in names(folder_name) else p
