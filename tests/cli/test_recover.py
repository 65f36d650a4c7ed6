"""A run killed mid-way (SIGKILL) leaves `x.partial.mcap` without summary or index: `rbsim info` says it is
truncated and how far it goes, `rbsim recover` rewrites it as a complete file that the `mcap` indexed
reader and `rbcli.read_recording` open, holding every complete frame written before the kill, bitwise
as `rbcli.simulate` computes them; what is lost is bounded (docs/robustness.md "Crashes")."""

from __future__ import annotations

import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

import rbcli
from rbcli.cli.app import app
from rbcli.record.mcap_layout import TOPIC_STATE
from rbcli.record.output_file import partial_path

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "scenes" / "tutorial.yaml"
DT = 0.001
GRID = f"""\
name: kill-grid
simulation: {{dt: {DT}, duration: 1000.0, integrator: split2}}
gravity: [0, 0, -9.81]
bodies:
  - grid:
      name: b
      count: [8, 8, 1]
      spacing: [1.0, 1.0, 1.0]
      template:
        particles: {{positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]], masses: [1.0, 0.5, 0.5, 0.25]}}
        angular_momentum: [0.02, 0.05, 0.01]
"""
runner = CliRunner()


@pytest.fixture(scope="module")
def grid_scene(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("scene") / "grid.yaml"
    path.write_text(GRID)
    return path


def start_run(scene: Path, out: Path, *extra: str, min_bytes: int) -> subprocess.Popen:
    """`rbsim run SCENE -o OUT`, returned once its partial holds at least `min_bytes`."""
    args = [sys.executable, "-m", "rbcli", "run", str(scene), "-o", str(out), *extra]
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    partial, deadline = partial_path(out), time.monotonic() + 60.0  # kernels may compile on a cold cache
    while not (partial.is_file() and partial.stat().st_size >= min_bytes):
        if proc.poll() is not None:
            raise AssertionError(proc.communicate())
        assert time.monotonic() < deadline, "the run did not start"
        time.sleep(0.005)
    return proc


def info_of(path: Path) -> tuple[str, int, int]:
    """`rbsim info` of a truncated file: its output, the complete frames and the last step it reports."""
    result = runner.invoke(app, ["info", str(path)])
    assert result.exit_code == 0, result.output
    assert "status       truncated: " in result.output and "-1 steps" not in result.output
    match = re.search(r"(\d+) complete frames up to step (\d+) \(t = (\S+) s\) are readable", result.output)
    assert match, result.output
    frames, step = int(match[1]), int(match[2])
    assert f"; {step} steps, {frames} frames recorded" in result.output
    assert float(match[3]) == pytest.approx(step * DT, rel=1e-6)
    assert f"rbsim recover {path} -o FIXED.mcap" in result.output
    return result.output, frames, step


def recover_and_check(scene: Path, broken: Path, fixed: Path, frames: int, step: int) -> None:
    """`rbsim recover`, then the indexed reader, read_recording and simulate agree on every frame."""
    result = runner.invoke(app, ["recover", str(broken), "-o", str(fixed)])
    assert result.exit_code == 0, result.output
    assert f"recovered {frames} frames up to step {step} " in result.output
    with open(fixed, "rb") as f:  # the mcap library's indexed (seeking) reader, CRCs checked
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.chunk_indexes and summary.statistics is not None
        assert sum(1 for _ in reader.iter_messages(topics=[TOPIC_STATE])) == frames
    recorded = rbcli.read_recording(fixed)
    assert recorded.status == "truncated" and recorded.summary is not None and recorded.summary.steps == step
    assert recorded.step.tolist() == list(range(frames)) and frames == step + 1
    expected = rbcli.simulate(scene, duration=step * DT)
    for name in ("x", "q", "v", "omega", "P", "L"):  # MCAP keeps float64: bit for bit
        assert np.array_equal(getattr(recorded, name), getattr(expected, name)), name
    info = runner.invoke(app, ["info", str(fixed)])
    assert info.exit_code == 0 and "status       truncated: the run was cut short" in info.output


def test_a_killed_runs_partial_is_reported_truncated_and_recovered(tmp_path, grid_scene):
    out = tmp_path / "run.mcap"
    proc = start_run(grid_scene, out, "-q", min_bytes=1_000_000)  # a few blocks of frames written
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL
    broken = partial_path(out)
    assert sorted(p.name for p in tmp_path.iterdir()) == [broken.name]
    with open(broken, "rb") as f:  # what the issue reported: the library cannot open it as it is
        with pytest.raises(Exception):  # noqa: B017 - the mcap library raises several types here
            make_reader(f).get_summary()
    _, frames, step = info_of(broken)
    assert frames > 100
    recover_and_check(grid_scene, broken, tmp_path / "fixed.mcap", frames, step)
    assert broken.read_bytes()  # the input is never changed or removed


def test_what_a_kill_loses_is_bounded(tmp_path, grid_scene):
    """SIGSTOP freezes the run where a SIGKILL would have ended it: the partial then holds what a killed
    run leaves. SIGCONT + SIGTERM then stop the run cleanly and its line says how far it had computed
    (at most one loop chunk, ~0.2 s of work, beyond the freeze): the frames missing from the frozen file
    are at most what the run computes in one second, and the recovered file holds the rest."""
    out = tmp_path / "run.mcap"
    proc = start_run(grid_scene, out, min_bytes=1_000_000)
    proc.send_signal(signal.SIGSTOP)
    try:
        time.sleep(0.2)  # the writer thread is frozen too: nothing more reaches the file
        frozen = tmp_path / "frozen.partial.mcap"
        shutil.copyfile(partial_path(out), frozen)
    finally:
        proc.send_signal(signal.SIGCONT)
        proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=30)
    assert proc.returncode == 143, stderr
    computed = int(re.search(r"interrupted at step (\d+)", stderr)[1])
    rate = float(re.search(r"\(([\d.e+]+) body-steps/s\)", stderr)[1]) / 64  # steps per second, as measured
    _, frames, step = info_of(frozen)
    lost = computed - step
    assert 0 <= lost <= rate * 1.0, (computed, step, rate)  # at most one second of the run's work
    recover_and_check(grid_scene, frozen, tmp_path / "fixed.mcap", frames, step)


