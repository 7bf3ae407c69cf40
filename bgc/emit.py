"""Stage **emit**: EquationSystem -> Python source of a numba module, written atomically.

The module holds ``rhs(t, x, p)``, ``jac(t, x, p)`` and ``outputs(t, x, p)`` as
``@njit(cache=True)`` functions of the parameter array ``p`` (changing a value never
recompiles), plus metadata. Each function computes only the assignments its results
depend on, in causal order. The same input gives the same bytes.
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
import re
import sys
import tempfile
from pathlib import Path

import jinja2

from . import __version__
from .equations import EquationSystem, LinearBlock
from .jacobian import BlockSensitivity, chain_rule
from .printer import code

_ENV = jinja2.Environment(loader=jinja2.PackageLoader("bgc", "templates"),
                          trim_blocks=True, lstrip_blocks=True, keep_trailing_newline=True,
                          undefined=jinja2.StrictUndefined)
_HASH_RE = re.compile(r'^MODEL_HASH = "([0-9a-f]+)"$', re.M)


def model_hash(model_digest: str, method: str) -> str:
    """What a generated module is keyed by: model content, method and bgc version."""
    return hashlib.sha256(f"{model_digest}|{method}|{__version__}".encode()).hexdigest()[:32]


def _defines(item) -> list:
    if isinstance(item, LinearBlock):
        return list(item.unknowns)
    if isinstance(item, BlockSensitivity):
        return item.defines
    return [item[0]]


def _free(item) -> set:
    return item.free_symbols if isinstance(item, (LinearBlock, BlockSensitivity)) \
        else item[1].free_symbols


def _cone(assignments, targets):
    """The assignments that ``targets`` depend on, in their original order."""
    need = set()
    for e in targets:
        need |= e.free_symbols
    keep = []
    for item in reversed(assignments):
        if any(v in need for v in _defines(item)):
            keep.append(item)
            need |= _free(item)
    return keep[::-1], need


def _body(assignments):
    lines = []
    for item in assignments:
        if isinstance(item, LinearBlock):
            k, n = item.index, len(item.unknowns)
            lines.append(f"_A{k} = np.zeros(({n}, {n}))")
            lines += [f"_A{k}[{i}, {j}] = {code(e)}" for i, j, e in item.A]
            lines.append(f"_b{k} = np.empty({n})")
            lines += [f"_b{k}[{i}] = {code(e)}" for i, e in enumerate(item.b)]
            lines.append(f"_u{k} = np.linalg.solve(_A{k}, _b{k})")
            lines += [f"{v.name} = _u{k}[{i}]" for i, v in enumerate(item.unknowns)]
        elif isinstance(item, BlockSensitivity):
            k, n, m = item.index, len(item.unknowns), len(item.cols)
            lines.append(f"_R{k} = np.zeros(({n}, {m}))")
            lines += [f"_R{k}[{i}, {c}] = {code(e)}" for i, c, e in item.R]
            lines.append(f"_D{k} = np.linalg.solve(_A{k}, _R{k})")
        else:
            v, e = item
            lines.append(f"{v.name} = {code(e)}")
    return lines


def _prologue(system, used):
    params = [f"{s.name} = p[{i}]" for i, (s, _, _) in enumerate(system.params) if s in used]
    unpack = [f"{st.sym.name} = x[{i}]" for i, st in enumerate(system.states)
              if st.sym in used]
    return params, unpack


def render(system: EquationSystem) -> str:
    """The module source for an equation system."""
    m = system.model
    dx = [st.dsym for st in system.states]
    rhs_asg, rhs_used = _cone(system.assignments, dx)
    extra, entries = chain_rule(rhs_asg, system.states)
    jac_targets = list(entries.values())
    jac_all, jac_used = _cone(rhs_asg + extra, jac_targets)
    out_exprs = [e for _, e in system.outputs]
    out_asg, out_used = _cone(system.assignments, out_exprs)
    funcs = {}
    for key, asg, used in (("rhs", rhs_asg, rhs_used | set(dx)),
                           ("jac", jac_all, jac_used | set(jac_targets)),
                           ("out", out_asg, out_used)):
        params, unpack = _prologue(system, used)
        funcs[key] = (params, unpack, _body(asg))
    ctx = dict(
        title=f"{m.name}: bgc-generated simulation module",
        version=__version__, source=Path(m.file).name, method=system.method, name=m.name,
        model_hash=model_hash(m.digest, system.method),
        state_names=[st.name for st in system.states],
        param_names=[name for _, name, _ in system.params],
        output_names=[name for name, _ in system.outputs],
        x0_params=[f"{sy.name} = p[{i}]" for i, (sy, _, _) in enumerate(system.params)
                   if any(st.initial.has(sy) for st in system.states)],
        x0=[code(st.initial) for st in system.states],
        p0=[repr(float(v)) for _, _, v in system.params],
        breakpoints=[repr(float(b)) for b in system.breakpoints],
        tables=[{"index": tb.index, "t": [repr(v) for v in tb.t], "y": [repr(v) for v in tb.y]}
                for tb in system.tables],
        n=len(system.states),
        rhs_out=[f"dx[{i}] = {code(st.dsym)}" for i, st in enumerate(system.states)],
        jac_out=[f"J[{i}, {j}] = {code(e)}" for (i, j), e in sorted(entries.items())],
        out_out=[f"y[{k}] = {code(e)}" for k, e in enumerate(out_exprs)],
    )
    for key, (params, unpack, body) in funcs.items():
        ctx[f"{key}_body"] = params + unpack + body
    return _ENV.get_template("module.py.j2").render(**ctx)


def module_path(name: str, out_dir: str | Path = "generated") -> Path:
    return Path(out_dir) / f"{name}.py"


def write(system: EquationSystem, out_dir: str | Path = "generated") -> Path:
    """Render and write ``out_dir/<name>.py`` atomically (temp file + rename)."""
    source = render(system)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    init = out_dir / "__init__.py"
    if not init.exists():
        _atomic_write(init, '"""Modules generated by `bgc compile`."""\n')
    path = module_path(system.model.name, out_dir)
    _atomic_write(path, source)
    return path


def _atomic_write(path: Path, text: str):
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="\n") as fh:
            fh.write(text)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def stored_hash(path: Path) -> str | None:
    """The MODEL_HASH a generated module was written with (read as text, not imported)."""
    try:
        head = Path(path).read_text(encoding="utf-8")
    except OSError:
        return None
    m = _HASH_RE.search(head)
    return m.group(1) if m else None


def is_stale(path: Path, model_digest: str, method: str) -> bool:
    """True if the module at ``path`` is missing or was generated from another model text,
    method or bgc version."""
    return stored_hash(path) != model_hash(model_digest, method)


def import_module(path: Path):
    """Import a generated module from its file (numba's cache sits beside it)."""
    path = Path(path).resolve()
    # Always the name `from <dir> import <model>` gives: numba's on-disk cache records the
    # module name, and loading it under another name would fail.
    name = f"{path.parent.name}.{path.stem}"
    if name in sys.modules and getattr(sys.modules[name], "__file__", None) == str(path) \
            and getattr(sys.modules[name], "MODEL_HASH", None) == stored_hash(path):
        return sys.modules[name]
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    return module


