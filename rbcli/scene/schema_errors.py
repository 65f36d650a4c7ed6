"""JSON Schema errors turned into located, readable scene issues: `what is wrong — what was expected`.

jsonschema reports a failed `oneOf` as one error holding the errors of every branch; dumping them all
buries the one that matters. We pick the branch the user evidently meant (a key only that branch requires,
a `const` discriminator that matches, else the branch with the least severe errors) and report its errors
only. Unknown keys get a "did you mean"; a `required` error that an unknown key explains (a typo) is
dropped.
"""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Set as AbstractSet
from dataclasses import dataclass
from typing import Any

from jsonschema import ValidationError

from rbcli.scene.issues import IssueCollector, did_you_mean, quoted_list
from rbcli.scene.yaml_located import YamlPath

_JSON_TYPE_NAMES = {
    "number": "a number",
    "integer": "an integer",
    "string": "a string",
    "boolean": "true or false",
    "array": "a list",
    "object": "a mapping",
    "null": "nothing (null)",
}

_PATTERN_NAMES = {
    "\\.(mcap|rrd)$": "a file name ending in .mcap or .rrd",
    "^([xyz]{3}|[XYZ]{3})$": "three axis letters, all lowercase (extrinsic, e.g. 'xyz') or all uppercase "
    "(intrinsic, e.g. 'ZYX')",
}


@dataclass
class _Found:
    path: YamlPath
    message: str
    expected: str = ""
    key: bool = False
    missing: tuple[str, ...] = ()  # the keys a `required` (or "one of") error names
    suggestion: str | None = None  # the key an unknown key probably meant


def describe_value(value: Any) -> str:
    """A short phrase for a YAML value's type, as a user would call it."""
    if value is None:
        return "nothing (an empty value)"
    if isinstance(value, bool):
        return f"a boolean ({str(value).lower()})"
    if isinstance(value, int | float):
        return f"a number ({value!r})"
    if isinstance(value, str):
        shown = value if len(value) <= 30 else value[:27] + "..."
        return f"a string ('{shown}')"
    if isinstance(value, list):
        return f"a list of {len(value)} item{'s' if len(value) != 1 else ''}"
    if isinstance(value, dict):
        return "a mapping"
    return type(value).__name__


