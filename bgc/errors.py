"""Errors a user can cause: each carries a location, the offending key and a hint.

The CLI prints them as one line (``file:line:col: key: message (hint)``) and exits
non-zero; they are never shown as a traceback.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Loc:
    """A place in a model file (1-based line and column)."""

    file: str
    line: int
    col: int = 1

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}"


class BgcError(Exception):
    """Base of every error caused by the user's input, not by bgc."""

    def __init__(self, message: str, loc: Loc | None = None, key: str | None = None,
                 hint: str | None = None):
        super().__init__(message)
        self.message = message
        self.loc = loc
        self.key = key
        self.hint = hint

    def __str__(self) -> str:
        parts = []
        if self.loc is not None:
            parts.append(f"{self.loc}:")
        if self.key:
            parts.append(f"{self.key}:")
        parts.append(self.message)
        text = " ".join(parts)
        if self.hint:
            text += f" (hint: {self.hint})"
        # one line whatever the input held: a line break or control character in a file
        # name or a model's key is shown escaped
        return "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)

    def to_dict(self) -> dict:
        return {
            "error": type(self).__name__,
            "message": self.message,
            "file": self.loc.file if self.loc else None,
            "line": self.loc.line if self.loc else None,
            "col": self.loc.col if self.loc else None,
            "key": self.key,
            "hint": self.hint,
        }


class ModelError(BgcError):
    """The model text is malformed or inconsistent (load and expand stages)."""


class CausalityError(BgcError):
    """Causality cannot be assigned without a conflict; ``conflicts`` lists all found."""

    conflicts: list = []

    def to_dict(self) -> dict:
        out = super().to_dict()
        out["conflicts"] = [{"file": c.loc.file, "line": c.loc.line, "key": c.key,
                             "message": c.message} for c in (self.conflicts or [self])]
        return out


class EquationError(BgcError):
    """The causal equations cannot be put in explicit form (e.g. a nonlinear loop)."""


class SimulationError(BgcError):
    """The integrator failed; the partial result is attached as ``result`` (and, once
    written, where: ``partial``)."""
    partial: str | None = None

    def to_dict(self) -> dict:
        """As any error's, with what the failed run keeps: how far it got, its
        statistics, the projection of its start, and where its results so far were
        written (None: nowhere)."""
        out = super().to_dict()
        r = self.result
        if r is not None:
            out["t_reached"] = float(r.t[-1]) if len(r.t) else None
            out["stats"] = r.stats.to_dict()
            out["projection"] = r.projection.to_dict() if r.projection is not None else None
            out["partial_results"] = self.partial
        return out

    def __init__(self, message: str, result=None, **kw):
        super().__init__(message, **kw)
        self.result = result
