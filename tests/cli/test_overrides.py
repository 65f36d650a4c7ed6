"""Command-line overrides are scene values: --dt, --duration, --integrator, --tolerance and --record-every
pass the scene's checks (scene/compile.py `run_settings`) and are refused before any work, exit 1, with
one line naming the option, writing nothing; a run that plans more than MAX_BODY_STEPS body-steps asks
for --allow-large."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

import rbcli.cli.run as cli_run
from rbcli.api import prepare
from rbcli.cli.app import app
from rbcli.cli.exit_codes import ExitCode

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "scenes" / "tutorial.yaml"  # dt 0.001 s, 5 s, one body, euler-matrix
runner = CliRunner()


def _refused(tmp_path: Path, *args: str) -> str:
    """Run with these options; assert exit 1, one error line, no traceback, nothing written; the line."""
    out = tmp_path / "out" / "run.mcap"
    result = runner.invoke(app, ["run", str(TUTORIAL), "-o", str(out), "-q", *args])
    assert result.exit_code == ExitCode.INVALID, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert "Traceback" not in result.output
    assert list(tmp_path.iterdir()) == []  # not even the output's folder
    return lines[0]


@pytest.mark.parametrize(
    ("args", "expected"),
    [
        (["--duration", "-1"], "error: --duration -1: must be a positive, finite number of seconds"),
        (["--duration", "0"], "error: --duration 0: must be a positive, finite number of seconds"),
        (["--duration", "inf"], "error: --duration inf: must be a positive, finite number of seconds"),
        (["--dt", "nan"], "error: --dt nan: must be a positive, finite number of seconds"),
        (["--dt", "-0.001"], "error: --dt -0.001: must be a positive, finite number of seconds"),
        (["--dt", "0"], "error: --dt 0: must be a positive, finite number of seconds"),
        (["--dt", "10"], "error: --dt 10: dt = 10 s is longer than duration = 5 s"),
        (["--duration", "1e-6"], "error: --duration 1e-06: dt = 0.001 s is longer than duration = 1e-06 s"),
        (["--dt", "1e-300", "--duration", "1e300"], "error: --dt 1e-300: duration / dt overflows float64"),
        (["--integrator", "split"], "error: --integrator 'split': unknown integrator (did you mean 'split4'?)"),
        (["--integrator", ""], "error: --integrator '': unknown integrator"),
        (["--tolerance", "0"], "error: --tolerance 0: must be a positive, finite number"),
        (["--tolerance", "nan", "--integrator", "dopri5"], "error: --tolerance nan: must be a positive, finite"),
        (["--tolerance", "-1e-6", "--integrator", "dopri5"], "error: --tolerance -1e-06: must be a positive"),
        (["--record-every", "0"], "error: --record-every 0: must be a whole number of steps, at least 1"),
        (["--record-every", "-5"], "error: --record-every -5: must be a whole number of steps, at least 1"),
    ],
)
def test_an_invalid_override_is_refused_before_any_work_naming_the_option(tmp_path, args, expected):
    assert _refused(tmp_path, *args).startswith(expected)


def test_a_tiny_dt_is_refused_for_its_planned_work_naming_the_option(tmp_path):
    """The issue's case: --dt 1e-300 planned 5e300 steps and wrote 4 GB in 10 minutes."""
    line = _refused(tmp_path, "--dt", "1e-300")
    assert line.startswith("error: --dt 1e-300: the run plans 5e+300 steps x 1 body = 5e+300 body-steps")
    assert "--allow-large" in line
    line = _refused(tmp_path, "--duration", "1e8")  # 1e11 steps of one body
    assert line.startswith("error: --duration 1e+08: the run plans 1e+11 steps") and "--allow-large" in line
    # a too-full disk that follows from it is said on the same line
    assert "not enough free disk" in line


def test_the_work_bound_counts_bodies_and_applies_to_the_scenes_own_values(tmp_path, monkeypatch):
    monkeypatch.setattr(cli_run, "MAX_BODY_STEPS", 150)
    line = _refused(tmp_path, "--duration", "0.2")  # 200 steps x 1 body
    assert line.startswith("error: --duration 0.2: the run plans 200 steps x 1 body = 200 body-steps")
    assert "more than the 2e+02 rbsim runs" in line
    scene = tmp_path / "s.yaml"
    scene.write_text(TUTORIAL.read_text().replace("duration: 5.0", "duration: 0.2"))
    out = tmp_path / "r.mcap"
    result = runner.invoke(app, ["run", str(scene), "-o", str(out), "-q"])
    assert result.exit_code == 1 and "the scene's dt and duration: the run plans 200 steps" in result.output
    assert not out.exists()


def test_allow_large_goes_past_the_work_bound(tmp_path, monkeypatch):
    monkeypatch.setattr(cli_run, "MAX_BODY_STEPS", 150)
    out = tmp_path / "r.mcap"
    args = ["run", str(TUTORIAL), "-o", str(out), "-q", "--duration", "0.2", "--allow-large"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    assert out.is_file()


def test_valid_overrides_still_run(tmp_path):
    out = tmp_path / "r.mcap"
    args = ["--dt", "0.002", "--duration", "0.02", "--record-every", "2", "--integrator", "split2"]
    result = runner.invoke(app, ["run", str(TUTORIAL), "-o", str(out), "-q", *args])
    assert result.exit_code == 0, result.output
    args = ["--duration", "0.02", "--integrator", "dopri5", "--tolerance", "1e-8"]
    assert runner.invoke(app, ["run", str(TUTORIAL), "-o", str(out), "-q", *args]).exit_code == 0


@pytest.mark.parametrize(
    ("overrides", "start"),
    [
        ({"dt": math.nan}, "dt=nan: "),
        ({"duration": -1.0}, "duration=-1.0: "),
        ({"record_every": 0}, "record_every=0: "),
        ({"record_every": 2.5}, "record_every=2.5: "),
        ({"integrator": "nope"}, "integrator='nope': "),
        ({"tolerance": math.inf, "integrator": "dopri5"}, "tolerance=inf: "),
    ],
)
def test_the_api_refuses_the_same_values_naming_the_keyword(overrides, start):
    with pytest.raises(ValueError) as info:
        prepare(TUTORIAL, **overrides)
    assert str(info.value).startswith(start)
