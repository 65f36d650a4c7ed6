"""cli/coercion.py converts plain command-line values without pydantic, to the values typer's pydantic
adapters give, and leaves everything else (and every error message) to typer."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from pydantic import TypeAdapter

from rbcli.cli.coercion import convert

ROOT = Path(__file__).resolve().parents[2]

NUMBERS = ["0", "7", "-3", "07", "+5", "1.", ".5", "-.5", "1e-3", "2.5E+4", "-0", "-0.0", "1e400", "0.1",
           "123456789012345678901234567890", "3.141592653589793238", "inf", "-inf", "nan", "1_000", " 5", "5 ",
           "", "1e", "0x10", "abc", "1.5.2"]  # fmt: skip


@pytest.mark.parametrize("kind", [int, float])
@pytest.mark.parametrize("text", NUMBERS)
def test_a_converted_number_is_what_pydantic_gives(kind, text):
    done, value = convert(kind, text)
    if not done:  # left to typer's pydantic adapters: nothing to compare
        return
    expected = TypeAdapter(kind).validate_python(text)
    assert type(value) is type(expected) and repr(value) == repr(expected)


def test_what_is_converted_and_what_is_left_to_typer():
    assert convert(float, "1e-3") == (True, 1e-3) and convert(int, "-12") == (True, -12)
    assert convert(Path, "out/a.mcap") == (True, Path("out/a.mcap"))
    assert convert(str, "split2") == (True, "split2") and convert(bool, True) == (True, True)
    for kind, text in [(float, "inf"), (float, "nan"), (float, "1_000"), (int, "1.0"), (int, "0x10"), (Path, ""),
                       (bool, "yes"), (float, " 1")]:  # fmt: skip
        assert convert(kind, text) == (False, None), (kind, text)


def test_the_cli_parses_without_pydantic_and_reports_typers_errors(tmp_path):
    scene = tmp_path / "one.yaml"
    scene.write_text(
        "name: one\nsimulation: {dt: 0.001, duration: 0.01}\n"
        "bodies:\n  - name: b\n    particles: {positions: [[0, 0, 0]], masses: 1.0, radius: 0.05}\n"
    )
    code = (
        "import sys\nfrom rbcli.cli.app import run_app\n"
        "code = run_app(['run', sys.argv[1], '-o', sys.argv[2], '-q', '--dt', '0.002', '--record-every', '2'])\n"
        "from rbcli.cli import coercion\n"
        "assert code == 0, code\nassert ('pydantic' in sys.modules) != coercion.active()\nprint('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code, str(scene), str(tmp_path / "o.mcap")], capture_output=True,
                         text=True, cwd=ROOT, timeout=300)  # fmt: skip
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr
    bad = subprocess.run([sys.executable, "-m", "rbcli", "run", str(scene), "--dt", "abc"], capture_output=True,
                         text=True, cwd=ROOT, timeout=300)  # fmt: skip
    assert bad.returncode == 2 and "Invalid value for '--dt'" in bad.stderr, bad.stderr


def test_a_list_of_paths_parses_without_pydantic(tmp_path):
    """`rbsim validate FILE...` takes a list[Path]: its values come as one sequence, converted here too (typer's
    adapter for it imported pydantic, ~0.1 s of every validate)."""
    scenes = []
    for name in ("a", "b"):
        scene = tmp_path / f"{name}.yaml"
        scene.write_text(
            f"name: {name}\nsimulation: {{dt: 0.001, duration: 0.01}}\n"
            "bodies:\n  - name: b\n    particles: {positions: [[0, 0, 0]], masses: 1.0, radius: 0.05}\n"
        )
        scenes.append(str(scene))
    code = (
        "import sys\nfrom rbcli.cli.app import run_app\nfrom rbcli.cli import coercion\n"
        "code = run_app(['validate', *sys.argv[1:]])\n"
        "assert code == 0, code\nassert ('pydantic' in sys.modules) != coercion.active()\nprint('ok')\n"
    )
    out = subprocess.run([sys.executable, "-c", code, *scenes], capture_output=True, text=True, cwd=ROOT, timeout=300)
    assert out.returncode == 0 and out.stdout.strip().endswith("ok"), out.stderr
    assert all(f"{s}: ok" in out.stdout for s in scenes), out.stdout
