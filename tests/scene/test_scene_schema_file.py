"""The scene schema itself: valid 2020-12, closed objects, a description with units on every field,
and the example scenes in scenes/ all valid."""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator

from rbcli.physics.integrators import integrator_names
from rbcli.scene.load import check_scene
from rbcli.scene.schema_path import scene_schema, scene_schema_path

REPO = Path(__file__).resolve().parents[2]
SCENE_FILES = sorted(p for p in (REPO / "scenes").rglob("*.yaml") if not p.name.endswith(".sweep.yaml"))
NUMERIC = {"number", "integer"}


def walk(schema, path="#"):
    """Every subschema that defines fields, with its JSON pointer-ish path (not the conditions of
    `if`/`then`/`else`, which restate fields defined elsewhere to constrain them)."""
    if isinstance(schema, dict):
        yield path, schema
        for key, value in schema.items():
            if key in ("properties", "$defs"):
                for name, sub in value.items():
                    yield from walk(sub, f"{path}/{key}/{name}")
            elif key in ("items", "not"):
                yield from walk(value, f"{path}/{key}")
            elif key in ("oneOf", "anyOf", "allOf"):
                for i, sub in enumerate(value):
                    yield from walk(sub, f"{path}/{key}/{i}")


def test_schema_is_valid_2020_12_and_found_from_the_package():
    assert scene_schema_path() == REPO / "schemas" / "scene.schema.json"
    schema = json.loads(scene_schema_path().read_text())
    assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
    Draft202012Validator.check_schema(schema)


def resolve(schema):
    while isinstance(schema, dict) and "$ref" in schema:
        target = scene_schema()
        for part in schema["$ref"][2:].split("/"):
            target = target[part]
        schema = target
    return schema


def is_structured(schema) -> bool:
    """A mapping, a list of mappings, or a choice among forms that include one (a section, not a value)."""
    schema = resolve(schema)
    if schema.get("type") == "object":
        return True
    if schema.get("type") == "array" and is_structured(schema.get("items", {})):
        return True
    return any(is_structured(branch) for branch in schema.get("oneOf", []) + schema.get("anyOf", []))


def test_every_field_has_a_description_and_every_value_its_units():
    missing, unitless = [], []
    for path, sub in walk(scene_schema()):
        for name, prop in sub.get("properties", {}).items():
            where = f"{path}/properties/{name}"
            description = prop.get("description", "")
            if len(description) < 10:
                missing.append(where)
            elif not is_structured(prop) and not re.search(r"\[[^\]]+\]", description):
                unitless.append(where)  # "[m]", "[kg m^2/s]", "[1]", "[name]", "[bool]" ...
    assert not missing, f"fields without a description: {missing}"
    assert not unitless, f"value descriptions without [units]: {unitless}"


def test_every_object_is_closed():
    open_objects = []
    for path, sub in walk(scene_schema()):
        if sub.get("type") == "object" and sub.get("additionalProperties") is not False:
            open_objects.append(path)
    assert open_objects == []


def test_defaults_and_templates_offer_the_body_keys():
    defs = scene_schema()["$defs"]
    body = set(defs["body"]["properties"])
    assert set(defs["defaults"]["properties"]) == body - {"name"}
    assert set(defs["template"]["properties"]) == body - {"name", "position"}


def test_schema_lists_the_registered_integrators():
    integrator = scene_schema()["$defs"]["simulation"]["properties"]["integrator"]
    assert integrator["examples"] == list(integrator_names())
    assert all(name in integrator["description"] for name in integrator_names())


@pytest.mark.parametrize("path", SCENE_FILES, ids=[str(p.relative_to(REPO)) for p in SCENE_FILES])
def test_example_scenes_are_valid(path):
    issues = check_scene(path)
    assert [str(i) for i in issues if i.severity == "error"] == []
    first = path.read_text().splitlines()[0]
    assert first.startswith("# yaml-language-server: $schema=") and first.endswith("schemas/scene.schema.json")


DOC_SIM = "simulation: {dt: 0.001, duration: 1.0}\n"
DOC_BODY = "bodies:\n  - {name: doc, particles: {positions: [[1, 0, 0], [0, 1, 0], [0, 0, 1]], masses: 1}}\n"


def doc_scenes():
    """The docs/scenes.md YAML examples that are whole scenes or a scene's sections, made whole."""
    text = (REPO / "docs" / "scenes.md").read_text()
    for block in re.findall(r"```yaml\n(.*?)```", text, re.S):
        if block.startswith("simulation:"):
            yield block + DOC_BODY
        elif "simulation:" in block:
            yield block
        elif block.startswith(("defaults:", "bodies:")):
            yield DOC_SIM + block
        elif block.startswith("- name:"):
            yield DOC_SIM + "bodies:\n" + "".join("  " + line + "\n" for line in block.splitlines())


@pytest.mark.parametrize("scene", list(doc_scenes()))
def test_docs_examples_are_valid(scene):
    from rbcli.scene.load import analyse_scene_text

    spec, issues = analyse_scene_text(scene, "docs/scenes.md", REPO / "scenes")
    assert spec is not None, [str(i) for i in issues]
