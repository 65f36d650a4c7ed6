"""Sweep files: the schema beside the scene schema, the example files valid, and every kind of mistake
reported at its place in the file (line and column found here from the file's text, not from the code
under test) with exit status 1 from `rbsim validate` and `rbsim sweep`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from jsonschema import Draft202012Validator
from sweep_cases import SPRING_SCENE
from typer.testing import CliRunner

from rbcli.cli.app import app
from rbcli.scene.schema_path import scene_schema_path
from rbcli.sweeps.load import analyse_sweep, is_sweep_file, sweep_schema_path

REPO = Path(__file__).resolve().parents[2]
EXAMPLES = sorted((REPO / "scenes" / "sweeps").glob("*.sweep.yaml"))
runner = CliRunner()


def test_schema_is_valid_2020_12_and_lives_beside_the_scene_schema():
    assert sweep_schema_path() == scene_schema_path().parent / "sweep.schema.json"
    assert sweep_schema_path() == REPO / "schemas" / "sweep.schema.json"
    Draft202012Validator.check_schema(json.loads(sweep_schema_path().read_text()))


@pytest.mark.parametrize("path", EXAMPLES, ids=lambda p: p.name)
def test_example_sweeps_are_valid(path):
    spec, issues = analyse_sweep(path)
    assert spec is not None, "\n".join(map(str, issues))
    assert not [i for i in issues if i.severity == "error"]
    assert is_sweep_file(path)


def test_scene_files_are_not_taken_for_sweeps():
    assert not is_sweep_file(REPO / "scenes" / "tutorial.yaml")


def _where(text: str, needle: str, nth: int = 0) -> tuple[int, int]:
    """1-based (line, column) of the nth occurrence of needle in text."""
    offset = -1
    for _ in range(nth + 1):
        offset = text.index(needle, offset + 1)
    line = text.count("\n", 0, offset) + 1
    return line, offset - (text.rfind("\n", 0, offset) + 1) + 1


BAD_CASES = {
    # name: (axes text, the text the error points at, words the message must hold)
    "unknown key": ("  - path: bodies[0].angular_velocty\n    values: [[0, 5, 0]]\n", "bodies[0].angular_velocty",
                    ["unknown key 'angular_velocty'", "did you mean 'angular_velocity'"]),
    "index past the end": ("  - path: bodies[2].position\n    values: [[0, 0, 0]]\n", "bodies[2].position",
                           ["bodies has 1 entry", "[2]"]),
    "wrong type": ("  - path: simulation.dt\n    values: [0.01, fast, 0.001]\n", "fast",
                   ["'fast' at simulation.dt gives an invalid scene", "wrong type"]),
    "wrong type in a vector": ("  - path: bodies[0].velocity\n    values: [[0, 0, 0], [0, yes, 0]]\n", "[0, yes, 0]",
                               ["invalid scene", "bodies[0].velocity"]),
    "unknown integrator": ("  - path: simulation.integrator\n    values: [rk4, rk5]\n", "rk5",
                           ["unknown integrator 'rk5'"]),
    "out of range": ("  - path: forces[0].stiffness\n    grid: {start: -10, stop: 100, num: 3}\n", "{start: -10",
                     ["gives an invalid scene", "stiffness"]),
    "empty axis": ("  - path: simulation.dt\n    values: []\n", "[]", ["wrong length: 0 items"]),
    "random without samples": ("  - path: simulation.dt\n    random: {distribution: uniform, low: 0.001, high: 0.01}\n",
                               "{distribution", ["needs `samples`"]),
    "unknown distribution": ("  - path: simulation.dt\n    random: {distribution: gauss, mean: 0.01, std: 0.001}\n",
                             "gauss", ["gauss"]),
    "path syntax": ("  - path: bodies.0.position\n    values: [[0, 0, 0]]\n", "bodies.0.position",
                    ["is not a scene path"]),
    "two axes on one value": ("  - path: bodies[0].velocity\n    values: [[0, 0, 0]]\n"
                              "  - path: bodies[0].velocity[1]\n    values: [1.0]\n", "bodies[0].velocity[1]",
                              ["overlaps axes[0]"]),
}  # fmt: skip


@pytest.mark.parametrize("case", sorted(BAD_CASES))
def test_bad_sweep_files_get_located_errors_and_exit_1(tmp_path, case):
    axes, needle, words = BAD_CASES[case]
    (tmp_path / "spring.yaml").write_text(SPRING_SCENE)
    text = f"scene: spring.yaml\naxes:\n{axes}"
    path = tmp_path / "bad.sweep.yaml"
    path.write_text(text)
    line, column = _where(text, needle)
    spec, issues = analyse_sweep(path)
    assert spec is None
    errors = [i for i in issues if i.severity == "error"]
    assert len(errors) == 1, "\n".join(map(str, issues))
    error = errors[0]
    assert (error.location.file, error.location.line, error.location.column) == (str(path), line, column), str(error)
    for word in words:
        assert word in error.message, str(error)
    validate = runner.invoke(app, ["validate", str(path)])
    assert validate.exit_code == 1
    assert f"{path}:{line}:{column}: error:" in validate.output
    sweep = runner.invoke(app, ["sweep", str(path), "--serial", "-o", str(tmp_path / "out")])
    assert sweep.exit_code == 1
    assert f"{path}:{line}:{column}: error:" in sweep.output
    assert not (tmp_path / "out").exists()  # nothing ran, nothing written


def test_every_mistake_of_a_file_at_once(tmp_path):
    (tmp_path / "spring.yaml").write_text(SPRING_SCENE)
    text = "scene: spring.yaml\naxes:\n" + "".join(BAD_CASES[c][0] for c in ("unknown key", "wrong type", "empty axis"))
    path = tmp_path / "bad.sweep.yaml"
    path.write_text(text)
    _, issues = analyse_sweep(path)
    lines = sorted(i.location.line for i in issues if i.severity == "error")
    assert lines == [_where(text, BAD_CASES[c][1])[0] for c in ("unknown key", "wrong type", "empty axis")]


def test_base_scene_errors_are_located_in_the_scene(tmp_path):
    scene = SPRING_SCENE.replace("dt: 0.01", "dt: -0.01")
    (tmp_path / "spring.yaml").write_text(scene)
    path = tmp_path / "s.sweep.yaml"
    path.write_text("scene: spring.yaml\naxes:\n  - path: simulation.dt\n    values: [0.01]\n")
    spec, issues = analyse_sweep(path)
    assert spec is None
    assert any(str(i).startswith(f"{path}:1:8: error: scene: the base scene has 1 error") for i in issues)
    line, column = _where(scene, "-0.01")
    located = [(i.location.file, i.location.line, i.location.column) for i in issues if i.location]
    assert (str(tmp_path / "spring.yaml"), line, column) in located
    assert runner.invoke(app, ["validate", str(path)]).exit_code == 1


def test_a_missing_base_scene_is_an_error_at_scene(tmp_path):
    path = tmp_path / "s.sweep.yaml"
    path.write_text("scene: nowhere.yaml\naxes:\n  - path: simulation.dt\n    values: [0.01]\n")
    spec, issues = analyse_sweep(path)
    assert spec is None and str(issues[0]).startswith(f"{path}:1:8: error: scene: cannot read the base scene")
