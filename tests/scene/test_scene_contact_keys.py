"""Contact keys as a new user meets them (issue 28 item 4): a body `material:` in a scene without `contact:`
warns (it would be ignored), the restitution rule is one rule in the schema and in the loader, and a file
with thousands of errors prints the first MAX_SHOWN_ISSUES and the count of the rest."""

from __future__ import annotations

import json
from pathlib import Path

import typer
import yaml
from jsonschema import validators
from typer.testing import CliRunner

from rbcli.cli.messages import MAX_SHOWN_ISSUES
from rbcli.cli.validate import validate
from rbcli.physics.contact.parameters import LOWEST_RESTITUTION
from rbcli.scene.load import analyse_scene_text

REPO = Path(__file__).resolve().parents[2]
SCHEMA = json.loads((REPO / "schemas" / "scene.schema.json").read_text(encoding="utf-8"))
BALL = "{{name: {name}, particles: {{positions: [[0, 0, 0]], masses: [1.0], radius: [0.05]}}{extra}}}"

app = typer.Typer(add_completion=False)
app.command("validate")(validate)
app.command("other")(lambda: None)  # a second command keeps `validate` a subcommand
runner = CliRunner()


def _scene(bodies: list[str], contact: str = "", defaults: str = "") -> str:
    return (
        "simulation: {dt: 0.001, steps: 10}\n"
        + contact
        + defaults
        + "bodies:\n"
        + "".join(f"  - {b}\n" for b in bodies)
    )


def _warnings(text: str) -> list:
    spec, issues = analyse_scene_text(text, file="s.yaml")
    assert spec is not None, [str(i) for i in issues]
    return [i for i in issues if i.severity == "warning" and "material" in i.message]


def test_a_body_material_without_contact_warns_at_the_key():
    """Without `contact:` a body's material does nothing: one warning located at its `material` key."""
    text = _scene([BALL.format(name="a", extra=", material: {restitution: 0.3}"), BALL.format(name="b", extra="")])
    found = _warnings(text)
    assert len(found) == 1, [str(w) for w in found]
    column = text.splitlines()[2].index("material") + 1
    assert (found[0].location.line, found[0].location.column) == (3, column)
    assert "body 'a'" in found[0].message and "contact" in found[0].expected


def test_a_material_from_defaults_warns_once_at_defaults():
    """A material in `defaults` reaches every body; it is one mistake, so one warning where it is written."""
    defaults = "defaults: {material: {friction: 0.2}}\n"
    found = _warnings(_scene([BALL.format(name=n, extra="") for n in "abc"], defaults=defaults))
    assert len(found) == 1, [str(w) for w in found]
    assert found[0].location.line == 2


def test_a_body_material_with_contact_does_not_warn():
    text = _scene([BALL.format(name="a", extra=", material: {restitution: 0.3}")], contact="contact: {ground: 0}\n")
    assert _warnings(text) == []


def _restitution_schemas(node: object, path: str = "") -> list[tuple[str, dict]]:
    found = []
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "restitution" and isinstance(value, dict) and "type" in value:
                found.append((f"{path}/{key}", value))
            found += _restitution_schemas(value, f"{path}/{key}")
    elif isinstance(node, list):
        for i, value in enumerate(node):
            found += _restitution_schemas(value, f"{path}/{i}")
    return found


def test_the_schema_says_the_loaders_lowest_restitution_everywhere():
    """One rule: every restitution in the schema has minimum LOWEST_RESTITUTION (the value the damping
    ratio's bisection accepts, physics/contact/parameters.py), none an exclusive minimum of 0."""
    found = _restitution_schemas(SCHEMA)
    assert len(found) >= 4, found  # body, contact.material, ground, planes, container
    for where, schema in found:
        assert schema.get("minimum") == LOWEST_RESTITUTION and "exclusiveMinimum" not in schema, where
        assert schema.get("maximum") == 1, where


def test_an_editor_and_the_loader_draw_the_restitution_line_at_the_same_value():
    """A restitution just below the limit is refused by the schema alone (what an editor checks) and by
    rbsim, with the error located at the value; the limit itself is accepted by both."""
    editor = validators.validator_for(SCHEMA)(SCHEMA)
    for value, ok in ((LOWEST_RESTITUTION * 0.999, False), (LOWEST_RESTITUTION, True), (1.0, True)):
        for contact in (f"contact: {{ground: 0, material: {{restitution: {value!r}}}}}\n",
                        f"contact: {{ground: {{height: 0, restitution: {value!r}}}}}\n"):  # fmt: skip
            text = _scene([BALL.format(name="a", extra="")], contact=contact)
            assert editor.is_valid(yaml.safe_load(text)) == ok, (value, contact)
            spec, issues = analyse_scene_text(text, file="s.yaml")
            errors = [i for i in issues if i.severity == "error"]
            assert (spec is not None) == ok and (not errors) == ok, [str(i) for i in issues]
            if not ok:
                assert len(errors) == 1 and errors[0].location.line == 2, [str(i) for i in errors]
                assert "restitution" in errors[0].message and "0.01" in errors[0].expected


def test_thousands_of_errors_print_the_first_ones_and_the_count(tmp_path):
    """3,000 bad masses: MAX_SHOWN_ISSUES located lines, then one line with how many were not shown."""
    bodies = [BALL.format(name=f"b{i}", extra="").replace("[1.0]", "[-1.0]") for i in range(3000)]
    path = tmp_path / "many.yaml"
    path.write_text(_scene(bodies))
    result = runner.invoke(app, ["validate", str(path)])
    assert result.exit_code == 1
    lines = result.output.splitlines()
    located = [line for line in lines if line.startswith(f"{path}:") and ": error: " in line]
    assert len(located) == MAX_SHOWN_ISSUES == 50, lines[:3]
    assert located[0].startswith(f"{path}:3:") and located[-1].startswith(f"{path}:{2 + MAX_SHOWN_ISSUES}:")
    tail = [line for line in lines if "not shown" in line]
    assert len(tail) == 1 and "2,950 more" in tail[0] and "3,000 errors" in tail[0], tail
    assert len(lines) == MAX_SHOWN_ISSUES + 1, lines[-3:]


def test_a_few_errors_print_all_of_them(tmp_path):
    bodies = [BALL.format(name=f"b{i}", extra="").replace("[1.0]", "[-1.0]") for i in range(MAX_SHOWN_ISSUES)]
    path = tmp_path / "some.yaml"
    path.write_text(_scene(bodies))
    result = runner.invoke(app, ["validate", str(path)])
    lines = result.output.splitlines()
    assert result.exit_code == 1 and len(lines) == MAX_SHOWN_ISSUES and "not shown" not in result.output
