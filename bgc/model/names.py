"""Which names a model may take: its name names its generated module (``<name>.py``), so
it must be a Python module name that shadows nothing installed. Read when a model is
loaded (``load``) and when a module is written (``codegen.emit``); light (no sympy), as
the warm path asks ``module_name_syntax_problem`` of a module it finds fresh."""

from __future__ import annotations

import functools
import keyword
import re
import sys


@functools.lru_cache(maxsize=1)
def _taken_names() -> frozenset:
    """Top-level module names a generated module must not shadow: the standard library's,
    the interpreter's built-in modules and every installed distribution's (from the
    installed metadata: deterministic, no search of sys.path or the working directory)."""
    return frozenset(sys.stdlib_module_names) | frozenset(sys.builtin_module_names) | \
        _installed_top_level() | {"bgc"}


def _installed_top_level() -> frozenset:
    """The top-level names of the installed distributions, as the keys of
    ``importlib.metadata.packages_distributions()``: a distribution's ``top_level.txt``,
    else the first part of each ``.py`` file its RECORD lists. Without the distribution
    names that function also reads (each one's METADATA parsed: half its time, which
    every run would pay, a fresh module's included)."""
    import importlib.metadata
    names = set()
    for dist in importlib.metadata.distributions():
        declared = (dist.read_text("top_level.txt") or "").split()
        names.update(declared or (f.parts[0] if len(f.parts) > 1 else f.with_suffix("").name
                                  for f in dist.files or () if f.suffix == ".py"))
    return frozenset(names)


def module_name_syntax_problem(name) -> str | None:
    """Why ``name`` cannot be a module's name as Python reads it (None if it can): a
    Python identifier, not a keyword, not a dunder such as ``__init__`` (which would
    overwrite the output package's ``__init__.py``). Cheap: the warm path asks only this
    of a module it finds fresh (which passed ``module_name_problem`` when written)."""
    if not (isinstance(name, str) and name.isascii() and name.isidentifier()):
        return f"{name!r} is not a valid Python module name"
    if keyword.iskeyword(name):
        return f"{name!r} is a Python keyword"
    if name.startswith("__") and name.endswith("__"):
        return f"{name!r} is a special (dunder) name"
    return None


def module_name_problem(name) -> str | None:
    """Why ``name`` cannot name a generated module (None if it can): it must pass
    ``module_name_syntax_problem`` and must not shadow a standard library module or an
    installed package (``numpy.py`` beside other modules breaks their imports)."""
    problem = module_name_syntax_problem(name)
    if problem is not None:
        return problem
    if name in _taken_names():
        what = "standard library module" if name in sys.stdlib_module_names \
            else "built-in module" if name in sys.builtin_module_names else "installed package"
        return f"{name!r} would shadow the {what} '{name}'"
    return None


def suggest_module_name(name) -> str:
    """A valid module name close to ``name`` (for the hint of a rejected one)."""
    base = re.sub(r"[^0-9A-Za-z_]+", "_", str(name)).strip("_") or "model"
    if base[0].isdigit():
        base = "m_" + base
    for cand in (base, f"{base}_model"):
        if module_name_problem(cand) is None:
            return cand
    return "bgc_model"