def test_recover_refuses_its_input_and_what_is_not_an_mcap(tmp_path):
    broken = tmp_path / "x.partial.mcap"
    broken.write_bytes(b"\x89MCAP0\r\n" + b"\x01")  # the magic, then a cut record
    for output in (broken, tmp_path / "." / "x.partial.mcap"):
        result = runner.invoke(app, ["recover", str(broken), "-o", str(output)])
        assert result.exit_code == 1 and "is the input file; recover never overwrites its input" in result.output
    link = tmp_path / "link.mcap"
    link.symlink_to(broken)
    result = runner.invoke(app, ["recover", str(broken), "-o", str(link)])
    assert result.exit_code == 1 and "is the input file" in result.output
    assert broken.read_bytes() == b"\x89MCAP0\r\n\x01"
    other = tmp_path / "notes.mcap"
    other.write_text("not an mcap file")
    result = runner.invoke(app, ["recover", str(other), "-o", str(tmp_path / "y.mcap")])
    assert result.exit_code == 1 and "cannot recover" in result.output and "MCAP magic" in result.output
    assert not (tmp_path / "y.mcap").exists() and sorted(p.name for p in tmp_path.iterdir()) == [
        "link.mcap",
        "notes.mcap",
        "x.partial.mcap",
    ]  # no temporary file left behind
    for args, fragment in (
        (["recover", str(tmp_path / "missing.mcap"), "-o", str(tmp_path / "z.mcap")], "recording not found"),
        (["recover", str(other), "-o", str(tmp_path / "z.rrd")], "recover writes an .mcap file"),
        (["recover", str(other), "-o", str(tmp_path)], "is a folder"),
    ):
        result = runner.invoke(app, args)
        assert result.exit_code == 1 and fragment in result.output, result.output
    assert runner.invoke(app, ["recover", str(other)]).exit_code == 2  # -o is required: a usage error


def test_recover_a_complete_file_and_a_partial_onto_its_own_target(tmp_path):
    """The usual call after a kill is `rbsim recover x.partial.mcap -o x.mcap`: allowed (x.mcap is not the
    input); a complete file is rewritten whole."""
    done = tmp_path / "x.mcap"
    assert runner.invoke(app, ["run", str(TUTORIAL), "-o", str(done), "-q", "--duration", "0.05"]).exit_code == 0
    partial = partial_path(done)
    shutil.copyfile(done, partial)
    result = runner.invoke(app, ["recover", str(partial), "-o", str(done)])
    assert result.exit_code == 0 and "the file was complete (nothing was cut)" in result.output, result.output
    recorded = rbcli.read_recording(done)
    assert recorded.status == "completed" and recorded.step.tolist() == list(range(51))
    assert partial.exists()  # never removed


def test_a_killed_runs_rrd_is_reported_truncated_with_what_it_holds(tmp_path, grid_scene):
    """rerun's reader refuses an .rrd cut inside a message ("payload exceeds file size") and one without
    its end marker printed "-1 steps": info now reads the whole messages and says how far they go (from
    the step timeline of the body transforms: the run's parameters reach an .rrd only when rerun's
    batcher flushes the logs of SinkRerun.open, often seconds into the run)."""
    out = tmp_path / "run.rrd"
    proc = start_run(grid_scene, out, "-q", min_bytes=2_000_000)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    result = runner.invoke(app, ["info", str(partial_path(out))])
    assert result.exit_code == 0, result.output
    assert "status       truncated: " in result.output and "a run killed or crashed" in result.output
    assert "-1 steps" not in result.output and "Warning" not in result.output
    match = re.search(r"; (\d+) steps, (\d+) frames recorded", result.output)
    assert match and int(match[2]) > 0 and int(match[1]) == int(match[2]) - 1, result.output
    assert f"{match[2]} complete frames up to step {match[1]}" in result.output
