"""Where a model's components come from: its own ``components:``, the files its ``uses:``
names (paths relative to the file that names them) and the library bgc ships
(``library/<name>.yaml``, installed as ``bgc.data.library``).

Only the text and PyYAML, no sympy: the digest of a model that uses components covers
every file it reads (``digest``), and ``pipeline.ensure_module`` computes it to find a
fresh module without loading the model. The assembly itself (instances, names,
placement) is ``bgc.model.components``.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import dataclass
from pathlib import Path

from bgc.errors import Loc, ModelError
from bgc.model import document
from bgc.model.document import YList, YMap

LIBRARY = "library"
# the sections that make a model an assembly: without them (and without -p of a
# constant) a model is read, and hashed, exactly as before components existed
ASSEMBLY_KEYS = ("components", "uses", "instances", "constants")
_NAME = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*\Z")


@dataclass(frozen=True)
class Definition:
    """A component as its file defines it: ``name``, its mapping ``body``, where its key
    stands (``loc``) and the file it is in (``file``: where its own instances' component
    names and ``uses:`` paths are resolved); ``library``: it is one of bgc's."""
    name: str
    body: YMap
    loc: Loc
    file: str
    library: bool = False

    def where(self) -> str:
        """'component NAME (FILE:LINE)' for messages."""
        return f"component '{self.name}' ({self.loc.file}:{self.loc.line})"


def library_folder() -> Path:
    """The folder of bgc's library of components (``bgc.data.library``)."""
    from bgc import data
    return data.folder(LIBRARY)


def library_names() -> list[str]:
    """The components the library ships, by name (one file each, ``<name>.yaml``)."""
    return sorted(p.stem for p in library_folder().glob("*.yaml"))


class Sources:
    """The documents an assembly reads, each read once (by resolved path), and the
    lookup of a component's name from the file that uses it."""

    def __init__(self, file: str, doc):
        self.model_file = file
        self.docs: dict[str, object] = {self._key(file): doc}
        self.used: dict[str, str] = {}         # key -> how the model names it (digest)

    @staticmethod
    def _key(file) -> str:
        try:
            return str(Path(file).resolve())
        except OSError:
            return str(file)

    def read(self, path: Path, loc: Loc, key: str, why: str):
        """The document of a component file, read once; a missing or unreadable file is
        one error at ``loc`` (the ``uses:`` entry), saying ``why`` it was read."""
        k = self._key(path)
        if k not in self.docs:
            if not Path(path).exists():
                raise ModelError(f"{why}: no such component file '{path}'", loc=loc,
                                 key=key, hint="a path in uses: is relative to the file "
                                               "that names it")
            self.docs[k] = document.read(path, "component file", key)
        return self.docs[k]

    def lookup(self, name, file: str, loc: Loc, key: str, why: str) -> Definition:
        """The component ``name`` as seen from ``file``: that file's ``components:``,
        then its ``uses:``, then bgc's library. ``loc``/``key``: the instance asking
        (``why`` names it in errors)."""
        doc = self.docs[self._key(file)]
        if not isinstance(name, str) or not _NAME.match(name):
            raise ModelError(f"{why}: component {name!r} is not a component name",
                             loc=loc, key=key, hint="component: NAME, from this file's "
                             "components:, its uses: or bgc's library (bgc library)")
        own = _section(doc, "components", file)
        if name in own:
            return Definition(name, _mapping(own[name], own.val_locs[name],
                                             f"components.{name}"),
                              own.key_locs[name], file)
        uses = _section(doc, "uses", file)
        if name in uses:
            return self._used(name, uses, file, why)
        lib = library_folder() / f"{name}.yaml"
        if lib.is_file():
            ldoc = self.read(lib, loc, key, why)
            self.used.setdefault(self._key(lib), f"{LIBRARY}:{name}")
            comps = _section(ldoc, "components", str(lib))
            if name not in comps:
                raise ModelError(f"library file {lib} does not define component '{name}'",
                                 loc=Loc(str(lib), 1), key="components")
            return Definition(name, _mapping(comps[name], comps.val_locs[name],
                                             f"components.{name}"),
                              comps.key_locs[name], str(lib), library=True)
        known = sorted(set(own) | set(uses))
        raise ModelError(
            f"{why}: unknown component '{name}'", loc=loc, key=key,
            hint=(f"this file's components: {', '.join(known)}; " if known else "")
            + "the library's: " + ", ".join(library_names())
            + " (a component from another file needs uses: {NAME: path.yaml})")

    def _used(self, name, uses: YMap, file: str, why: str) -> Definition:
        """``uses: {name: path}`` or ``{name: {file: path, component: other}}``."""
        v, loc, key = uses[name], uses.val_locs[name], f"uses.{name}"
        other = name
        if isinstance(v, YMap):
            for k in v:
                if k not in ("file", "component", "description"):
                    raise ModelError(f"unknown key '{k}'", loc=v.key_locs[k],
                                     key=f"{key}.{k}", hint="valid keys: file, component")
            if "file" not in v:
                raise ModelError("missing 'file'", loc=v.loc, key=key,
                                 hint="uses: {NAME: {file: parts.yaml, component: OTHER}}")
            other = v.get("component", name)
            loc, v = v.val_locs["file"], v["file"]
        if not isinstance(v, str) or not v.strip():
            raise ModelError(f"expected the path of a component file, got {v!r}", loc=loc,
                             key=key, hint="uses: {NAME: parts.yaml} (relative to this "
                                           "file)")
        path = Path(file).parent / v
        fdoc = self.read(path, loc, key, why)
        self.used.setdefault(self._key(path), v)
        comps = _section(fdoc, "components", str(path))
        if other not in comps:
            raise ModelError(f"{why}: '{path}' defines no component '{other}'", loc=loc,
                             key=key, hint="its components: " + (", ".join(comps) or
                                                                   "none"))
        return Definition(other, _mapping(comps[other], comps.val_locs[other],
                                          f"components.{other}"),
                          comps.key_locs[other], str(path))


