"""Large explicit scenes: 20,000 particles validated with every error located exactly, deep inside the
lists; the fast paths (events straight to values, compact locations, the schema's fast array items) agree
with the slow obvious versions (jsonschema item by item; a location per value). Timing and memory of the
160,000-particle case: benchmarks/bench_validate.py."""

from __future__ import annotations

import numpy as np
import pytest
from jsonschema import Draft202012Validator

from rbcli.scene.load import analyse_scene_text
from rbcli.scene.schema_path import scene_schema
from rbcli.scene.schema_validator import LONG_ARRAY, scene_validator
from rbcli.scene.yaml_located import parse_located_yaml

N = 20_000
HEAD = "simulation: {dt: 0.001, duration: 0.01}\nbodies:\n  - name: cloud\n    particles:\n      positions:\n"
FIRST_POSITION_LINE = HEAD.count("\n") + 1


def cloud(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(size=(N, 3)), rng.uniform(0.5, 2.0, size=N)


def scene_text(positions, masses, replace: dict[tuple[str, int], str] | None = None) -> str:
    """One position per line (`        - [x, y, z]`), masses as one flow list per 10 on their own lines."""
    replace = replace or {}
    lines = [
        replace.get(("position", i), f"        - [{x!r}, {y!r}, {z!r}]")
        for i, (x, y, z) in enumerate(positions.tolist())
    ]
    lines.append("      masses:")
    for start in range(0, N, 10):
        items = [replace.get(("mass", i), repr(float(masses[i]))) for i in range(start, start + 10)]
        lines.append("        - " + "\n        - ".join(items))
    return HEAD + "\n".join(lines) + "\n"


def test_a_valid_large_scene_reads_exactly():
    positions, masses = cloud()
    spec, issues = analyse_scene_text(scene_text(positions, masses), "big.yaml")
    assert [str(i) for i in issues if i.severity == "error"] == []
    body = spec.bodies[0]
    assert len(body.particle_mass) == N
    np.testing.assert_array_equal(np.sort(body.particle_mass), np.sort(masses))  # repr round-trips floats


def test_errors_deep_inside_are_located_exactly():
    positions, masses = cloud(1)
    replace = {
        ("position", 17_321): "        - [0.5, x, 0.25]",
        ("position", 19_998): "        - [0.5, 0.25]",
        ("position", 4_000): "        - [1.0, .nan, 2.0]",
        ("mass", 12_345): "-1.5",
    }
    text = scene_text(positions, masses, replace)
    _, issues = analyse_scene_text(text, "big.yaml")
    errors = {i.message.split(":")[0]: i for i in issues if i.severity == "error"}
    assert set(errors) == {
        "bodies[0].particles.positions[17321][1]",
        "bodies[0].particles.positions[19998]",
        "bodies[0].particles.positions[4000][1]",
        "bodies[0].particles.masses[12345]",
    }
    lines = text.split("\n")

    def at(issue):
        return issue.location.line, issue.location.column

    def where(line_index: int, fragment: str) -> tuple[int, int]:
        return line_index + 1, lines[line_index].index(fragment) + 1

    assert at(errors["bodies[0].particles.positions[17321][1]"]) == where(FIRST_POSITION_LINE - 1 + 17_321, "x,")
    assert "wrong type" in errors["bodies[0].particles.positions[17321][1]"].message
    assert at(errors["bodies[0].particles.positions[19998]"]) == where(FIRST_POSITION_LINE - 1 + 19_998, "[0.5")
    assert "wrong length: 2 items" in errors["bodies[0].particles.positions[19998]"].message
    assert at(errors["bodies[0].particles.positions[4000][1]"]) == where(FIRST_POSITION_LINE - 1 + 4_000, ".nan")
    mass_line = FIRST_POSITION_LINE - 1 + N + 1 + 12_345  # "masses:", then one mass per line
    assert at(errors["bodies[0].particles.masses[12345]"]) == where(mass_line, "-1.5")
    assert "-1.5 is out of range" in errors["bodies[0].particles.masses[12345]"].message


def test_fast_array_items_give_jsonschemas_own_errors():
    """The scene validator against plain Draft 2020-12, item by item, on bodies with many bad items of
    every kind the fast test screens (type, bounds, lengths, booleans, NaN)."""
    rng = np.random.default_rng(7)
    bad_values = [True, "1", None, -1.0, 0.0, float("nan"), [1.0], [1.0, 2.0, 3.0, 4.0], 3, 2.5]
    data = {
        "simulation": {"dt": 0.001, "duration": 1.0},
        "bodies": [
            {
                "name": "a",
                "particles": {
                    "positions": [[float(v) for v in p] for p in rng.normal(size=(300, 3))],
                    "masses": [float(m) for m in rng.uniform(0.1, 1.0, size=300)],
                },
            }
        ],
    }
    particles = data["bodies"][0]["particles"]
    for i in rng.choice(300, size=40, replace=False):
        bad = bad_values[int(rng.integers(len(bad_values)))]
        if rng.random() < 0.5:
            particles["masses"][int(i)] = bad
        else:
            particles["positions"][int(i)][int(rng.integers(3))] = bad
    particles["positions"][5] = "not a point"
    assert len(particles["positions"]) >= LONG_ARRAY

    def flat(errors):  # every error with the errors of each oneOf branch under it
        for e in errors:
            yield (str(list(e.absolute_path)), str(list(e.absolute_schema_path)), e.message)
            yield from flat(e.context)

    def errors(validator):
        return sorted(flat(validator.iter_errors(data)))

    plain = errors(Draft202012Validator(scene_schema()))
    assert len(plain) >= 20  # 40 replaced items; 3 and 2.5 are valid numbers there
    assert errors(scene_validator(scene_schema())) == plain


@pytest.mark.parametrize("n", [LONG_ARRAY - 1, LONG_ARRAY, 3 * LONG_ARRAY])
def test_fast_path_accepts_what_jsonschema_accepts(n):
    positions = [[0.0, 1, -2.5e300]] * n
    data = {"simulation": {"dt": 0.001, "steps": 3}, "bodies": [{"name": "a", "particles": {
        "positions": positions, "masses": [1] * n, "radius": 0.1}}]}  # fmt: skip
    assert list(scene_validator(scene_schema()).iter_errors(data)) == []


def test_aliases_are_copies_with_their_own_locations():
    doc = parse_located_yaml("base: &b {m: [1, 2]}\ncopy: *b\nmore: {<<: *b, n: 3}\n", "s.yaml")
    value = doc.value
    assert value["copy"] == value["base"] == {"m": [1, 2]} and value["more"] == {"m": [1, 2], "n": 3}
    assert value["copy"] is not value["base"] and value["copy"]["m"] is not value["base"]["m"]
    assert value["more"]["m"] is not value["base"]["m"]
    value["copy"]["m"].append(3)
    assert value["base"]["m"] == [1, 2]
    # inside an alias: the anchored text's place; the alias itself: where it is used
    assert (doc.locate(("copy", "m", 1)).line, doc.locate(("copy", "m", 1)).column) == (1, 18)
    assert (doc.locate(("copy",)).line, doc.locate(("copy",)).column) == (2, 7)


PLAIN_SCALARS = [
    "1.5", "-0.732267355", "+1.5", "1.", ".5", "-.5", "+.5", "1e5", "1E+05", "1e-3", "-2.5e300", "1e999", "-1e999",
    "1.e5", "00.5", "-0.0", "1_000.5", "1_000", "017", "0", "-0", "12", "-12", "+12", "0x1F", "0o17", "1:30.5",
    "1:30", ".inf", "-.inf", ".nan", "inf", "nan", "-inf", "infinity", "1.5.3", "e5", "5e", ".", "١.٥", "1.5x",
    "123456789012345678901234567890", "null", "~", "true", "no", "2024-01-02", "1e5_0", "1__0.5",
]  # fmt: skip


@pytest.mark.parametrize("text", PLAIN_SCALARS)
def test_fast_number_reading_agrees_with_the_yaml_resolver(text):
    """Plain scalars read on the fast path (float()/int() at C speed) equal what the YAML 1.2 resolver and
    PyYAML's constructor make of them, type included; in a list (the bulk path) and as a mapping value."""
    from yaml.constructor import SafeConstructor
    from yaml.nodes import ScalarNode

    from rbcli.scene.yaml_located import _SceneResolver

    tag = _SceneResolver().resolve(ScalarNode, text, (True, False))
    kind = tag.rsplit(":", 1)[-1]
    if kind in ("str", "timestamp"):
        want = text
    else:
        want = getattr(SafeConstructor(), f"construct_yaml_{kind}")(ScalarNode(tag, text))
    for source, get in ((f"[{text}]\n", lambda v: v[0]), (f"a: {text}\n", lambda v: v["a"])):
        got = get(parse_located_yaml(source, "s.yaml").value)
        assert type(got) is type(want)
        assert got == want or (got != got and want != want)  # NaN equals NaN here
