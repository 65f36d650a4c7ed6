"""Damaged and foreign files through `rbsim info`, `rbsim replay --save`, `rbcli.read_recording` and mesh
loading: a documented exit code (0, or 1 with a message), a ValueError/OSError from the Python reader, a
located scene error for a mesh; never a traceback or another exception.

The files: a real 2-body recording (.mcap and .rrd, particles and invariants recorded) and closed meshes
(OBJ, binary and ASCII STL, PLY), truncated, with flipped bits, overwritten or cut slices, or random
bytes (tests/fuzz_cases.py `damaged`). .rrd files are only truncated here (what a killed run leaves):
rerun's reader aborts the process on some bit flips (`test_rerun_reader_crash_on_a_damaged_rrd`).
~15 s.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
from pathlib import Path

import pytest
from fuzz_cases import analyse_mesh_file, check_analysis, check_command, ci_settings, damaged, write_mesh_files
from hypothesis import given
from hypothesis import strategies as st
from typer.testing import CliRunner

import rbcli
from rbcli.cli.app import app

pytestmark = pytest.mark.filterwarnings("error::RuntimeWarning")
DATA = Path(__file__).parent / "data"
SCENE = """\
name: two
simulation: {dt: 0.001, steps: 20, integrator: split2, record: {streams: [bodies, invariants, particles]}}
bodies:
  - name: b
    particles: {positions: [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], masses: 1}
    angular_velocity: [1, 2, 3]
  - name: c
    particles: {positions: [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], masses: 1}
    position: [3, 0, 0]
"""
_RECORDINGS: dict[str, bytes] = {}


def recording(fmt: str) -> bytes:
    """The bytes of a real recording in `fmt`, written once per session."""
    if fmt not in _RECORDINGS:
        with tempfile.TemporaryDirectory() as folder:
            scene = Path(folder) / "two.yaml"
            scene.write_text(SCENE)
            output = Path(folder) / f"two.{fmt}"
            rbcli.run_to_file(rbcli.prepare(scene), output)
            _RECORDINGS[fmt] = output.read_bytes()
    return _RECORDINGS[fmt]


def check_reader(path: Path) -> None:
    """rbcli.read_recording gives a Trajectory or raises ValueError/OSError with a message."""
    try:
        trajectory = rbcli.read_recording(path)
    except (ValueError, OSError) as exc:
        assert str(exc)
        return
    assert trajectory.x.shape[0] == len(trajectory.t)


def check_commands(path: Path, folder: Path) -> None:
    runner = CliRunner()
    check_command(runner.invoke(app, ["info", str(path)]), codes={0, 1})
    check_command(runner.invoke(app, ["replay", str(path), "--save", str(folder / "saved.rrd")]), codes={0, 1})


@ci_settings(50)
@given(st.data())
def test_damaged_mcap_files(data):
    raw = data.draw(damaged(recording("mcap")))
    with tempfile.TemporaryDirectory() as name:
        path = Path(name) / "run.mcap"
        path.write_bytes(raw)
        check_commands(path, Path(name))
        check_reader(path)


@ci_settings(25)
@given(st.data())
def test_truncated_rrd_files(data):
    raw = recording("rrd")
    raw = raw[: data.draw(st.integers(0, len(raw) - 1))]
    with tempfile.TemporaryDirectory() as name:
        path = Path(name) / "run.rrd"
        path.write_bytes(raw)
        check_commands(path, Path(name))
        check_reader(path)


def test_rerun_reader_crash_on_a_damaged_rrd():
    """A real .rrd with 1-4 flipped bits (found by benchmarks/fuzz_long.py) on which rerun-sdk 0.41's reader
    panics in arrow-rs and aborts its process: `rbsim info` reads it in a forked child and ends with one
    line and exit 1, no panic text or traceback. Run in a child process (a regression would abort pytest)."""
    result = subprocess.run(
        [sys.executable, "-m", "rbcli", "info", str(DATA / "rerun_panic.rrd")], capture_output=True, text=True
    )
    assert result.returncode in (0, 1), result.stderr[-2000:]
    assert "panicked" not in result.stderr and "Traceback" not in result.stderr
    assert result.stderr.count("\n") == 1 and "cannot read" in result.stderr, result.stderr


def test_a_damaged_mcap_whose_invariants_decode_wrong_raises_value_error():
    """Found by benchmarks/fuzz_long.py: a .mcap with a few damaged bytes decoded into invariants that were
    protobuf classes, and rbcli.read_recording raised TypeError (the API promises ValueError)."""
    with pytest.raises(ValueError, match=r"not a readable rbsim \.mcap recording \(TypeError: float\(\) argument"):
        rbcli.read_recording(DATA / "damaged_invariants.mcap")


MESHES = write_mesh_files()


@ci_settings(60)
@given(st.sampled_from(sorted(MESHES)).flatmap(lambda n: st.tuples(st.just(n), damaged(MESHES[n]))))
def test_damaged_mesh_files_are_read_or_refused_located(case):
    name, raw = case
    with tempfile.TemporaryDirectory() as folder:
        spec, issues, text, stderr = analyse_mesh_file(name, raw, Path(folder))
        check_analysis(spec, issues, text)
        assert "Traceback" not in stderr, stderr
