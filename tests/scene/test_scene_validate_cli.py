"""`rbsim validate` and `rbsim schema` through Typer's CliRunner on a tiny app with just these commands."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import typer
from typer.testing import CliRunner

from rbcli.cli.schema import schema
from rbcli.cli.validate import validate

REPO = Path(__file__).resolve().parents[2]
GOOD = """\
simulation: {dt: 0.001, duration: 1.0}
bodies:
  - name: handle
    particles:
      positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]]
      masses: [1.0, 0.5, 0.5, 0.25]
"""

app = typer.Typer(add_completion=False)
app.command("validate")(validate)
app.command("schema")(schema)
runner = CliRunner()


def write(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_valid_file_exits_0(tmp_path):
    result = runner.invoke(app, ["validate", str(write(tmp_path, "good.yaml", GOOD))])
    assert result.exit_code == 0, result.output
    assert "ok (1 body, 4 particles)" in result.output


def test_invalid_file_exits_1_with_located_issues(tmp_path):
    bad = write(tmp_path, "bad.yaml", GOOD.replace("dt: 0.001", "dt: -1").replace("masses:", "mases:"))
    result = runner.invoke(app, ["validate", str(bad)])
    assert result.exit_code == 1
    lines = result.output.splitlines()
    assert f"{bad}:1:18: error: simulation.dt: -1 is out of range; expected a value > 0 (time step [s])" in lines
    assert any(line.startswith(f"{bad}:6:7: error: bodies[0].particles.mases: unknown key 'mases'") for line in lines)


def test_every_file_is_checked_and_any_failure_exits_1(tmp_path):
    good = write(tmp_path, "good.yaml", GOOD)
    bad = write(tmp_path, "bad.yaml", "simulation: {dt: 1}\n")
    result = runner.invoke(app, ["validate", str(bad), str(good)])
    assert result.exit_code == 1
    assert f"{good}: ok" in result.output and f"{bad}:1:1: error:" in result.output
    assert "1 of 2 scene files valid" in result.output


def test_missing_file_exits_1_naming_it(tmp_path):
    result = runner.invoke(app, ["validate", str(tmp_path / "nope.yaml")])
    assert result.exit_code == 1
    assert f"{tmp_path / 'nope.yaml'}: error: scene file does not exist; expected" in result.output


def test_usage_errors_exit_2():
    assert runner.invoke(app, ["validate"]).exit_code == 2
    assert runner.invoke(app, ["validate", "--bogus", "x.yaml"]).exit_code == 2


def test_warnings_alone_exit_0(tmp_path):
    text = GOOD + "    orientation: {wxyz: [2, 0, 0, 0]}\n"
    result = runner.invoke(app, ["validate", str(write(tmp_path, "w.yaml", text))])
    assert result.exit_code == 0 and ": warning: bodies[0].orientation.wxyz: quaternion has norm 2" in result.output


def test_verbose_prints_mass_properties(tmp_path):
    plate = GOOD.replace(
        "[[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]]", "[[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]"
    ).replace("[1.0, 0.5, 0.5, 0.25]", "[1.0, 1.0, 0.5, 0.5]")
    result = runner.invoke(app, ["validate", "-v", str(write(tmp_path, "plate.yaml", plate))])
    assert result.exit_code == 0
    assert (
        "handle: 4 particles, mass 3 kg, centre of mass [0, 0, 0] m (body frame), principal inertia [1, 2, 3] kg m^2"
        in (result.output)
    )


def test_validate_writes_nothing(tmp_path):
    path = write(tmp_path, "good.yaml", GOOD.replace("duration: 1.0", "duration: 1.0, output: run.mcap"))
    assert runner.invoke(app, ["validate", str(path)]).exit_code == 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["good.yaml"]


def test_schema_command_prints_the_schema():
    result = runner.invoke(app, ["schema"])
    assert result.exit_code == 0
    assert json.loads(result.output)["title"] == "rbsim scene"


def test_validate_imports_no_heavy_libraries(tmp_path):
    path = write(tmp_path, "good.yaml", GOOD)
    code = (
        "import sys, typer\n"
        "from rbcli.cli.validate import validate\n"
        "app = typer.Typer(); app.command()(validate); app.command('x')(lambda: None)\n"
        f"sys.argv = ['v', 'validate', {str(path)!r}]\n"
        "try:\n    app()\nexcept SystemExit:\n    pass\n"
        "print(sorted(m for m in ('numba', 'rerun', 'mcap', 'trimesh', 'scipy') if m in sys.modules))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"
