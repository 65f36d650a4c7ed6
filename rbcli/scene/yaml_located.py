"""Safe YAML with source locations: plain Python values plus `path -> SourceLocation` for every key and value.

A path is the tuple of mapping keys and sequence indices from the document root, e.g.
`("bodies", 0, "particles", "masses", 1)`. Only plain data is built (mappings with string keys,
sequences, strings, numbers, booleans, null); any other tag (`!!python/object`, `!custom`, `!!binary`)
is an error at its location. Anchors, aliases and merge keys (`<<`) work; duplicate keys are an error at
the second key.

Limits keep hostile or accidental input from hanging or exhausting memory:
- input size (`MAX_SCENE_BYTES`);
- nesting depth while composing (`MAX_DEPTH`) and while expanding aliases (`MAX_EXPANDED_DEPTH`);
- alias expansion: building the value visits every node once per path that reaches it, so an alias bomb
  ("billion laughs") multiplies visits while the text stays tiny. We allow `EXPANSION_FACTOR` visits per
  composed node plus `EXPANSION_ALLOWANCE`, which is generous for templates reused by many bodies but stops
  a bomb after well under a second.

Floats follow YAML 1.2 (`1e-3` is a number; PyYAML's YAML 1.1 resolver would make it a string).
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from yaml.composer import Composer
from yaml.constructor import SafeConstructor
from yaml.events import AliasEvent
from yaml.nodes import MappingNode, Node, ScalarNode, SequenceNode
from yaml.resolver import BaseResolver, Resolver

from rbcli.scene.spec import SceneError, SceneIssue, SourceLocation

YamlPath = tuple[str | int, ...]

MAX_SCENE_BYTES = 10 * 1024 * 1024
TOO_LARGE_HINT = "a smaller scene; give large particle sets as a mesh or a generated grid"
MAX_DEPTH = 100
MAX_EXPANDED_DEPTH = 200
EXPANSION_FACTOR = 10
EXPANSION_ALLOWANCE = 100_000

_TAG = "tag:yaml.org,2002:"
_MERGE_TAG = _TAG + "merge"

# characters YAML 1.2 allows in a stream (c-printable); anything else means binary or corrupted text
_NON_PRINTABLE = re.compile("[^\x09\x0a\x0d\x20-\x7e\x85\xa0-\ud7ff\ue000-\ufffd\U00010000-\U0010ffff]")

_FLOAT_1_2 = re.compile(
    r"""^(?:[-+]?(?:[0-9][0-9_]*)\.[0-9_]*(?:[eE][-+]?[0-9]+)?
    |[-+]?(?:[0-9][0-9_]*)(?:[eE][-+]?[0-9]+)
    |\.[0-9_]+(?:[eE][-+]?[0-9]+)?
    |[-+]?[0-9][0-9_]*(?::[0-5]?[0-9])+\.[0-9_]*
    |[-+]?\.(?:inf|Inf|INF)
    |\.(?:nan|NaN|NAN))$""",
    re.X,
)


class _SceneResolver(BaseResolver):
    """PyYAML's safe resolver with the float pattern widened to YAML 1.2 (`1e-3`, `2E5`)."""

    yaml_implicit_resolvers = {
        first: [(tag, _FLOAT_1_2 if tag == _TAG + "float" else regexp) for tag, regexp in entries]
        for first, entries in Resolver.yaml_implicit_resolvers.items()
    }


class _AliasNode(Node):
    """Where an alias (`*name`) was written, pointing at the node its anchor names."""

    id = "alias"

    def __init__(self, target: Node, start_mark: Any, end_mark: Any):
        super().__init__(target.tag, None, start_mark, end_mark)
        self.target = target


class _LocatedComposer(Composer):
    """Composer that keeps alias positions (as `_AliasNode`) and bounds depth; counts composed nodes."""

    def __init__(self) -> None:
        super().__init__()
        self.composed_count = 0
        self._depth = 0

    def compose_node(self, parent: Node | None, index: Any) -> Node:
        if self.check_event(AliasEvent):
            event = self.peek_event()
            target = super().compose_node(parent, index)
            return _AliasNode(target, event.start_mark, event.end_mark)
        self._depth += 1
        if self._depth > MAX_DEPTH:
            raise _Located(self.peek_event().start_mark, f"nesting deeper than {MAX_DEPTH} levels", "")
        self.composed_count += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


if getattr(yaml, "__with_libyaml__", False):
    from yaml.cyaml import CParser as _Parser

    class _Loader(_LocatedComposer, _Parser, _SceneResolver):  # libyaml scans and parses; we compose
        def __init__(self, stream: str):
            _Parser.__init__(self, stream)
            _LocatedComposer.__init__(self)
            _SceneResolver.__init__(self)

