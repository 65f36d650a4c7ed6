"""Scene paths: `bodies[0].angular_velocity[2]` as the tuple `("bodies", 0, "angular_velocity", 2)`, checked
against the scene schema and set in a scene's parsed data.

A sweep axis names the scene value it varies by such a path. The path is checked twice before any variant
is built: against the scene schema (is there such a key at all? `known_in_schema`) and against the base
scene's data (does the list hold that index, is there a mapping to put the key in? `set_at`).
"""

from __future__ import annotations

import copy
import re
from collections.abc import Iterable, Iterator
from typing import Any

import yaml

from rbcli.scene.issues import did_you_mean, format_path

ScenePath = tuple[str | int, ...]

_NAME = r"[A-Za-z_][A-Za-z0-9_]*"
_PATH = re.compile(rf"^{_NAME}(\[[0-9]+\])*(\.{_NAME}(\[[0-9]+\])*)*$")
_PART = re.compile(rf"({_NAME})|\[([0-9]+)\]")


class PathError(ValueError):
    """A path that cannot name a scene value: its message says why, `expected` what would."""

    def __init__(self, message: str, expected: str = "") -> None:
        super().__init__(message)
        self.expected = expected


def parse_path(text: str) -> ScenePath:
    """`"bodies[0].angular_velocity"` -> `("bodies", 0, "angular_velocity")`; PathError for bad syntax."""
    if not isinstance(text, str) or not _PATH.match(text):
        raise PathError(
            f"{text!r} is not a scene path",
            "keys joined by dots, list indices in brackets, e.g. 'bodies[0].angular_velocity' or 'simulation.dt'",
        )
    return tuple(int(index) if index else name for name, index in _PART.findall(text))


def path_text(path: ScenePath) -> str:
    """The inverse of `parse_path`."""
    return format_path(path)


def overlapping(a: ScenePath, b: ScenePath) -> bool:
    """True when one path is the other or lies inside it (two axes would set the same value)."""
    n = min(len(a), len(b))
    return a[:n] == b[:n]


# ---- the schema ---------------------------------------------------------------------------------------
def known_in_schema(root: dict[str, Any], path: ScenePath) -> None:
    """Raise PathError unless the scene schema has a place for every part of `path` (in any of the forms a
    oneOf / anyOf allows there); the error names the first part that fits nowhere, with a close key."""
    nodes = [root]
    for depth, part in enumerate(path):
        children = [child for node in nodes for child in _children(root, node, part)]
        if not children:
            where = path_text(path[:depth]) or "the scene's top level"
            if isinstance(part, int):
                raise PathError(f"{where} is not a list, so [{part}] names nothing", "a key there, not an index")
            keys = sorted({key for node in nodes for key in _keys(root, node)})
            hint = did_you_mean(part, keys)
            guess = f" — did you mean '{hint}'?" if hint else ""
            if not keys:
                raise PathError(f"{where} holds a value, not keys: '{part}' names nothing", "a shorter path")
            raise PathError(f"unknown key '{part}' under {where}{guess}", f"one of {', '.join(repr(k) for k in keys)}")
        nodes = children


def _branches(root: dict[str, Any], node: Any) -> Iterator[dict[str, Any]]:
    """The node and every schema it admits through $ref, oneOf, anyOf and allOf."""
    stack = [node]
    seen: set[int] = set()
    while stack:
        item = stack.pop()
        while isinstance(item, dict) and isinstance(item.get("$ref"), str) and item["$ref"].startswith("#/"):
            target: Any = root
            for name in item["$ref"][2:].split("/"):
                target = target[name]
            item = target
        if not isinstance(item, dict) or id(item) in seen:
            continue
        seen.add(id(item))
        yield item
        for key in ("oneOf", "anyOf", "allOf"):
            stack.extend(item.get(key, ()))


def _types(schema: dict[str, Any]) -> set[str]:
    kind = schema.get("type")
    return set(kind) if isinstance(kind, list) else {kind} if isinstance(kind, str) else set()


def _children(root: dict[str, Any], node: Any, part: str | int) -> list[Any]:
    found: list[Any] = []
    for schema in _branches(root, node):
        kinds = _types(schema)
        if isinstance(part, int):
            if "array" in kinds or "items" in schema or "prefixItems" in schema:
                prefix = schema.get("prefixItems", [])
                found.append(prefix[part] if part < len(prefix) else schema.get("items", {}))
        elif part in schema.get("properties", {}):
            found.append(schema["properties"][part])
        elif ("object" in kinds or "properties" in schema) and schema.get("additionalProperties", True) is not False:
            extra = schema.get("additionalProperties", True)
            found.append(extra if isinstance(extra, dict) else {})
    return found


def _keys(root: dict[str, Any], node: Any) -> Iterable[str]:
    for schema in _branches(root, node):
        yield from schema.get("properties", {})


# ---- the data -----------------------------------------------------------------------------------------
def check_in_data(data: Any, path: ScenePath) -> None:
    """Raise PathError when `set_at(data, path, ...)` could not place a value (an index past a list's end,
    a key into a number or a list, an index into a mapping)."""
    set_at(copy.deepcopy(data), path, None)


def set_at(data: Any, path: ScenePath, value: Any) -> Any:
    """Put `value` at `path` inside `data` (changed in place and returned). Missing mapping keys on the way
    are created as empty mappings (a `contact.material.friction` in a scene whose contact names no material
    yet); list indices must exist."""
    if not path:
        raise PathError("an empty path names the whole scene", "a path to one value")
    target = data
    for depth, part in enumerate(path):
        last = depth == len(path) - 1
        where = path_text(path[:depth]) or "the scene"
        if isinstance(part, int):
            if not isinstance(target, list):
                raise PathError(f"{where} is {_kind(target)}, not a list: [{part}] names nothing", "a key there")
            if part >= len(target):
                raise PathError(
                    f"{where} has {len(target)} entr{'y' if len(target) == 1 else 'ies'}: [{part}] is past its end",
                    f"an index below {len(target)}",
                )
            if last:
                target[part] = value
            else:
                target = target[part]
            continue
        if not isinstance(target, dict):
            raise PathError(f"{where} is {_kind(target)}, not a mapping: '{part}' names nothing", "an index or less")
        if last:
            target[part] = value
        else:
            target = target.setdefault(part, {})
    return data


def _kind(value: Any) -> str:
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "a mapping"
    return f"a value ({value!r})"


def variant_text(base: dict[str, Any], settings: tuple[tuple[ScenePath, Any], ...]) -> str:
    """The scene text of a variant: the base scene's parsed data with each (path, value) set, as YAML
    (floats written as repr, so every number reads back exactly)."""
    data = copy.deepcopy(base)
    for path, value in settings:
        set_at(data, path, copy.deepcopy(value))
    return yaml.safe_dump(data, sort_keys=False, allow_unicode=True)
