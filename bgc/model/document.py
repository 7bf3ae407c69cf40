"""Stage **load**, its first half: a model or scene file -> located YAML values.

Only the text and PyYAML, no sympy: the digest of a model (``digest``), which keys its
generated module, is known from here, so a run whose module is fresh reads no more of
the model than this (``pipeline.ensure_module``). Every value remembers its
``file:line:col``; hostile files (huge, deeply nested, alias bombs, tags) are refused
while composing.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import stat
from pathlib import Path

import yaml

from bgc.errors import Loc, ModelError


# ---------------------------------------------------------------- located YAML values
class YMap(dict):
    """A YAML mapping that remembers where it and each of its keys and values stand."""
    loc: Loc
    key_locs: dict
    val_locs: dict


class YList(list):
    loc: Loc
    item_locs: list


def _loc(file: str, node) -> Loc:
    m = node.start_mark
    return Loc(file, m.line + 1, m.column + 1)


# Limits on what a model or scene file may be, so a hostile file is refused at once
# instead of exhausting time, memory or the Python stack (issue 23). The largest shipped
# model is ~11 kB and ~2 000 YAML nodes, nested 6 deep; PyYAML composes ~0.5 MB/s.
MAX_FILE_BYTES = 1 << 20      # 1 MiB: ~100x the largest model, composed in ~2 s
MAX_NODES = 100_000           # YAML nodes after alias expansion (billion laughs)
MAX_DEPTH = 64                # nesting of lists and mappings (Python recursion)
# scalar tags bgc understands (plain YAML scalars); anything else (!!python/..., !!binary,
# !!set, a local !tag, the merge key '<<') is refused
_SCALAR_TAGS = {f"tag:yaml.org,2002:{t}": t for t in
                ("null", "bool", "int", "float", "str", "timestamp")}
_SEQ_TAG, _MAP_TAG = "tag:yaml.org,2002:seq", "tag:yaml.org,2002:map"


def read_source(path: str | Path, what: str = "model file", key: str = "model") -> str:
    """The text of a model or scene file, refused with a one-line error naming the path
    if it is missing, not a regular file (a directory, a FIFO that would block, a device
    such as /dev/zero that never ends), larger than ``MAX_FILE_BYTES`` or not UTF-8.
    The type and size are checked with ``os.stat`` before the file is opened."""
    file = str(path)
    loc = Loc(file, 1)

    def refuse(msg, hint=f"give the path of a YAML {what} (UTF-8 text)", where=loc):
        raise ModelError(msg, loc=where, key=key, hint=hint)
    try:
        st = os.stat(file)
    except FileNotFoundError:
        refuse(f"no such {what}")
    except OSError as exc:
        refuse(f"cannot read {what}: {exc.strerror or type(exc).__name__}")
    if stat.S_ISDIR(st.st_mode):
        refuse(f"is a directory, not a {what}")
    if not stat.S_ISREG(st.st_mode):
        kind = ("a FIFO" if stat.S_ISFIFO(st.st_mode) else "a device"
                if stat.S_ISCHR(st.st_mode) or stat.S_ISBLK(st.st_mode) else "a socket"
                if stat.S_ISSOCK(st.st_mode) else "not a regular file")
        refuse(f"is {kind}, not a regular {what}")
    if st.st_size > MAX_FILE_BYTES:
        refuse(f"{what} of {st.st_size} bytes is larger than bgc's limit of "
               f"{MAX_FILE_BYTES} bytes", hint=f"a {what} is at most "
               f"{MAX_FILE_BYTES >> 20} MiB (the largest shipped model is ~11 kB); a long "
               "table signal is the usual cause: resample it to fewer samples")
    try:        # non-blocking, and checked again: it may have been swapped since the stat
        fd = os.open(file, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0))
        with os.fdopen(fd, "rb") as fh:
            if not stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
                refuse(f"is not a regular {what}")
            data = fh.read(MAX_FILE_BYTES + 1)
    except OSError as exc:
        refuse(f"cannot read {what}: {exc.strerror or type(exc).__name__}")
    if len(data) > MAX_FILE_BYTES:      # grew since the stat
        refuse(f"{what} is larger than bgc's limit of {MAX_FILE_BYTES} bytes")
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = data.count(b"\n", 0, exc.start) + 1
        col = exc.start - (data.rfind(b"\n", 0, exc.start) + 1) + 1
        refuse(f"byte 0x{data[exc.start]:02x} is not UTF-8 text", where=Loc(file, line, col),
               hint="save the file as UTF-8")


class _Composer(yaml.SafeLoader):
    """PyYAML's safe composer, bounded: nesting deeper than ``MAX_DEPTH``, an alias to a
    node that contains it (a recursive alias) and more than ``MAX_NODES`` nodes once
    aliases are expanded are refused while composing, before any Python value is built
    (aliases make the node graph a DAG whose expanded size each node records)."""

    def __init__(self, text: str, file: str):
        super().__init__(text)
        self.text, self.file, self.depth, self.open_anchors = text, file, 0, set()

    def refuse(self, msg, mark, hint):
        raise ModelError(msg, loc=Loc(self.file, mark.line + 1, mark.column + 1),
                         key=_section_at(self.text, mark.line + 1) or "model", hint=hint)

    def compose_node(self, parent, index):
        event = self.peek_event()
        if isinstance(event, yaml.AliasEvent):
            if event.anchor in self.open_anchors:
                self.refuse(f"alias *{event.anchor} refers to a node that contains it",
                            event.start_mark, "a recursive alias has no finite value; "
                            "write the value out")
            return super().compose_node(parent, index)
        self.depth += 1
        if self.depth > MAX_DEPTH:
            self.refuse(f"lists and mappings nested more than {MAX_DEPTH} deep",
                        event.start_mark, "a model nests a few levels; flatten the data")
        if event.anchor is not None:
            self.open_anchors.add(event.anchor)
        node = super().compose_node(parent, index)
        self.open_anchors.discard(event.anchor)
        self.depth -= 1
        if isinstance(node, yaml.SequenceNode):
            node.size = 1 + sum(c.size for c in node.value)
        elif isinstance(node, yaml.MappingNode):
            node.size = 1 + sum(k.size + v.size for k, v in node.value)
        else:
            node.size = 1
        if node.size > MAX_NODES:
            aliased = "*" in self.text and "&" in self.text
            self.refuse(f"more than {MAX_NODES} YAML values"
                        + (" once aliases are expanded" if aliased else ""),
                        event.start_mark, "aliases (*name) that repeat large values "
                        "multiply; write the model without them" if aliased else
                        "a long table signal is the usual cause: resample it to fewer "
                        "samples")
        return node


def from_text(text: str, file: str):
    """The located YAML document of a model or scene text (``file`` names it in errors):
    a tree of ``YMap``, ``YList`` and plain scalars, composed within the limits above."""
    return _build(_compose(text, file), text, file)


def _compose(text: str, file: str) -> yaml.Node:
    """The text's YAML node graph (``_Composer``); PyYAML's errors become located
    ModelErrors."""
    try:
        loader = _Composer(text, file)
        try:
            node = loader.get_single_node()
        finally:
            loader.dispose()
    except yaml.MarkedYAMLError as exc:
        # An unclosed [ or { is best shown where it was opened (the context mark).
        opened = exc.context_mark is not None and "flow" in (exc.context or "")
        mark = (exc.context_mark if opened else exc.problem_mark) or exc.context_mark
        loc = Loc(file, mark.line + 1, mark.column + 1) if mark else Loc(file, 1)
        what = exc.problem or exc.context
        if opened:
            what = f"{exc.context} that is never closed ({exc.problem})"
        raise ModelError(f"malformed YAML: {what}", loc=loc, key=_section_at(text, loc.line),
                         hint="check indentation, colons, brackets and quotes near this "
                              "line") from None
    except yaml.reader.ReaderError as exc:      # a control character: where it stands
        line = text.count("\n", 0, exc.position) + 1
        col = exc.position - (text.rfind("\n", 0, exc.position) + 1) + 1
        raise ModelError(f"character {exc.character:#06x} is not allowed in YAML",
                         loc=Loc(file, line, col), key=_section_at(text, line) or "model",
                         hint="remove the control character; write it escaped in a "
                              "double-quoted string (\\x07) if it is meant") from None
    except yaml.YAMLError as exc:
        raise ModelError(f"malformed YAML: {str(exc).splitlines()[0]}", loc=Loc(file, 1),
                         key="model", hint="check the file is YAML text") from None
    if node is None:
        raise ModelError("the model file is empty", loc=Loc(file, 1),
                         hint="a model needs at least 'elements:' and 'bonds:'")
    return node


def _build(node: yaml.Node, text: str, file: str):
    """YAML nodes -> located values; a tag other than plain YAML's (``_SCALAR_TAGS``), a
    merge key, a key that is not a scalar and a duplicate key are refused."""
    scalar_loader = yaml.SafeLoader("")

    def refuse_tag(n, what):
        loc = _loc(file, n)
        raise ModelError(f"{what} is not supported", loc=loc,
                         key=_section_at(text, loc.line) or "model",
                         hint="bgc reads plain YAML: numbers, strings, true/false, lists, "
                              "mappings and aliases (*name); no tags (!!...) or merge "
                              "keys (<<)")

    def scalar(n):
        if n.tag not in _SCALAR_TAGS:
            refuse_tag(n, "merge key '<<'" if n.tag == "tag:yaml.org,2002:merge"
                       else f"YAML tag {n.tag!r}")
        try:
            return scalar_loader.construct_object(n)
        except (ValueError, OverflowError, yaml.YAMLError) as exc:
            loc = _loc(file, n)
            reason = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ModelError(f"cannot read {_SCALAR_TAGS[n.tag]} {n.value[:40]!r}: "
                             f"{reason[:120]}", loc=loc,
                             key=_section_at(text, loc.line) or "model",
                             hint="write a plain number such as 1.5 or 2e-3") from None

    def build(n, path=""):
        if isinstance(n, yaml.MappingNode):
            if n.tag != _MAP_TAG:
                refuse_tag(n, f"YAML tag {n.tag!r}")
            out = YMap()
            out.loc, out.key_locs, out.val_locs = _loc(file, n), {}, {}
            for kn, vn in n.value:
                k = build(kn)
                key = f"{path}.{k}" if path else str(k)
                if isinstance(k, (YMap, YList)):
                    raise ModelError("a key must be a plain name", loc=_loc(file, kn),
                                     key=path or None, hint="write name: value")
                if k in out:
                    raise ModelError(f"duplicate key '{k}'", loc=_loc(file, kn), key=key,
                                     hint=f"'{k}' is already defined at line "
                                          f"{out.key_locs[k].line}")
                out[k] = build(vn, key)
                out.key_locs[k] = _loc(file, kn)
                out.val_locs[k] = _loc(file, vn)
            return out
        if isinstance(n, yaml.SequenceNode):
            if n.tag != _SEQ_TAG:
                refuse_tag(n, f"YAML tag {n.tag!r}")
            out = YList(build(c, f"{path}[{i}]") for i, c in enumerate(n.value))
            out.loc, out.item_locs = _loc(file, n), [_loc(file, c) for c in n.value]
            return out
        return scalar(n)

    return build(node)


def read(path: str | Path, what: str = "model file", key: str = "model"):
    """A model (or scene: ``what``, ``key`` as in ``read_source``) file's located YAML
    document: ``read_source``, then ``from_text``."""
    return from_text(read_source(path, what, key), str(path))


def _section_at(text: str, line: int) -> str | None:
    """The top-level section a (1-based) line of the model text belongs to."""
    section = None
    for ln in text.splitlines()[:line]:
        m = re.match(r"^([A-Za-z_][A-Za-z0-9_]*)\s*:", ln)
        if m:
            section = m.group(1)
    return section


def plain(v):
    """The located value as plain JSON data (for hashing)."""
    if isinstance(v, dict):
        return {str(k): plain(x) for k, x in v.items()}
    if isinstance(v, list):
        return [plain(x) for x in v]
    return v


def digest(doc) -> str:
    """The model's digest: sha256 of its values as JSON (not of its text: comments and
    layout do not change it), which the generated module's MODEL_HASH is made from."""
    return hashlib.sha256(json.dumps(plain(doc), sort_keys=True, default=str)
                          .encode()).hexdigest()


def plain_json(v) -> bool:
    """Whether ``plain`` loses nothing of ``v``: every key a string, every scalar a JSON
    one (str, int, float, bool, None). Else two documents the loader tells apart may share
    a digest (``1:`` and ``"1":``, a date and its text), so a fresh module does not prove
    the document is the one that loaded: ``pipeline`` then loads it in full."""
    if isinstance(v, dict):
        return all(isinstance(k, str) and plain_json(x) for k, x in v.items())
    if isinstance(v, list):
        return all(plain_json(x) for x in v)
    return v is None or isinstance(v, (str, int, float, bool))