else:  # pragma: no cover - PyYAML without libyaml
    from yaml.parser import Parser
    from yaml.reader import Reader
    from yaml.scanner import Scanner

    class _Loader(Reader, Scanner, Parser, _LocatedComposer, _SceneResolver):  # type: ignore[no-redef]
        def __init__(self, stream: str):
            Reader.__init__(self, stream)
            Scanner.__init__(self)
            Parser.__init__(self)
            _LocatedComposer.__init__(self)
            _SceneResolver.__init__(self)


class _Located(Exception):
    """Internal: an error at a YAML mark, turned into a SceneIssue at the boundary."""

    def __init__(self, mark: Any, message: str, expected: str):
        super().__init__(message)
        self.mark = mark
        self.message = message
        self.expected = expected


@dataclass
class LocatedDocument:
    """A YAML document as plain values, with the location of every value and every mapping key."""

    value: Any
    file: str
    value_locations: dict[YamlPath, SourceLocation] = field(default_factory=dict)
    key_locations: dict[YamlPath, SourceLocation] = field(default_factory=dict)

    def locate(self, path: YamlPath, *, key: bool = False) -> SourceLocation:
        """Location of the value at `path` (or of its key when `key`), else of the nearest ancestor."""
        path = tuple(path)
        if key and path in self.key_locations:
            return self.key_locations[path]
        while path:
            if path in self.value_locations:
                return self.value_locations[path]
            path = path[:-1]
        return self.value_locations.get((), SourceLocation(self.file, 1, 1))

    def copy_locations(self, source: YamlPath, target: YamlPath) -> None:
        """Give every path under `target` the locations of the same path under `source` (defaults merge)."""
        n = len(source)
        for table in (self.value_locations, self.key_locations):
            for path, loc in list(table.items()):
                if path[:n] == source:
                    table.setdefault(target + path[n:], loc)


def _issue(file: str, line: int, column: int, message: str, expected: str = "") -> SceneIssue:
    return SceneIssue(SourceLocation(file, line, column), message, expected)


def decode_scene_bytes(raw: bytes, file: str, size: int | None = None) -> str:
    """UTF-8 text of a scene file, or SceneError located at the first offending byte or character.

    size: the file's real length [bytes] when `raw` is only its first MAX_SCENE_BYTES + 1 bytes (the
    readers stop there), so an oversized file is reported with its true size."""
    if len(raw) > MAX_SCENE_BYTES:
        raise SceneError([_issue(file, 1, 1, _too_large(size if size is not None else len(raw)),
                                 TOO_LARGE_HINT)])  # fmt: skip
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise SceneError([_issue(file, 1, 1, "file is UTF-16 encoded", "UTF-8 text (save the file as UTF-8)")])
    nul = raw.find(b"\x00")
    if nul >= 0:
        line, column = _byte_line_column(raw, nul)
        raise SceneError([_issue(file, line, column, "file looks binary (NUL byte)", "a UTF-8 YAML text file")])
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line, column = _byte_line_column(raw, exc.start)
        raise SceneError(
            [
                _issue(
                    file,
                    line,
                    column,
                    f"not valid UTF-8 (byte 0x{raw[exc.start]:02x})",
                    "UTF-8 text (save the file as UTF-8)",
                )
            ]
        ) from None
    return text.removeprefix("\ufeff")


def _too_large(size: int) -> str:
    """'file is 52,428,800 bytes (50.0 MiB), over the 10,485,760-byte (10.0 MiB) limit for scenes': exact
    sizes, as rounding both to one decimal made a 50 MB file read as 10.5 MB (only its first bytes are read)."""
    return (
        f"file is {size:,} bytes ({size / 2**20:.1f} MiB), over the {MAX_SCENE_BYTES:,}-byte "
        f"({MAX_SCENE_BYTES / 2**20:.1f} MiB) limit for scenes"
    )


def _byte_line_column(raw: bytes, offset: int) -> tuple[int, int]:
    line_start = raw.rfind(b"\n", 0, offset) + 1
    column = len(raw[line_start:offset].decode("utf-8", errors="replace")) + 1
    return raw.count(b"\n", 0, offset) + 1, column


def _text_line_column(text: str, offset: int) -> tuple[int, int]:
    line_start = text.rfind("\n", 0, offset) + 1
    return text.count("\n", 0, offset) + 1, offset - line_start + 1


def read_located_yaml(path: str | Path) -> LocatedDocument:
    """Read and parse a scene file; SceneError (located) for unreadable, oversized or malformed input."""
    file = str(path)
    try:
        with open(path, "rb") as handle:
            raw = handle.read(MAX_SCENE_BYTES + 1)
            size = os.fstat(handle.fileno()).st_size
    except OSError as exc:
        raise SceneError(
            [SceneIssue(None, f"cannot read scene file '{file}': {exc.strerror or exc}", "a readable YAML file")]
        ) from None
    return parse_located_yaml(decode_scene_bytes(raw, file, max(size, len(raw))), file)


