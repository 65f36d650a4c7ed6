"""The scene schema's validator: jsonschema's own for the schema's draft, with a fast path for long arrays.

A scene of 160,000 explicit particles is a list of 160,000 `[x, y, z]` items, and jsonschema spends ~60 us
descending into each (resolving `$ref`, evolving the validator, checking every keyword). When an array's
item schema is plain numbers (a type, bounds) or arrays of them (lengths), the same test is a few Python
comparisons; an item that fails it is handed to jsonschema itself, so every error is the one jsonschema
gives (same message, same path), and an item the fast test passes is one jsonschema passes too: the fast
test mirrors jsonschema's keyword code exactly (`instance < minimum` fails, ...).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any

from jsonschema import validators

# arrays shorter than this go through jsonschema item by item: the fast path is for bulk data
LONG_ARRAY = 64
# keywords that only describe: they never make an instance invalid
ANNOTATIONS = frozenset({"description", "title", "examples", "default", "$comment", "deprecated"})

Check = Callable[[Any], bool]


def scene_validator(schema: dict[str, Any]) -> Any:
    """A validator for `schema` (the class its `$schema` names) whose `items` takes the fast path."""
    base = validators.validator_for(schema)
    plain_items = base.VALIDATORS["items"]
    checks: dict[int, Check | None] = {}

    def items(validator: Any, item_schema: Any, instance: Any, schema_here: dict[str, Any]) -> Iterator[Any]:
        if type(instance) is not list or len(instance) < LONG_ARRAY or "prefixItems" in schema_here:
            yield from plain_items(validator, item_schema, instance, schema_here)
            return
        key = id(item_schema)
        if key not in checks:
            checks[key] = _check_of(item_schema, schema)
        check = checks[key]
        if check is None:
            yield from plain_items(validator, item_schema, instance, schema_here)
            return
        for index, item in enumerate(instance):
            if not check(item):  # jsonschema says what is wrong with it
                yield from validator.descend(instance=item, schema=item_schema, path=index)

    cls = validators.extend(base, {"items": items})
    return cls(schema)


def _resolve(schema: Any, root: dict[str, Any]) -> Any:
    """A schema with its `$ref` (to this document, and with only annotations beside it) followed; None when
    it has anything else next to the `$ref`."""
    while isinstance(schema, dict) and "$ref" in schema:
        ref = schema["$ref"]
        if set(schema) - ANNOTATIONS - {"$ref"} or not isinstance(ref, str) or not ref.startswith("#/"):
            return None
        target: Any = root
        for part in ref[2:].split("/"):
            if not isinstance(target, dict) or part not in target:
                return None
            target = target[part]
        schema = target
    return schema


def _check_of(schema: Any, root: dict[str, Any]) -> Check | None:
    """A fast exact test for an item schema made of number types, bounds, arrays and lengths; else None."""
    schema = _resolve(schema, root)
    if not isinstance(schema, dict):
        return None
    kind = schema.get("type")
    keys = set(schema) - ANNOTATIONS
    if kind in ("number", "integer"):
        if keys - {"type", "minimum", "maximum", "exclusiveMinimum", "exclusiveMaximum"}:
            return None
        return _number_check(schema, integer=kind == "integer")
    if kind == "array":
        if keys - {"type", "items", "minItems", "maxItems"}:
            return None
        item_check = _check_of(schema["items"], root) if "items" in schema else (lambda _: True)
        if item_check is None:
            return None
        return _array_check(schema.get("minItems"), schema.get("maxItems"), item_check)
    return None


def _number_check(schema: dict[str, Any], *, integer: bool) -> Check:
    """jsonschema's `type` (number: int or float, not bool; integer: also a float with no fraction) and
    bound keywords, in its own comparisons (so NaN passes the bounds as it does there)."""
    lo, hi = schema.get("minimum"), schema.get("maximum")
    xlo, xhi = schema.get("exclusiveMinimum"), schema.get("exclusiveMaximum")

    def check(value: Any) -> bool:
        kind = type(value)
        if kind is not float and kind is not int:
            return False
        if integer and kind is float and not value.is_integer():
            return False
        if lo is not None and value < lo:
            return False
        if hi is not None and value > hi:
            return False
        if xlo is not None and value <= xlo:
            return False
        return not (xhi is not None and value >= xhi)

    return check


def _array_check(lo: int | None, hi: int | None, item_check: Check) -> Check:
    def check(value: Any) -> bool:
        if type(value) is not list:
            return False
        if (lo is not None and len(value) < lo) or (hi is not None and len(value) > hi):
            return False
        return all(item_check(item) for item in value)

    return check