class SchemaErrorFormatter:
    """Formats every error of one validation run into an `IssueCollector`."""

    def __init__(self, root_schema: dict[str, Any], collector: IssueCollector):
        self.root = root_schema
        self.collector = collector

    def report(self, errors: list[ValidationError], skip_paths: AbstractSet[YamlPath] = frozenset()) -> set[YamlPath]:
        """Add an issue per error (skipping errors at `skip_paths`); returns the paths with issues."""
        found: list[_Found] = []
        for error in errors:
            found.extend(self._format(error))
        suggested = {(f.path[:-1], f.suggestion) for f in found if f.suggestion}  # (mapping path, key meant)
        paths: set[YamlPath] = set()
        for f in found:
            if f.path in skip_paths:
                continue
            # a missing key marks that key's subtree as bad, not the whole mapping around it
            paths.add((*f.path, f.missing[0]) if len(f.missing) == 1 else f.path)
            if any((f.path, k) in suggested for k in f.missing):
                continue  # "unknown key 'durtion' — did you mean 'duration'?" already says it
            self.collector.error(f.path, f.message, f.expected, key=f.key)
        return paths

    # ---- one error ---------------------------------------------------------------------------------
    def _format(self, error: ValidationError) -> list[_Found]:
        path: YamlPath = tuple(error.absolute_path)
        kind = error.validator
        value = error.validator_value
        instance = error.instance
        schema = error.schema if isinstance(error.schema, dict) else {}
        handler = getattr(self, f"_on_{kind}", None)
        if handler is not None:
            return handler(path, value, instance, schema, error)
        return [_Found(path, error.message)]

    def _on_oneOf(self, path, value, instance, schema, error) -> list[_Found]:  # noqa: N802 (keyword name)
        choice = _choice_keys(value)
        if choice is not None:
            present = [k for k in choice if isinstance(instance, dict) and k in instance]
            if not present:
                return [
                    _Found(
                        path,
                        f"missing one of {quoted_list(choice)}",
                        "exactly one of them",
                        key=True,
                        missing=tuple(choice),
                    )
                ]
            present.sort(key=lambda k: _order(self.collector.locate((*path, k), key=True)))
            return [
                _Found(
                    (*path, present[1]),
                    f"give only one of {quoted_list(choice)} (found {quoted_list(present)})",
                    "exactly one of them",
                    key=True,
                )
            ]
        if not error.context:
            return [_Found(path, "matches more than one accepted form", self._forms(value))]
        by_branch: dict[int, list[ValidationError]] = defaultdict(list)
        for sub in error.context:
            by_branch[int(sub.relative_schema_path[0])].append(sub)
        branch = self._pick_branch(value, instance, by_branch)
        if branch is not None:
            found: list[_Found] = []
            for sub in by_branch[branch]:
                found.extend(self._format(sub))
            return found
        return self._no_branch(path, value, instance)

    _on_anyOf = _on_oneOf  # noqa: N815

    def _pick_branch(self, branches: list[Any], instance: Any, by_branch: dict[int, list]) -> int | None:
        resolved = [self._resolve(b) for b in branches]
        if isinstance(instance, dict):
            claims = set()
            for i, branch in enumerate(resolved):
                if any(sub.validator == "const" for sub in by_branch.get(i, ())):
                    continue  # a discriminator that does not match outweighs any key the branch requires
                others = set().union(*(set(r.get("required", ())) for j, r in enumerate(resolved) if j != i))
                if any(k in instance and k not in others for k in branch.get("required", ())):
                    claims.add(i)
                for k, prop in branch.get("properties", {}).items():
                    if isinstance(prop, dict) and "const" in prop and instance.get(k) == prop["const"]:
                        claims.add(i)
            if len(claims) == 1:
                return claims.pop()
        scores = {i: sum(_severity(sub) for sub in subs) for i, subs in by_branch.items()}
        best = min(scores.values())
        winners = [i for i, s in scores.items() if s == best]
        if len(winners) == 1 and best < 100:
            return winners[0]
        return None

    def _no_branch(self, path: YamlPath, branches: list[Any], instance: Any) -> list[_Found]:
        resolved = [self._resolve(b) for b in branches]
        if isinstance(instance, dict):
            consts: dict[str, list[Any]] = defaultdict(list)
            for r in resolved:
                for k, prop in r.get("properties", {}).items():
                    if isinstance(prop, dict) and "const" in prop:
                        consts[k].append(prop["const"])
            for k, options in consts.items():
                if len(options) == len(resolved) and k in instance:
                    hint = did_you_mean(str(instance[k]), [str(o) for o in options])
                    guess = f" — did you mean '{hint}'?" if hint else ""
                    return [_Found((*path, k), f"unknown {k} '{instance[k]}'{guess}", f"one of {quoted_list(options)}")]
            known = set().union(*(set(r.get("properties", {})) for r in resolved))
            unknown = [k for k in instance if k not in known]
            if unknown:
                found = []
                for k in unknown:
                    hint = did_you_mean(k, known)
                    guess = f" — did you mean '{hint}'?" if hint else ""
                    found.append(_Found((*path, k), f"unknown key '{k}'{guess}", self._forms(branches), key=True))
                return found
        return [_Found(path, f"got {describe_value(instance)}, which matches no accepted form", self._forms(branches))]

    def _forms(self, branches: list[Any]) -> str:
        titles = [self._title(b) for b in branches]
        return "one of: " + "; ".join(titles)

    def _title(self, branch: Any) -> str:
        resolved = self._resolve(branch)
        if "title" in resolved:
            return str(resolved["title"])
        return _JSON_TYPE_NAMES.get(str(resolved.get("type")), "another form")

    def _resolve(self, schema: Any) -> dict[str, Any]:
        while isinstance(schema, dict) and "$ref" in schema and str(schema["$ref"]).startswith("#/"):
            target: Any = self.root
            for part in str(schema["$ref"])[2:].split("/"):
                target = target[part]
            schema = target
        return schema if isinstance(schema, dict) else {}

    def _on_additionalProperties(self, path, value, instance, schema, error) -> list[_Found]:  # noqa: N802
        known = list(schema.get("properties", {}))
        defs = self.root.get("$defs", {})
        found = []
        for k in instance:
            if k in known:
                continue
            if schema is defs.get("template") and k in ("name", "position"):
                found.append(_Found((*path, k), f"'{k}' is set by the generator, not by its template", "", key=True))
                continue
            if schema is defs.get("defaults") and k == "name":
                found.append(_Found((*path, k), "names are per body; defaults cannot give one", "", key=True))
                continue
            hint = did_you_mean(k, known)
            guess = f" — did you mean '{hint}'?" if hint else ""
            expected = f"one of {quoted_list(known)}" if known else "no keys here"
            found.append(_Found((*path, k), f"unknown key '{k}'{guess}", expected, key=True, suggestion=hint))
        return found

    def _on_required(self, path, value, instance, schema, error) -> list[_Found]:
        missing = [k for k in value if isinstance(instance, dict) and k not in instance]
        found = []
        for k in missing:
            desc = _first_sentence(schema.get("properties", {}).get(k, {}).get("description", ""))
            expected = f"'{k}': {desc}" if desc else f"'{k}'"
            found.append(_Found(path, f"missing required key '{k}'", expected, key=True, missing=(k,)))
        return found

    def _on_type(self, path, value, instance, schema, error) -> list[_Found]:
        kinds: list[str] = value if isinstance(value, list) else [value]  # the schema's `type`: one name or a list
        expected = " or ".join(_JSON_TYPE_NAMES.get(k, k) for k in kinds)
        desc = _first_sentence(schema.get("description", ""))
        return [
            _Found(path, f"wrong type: got {describe_value(instance)}", f"{expected}" + (f" ({desc})" if desc else ""))
        ]

    def _on_minItems(self, path, value, instance, schema, error) -> list[_Found]:  # noqa: N802
        return [self._length(path, instance, schema)]

    _on_maxItems = _on_minItems  # noqa: N815

    def _length(self, path: YamlPath, instance: Any, schema: dict) -> _Found:
        lo, hi = schema.get("minItems"), schema.get("maxItems")
        if lo is not None and lo == hi:
            want = f"exactly {lo} item{'s' if lo != 1 else ''}"
        elif hi is None:
            want = f"at least {lo} item{'s' if lo != 1 else ''}"
        else:
            want = f"at most {hi} items" if lo is None else f"{lo} to {hi} items"
        desc = _first_sentence(schema.get("description", ""))
        return _Found(
            path,
            f"wrong length: {len(instance)} item{'s' if len(instance) != 1 else ''}",
            want + (f" ({desc})" if desc else ""),
        )

    def _bound(self, path: YamlPath, instance: Any, relation: str, limit: Any, schema: dict) -> list[_Found]:
        desc = _first_sentence(schema.get("description", ""))
        return [
            _Found(
                path, f"{instance!r} is out of range", f"a value {relation} {limit}" + (f" ({desc})" if desc else "")
            )
        ]

    def _on_exclusiveMinimum(self, path, value, instance, schema, error):  # noqa: N802
        return self._bound(path, instance, ">", value, schema)

    def _on_minimum(self, path, value, instance, schema, error):
        return self._bound(path, instance, ">=", value, schema)

    def _on_maximum(self, path, value, instance, schema, error):
        return self._bound(path, instance, "<=", value, schema)

    def _on_exclusiveMaximum(self, path, value, instance, schema, error):  # noqa: N802
        return self._bound(path, instance, "<", value, schema)

    def _on_enum(self, path, value, instance, schema, error) -> list[_Found]:
        hint = did_you_mean(str(instance), [str(v) for v in value])
        guess = f" — did you mean '{hint}'?" if hint else ""
        return [_Found(path, f"unknown value {instance!r}{guess}", f"one of {quoted_list(value)}")]

    def _on_const(self, path, value, instance, schema, error) -> list[_Found]:
        return [_Found(path, f"got {instance!r}", f"'{value}'")]

    def _on_pattern(self, path, value, instance, schema, error) -> list[_Found]:
        want = _PATTERN_NAMES.get(value, f"text matching {value}")
        return [_Found(path, f"{instance!r} is not of the expected form", want)]

    def _on_minLength(self, path, value, instance, schema, error) -> list[_Found]:  # noqa: N802
        return [_Found(path, "must not be empty", "a non-empty string")]

    def _on_uniqueItems(self, path, value, instance, schema, error) -> list[_Found]:  # noqa: N802
        return [_Found(path, "has repeated entries", "each entry at most once")]

    def _on_not(self, path, value, instance, schema, error) -> list[_Found]:
        keys = value.get("required") if isinstance(value, dict) else None
        if keys and not isinstance(instance, dict):
            # `required` holds for anything that is not a mapping, so its `not` fails there: the wrong type
            # is reported on its own (a `defaults` given as a list read as "velocity and momentum both")
            return []
        if keys and len(keys) == 2:
            a, b = keys
            # point at whichever of the two comes second in the file
            later = max(keys, key=lambda k: _order(self.collector.locate((*path, k), key=True)))
            return [
                _Found((*path, later), f"give either '{a}' or '{b}', not both", f"only one of '{a}', '{b}'", key=True)
            ]
        return [_Found(path, error.message)]