def parse_located_yaml(source: str | bytes, file: str = "<string>") -> LocatedDocument:
    """Parse one YAML document into plain values with locations (see module docstring for the rules)."""
    text = decode_scene_bytes(source, file) if isinstance(source, bytes) else source
    encoded_size = len(text.encode("utf-8", errors="surrogatepass"))
    if encoded_size > MAX_SCENE_BYTES:
        raise SceneError([_issue(file, 1, 1, _too_large(encoded_size), TOO_LARGE_HINT)])
    bad = _NON_PRINTABLE.search(text)
    if bad:
        line, column = _text_line_column(text, bad.start())
        code = ord(bad.group())
        what = "file looks binary (NUL character)" if code == 0 else f"control character U+{code:04X}"
        raise SceneError([_issue(file, line, column, what, "printable UTF-8 text")])
    loader = _Loader(text)
    try:
        try:
            root = loader.get_single_node()
        except _Located as exc:
            raise SceneError([_mark_issue(file, exc.mark, exc.message, exc.expected)]) from None
        except yaml.MarkedYAMLError as exc:
            raise SceneError([_yaml_error_issue(file, exc, text)]) from None
        except yaml.YAMLError as exc:
            raise SceneError([_issue(file, 1, 1, f"YAML error: {exc}", "valid YAML")]) from None
    finally:
        loader.dispose()
    if root is None or (isinstance(root, ScalarNode) and root.tag == _TAG + "null" and not root.value):
        raise SceneError([_issue(file, 1, 1, "scene file is empty", "a YAML mapping with name, simulation and bodies")])
    builder = _Builder(file, EXPANSION_FACTOR * loader.composed_count + EXPANSION_ALLOWANCE)
    try:
        value = builder.build(root, (), root.start_mark, 0)
    except _Located as exc:
        raise SceneError([_mark_issue(file, exc.mark, exc.message, exc.expected)]) from None
    if builder.issues:
        raise SceneError(builder.issues)
    return LocatedDocument(value, file, builder.value_locations, builder.key_locations)


def _mark_location(file: str, mark: Any) -> SourceLocation:
    if mark is None:
        return SourceLocation(file, 1, 1)
    return SourceLocation(file, int(mark.line) + 1, int(mark.column) + 1)


def _mark_issue(file: str, mark: Any, message: str, expected: str) -> SceneIssue:
    return SceneIssue(_mark_location(file, mark), message, expected)


def _yaml_error_issue(file: str, exc: yaml.MarkedYAMLError, text: str) -> SceneIssue:
    problem = exc.problem or "invalid YAML"
    context = f" ({exc.context} at line {exc.context_mark.line + 1})" if exc.context and exc.context_mark else ""
    expected = "valid YAML"
    mark = exc.problem_mark or exc.context_mark
    lines = text.split("\n")
    if mark is not None and mark.line < len(lines) and lines[mark.line][mark.column : mark.column + 1] == "\t":
        problem = "a tab character where YAML expects indentation or a value"
        expected = "spaces for indentation (YAML does not allow tabs there)"
    elif "expected a single document" in (exc.context or ""):
        expected = "one YAML document per scene file (no second '---')"
    return SceneIssue(_mark_location(file, mark), f"YAML syntax error: {problem}{context}", expected)


