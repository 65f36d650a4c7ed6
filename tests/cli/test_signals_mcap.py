"""A real `rbsim run` writing .mcap, stopped by SIGINT, SIGTERM or SIGHUP mid-run: exit 130 / 143 / 129,
one line saying where the log is and up to which step and time it holds, an MCAP whose summary and index
the `mcap` library's indexed reader reads, and every step up to the stop bitwise equal to `rbcli.simulate`
of the same scene for the same number of steps. A second signal while the log is being finished (MCAP
summary and index, rename) does not cut it short."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import sys
import threading
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
from rbcli.record.read import read_mcap

ROOT = Path(__file__).resolve().parents[2]
TUTORIAL = ROOT / "scenes" / "tutorial.yaml"
DT = 0.001
# 64 bodies, every step recorded: ~30,000 frames/s on one core, so the run (1e6 steps) is still going when
# the signal comes, and the few thousand frames written by then read back in about a second.
GRID = f"""\
name: signal-grid
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
LINE = re.compile(
    r"^interrupted at step (\d+) \(t = (\S+) s\) by (SIG\w+); the log up to that point is complete: (.+)$"
)


@pytest.fixture(scope="module")
def grid_scene(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("scene") / "grid.yaml"
    path.write_text(GRID)
    return path


def start_run(scene: Path, out: Path, *extra: str, min_bytes: int = 1) -> subprocess.Popen:
    """`rbsim run SCENE -o OUT -q`, returned once its partial file holds at least `min_bytes` (the run
    loop is then running)."""
    args = [sys.executable, "-m", "rbcli", "run", str(scene), "-o", str(out), "-q", *extra]
    proc = subprocess.Popen(args, cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    partial, deadline = partial_path(out), time.monotonic() + 60.0  # kernels may compile on a cold cache
    while not (partial.is_file() and partial.stat().st_size >= min_bytes):
        if proc.poll() is not None:
            raise AssertionError(proc.communicate())
        assert time.monotonic() < deadline, "the run did not start"
        time.sleep(0.01)
    return proc


def check_log(scene: Path, out: Path, stderr: str, signame: str) -> int:
    """The one line, the indexed MCAP, every step up to the stop as simulate computes it; the last step."""
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    match = LINE.match(lines[0])
    assert match, stderr
    steps, t_end = int(match[1]), float(match[2])
    assert match[3] == signame and match[4] == str(out)
    assert steps > 0 and t_end == pytest.approx(steps * DT, rel=1e-5)
    assert sorted(p.name for p in out.parent.iterdir()) == [out.name]  # renamed: no partial left

    with open(out, "rb") as f:  # the mcap library's indexed (seeking) reader: summary, chunk index, CRCs
        reader = make_reader(f, validate_crcs=True)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None and summary.chunk_indexes
        states = [m.log_time for _, _, m in reader.iter_messages(topics=[TOPIC_STATE])]
    assert len(states) == steps + 1

    recorded = read_mcap(out)
    assert recorded.summary["status"] == "interrupted" and int(recorded.summary["steps"]) == steps
    assert recorded.step.tolist() == list(range(steps + 1))  # every step, none missing, none twice
    expected = rbcli.simulate(scene, duration=steps * DT)
    assert expected.step.tolist() == recorded.step.tolist()
    for name in ("x", "q", "v", "omega", "P", "L"):  # MCAP stores float64: bit for bit
        assert np.array_equal(getattr(recorded, name), getattr(expected, name)), name
    return steps


@pytest.mark.parametrize(
    ("signum", "status"), [(signal.SIGINT, 130), (signal.SIGTERM, 143), (signal.SIGHUP, 129)], ids=lambda v: str(v)
)
def test_a_signal_stops_an_mcap_run_with_a_complete_indexed_log(tmp_path, grid_scene, signum, status):
    out = tmp_path / "out" / "run.mcap"
    proc = start_run(grid_scene, out)
    proc.send_signal(signum)
    _, stderr = proc.communicate(timeout=30)
    assert proc.returncode == status, stderr
    check_log(grid_scene, out, stderr, signal.Signals(signum).name)


def test_more_sigterms_while_the_log_is_finished_do_not_cut_it_short(tmp_path, grid_scene):
    """SIGTERM, then SIGTERM every 2 ms until the process is gone: some land while the loop stops, some
    while the MCAP summary and index are written and the partial renamed, some after; none may cut the
    log short or change the exit status."""
    out = tmp_path / "out" / "run.mcap"
    proc = start_run(grid_scene, out)
    sent = 0
    deadline = time.monotonic() + 20.0
    while proc.poll() is None and time.monotonic() < deadline:
        proc.send_signal(signal.SIGTERM)  # does nothing once the process has been waited for
        sent += 1
        time.sleep(0.002)
    _, stderr = proc.communicate(timeout=30)
    assert sent > 2 and proc.returncode == 143, (sent, stderr)
    check_log(grid_scene, out, stderr, "SIGTERM")


def test_a_second_signal_in_the_middle_of_writing_the_mcap_summary_is_ignored(tmp_path, monkeypatch):
    """Deterministic: the second SIGTERM is raised inside the MCAP writer's `finish`, between the data
    section and the summary (before, such a signal raised KeyboardInterrupt there: no summary, no index,
    the log left as an unreadable partial)."""
    from rbcli.record import mcap_writer

    real = mcap_writer.McapChunkWriter._statistics
    during_finish = []

    def statistics_with_a_signal(self):  # noqa: ANN001, ANN202
        during_finish.append(True)
        os.kill(os.getpid(), signal.SIGTERM)  # handled at the next bytecode, inside finish
        time.sleep(0.01)
        return real(self)

    monkeypatch.setattr(mcap_writer.McapChunkWriter, "_statistics", statistics_with_a_signal)
    out = tmp_path / "run.mcap"
    saved = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)}
    signal.signal(signal.SIGTERM, lambda *_: None)  # a stray SIGTERM must not end pytest
    running = threading.Event()

    def first_sigterm() -> None:  # once the run writes its partial (the command handles signals then)
        while not partial_path(out).exists() and not running.wait(0.01):
            pass
        if not running.wait(0.3):
            os.kill(os.getpid(), signal.SIGTERM)

    first = threading.Thread(target=first_sigterm)
    try:
        first.start()
        args = ["run", str(TUTORIAL), "-o", str(out), "-q", "--duration", "100000", "--record-every", "100"]
        result = CliRunner().invoke(app, args)
    finally:
        running.set()
        first.join()
        for number, handler in saved.items():  # the command leaves stop signals ignored once one came
            signal.signal(number, handler)
    assert during_finish and result.exit_code == 143, result.output
    assert "interrupted at step" in result.output and "by SIGTERM" in result.output
    with open(out, "rb") as f:
        assert make_reader(f, validate_crcs=True).get_summary() is not None
    recorded = read_mcap(out)
    assert recorded.summary["status"] == "interrupted" and recorded.frames > 1
    assert not partial_path(out).exists()
