"""Stage **load**: model text (YAML) -> Model.

YAML is read with node positions kept, so every error names ``file:line:col`` and the key
path (``elements.spring.C``). Values are checked here: names, kinds, keys, numbers,
expressions (parsed by ``bgc.model.expr``, never eval'd) and physically impossible parameters.
Graph-level checks (arity, power direction) belong to ``expand``.

The first half, text to located YAML values, is ``bgc.model.document``; the checks of one
value are ``bgc.model.values``; each group of sections has its reader in
``bgc.model.sections``. ``from_document`` runs them in order.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from bgc.model.names import module_name_problem, suggest_module_name
from bgc.errors import Loc, ModelError
from bgc.model import components, library, symbols
from bgc.model.document import (  # noqa: F401  (MAX_*, read_source: bgc's limits, here too)
    MAX_DEPTH,
    MAX_FILE_BYTES,
    MAX_NODES,
    YList,
    YMap,
    digest,
    from_text,
    read,
    read_source,
)
from bgc.model.model import Model, Parasitic, Table
from bgc.model.sections import blocks, bodies, excitation, joints, network, parameters
from bgc.model.sections.context import Context
from bgc.model.sections.joints import joint_params  # noqa: F401  (scene.reduce's)
from bgc.model.sections.settings import settings
from bgc.model.values import check_keys, fail, kind_of, text

TOP_KEYS = ("name", "description", "parameters", "signals", "gravity", "bodies", "joints",
            "parasitic", "excitation", "elements", "bonds", "blocks", "outputs",
            "simulation")


def loads(text: str, file: str = "<string>", overrides: dict | None = None,
          constants: dict | None = None) -> Model:
    """Parse model text; ``file`` is used in error locations and for the default name
    (and the component files it uses are found relative to it). ``overrides``: parameter
    values that replace the file's (``-p NAME=VALUE``) before anything uses them, so that
    every check of the model (a positive capacitance, a finite constant) holds for them
    too; ``constants``: compile-time constants that replace the file's."""
    return from_document(from_text(text, file), file, overrides, constants)


def from_document(doc, file: str, overrides: dict | None = None,
                  constants: dict | None = None) -> Model:
    """The Model of a document ``document.read`` gave (``loads``, past the YAML): its
    components assembled into a flat document (``bgc.model.components``), then the
    section readers of ``bgc.model.sections`` in the order their names are needed."""
    source = doc
    doc, instances = components.flatten(doc, file, constants)
    name = _check_top(doc, file)

    def section(key, kind=YMap):
        if key not in doc or doc[key] is None:
            return kind() if kind is YMap else YList()
        v = doc[key]
        if not isinstance(v, kind):
            fail(f"expected {'a mapping' if kind is YMap else 'a list'}, got {kind_of(v)}",
                 doc.val_locs[key], key)
        return v

    cx = Context(file)
    sets = settings(section("simulation"))
    cx.t_end = sets.t_end
    params = parameters.parameters(cx, section("parameters"))
    cx.overridden = set(overrides or ())
    for pname, value in (overrides or {}).items():
        if pname in params:
            params[pname] = dataclasses.replace(params[pname], value=float(value))
            cx.pvals[symbols.param(pname)] = float(value)
    tables: list[Table] = []
    sigs = parameters.signals(cx, section("signals"), params, tables)
    gravity, gravity_expr = bodies.gravity(cx, doc, params)
    bods = bodies.bodies(cx, section("bodies"), params)
    base = (joints.parasitic(doc["parasitic"], doc.val_locs["parasitic"], "parasitic",
                             Parasitic()) if "parasitic" in doc else Parasitic())
    jts = joints.joints(cx, section("joints"), params, sigs, base)
    exc = excitation.excitation(cx, section("excitation"), params, sigs, tables)
    headers = network.element_headers(cx, section("elements"))
    bnds = network.bonds(cx, section("bonds", YList), headers)
    block_heads = blocks.headers(cx, section("blocks"))     # an MSe may read ctrl.y
    elements = network.element_fields(cx, headers, params, sigs, bnds)
    blks = blocks.blocks(cx, block_heads, params, sigs, elements, bnds)
    outputs = network.outputs(cx, section("outputs"), params, sigs, elements, bnds)
    return Model(name=name, file=file, digest=library.digest(source, file, constants) or
                 digest(source), parameters=params, signals=sigs,
                 tables=tables, elements=elements, bonds=bnds, outputs=outputs,
                 settings=sets, bodies=bods, description=text(
                     doc.get("description"), doc.val_locs.get("description"), "description"),
                 gravity=gravity, gravity_expr=gravity_expr, joints=jts, excitation=exc,
                 static_loads=doc.get("parasitic", {}).get("loads") == "static",
                 ports=cx.ports, blocks=blks, instances=instances)


def _check_top(doc, file: str) -> str:
    """The document is a mapping of known sections, with elements and bonds or bodies;
    its model name (``name:``, else the file's stem) names a module. Returns the name."""
    if not isinstance(doc, YMap):
        raise ModelError(f"a model file is a mapping of sections, got {kind_of(doc)}",
                         loc=Loc(file, 1), hint="sections: " + ", ".join(TOP_KEYS))
    check_keys(doc, TOP_KEYS, "model")
    if not doc.get("bodies"):
        for required in ("elements", "bonds"):
            if not doc.get(required):
                fail(f"missing section '{required}'", doc.loc, required,
                     "a model needs elements and the bonds between them (or bodies)")
    elif doc.get("elements") and not doc.get("bonds"):
        fail("missing section 'bonds'", doc.loc, "bonds",
             "elements need the bonds between them")
    name = doc.get("name", Path(file).stem)
    problem = module_name_problem(name)
    if problem:     # without a name: key, the file's stem names the module
        fail(f"model name {problem}", doc.val_locs.get("name", doc.loc), "name",
             f"write name: {suggest_module_name(name)} (it names the generated module "
             "<name>.py)")
    return name


def load(path: str | Path, overrides: dict | None = None,
         constants: dict | None = None) -> Model:
    """Read and parse a model file (``overrides``, ``constants``: as in ``loads``)."""
    return from_document(read(path), str(path), overrides, constants)