def _section(doc, name: str, file: str) -> YMap:
    """A file's ``components:`` or ``uses:`` mapping (empty if it has none)."""
    if not isinstance(doc, YMap) or doc.get(name) is None:
        return _empty()
    v = doc[name]
    if not isinstance(v, YMap):
        raise ModelError(f"'{name}' must be a mapping, got {type(v).__name__}",
                         loc=doc.val_locs[name], key=name,
                         hint="components: {NAME: {...}}" if name == "components"
                         else "uses: {NAME: path.yaml}")
    return v


def _empty() -> YMap:
    m = YMap()
    m.loc, m.key_locs, m.val_locs = None, {}, {}
    return m


def _mapping(v, loc, key) -> YMap:
    if not isinstance(v, YMap):
        raise ModelError(f"a component is a mapping, got {type(v).__name__}", loc=loc,
                         key=key, hint="NAME: {parameters: ..., ports: ..., bodies: ...}")
    return v


def is_assembly(doc) -> bool:
    """Whether a model document defines, uses or instantiates components (or declares
    compile-time constants): read by ``bgc.model.components``."""
    return isinstance(doc, YMap) and any(k in doc for k in ASSEMBLY_KEYS)


def component_names(body) -> list[str]:
    """The component names a mapping's ``instances:`` asks for (no evaluation)."""
    inst = body.get("instances") if isinstance(body, YMap) else None
    if not isinstance(inst, YMap):
        return []
    return [v["component"] for v in inst.values()
            if isinstance(v, YMap) and isinstance(v.get("component"), str)]


def digest(doc, file: str, constants: dict | None = None) -> str | None:
    """The model's digest: ``document.digest`` for a flat model; for an assembly the
    digest of the model's document, of every component file it reads (as it names them)
    and of the constants given on the command line. None when a file it needs cannot be
    read or a document does not survive ``document.plain`` (the full load then decides
    and reports)."""
    if not is_assembly(doc) and not constants:
        return document.digest(doc)
    src = Sources(file, doc)
    try:
        todo = [(file, doc)]
        seen = set()
        while todo:
            f, body = todo.pop()
            for name in component_names(body):
                if (f, name) in seen:
                    continue
                seen.add((f, name))
                d = src.lookup(name, f, Loc(file, 1), "instances", "instance")
                todo.append((d.file, d.body))
    except ModelError:
        return None
    docs = {"model": document.plain(doc), "constants": dict(sorted((constants or {})
                                                                    .items()))}
    for k, how in sorted(src.used.items(), key=lambda kv: kv[1]):
        d = src.docs[k]
        if not document.plain_json(d):
            return None
        docs[f"uses:{how}"] = document.plain(d)
    return hashlib.sha256(json.dumps(docs, sort_keys=True, default=str).encode()).hexdigest()


def listing() -> list[dict]:
    """The library's components for ``bgc library``: name, description, ports (name,
    kind, what it is), parameters (name, value, unit, description) and constants."""
    out = []
    for name in library_names():
        path = library_folder() / f"{name}.yaml"
        src = Sources(str(path), document.read(path, "component file", "components"))
        d = src.lookup(name, str(path), Loc(str(path), 1), "components", "library")
        out.append(describe(d))
    return out


def describe(d: Definition) -> dict:
    """A component's interface, as plain data."""
    body = d.body

    def entries(sec):
        v = body.get(sec)
        return v.items() if isinstance(v, YMap) else []

    ports = []
    for pname, p in entries("ports"):
        if isinstance(p, YMap):
            kind = next((k for k in p if k not in ("description", "power")), None)
            entry = {"name": pname, "kind": "external " + str(p[kind]) if kind == "external"
                     else kind, "target": None if kind == "external" else p.get(kind)}
            if "power" in p:
                entry["power"] = p["power"]
            entry["description"] = p.get("description")
            ports.append(entry)
    params = []
    for pname, p in entries("parameters"):
        m = p if isinstance(p, YMap) else {"value": p}
        params.append({"name": pname, "value": m.get("value"), "unit": m.get("unit"),
                       "description": m.get("description")})
    consts = [{"name": c, "value": v.get("value") if isinstance(v, YMap) else v}
              for c, v in entries("constants")]
    desc = body.get("description")
    return {"name": d.name, "description": " ".join(str(desc).split()) if desc else None,
            "file": d.loc.file, "line": d.loc.line, "ports": ports,
            "parameters": params, "constants": consts}


__all__ = ["Definition", "Sources", "digest", "is_assembly", "library_names", "listing",
           "describe", "YList"]
