"""Plain values and compact locations straight from libyaml's events (no node tree).

PyYAML's composer keeps a node and two `Mark` objects per value; for a scene of 160,000 explicit particles
that was 640,000 nodes, ~500 MB and most of the load time, and a `path -> SourceLocation` entry per value
doubled it. Here each event is turned into its value as it arrives, and a location is kept as one packed
integer (line << 32 | column) in a table per container: an `array` of item locations per list, a
`key -> (key location, value location)` dict per mapping, both keyed by the container's id.
`LocatedDocument.locate` walks a path through them only when an issue needs a place.

Aliases first share the anchored value (so an alias bomb costs nothing to build and is refused by the
expansion budget before anything is expanded); once the budget passes, `unshare` gives every alias its own
copy, as a composer-based loader would, so editing one place of a document never changes another.
"""

from __future__ import annotations

from array import array
from dataclasses import dataclass
from typing import Any

import yaml
from yaml.composer import ComposerError
from yaml.constructor import SafeConstructor
from yaml.error import Mark
from yaml.events import (
    AliasEvent,
    DocumentEndEvent,
    DocumentStartEvent,
    MappingEndEvent,
    MappingStartEvent,
    ScalarEvent,
    SequenceEndEvent,
    SequenceStartEvent,
    StreamEndEvent,
    StreamStartEvent,
)
from yaml.nodes import ScalarNode
from yaml.resolver import BaseResolver

TAG = "tag:yaml.org,2002:"
MERGE_TAG = TAG + "merge"
_SCALAR_KINDS = {"null", "bool", "int", "float", "str", "timestamp"}

_FLOAT_END = frozenset("0123456789.")


def plain_float(text: str) -> bool:
    """Whether `float(text)`, when it succeeds, reads a plain scalar exactly as YAML 1.2 (our resolver) does:
    a float (with a fraction or an exponent). Python also takes what YAML reads otherwise: inf/nan
    spellings (they end in a letter), underscores (1_000 is an int to YAML), non-ASCII digits, a sign
    before the point (-.5 is text to YAML) and integers; those go to the resolver."""
    return (
        text[-1:] in _FLOAT_END
        and ("." in text or "e" in text or "E" in text)
        and "_" not in text
        and text.isascii()
        and text[:2] not in ("-.", "+.")
    )


# a location packed in one integer: 1-based line and column
_SHIFT = 32


def pack(line0: int, column0: int) -> int:
    """A 0-based (line, column), as libyaml marks give them, packed 1-based."""
    return ((line0 + 1) << _SHIFT) | (column0 + 1)


def unpack(packed: int) -> tuple[int, int]:
    return packed >> _SHIFT, packed & ((1 << _SHIFT) - 1)


class LocatedError(Exception):
    """An error at a packed location, turned into a SceneIssue by the caller."""

    def __init__(self, where: int, message: str, expected: str = ""):
        super().__init__(message)
        self.where = where
        self.message = message
        self.expected = expected


@dataclass
class Built:
    """A document's value, its location tables and what the caller checks after building."""

    value: Any
    root: int  # packed location of the root value
    tables: dict[int, Any]  # id(container) -> array of item locations (list) or {key: (key, value)} (dict)
    keep: list[Any]  # every container built, so no id in `tables` is reused by another object
    composed: int  # values and keys written in the text
    alias_visits: list[tuple[int, int]]  # (values expanded so far, alias location), one per alias
    duplicates: list[tuple[int, str, int]]  # (location, key, line of its first occurrence)
    empty: bool  # no document, or an empty scalar as the whole document
    suspect_numbers: bool  # some number is non-finite or beyond int64


class _Frame:
    """A list or mapping being built."""

    __slots__ = ("value", "table", "is_map", "anchor", "where", "key", "key_where", "merges", "size", "height")

    def __init__(self, value: Any, table: Any, is_map: bool, anchor: str | None, where: int):
        self.value = value
        self.table = table
        self.is_map = is_map
        self.anchor = anchor
        self.where = where
        self.key: Any = _NO_KEY  # a mapping's pending key (or _MERGE, or _SKIP for a duplicate)
        self.key_where = 0
        self.merges: list[tuple[Any, int]] = []  # (value given to `<<`, its location)
        self.size = 1  # values in the expansion, this one included
        self.height = 1  # nesting levels below and including this one


_NO_KEY = object()
_MERGE = object()
_SKIP = object()


