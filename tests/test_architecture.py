"""Import rules of docs/architecture.md: physics is pure numerics; the CLI front door stays light."""

import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _modules_after(code: str) -> set[str]:
    out = subprocess.run(
        [sys.executable, "-c", code + "\nimport sys; print('\\n'.join(sys.modules))"],
        capture_output=True, text=True, check=True, cwd=ROOT,
    )  # fmt: skip
    return set(out.stdout.split())


def test_physics_imports_only_numpy_and_numba():
    code = (
        "import pkgutil, importlib, rbcli.physics as p\n"
        "for m in pkgutil.walk_packages(p.__path__, 'rbcli.physics.'): importlib.import_module(m.name)"
    )
    loaded = _modules_after(code)
    rbcli_outside = {m for m in loaded if m.startswith("rbcli.") and not m.startswith("rbcli.physics")}
    assert rbcli_outside <= {"rbcli._version"}, rbcli_outside
    # (yaml and scipy are not on the list: numba itself imports them when they are installed)
    for banned in ("rerun", "mcap", "typer", "rich", "jsonschema", "google.protobuf"):
        assert banned not in loaded, f"rbcli.physics imported {banned}"


@pytest.mark.parametrize("heavy", ["numba", "rerun", "mcap"])
def test_cli_front_door_does_not_import_heavy_libraries(heavy):
    assert heavy not in _modules_after("import rbcli.cli.app")


def test_help_and_version_work():
    out = subprocess.run([sys.executable, "-m", "rbcli", "--help"], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0 and "run" in out.stdout and "validate" in out.stdout
    out = subprocess.run([sys.executable, "-m", "rbcli", "--version"], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0 and out.stdout.startswith("rbsim ")


def test_code_is_lint_clean():
    ruff = [sys.executable, "-m", "ruff"]
    lint = subprocess.run([*ruff, "check", "rbcli", "tests", "benchmarks"], capture_output=True, text=True, cwd=ROOT)
    assert lint.returncode == 0, lint.stdout
    fmt = subprocess.run([*ruff, "format", "--check", "rbcli", "tests", "benchmarks"], capture_output=True,
                         text=True, cwd=ROOT)  # fmt: skip
    assert fmt.returncode == 0, fmt.stdout


def test_package_type_checks():
    """mypy on rbcli/ (settings in pyproject.toml), as STYLE.md asks."""
    out = subprocess.run([sys.executable, "-m", "mypy"], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stdout[-4000:]