class _Builder:
    """Turns composed nodes into plain values, recording locations and bounding alias expansion."""

    _SCALAR_TAGS = {"null", "bool", "int", "float", "str", "timestamp"}

    def __init__(self, file: str, visit_budget: int):
        self.file = file
        self.visit_budget = visit_budget
        self.visits = 0
        self.value_locations: dict[YamlPath, SourceLocation] = {}
        self.key_locations: dict[YamlPath, SourceLocation] = {}
        self.issues: list[SceneIssue] = []
        self._active: set[int] = set()  # ids of nodes being built: an alias back into one is a cycle
        self._alias_marks: list[Any] = []  # aliases being expanded, outermost first
        self._constructor = SafeConstructor()

    def _visit(self, mark: Any) -> None:
        self.visits += 1
        if self.visits > self.visit_budget:
            raise _Located(
                self._alias_marks[0] if self._alias_marks else mark,
                f"aliases expand to more than {self.visit_budget} values (an alias bomb?)",
                "aliases that each expand to a modest amount of data",
            )

    def build(self, node: Node, path: YamlPath, mark: Any, depth: int) -> Any:
        self._visit(mark)
        if depth > MAX_EXPANDED_DEPTH:
            raise _Located(mark, f"nesting deeper than {MAX_EXPANDED_DEPTH} levels after expanding aliases", "")
        self.value_locations[path] = _mark_location(self.file, mark)
        if isinstance(node, _AliasNode):
            self._alias_marks.append(mark)
            try:
                return self.build(node.target, path, mark, depth + 1)
            finally:
                self._alias_marks.pop()
        if id(node) in self._active:
            raise _Located(mark, "alias refers to a node that contains it (a cycle)", "aliases without cycles")
        tag = node.tag
        if isinstance(node, ScalarNode):
            return self._scalar(node, mark)
        self._active.add(id(node))
        try:
            if isinstance(node, SequenceNode):
                if tag != _TAG + "seq":
                    raise _Located(mark, f"tag '{_short_tag(tag)}' is not allowed", "a plain list")
                return [self.build(item, (*path, i), item.start_mark, depth + 1) for i, item in enumerate(node.value)]
            if tag != _TAG + "map":
                raise _Located(mark, f"tag '{_short_tag(tag)}' is not allowed", "a plain mapping")
            result: dict[str, Any] = {}
            for key, key_mark, value_node in self._mapping_pairs(node):
                self.key_locations[(*path, key)] = _mark_location(self.file, key_mark)
                result[key] = self.build(value_node, (*path, key), value_node.start_mark, depth + 1)
            return result
        finally:
            self._active.discard(id(node))

    def _scalar(self, node: ScalarNode, mark: Any) -> Any:
        kind = node.tag[len(_TAG) :] if node.tag.startswith(_TAG) else None
        if kind not in self._SCALAR_TAGS:
            raise _Located(
                mark,
                f"tag '{_short_tag(node.tag)}' is not allowed",
                "plain data: numbers, strings, booleans, lists and mappings",
            )
        if kind in ("str", "timestamp"):  # a date-like name stays the text the user wrote
            return node.value
        try:
            return getattr(self._constructor, f"construct_yaml_{kind}")(node)
        except (ValueError, OverflowError, yaml.YAMLError):
            raise _Located(mark, f"cannot read {kind} '{node.value[:40]}'", f"a valid {kind}") from None

    def _key(self, node: Node) -> tuple[str, Any]:
        mark = node.start_mark
        while isinstance(node, _AliasNode):
            node = node.target
        if not isinstance(node, ScalarNode):
            raise _Located(mark, "a mapping key must be a plain name, not a list or mapping", "a name")
        return node.value, mark

    def _mapping_pairs(self, node: MappingNode) -> list[tuple[str, Any, Node]]:
        """(key, key mark, value node) after merge keys: explicit keys win, then earlier merge sources."""
        explicit: dict[str, tuple[Any, Node]] = {}
        merged: dict[str, tuple[Any, Node]] = {}
        for key_node, value_node in node.value:
            self._visit(key_node.start_mark)
            if key_node.tag == _MERGE_TAG and isinstance(key_node, ScalarNode):
                for source in self._merge_sources(value_node):
                    if id(source) in self._active:
                        raise _Located(value_node.start_mark, "merge refers to a mapping that contains it", "")
                    self._active.add(id(source))
                    try:
                        pairs = self._mapping_pairs(source)
                    finally:
                        self._active.discard(id(source))
                    for key, key_mark, value in pairs:
                        merged.setdefault(key, (key_mark, value))
                continue
            key, key_mark = self._key(key_node)
            if key in explicit:
                first = _mark_location(self.file, explicit[key][0])
                self.issues.append(
                    SceneIssue(
                        _mark_location(self.file, key_mark),
                        f"duplicate key '{key}' (first given at line {first.line})",
                        "each key at most once in a mapping",
                    )
                )
                continue
            explicit[key] = (key_mark, value_node)
        pairs_out = [(k, m, v) for k, (m, v) in merged.items() if k not in explicit]
        pairs_out += [(k, m, v) for k, (m, v) in explicit.items()]
        return pairs_out

    def _merge_sources(self, node: Node) -> list[MappingNode]:
        mark = node.start_mark
        while isinstance(node, _AliasNode):
            node = node.target
        if isinstance(node, MappingNode):
            return [node]
        if isinstance(node, SequenceNode):
            sources = []
            for item in node.value:
                item_mark = item.start_mark
                while isinstance(item, _AliasNode):
                    item = item.target
                if not isinstance(item, MappingNode):
                    raise _Located(item_mark, "a merge key (<<) list must hold mappings", "mappings or aliases")
                sources.append(item)
            return sources
        raise _Located(mark, "a merge key (<<) needs a mapping or a list of mappings", "a mapping or an alias")


def _short_tag(tag: str) -> str:
    return "!!" + tag[len(_TAG) :] if tag.startswith(_TAG) else tag
