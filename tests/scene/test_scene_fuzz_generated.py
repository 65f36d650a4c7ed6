"""Generated scenes (tests/fuzz_cases.py) through `rbcli.load_scene` and `rbsim validate`.

Valid scenes (every body form, orientation form, generator, force type, contact) must load; broken ones
(wrong types, out-of-range values, NaN/inf, huge arrays and counts, degenerate inertia, duplicate names,
unknown keys, deep nesting) must be refused with every error located in the file, never an exception.
test_scene_fuzz.py mutates fixed scenes at random; here the scenes are built from the format's parts.
benchmarks/fuzz_long.py runs the same properties with >= 10^4 examples. ~12 s.
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import pytest
from fuzz_cases import (
    LOCATED,
    broken_scene,
    check_analysis,
    check_command,
    ci_settings,
    dump,
    load_scene_file,
    valid_scene,
)
from hypothesis import given
from hypothesis import strategies as st
from typer.testing import CliRunner

from rbcli.cli.app import app
from rbcli.scene.load import analyse_scene_text

# a number that slips past the checks shows as a numpy warning: make it fail the test
pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")


@ci_settings(40)
@given(valid_scene())
def test_generated_valid_scenes_load(scene):
    text = dump(scene)
    spec, issues = analyse_scene_text(text, "valid.yaml")
    assert spec is not None, "\n".join(map(str, issues))
    check_analysis(spec, issues, text)


@ci_settings(100)
@given(broken_scene())
def test_generated_broken_scenes_load_or_are_refused_located(text):
    """Through the public API and a real file: a SceneSpec, or SceneError whose issues are all located."""
    with tempfile.TemporaryDirectory() as folder:
        spec, issues, path = load_scene_file(text, Path(folder))
        check_analysis(spec, issues, text)
        assert all(issue.location.file == str(path) for issue in issues)


@ci_settings(30)
@given(st.one_of(valid_scene().map(dump), broken_scene()))
def test_validate_command_says_ok_or_located_errors(text):
    """`rbsim validate` in-process: exit 0 or 1, and every error line is `file:line:col: error: ...`."""
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "scene.yaml"
        path.write_text(text, encoding="utf-8", errors="surrogatepass")
        result = CliRunner().invoke(app, ["validate", str(path)])
        check_command(result, codes={0, 1})  # errors on stderr (cli/messages.py), "ok" on stdout
        lines = result.stderr.splitlines()
        errors = [line for line in lines if ": error: " in line]
        assert (result.exit_code == 1) == bool(errors), result.stderr
        for line in errors:
            match = LOCATED.match(line)
            assert match and match["file"] == str(path), line