class EventBuilder:
    """Builds plain values from a libyaml parser's events (see the module docstring)."""

    def __init__(self, parser: Any, resolver: BaseResolver, max_depth: int, max_expanded_depth: int):
        self.parser = parser
        self.resolver = resolver
        self.max_depth = max_depth
        self.max_expanded_depth = max_expanded_depth
        self.constructor = SafeConstructor()
        self.tables: dict[int, Any] = {}
        self.keep: list[Any] = []
        self.anchors: dict[str, tuple[Any, int, int, int, str | None]] = {}  # value, where, size, height, text
        self.stack: list[_Frame] = []
        self.composed = 0
        self.visits = 0
        self.alias_visits: list[tuple[int, int]] = []
        self.duplicates: list[tuple[int, str, int]] = []
        self.root: tuple[Any, int] | None = None
        self._root_was_empty = False
        self.suspect_numbers = False  # a non-finite float or an integer beyond int64 was read

    # ---- the event loop ----------------------------------------------------------------------------
    def build(self) -> Built:
        get = self.parser.get_event
        event = get()
        if not isinstance(event, StreamStartEvent):  # pragma: no cover - libyaml always starts a stream
            raise ComposerError(None, None, "expected a stream", event.start_mark)
        event = get()
        if isinstance(event, StreamEndEvent):
            return self._built(None, 0, empty=True)
        document_start = event
        while True:
            event = get()
            if not self._event(event, get):
                if type(event) is DocumentEndEvent:
                    break
                unexpected = type(event).__name__  # pragma: no cover - libyaml allows nothing else in a document
                raise ComposerError(None, None, f"unexpected {unexpected}", event.start_mark)  # pragma: no cover
        event = get()
        if isinstance(event, DocumentStartEvent):
            raise ComposerError(
                "expected a single document in the stream",
                document_start.start_mark,
                "but found another document",
                event.start_mark,
            )
        assert self.root is not None
        value, where = self.root
        empty = value is None and self._root_was_empty
        return self._built(value, where, empty=empty)

    def _built(self, value: Any, where: int, *, empty: bool) -> Built:
        return Built(
            value, where, self.tables, self.keep, self.composed, self.alias_visits, self.duplicates, empty,
            self.suspect_numbers,
        )  # fmt: skip

    # ---- values ------------------------------------------------------------------------------------
    def _depth_check(self, where: int) -> None:
        self.composed += 1
        if len(self.stack) + 1 > self.max_depth:
            raise LocatedError(where, f"nesting deeper than {self.max_depth} levels")

    def _scalars(self, get: Any) -> None:
        """The plain scalars that open a list just started (the bulk of a large scene: particle positions and
        masses), straight into it; the first other event is handled as usual and ends the run."""
        frame = self.stack[-1]
        values, table = frame.value.append, frame.table.append
        construct = self._construct
        count = 0
        deep = len(self.stack) >= self.max_depth
        while True:
            event = get()
            if type(event) is not ScalarEvent or event.anchor is not None or deep:
                break
            mark = event.start_mark
            where = ((mark.line + 1) << _SHIFT) | (mark.column + 1)
            text = event.value
            if event.tag is None and event.implicit[0] and plain_float(text):
                try:
                    number = float(text)
                except ValueError:
                    number = construct(event, where)
                else:
                    if number - number != 0.0:  # 1e999: inf (and load.py reports it)
                        self.suspect_numbers = True
                values(number)
            else:
                values(construct(event, where))
            table(where)
            count += 1
        self.composed += count
        frame.size += count
        if count:
            frame.height = max(frame.height, 2)
        if not self._event(event, get):  # pragma: no cover - a list ends before its document does
            raise ComposerError(None, None, f"unexpected {type(event).__name__}", event.start_mark)

    def _event(self, event: Any, get: Any) -> bool:
        """Build one event of a document's content (a list just opened takes its plain scalars in bulk,
        `_scalars`); False for an event that is not content (the document's end)."""
        kind = type(event)
        if kind is ScalarEvent:
            self._scalar(event)
        elif kind is SequenceStartEvent:
            self._start(event, False)
            self._scalars(get)
        elif kind is MappingStartEvent:
            self._start(event, True)
        elif kind is SequenceEndEvent or kind is MappingEndEvent:
            self._end()
        elif kind is AliasEvent:
            self._alias(event)
        else:
            return False
        return True

    def _scalar(self, event: Any) -> None:
        mark = event.start_mark
        where = ((mark.line + 1) << _SHIFT) | (mark.column + 1)
        stack = self.stack
        self.composed += 1
        if len(stack) >= self.max_depth:
            raise LocatedError(where, f"nesting deeper than {self.max_depth} levels")
        frame = stack[-1] if stack else None
        if frame is not None and not frame.is_map and event.anchor is None:
            # the bulk of a large scene (particle positions, masses): straight into the list
            frame.value.append(self._construct(event, where))
            frame.table.append(where)
            frame.size += 1
            if frame.height < 2:
                frame.height = 2
            return
        if frame is not None and frame.is_map and frame.key is _NO_KEY:
            self._key(frame, event.value, where, event.tag == MERGE_TAG or (event.implicit[0] and event.value == "<<"))
            if event.anchor is not None:
                self._anchor(event.anchor, event.value, where, 1, 1, event.value, event.start_mark)
            return
        value = self._construct(event, where)
        if frame is None:
            self._root_was_empty = value is None and event.value == ""
        if event.anchor is not None:
            self._anchor(event.anchor, value, where, 1, 1, event.value, event.start_mark)
        self._emit(value, where, 1, 1)

    def _construct(self, event: Any, where: int) -> Any:
        value = self._value(event, where)
        kind = type(value)
        if (kind is float and value - value != 0.0) or (kind is int and not -(2**63) < value < 2**63):
            self.suspect_numbers = True  # load.py's finite-number check has something to find
        return value

    def _value(self, event: Any, where: int) -> Any:
        tag = event.tag
        value = event.value
        if tag is None and event.implicit[0]:
            if plain_float(value):
                try:  # the common case at C speed (YAML's other number forms: the resolver below)
                    return float(value)
                except ValueError:
                    pass
            elif value.isascii() and value.isdigit() and len(value) <= 18 and (value[0] != "0" or value == "0"):
                return int(value)  # plain decimal (a leading 0 is octal in YAML 1.1: the constructor reads it)
        if tag is None or tag == "!":
            tag = self.resolver.resolve(ScalarNode, value, event.implicit)
        kind = tag[len(TAG) :] if tag.startswith(TAG) else None
        if kind not in _SCALAR_KINDS:
            plain = "plain data: numbers, strings, booleans, lists and mappings"
            raise LocatedError(where, f"tag '{short_tag(tag)}' is not allowed", plain)
        if kind == "str" or kind == "timestamp":  # a date-like name stays the text the user wrote
            return value
        try:
            return getattr(self.constructor, f"construct_yaml_{kind}")(ScalarNode(tag, value))
        except (ValueError, OverflowError, yaml.YAMLError):
            raise LocatedError(where, f"cannot read {kind} '{value[:40]}'", f"a valid {kind}") from None

    def _start(self, event: Any, is_map: bool) -> None:
        mark = event.start_mark
        where = pack(mark.line, mark.column)
        self._depth_check(where)
        parent = self.stack[-1] if self.stack else None
        if parent is not None and parent.is_map and parent.key is _NO_KEY:
            raise LocatedError(where, "a mapping key must be a plain name, not a list or mapping", "a name")
        tag = event.tag
        want = TAG + ("map" if is_map else "seq")
        if tag is not None and tag != "!" and tag != want:
            raise LocatedError(
                where, f"tag '{short_tag(tag)}' is not allowed", "a plain mapping" if is_map else "a plain list"
            )
        if event.anchor is not None and event.anchor in self.anchors:
            self._duplicate_anchor(event.anchor, event.start_mark)
        value: Any = {} if is_map else []
        table: Any = {} if is_map else array("q")
        self.tables[id(value)] = table
        self.keep.append(value)
        self.stack.append(_Frame(value, table, is_map, event.anchor, where))

    def _end(self) -> None:
        frame = self.stack.pop()
        if frame.is_map and frame.merges:
            self._merge(frame)
        if frame.anchor is not None:
            self._anchor(frame.anchor, frame.value, frame.where, frame.size, frame.height, None, None)
        self._emit(frame.value, frame.where, frame.size, frame.height)

    def _alias(self, event: Any) -> None:
        mark = event.start_mark
        where = pack(mark.line, mark.column)
        name = event.anchor
        if any(f.anchor == name for f in self.stack):
            raise LocatedError(where, "alias refers to a node that contains it (a cycle)", "aliases without cycles")
        if name not in self.anchors:
            raise ComposerError(None, None, f"found undefined alias {name!r}", mark)
        value, _, size, height, text = self.anchors[name]
        if len(self.stack) + height > self.max_expanded_depth:
            raise LocatedError(where, f"nesting deeper than {self.max_expanded_depth} levels after expanding aliases")
        self.visits += size
        self.alias_visits.append((self.visits, where))
        frame = self.stack[-1] if self.stack else None
        if frame is not None and frame.is_map and frame.key is _NO_KEY:
            if text is None:
                raise LocatedError(where, "a mapping key must be a plain name, not a list or mapping", "a name")
            self._key(frame, text, where, False)
            return
        self._emit(value, where, size, height)

    # ---- into the parent ---------------------------------------------------------------------------
    def _emit(self, value: Any, where: int, size: int, height: int) -> None:
        if not self.stack:
            self.root = (value, where)
            return
        frame = self.stack[-1]
        frame.size += size
        frame.height = max(frame.height, height + 1)
        if not frame.is_map:
            frame.value.append(value)
            frame.table.append(where)
            return
        key = frame.key
        frame.key = _NO_KEY
        if key is _SKIP:
            return
        if key is _MERGE:
            frame.merges.append((value, where))
            return
        frame.value[key] = value
        frame.table[key] = (frame.key_where, where)

    def _key(self, frame: _Frame, key: str, where: int, merge: bool) -> None:
        frame.size += 1
        if merge:
            frame.key = _MERGE
            return
        if key in frame.value:
            first = frame.table[key][0] >> _SHIFT
            self.duplicates.append((where, key, first))
            frame.key = _SKIP
            return
        frame.key = key
        frame.key_where = where

    def _merge(self, frame: _Frame) -> None:
        """`<<` sources into the mapping: its own keys win, then earlier sources (YAML merge rules)."""
        merged: dict[str, Any] = {}
        locations: dict[str, tuple[int, int]] = {}
        for source, where in frame.merges:
            if isinstance(source, dict):
                mappings = [source]
            elif isinstance(source, list):
                items = self.tables[id(source)]
                for item, item_where in zip(source, items, strict=True):
                    if not isinstance(item, dict):
                        raise LocatedError(
                            item_where, "a merge key (<<) list must hold mappings", "mappings or aliases"
                        )
                mappings = source
            else:
                raise LocatedError(
                    where, "a merge key (<<) needs a mapping or a list of mappings", "a mapping or an alias"
                )
            for mapping in mappings:
                table = self.tables[id(mapping)]
                for key, value in mapping.items():
                    if key not in merged and key not in frame.value:
                        merged[key] = value
                        locations[key] = table[key]
                        frame.size += 1
        own = frame.value
        combined = {**merged, **own}
        own.clear()
        own.update(combined)  # the same dict object: its id keys the table
        frame.table.update(locations)

    def _anchor(self, name: str, value: Any, where: int, size: int, height: int, text: str | None, mark: Any) -> None:
        if name in self.anchors and mark is not None:
            self._duplicate_anchor(name, mark)
        self.anchors[name] = (value, where, size, height, text)

    def _duplicate_anchor(self, name: str, mark: Any) -> None:
        line, column = unpack(self.anchors[name][1])
        first = Mark(mark.name, 0, line - 1, column - 1, None, None)
        raise ComposerError(f"found duplicate anchor {name!r}; first occurrence", first, "second occurrence", mark)


def unshare(built: Built) -> None:
    """Give every alias its own copy of what it names (and every merged value its own), tables included."""
    seen: set[int] = {id(built.value)}

    def copy(value: Any) -> Any:
        out: Any
        if isinstance(value, list):
            out = [copy(v) for v in value]
            built.tables[id(out)] = array("q", built.tables[id(value)])
        elif isinstance(value, dict):
            out = {k: copy(v) for k, v in value.items()}
            built.tables[id(out)] = dict(built.tables[id(value)])
        else:
            return value
        built.keep.append(out)
        seen.add(id(out))
        return out

    stack = [built.value]
    while stack:
        value = stack.pop()
        if isinstance(value, list):
            for i, item in enumerate(value):
                if isinstance(item, list | dict):
                    if id(item) in seen:
                        value[i] = copy(item)
                    else:
                        seen.add(id(item))
                        stack.append(item)
        elif isinstance(value, dict):
            for key, item in value.items():
                if isinstance(item, list | dict):
                    if id(item) in seen:
                        value[key] = copy(item)
                    else:
                        seen.add(id(item))
                        stack.append(item)


def short_tag(tag: str) -> str:
    return "!!" + tag[len(TAG) :] if tag.startswith(TAG) else tag
