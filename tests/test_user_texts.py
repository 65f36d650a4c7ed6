"""What a new user reads first (issue 44): `--help` as plain text, and install hints that name the
distribution that exists on the package index."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import pytest
import typer
from typer.testing import CliRunner

from rbcli.cli.app import PROG_NAME, app

ROOT = Path(__file__).resolve().parents[1]
# help is plain text (cli/app.py: rich_markup_mode=None): a `\[` written to escape Rich markup prints as is
ESCAPED_BRACKET = re.compile(r"\\\[")
COMMANDS = sorted(typer.main.get_command(app).commands)  # type: ignore[attr-defined]


def rendered_help(*args: str) -> str:
    result = CliRunner().invoke(app, [*args, "--help"], prog_name=PROG_NAME, terminal_width=100)
    assert result.exit_code == 0, result.output
    return result.output


@pytest.mark.parametrize("command", COMMANDS)
def test_no_help_prints_an_escaped_bracket(command):
    text = rendered_help(command)
    assert not ESCAPED_BRACKET.search(text), text


def test_study_help_names_its_values_as_run_help_does():
    """Every option of `rbsim study` that takes a value shows a metavar naming it (as `rbsim run`'s), not
    typer's type placeholder (`<list[str]>`, `<float range>`), and its default inside its own help."""
    text = rendered_help("study")
    assert "<list[" not in text and "range>" not in text, text
    assert "Usage: rbsim study [OPTIONS] {SCENE}" in text
    for shown in ("-i, --integrator NAME", "--dt SECONDS", "--duration SECONDS", "--out FOLDER",
                  "--min-time SECONDS", "--rerun FILE"):  # fmt: skip
        assert shown in text, (shown, text)
    flat = " ".join(text.split())
    assert "Time [s] spent timing each (integrator, dt) point" in flat
    assert "[default: 0.2; 0.05 with --quick]" in flat and "[default: outputs]" in flat


def test_study_options_still_take_their_values():
    """The metavars change the help only: repeated --dt and -i arrive as lists of their types."""
    study = typer.main.get_command(app).commands["study"]  # type: ignore[attr-defined]
    args = ["scene.yaml", "--dt", "0.01", "--dt", "5e-3", "-i", "split2", "-i", "rk4", "--min-time", "0.1"]
    context = study.make_context("study", args)
    assert context.params["dt"] == [0.01, 0.005]
    assert context.params["integrator"] == ["split2", "rk4"]
    assert context.params["min_time"] == 0.1 and context.params["scene"] == Path("scene.yaml")


def test_install_hints_name_the_rbsim_distribution():
    """The distribution is `rbsim` (pyproject.toml); `rbcli` on the package index is an unrelated project, so
    `pip install 'rbcli[bench]'` would install someone else's code. No doc or source of rbsim may say it."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    assert project["name"] == "rbsim"
    assert any(dep.startswith("mujoco") for dep in project["optional-dependencies"]["bench"])
    texts = [ROOT / "README.md", *(ROOT / "docs").rglob("*.md"), *(ROOT / "rbcli").rglob("*.py")]
    texts += (ROOT / "benchmarks").rglob("*.py")
    found = [
        f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
        for path in texts
        for number, line in enumerate(path.read_text(encoding="utf-8").splitlines(), 1)
        if "rbcli[" in line
    ]
    assert found == [], "\n".join(found)
