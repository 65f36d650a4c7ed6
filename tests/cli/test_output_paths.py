"""Output paths and how outputs are written (record/output_file.py): bad paths fail before any work with
one line and exit 1; a run writes `x.partial.<ext>` and renames it onto `x.<ext>` when it ends
(completed, interrupted, diverged); a failed run leaves an existing file byte-identical; two runs on
one path never interleave; a killed run leaves its partial under that name."""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from typer.testing import CliRunner

from rbcli.api import prepare, run_to_file
from rbcli.cli.app import app
from rbcli.record.output_file import (
    OutputError,
    OutputFile,
    check_output,
    expected_output_bytes,
    partial_path,
    safe_file_stem,
)
from rbcli.record.read import read_mcap, read_recording

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "scenes" / "tutorial.yaml"
OLD = b"a good recording from an earlier run\n"  # not a real log: byte equality is what is checked
runner = CliRunner()

# gravity of 1e98 m/s^2 pushes |x| past the 1e100 blow-up limit after a few steps (tests/runner/test_loop.py)
DIVERGING = """\
name: blow-up
simulation: {dt: 1.0, duration: 100.0, integrator: euler-matrix}
gravity: [0, 0, -1.0e98]
bodies:
  - name: rock
    particles: {positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0]], masses: [1.0, 0.5, 0.5]}
    position: [0, 0, 0]
    orientation: {wxyz: [1, 0, 0, 0]}
"""


def _run(*args: str):
    return runner.invoke(app, ["run", str(TUTORIAL), *args, "--duration", "0.05", "-q"])


def _one_line_error(result) -> str:
    """The error as printed: exactly one line, no traceback."""
    assert result.exit_code == 1, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert "Traceback" not in result.output
    return lines[0]


# --- paths refused before any work ----------------------------------------------------------------


def test_a_folder_as_output_is_refused(tmp_path):
    line = _one_line_error(_run("-o", str(tmp_path)))
    assert "is a folder" in line and str(tmp_path) in line
    assert list(tmp_path.iterdir()) == []


def test_a_path_under_proc_is_refused():
    line = _one_line_error(_run("-o", "/proc/x.mcap"))
    assert "cannot create files in '/proc'" in line
    assert not Path("/proc/x.mcap").exists()


def test_a_folder_that_is_a_file_is_refused(tmp_path):
    # a regular file as the parent stops root too (chmod does not)
    (tmp_path / "plain").write_text("")
    line = _one_line_error(_run("-o", str(tmp_path / "plain" / "sub" / "x.mcap")))
    assert "is a file, not a folder" in line


