"""``bgc draw --energy RUN.json``: a run's element activities (``bgc energy --out``) on
the bond graph. Each element that supplies, stores or dissipates power keeps its share
of the run's total activity (int |P| dt, Louca et al. 1997); its bond is drawn as wide
and as dark as that share, on a logarithmic scale from ``FLOOR`` to 1, so that the
elements a run hardly uses (candidates for removal by the activity pass of a scene) fade
out and the paths the power takes stand out."""

from __future__ import annotations

import json
import math
from pathlib import Path

from bgc.errors import BgcError

FLOOR = 1e-5            # shares below this are drawn as thin as the unused
WIDTH = (1.0, 10.0)     # the bond's width [pt] at the floor and at share 1
CMAP = "viridis_r"      # light (little) to dark (much)


def load(path: str | Path) -> list[dict]:
    """RUN.json's elements (``name``, ``share``), read and checked before any work: a
    file that is not a ``bgc energy`` JSON is a one-line error."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except OSError as err:
        raise BgcError(f"cannot read {str(path)!r}: {err.strerror or err}",
                       key="--energy", hint="give the file bgc energy --out wrote") from None
    except (UnicodeDecodeError, json.JSONDecodeError) as err:
        raise BgcError(f"{path}: not JSON ({err})", key="--energy",
                       hint="give the file bgc energy --out (or --json) wrote") from None
    els = data.get("elements") if isinstance(data, dict) else None
    if not isinstance(els, list) or not all(
            isinstance(e, dict) and isinstance(e.get("name"), str)
            and isinstance(e.get("share"), (int, float)) and not isinstance(e["share"], bool)
            and math.isfinite(e["share"]) and 0 <= e["share"] <= 1 for e in els):
        raise BgcError(f"{path}: not a bgc energy result (no 'elements' with a 'name' and "
                       "a 'share' between 0 and 1)", key="--energy",
                       hint="give the file bgc energy --out (or --json) wrote")
    return els


def apply(diagram, els: list[dict], path: str | Path) -> int:
    """Put the shares on the Diagram (``diagram.activity``, by node name); returns how
    many of the run's elements it has. None of them (another model or method) is a
    one-line error; some missing (--only, another method) a note on the drawing."""
    by_name = {n.replace("__", "."): n for n in diagram.nodes}
    known = [e for e in els if e["name"] in by_name]
    if els and not known:
        raise BgcError(f"{path}: none of its {len(els)} elements is in this bond graph "
                       f"({', '.join(e['name'] for e in els[:3])}, ...)", key="--energy",
                       hint="run bgc energy on this model, with the same --method")
    diagram.activity = {by_name[e["name"]]: float(e["share"]) for e in known}
    missing = len(els) - len(known)
    if missing:
        diagram.notes.append(f"{missing} of the {len(els)} elements of {Path(path).name} "
                             "are not in this drawing (--only, or another --method's run)")
    return len(known)


def level(share: float) -> float:
    """0 at ``FLOOR`` (and below), 1 at share 1, logarithmic between."""
    if not share > FLOOR:
        return 0.0
    return min(1.0, math.log10(share / FLOOR) / -math.log10(FLOOR))


def style(share: float) -> tuple[float, tuple]:
    """A bond's width [pt] and colour (RGBA) for an element's activity share."""
    from matplotlib import colormaps
    v = level(share)
    return WIDTH[0] + (WIDTH[1] - WIDTH[0]) * v, colormaps[CMAP](0.1 + 0.9 * v)