def _order(location: Any) -> tuple[int, int]:
    return (location.line, location.column) if location is not None else (0, 0)


def _choice_keys(branches: Any) -> list[str] | None:
    """Keys of a 'give exactly one of these keys' oneOf (every branch is just `required: [key]`)."""
    if not isinstance(branches, list) or not branches:
        return None
    keys = []
    for b in branches:
        if not isinstance(b, dict) or set(b) - {"required", "title"} or len(b.get("required", ())) != 1:
            return None
        keys.append(b["required"][0])
    return keys


def _severity(error: ValidationError) -> int:
    """How strongly an error says 'this branch is not what the user meant' (higher: less likely)."""
    depth = len(error.relative_path)
    if depth == 0 and error.validator == "type":
        return 1000
    if depth <= 1 and error.validator == "const":
        return 100
    if depth == 0 and error.validator in ("required", "additionalProperties"):
        return 10
    if depth == 0 and error.validator == "oneOf" and _choice_keys(error.validator_value):
        return 10
    return 1


def _first_sentence(text: str) -> str:
    """The gist of a schema description for an `expected` hint: its first clause, e.g. 'time step [s]'."""
    text = str(text)
    for stop in (". ", "; ", " (", ": "):
        cut = text.find(stop)
        if cut >= 0:
            text = text[:cut]
    text = text.rstrip(".")
    if not text or len(text) > 80:
        return ""
    return text[0].lower() + text[1:] if not text[:2].isupper() else text