def test_an_unwritable_folder_is_refused(tmp_path, monkeypatch):
    """A folder where files cannot be created (EACCES from the creation probe: what chmod 0o500 gives a
    user; tests here may run as root, whom chmod does not stop, so the refusal is injected)."""
    import tempfile

    import rbcli.record.output_file as output_file

    locked = tmp_path / "locked"
    locked.mkdir()
    real = tempfile.mkstemp

    def refuse(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        if str(kwargs.get("dir", "")).startswith(str(locked)):
            raise PermissionError(13, "Permission denied")
        return real(*args, **kwargs)

    monkeypatch.setattr(output_file.tempfile, "mkstemp", refuse)
    line = _one_line_error(_run("-o", str(locked / "x.mcap")))
    assert "cannot create files in" in line and "locked" in line and "Permission denied" in line
    assert list(locked.iterdir()) == []


def test_too_little_free_disk_is_refused_before_the_run(tmp_path):
    out = tmp_path / "huge.mcap"
    # 1e12 steps of one body: hundreds of terabytes at ~200 bytes per frame
    result = runner.invoke(app, ["run", str(TUTORIAL), "-o", str(out), "--duration", "1e9", "-q"])
    line = _one_line_error(result)
    assert "not enough free disk" in line and "TB" in line
    assert list(tmp_path.iterdir()) == []


def test_the_size_estimate_is_above_what_runs_write(tmp_path):
    """The disk check must not pass runs that then fill the disk: the estimate bounds real files from
    above (a tumbling body, the least compressible case; expected_output_bytes lists the margins)."""
    compiled = prepare(TUTORIAL, duration=0.5)
    for suffix, fmt in ((".mcap", "mcap"), (".rrd", "rerun")):
        out = tmp_path / f"t{suffix}"
        summary = run_to_file(compiled, out)
        estimate = expected_output_bytes(
            fmt, body_count=1, particle_count=4, frames=summary.frames, scene_bytes=len(TUTORIAL.read_bytes())
        )
        assert out.stat().st_size < estimate < 4 * out.stat().st_size, (suffix, out.stat().st_size, estimate)


@pytest.mark.parametrize(
    "name, stem",
    [("../../x", "x"), ("t-handle", "t-handle"), ("a/b c", "a_b_c"), ("", "scene"), ("...", "scene"),
     (".hidden", "hidden"), ("-rf", "rf"), ("C:\\win\\x", "C_win_x"), ("Würfel 1", "Würfel_1"), ("é" * 300, "é" * 60)],
)  # fmt: skip
def test_scene_names_become_one_safe_file_name(name, stem):
    assert safe_file_stem(name) == stem


def test_a_scene_named_dot_dot_writes_inside_outputs(tmp_path, monkeypatch):
    work = tmp_path / "a" / "b"
    work.mkdir(parents=True)
    scene = tmp_path / "escape.yaml"
    scene.write_text(TUTORIAL.read_text().replace("name: t-handle", 'name: "../../x"'))
    monkeypatch.chdir(work)
    result = runner.invoke(app, ["run", str(scene), "--duration", "0.02", "-q"])
    assert result.exit_code == 0, result.output
    assert [p.name for p in (work / "outputs").iterdir()] == ["x.rrd"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a", "escape.yaml"]  # nothing at ../../x.rrd


# --- a failed run never destroys a good file -----------------------------------------------------


def test_a_run_failing_before_its_first_frame_leaves_the_old_file_byte_identical(tmp_path, monkeypatch):
    from rbcli.record.mcap_sink import SinkMcap

    out = tmp_path / "keep.mcap"
    out.write_bytes(OLD)

    def open_then_fail(self, header):  # what a full disk does: the file is made, then a write fails
        with open(self.path, "wb") as f:
            f.write(b"\x89MCAP0\r\n")
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(SinkMcap, "open", open_then_fail)
    line = _one_line_error(_run("-o", str(out)))
    assert "No space left on device" in line and "is unchanged" in line
    assert out.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.mcap"]  # no partial left behind


def test_a_run_failing_mid_way_keeps_its_log_as_the_partial_and_the_old_file(tmp_path, monkeypatch):
    from rbcli.record.mcap_sink import SinkMcap

    out = tmp_path / "keep.mcap"
    out.write_bytes(OLD)
    write = SinkMcap.write

    def write_then_fail(self, block):
        if self.frames_written:
            raise OSError(5, "Input/output error")
        write(self, block)

    monkeypatch.setattr(SinkMcap, "write", write_then_fail)
    args = ["run", str(TUTORIAL), "-o", str(out), "--duration", "2", "--record-every", "1", "-q"]
    monkeypatch.setattr("rbcli.runner.loop.MAX_BLOCK_FRAMES", 64, raising=False)  # several blocks
    result = runner.invoke(app, args)
    line = _one_line_error(result)
    partial = tmp_path / "keep.partial.mcap"
    assert "Input/output error" in line and str(partial) in line
    assert out.read_bytes() == OLD
    kept = read_mcap(partial)
    assert kept.summary["status"] == "error" and kept.frames > 0
    # the leftover is not overwritten by the next run: it says so instead
    monkeypatch.undo()
    line = _one_line_error(_run("-o", str(out)))
    assert "left from an earlier run" in line and "keep.partial.mcap" in line
    assert out.read_bytes() == OLD


@pytest.mark.parametrize("suffix", [".mcap", ".rrd"])
def test_a_diverging_run_replaces_the_file_with_the_log_up_to_the_stop(tmp_path, suffix):
    scene = tmp_path / "blow_up.yaml"
    scene.write_text(DIVERGING)
    out = tmp_path / f"run{suffix}"
    out.write_bytes(OLD)
    result = runner.invoke(app, ["run", str(scene), "-o", str(out), "-q"])
    assert result.exit_code == 3, result.output
    recorded = read_recording(out)
    assert recorded.summary["status"] == "diverged"
    assert 1 < recorded.frames < 101 and recorded.step.tolist() == list(range(recorded.frames))
    assert sorted(p.name for p in tmp_path.iterdir()) == ["blow_up.yaml", f"run{suffix}"]


@pytest.mark.parametrize("suffix", [".mcap", ".rrd"])
def test_an_interrupted_run_replaces_the_file_with_the_log_up_to_the_stop(tmp_path, suffix):
    out = tmp_path / f"run{suffix}"
    out.write_bytes(OLD)
    compiled = prepare(TUTORIAL, duration=1e4, record_every=1000)
    seen = []

    def progress(done: int, total: int) -> None:
        seen.append(done)
        assert partial_path(out).is_file() and out.read_bytes() == OLD  # written aside while running
        if len(seen) == 2:
            os.kill(os.getpid(), signal.SIGINT)  # what Ctrl-C does

    summary = run_to_file(compiled, out, progress=progress)
    assert summary.status == "interrupted" and 0 < summary.steps < compiled.settings.steps
    recorded = read_recording(out)
    assert recorded.summary["status"] == "interrupted"
    assert int(recorded.step[-1]) == summary.steps  # the state at the interruption is the last frame
    assert not partial_path(out).exists()


def test_a_completed_run_keeps_the_replaced_files_permissions(tmp_path):
    out = tmp_path / "shared.mcap"
    out.write_bytes(OLD)
    out.chmod(0o640)
    assert _run("-o", str(out)).exit_code == 0
    assert out.stat().st_mode & 0o777 == 0o640 and read_mcap(out).frames == 51


# --- concurrent writers and killed runs ----------------------------------------------------------


def test_a_second_writer_to_the_same_path_is_refused(tmp_path):
    out = tmp_path / "shared.mcap"
    out.write_bytes(OLD)
    first = OutputFile(out)
    first.open()  # a run in progress holds the lock on shared.partial.mcap
    try:
        line = _one_line_error(_run("-o", str(out)))
        assert "another rbsim run is writing it" in line
        with pytest.raises(OutputError, match="another rbsim run"):
            OutputFile(out).open()
        with pytest.raises(OutputError, match="another rbsim run"):
            run_to_file(prepare(TUTORIAL, duration=0.01), out)
    finally:
        first.abandon(keep=False)
    assert out.read_bytes() == OLD and not partial_path(out).exists()
    check_output(out)  # free again once the first writer is done
    assert _run("-o", str(out)).exit_code == 0


def _start_long_run(out: Path, record_every: int) -> subprocess.Popen:
    """`rbsim run` of 1e9 steps (minutes), returned once its sink has written to the partial (so the
    run loop, which turns Ctrl-C into a clean stop, has started) and half a second more."""
    args = [sys.executable, "-m", "rbcli", "run", str(TUTORIAL), "-o", str(out), "-q"]
    args += ["--duration", "1e6", "--record-every", str(record_every)]
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 30.0  # kernels may compile on a cold cache
    partial = partial_path(out)
    while not (partial.is_file() and partial.stat().st_size > 0):
        assert proc.poll() is None, proc.communicate()[0]
        assert time.monotonic() < deadline, "the run did not start"
        time.sleep(0.05)
    time.sleep(0.5)
    return proc


def test_a_killed_run_leaves_its_partial_and_the_old_file(tmp_path):
    out = tmp_path / "long.rrd"  # rerun writes its file as it goes (an .mcap buffers its first 4 MB chunk)
    out.write_bytes(OLD)
    proc = _start_long_run(out, record_every=100_000)
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=10)
    assert proc.returncode == -signal.SIGKILL
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.partial.rrd", "long.rrd"]
    assert out.read_bytes() == OLD


@pytest.mark.parametrize(("signum", "status"), [(signal.SIGTERM, 143), (signal.SIGHUP, 129)])
def test_sigterm_and_sighup_stop_a_cli_run_like_ctrl_c_and_rename_the_log(tmp_path, signum, status):
    """Exit status 128 + the signal, as shells report a process killed by it."""
    out = tmp_path / "long.rrd"
    out.write_bytes(OLD)
    proc = _start_long_run(out, record_every=10_000)
    proc.send_signal(signum)
    output = proc.communicate(timeout=30)[0]
    assert proc.returncode == status, output
    assert "interrupted at step" in output and "Traceback" not in output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["long.rrd"]
    recorded = read_recording(out)
    assert recorded.summary["status"] == "interrupted" and recorded.frames >= 1
