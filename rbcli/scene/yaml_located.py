"""Safe YAML with source locations: plain Python values, and the location of every key and value by path.

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

Values are built straight from libyaml's events and locations kept packed per container
(`scene/yaml_build.py`): a 9 MB scene of 160,000 explicit particles reads in linear time and a fraction of
the memory a node tree and a `SourceLocation` per value took (benchmarks/bench_validate.py).
"""

from __future__ import annotations

import os
import re
from array import array
from pathlib import Path
from typing import Any

import yaml
from yaml.resolver import BaseResolver, Resolver

from rbcli.scene.spec import SceneError, SceneIssue, SourceLocation
from rbcli.scene.yaml_build import Built, EventBuilder, LocatedError, pack, unpack, unshare

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


def _parser(text: str) -> Any:
    """libyaml's parser when PyYAML has it (scanning and parsing in C), else PyYAML's own."""
    if getattr(yaml, "__with_libyaml__", False):
        from yaml.cyaml import CParser

        return CParser(text)
    from yaml.parser import Parser  # pragma: no cover - PyYAML without libyaml
    from yaml.reader import Reader
    from yaml.scanner import Scanner

    class _Parser(Reader, Scanner, Parser):
        def __init__(self, stream: str):
            Reader.__init__(self, stream)
            Scanner.__init__(self)
            Parser.__init__(self)

    return _Parser(text)


class LocatedDocument:
    """A YAML document as plain values, with the location of every value and every mapping key.

    Locations are kept compactly per container (yaml_build) and turned into SourceLocations only when
    asked: `locate` walks one path; `value_locations` / `key_locations` build the whole table."""

    def __init__(self, value: Any, file: str, built: Built | None = None):
        self.value = value
        self.file = file
        self._root = built.root if built is not None else pack(0, 0)
        self._tables: dict[int, Any] = built.tables if built is not None else {}
        self._keep = built.keep if built is not None else []
        self._copies: dict[YamlPath, YamlPath] = {}  # target prefix -> source prefix (copy_locations)
        # False only when the reader saw every number: then none is non-finite or beyond int64
        self.suspect_numbers = built.suspect_numbers if built is not None else True

    def _location(self, packed: int) -> SourceLocation:
        line, column = unpack(packed)
        return SourceLocation(self.file, line, column)

    def _walk(self, path: YamlPath) -> tuple[int, int | None, int]:
        """(value location of the deepest existing prefix, its key location or None, its length)."""
        node, where, key_where = self.value, self._root, None
        for depth, part in enumerate(path):
            table = self._tables.get(id(node))
            if isinstance(node, dict) and isinstance(table, dict) and part in table:
                key_where, where = table[part]
            elif isinstance(node, list) and isinstance(table, array) and type(part) is int and 0 <= part < len(node):
                key_where, where = None, table[part]
            else:
                return where, None, depth
            node = node[part]
        return where, key_where, len(path)

    def locate(self, path: YamlPath, *, key: bool = False) -> SourceLocation:
        """Location of the value at `path` (or of its key when `key`), else of the nearest ancestor."""
        path = tuple(path)
        where, key_where, reached = self._walk(path)
        if reached < len(path):
            for length in range(len(path), reached, -1):  # a key merged in from `defaults`?
                source = self._copies.get(path[:length])
                if source is not None:
                    return self.locate(source + path[length:], key=key)
        if key and key_where is not None and reached == len(path):
            return self._location(key_where)
        return self._location(where)

    def copy_locations(self, source: YamlPath, target: YamlPath) -> None:
        """Give every path under `target` the locations of the same path under `source` (defaults merge);
        paths the document itself has keep their own."""
        self._copies.setdefault(tuple(target), tuple(source))

    @property
    def value_locations(self) -> dict[YamlPath, SourceLocation]:
        """Every value's location by path (built on each call; `locate` is the cheap way to one)."""
        return self._table(key=False)

    @property
    def key_locations(self) -> dict[YamlPath, SourceLocation]:
        """Every mapping key's location by path (built on each call)."""
        return self._table(key=True)

    def _table(self, *, key: bool) -> dict[YamlPath, SourceLocation]:
        out: dict[YamlPath, SourceLocation] = {} if key else {(): self._location(self._root)}
        stack: list[tuple[Any, YamlPath]] = [(self.value, ())]
        while stack:
            node, path = stack.pop()
            table = self._tables.get(id(node))
            if isinstance(node, dict) and isinstance(table, dict):
                for k, child in node.items():
                    key_where, where = table[k]
                    out[(*path, k)] = self._location(key_where if key else where)
                    stack.append((child, (*path, k)))
            elif isinstance(node, list) and isinstance(table, array):
                for i, child in enumerate(node):
                    if not key:
                        out[(*path, i)] = self._location(table[i])
                    stack.append((child, (*path, i)))
        return out


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
    builder = EventBuilder(_parser(text), _SceneResolver(), MAX_DEPTH, MAX_EXPANDED_DEPTH)
    try:
        built = builder.build()
    except LocatedError as exc:
        raise SceneError([_packed_issue(file, exc.where, exc.message, exc.expected)]) from None
    except yaml.MarkedYAMLError as exc:
        raise SceneError([_yaml_error_issue(file, exc, text)]) from None
    except yaml.YAMLError as exc:
        raise SceneError([_issue(file, 1, 1, f"YAML error: {exc}", "valid YAML")]) from None
    if built.empty:
        raise SceneError([_issue(file, 1, 1, "scene file is empty", "a YAML mapping with name, simulation and bodies")])
    budget = EXPANSION_FACTOR * built.composed + EXPANSION_ALLOWANCE
    over = next((where for visits, where in built.alias_visits if built.composed + visits > budget), None)
    if over is not None:
        raise SceneError([_packed_issue(file, over, f"aliases expand to more than {budget} values (an alias bomb?)",
                                        "aliases that each expand to a modest amount of data")])  # fmt: skip
    if built.duplicates:
        raise SceneError([
            _packed_issue(file, where, f"duplicate key '{key}' (first given at line {first})",
                          "each key at most once in a mapping")
            for where, key, first in built.duplicates
        ])  # fmt: skip
    if built.alias_visits:
        unshare(built)
    return LocatedDocument(built.value, file, built)


def top_level_keys(text: str, stop: frozenset[str] = frozenset()) -> set[str]:
    """The keys of a document's top-level mapping, read from the parser's events without building any value;
    the scan ends at the first key in `stop` (what it needs to tell a sweep file from a 9 MB scene at once).
    Empty for a document that is not a mapping; yaml.YAMLError for text that is not YAML."""
    parser = _parser(text)
    starts = (yaml.MappingStartEvent, yaml.SequenceStartEvent)
    ends = (yaml.MappingEndEvent, yaml.SequenceEndEvent)
    keys: set[str] = set()
    depth = 0
    child = 0  # children of the top-level mapping so far: keys at even positions, values at odd
    while parser.check_event():
        event = parser.get_event()
        if depth == 0:
            if isinstance(event, yaml.MappingStartEvent):
                depth = 1
            elif not isinstance(event, yaml.StreamStartEvent | yaml.DocumentStartEvent):
                return keys  # not a mapping, or no document
        elif isinstance(event, starts):
            depth += 1
        elif isinstance(event, ends):
            depth -= 1
            if depth == 0:
                return keys
            if depth == 1:
                child += 1
        elif depth == 1:  # a scalar or an alias in the top-level mapping
            if child % 2 == 0 and isinstance(event, yaml.ScalarEvent):
                keys.add(event.value)
                if event.value in stop:
                    return keys
            child += 1
    return keys


def _packed_issue(file: str, where: int, message: str, expected: str) -> SceneIssue:
    line, column = unpack(where)
    return SceneIssue(SourceLocation(file, line, column), message, expected)


def _mark_location(file: str, mark: Any) -> SourceLocation:
    if mark is None:
        return SourceLocation(file, 1, 1)
    return SourceLocation(file, int(mark.line) + 1, int(mark.column) + 1)


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
