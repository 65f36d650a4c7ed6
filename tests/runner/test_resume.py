"""`rbsim run --resume LOG`: a run stopped by a signal, or killed, continues from the last checkpoint in
its .mcap log, and the new log's states are bit for bit those of a run never stopped.

The uninterrupted reference is the same scene run in one go (a different process for the CLI case);
frames compare as raw bits, invariants included. A stop is made in-process by raising SIGINT from the
progress callback (the run loop's own handler stops at the end of the chunk); a kill by cutting a log
written with a checkpoint at every block at a byte offset inside a later block, as a crash leaves it.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import rbcli.runner.loop as loop
from rbcli.record.mcap_recovery import read_mcap_resume_point
from rbcli.record.mcap_sink import SinkMcap
from rbcli.record.output_file import partial_path
from rbcli.record.read import read_mcap, read_trajectory
from rbcli.runner.resume import ResumeError, plan_resume, resume_run
from rbcli.runner.simulation import Simulation

ROOT = Path(__file__).resolve().parents[2]
BOX_DROP = ROOT / "scenes" / "contact" / "box_drop.yaml"  # contact: history, sub-steps, contact invariants
PLATE = ROOT / "scenes" / "tumbling_plate.yaml"


def same_bits(a, b) -> bool:  # noqa: ANN001
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def assert_same_log(resumed: Path, reference: Path) -> None:
    a, b = read_trajectory(resumed), read_trajectory(reference)
    assert a.step.tolist() == b.step.tolist()
    for name in ("t", "x", "q", "v", "omega", "P", "L"):
        assert same_bits(getattr(a, name), getattr(b, name)), name
    assert a.invariants.keys() == b.invariants.keys()
    for name in a.invariants:
        assert same_bits(a.invariants[name], b.invariants[name]), name
    assert read_mcap(resumed).summary["status"] == "completed"


def stopped_run(scene: Path, out: Path, *, stop_after_calls: int, **overrides) -> int:  # noqa: ANN003
    """Run to `out` and stop it like Ctrl-C after `stop_after_calls` chunks; the step it stopped at."""
    sim = Simulation(scene, **overrides)
    calls = []

    def progress(done: int, total: int) -> None:
        calls.append(done)
        if len(calls) == stop_after_calls:
            os.kill(os.getpid(), signal.SIGINT)

    summary = sim.run(sinks=[SinkMcap(out)], progress=progress)
    assert summary.status == "interrupted", summary
    return summary.steps


@pytest.fixture
def small_chunks(monkeypatch):  # noqa: ANN201
    monkeypatch.setattr(loop, "CHUNK_SECONDS", 0.002)  # many chunks, so the stop falls mid-run


@pytest.mark.parametrize(
    ("scene", "overrides"),
    [(BOX_DROP, {"duration": 0.6, "record_every": 7}), (PLATE, {"integrator": "dopri5", "tolerance": 1e-9})],
    ids=["contact-split2", "adaptive-dopri5"],
)
def test_a_resumed_run_is_bitwise_the_run_never_stopped(tmp_path, small_chunks, scene, overrides):
    Simulation(scene, **overrides).run(sinks=[SinkMcap(tmp_path / "whole.mcap")])
    # the stop lands after the chunk that follows the second progress call: early enough that box_drop,
    # whose first 0.3 s of free fall the two-level broad phase makes nearly free, still has steps left
    # (it ran in 5 chunks, [64, 80, 144, 400, 600] steps done, and a stop after the 4th came too late)
    stopped = stopped_run(scene, tmp_path / "cut.mcap", stop_after_calls=2, **overrides)
    plan = plan_resume(tmp_path / "cut.mcap")
    assert plan.checkpoint.step == stopped and 0 < stopped < plan.total_steps and plan.log_status == "interrupted"
    resume_run(plan, [SinkMcap(tmp_path / "resumed.mcap")])
    assert_same_log(tmp_path / "resumed.mcap", tmp_path / "whole.mcap")


def test_a_killed_run_resumes_from_its_last_checkpoint(tmp_path, monkeypatch):
    """Every block carries a checkpoint; the log is cut inside a later block (no summary, no index, a torn
    chunk): the resume starts at the last whole checkpoint and still ends bitwise as the whole run."""
    monkeypatch.setattr(loop, "CHECKPOINT_SECONDS", 0.0)
    monkeypatch.setattr(loop, "HAND_OVER_SECONDS", 0.0)  # a block per chunk
    monkeypatch.setattr(loop, "CHUNK_SECONDS", 0.002)
    overrides = {"duration": 0.6, "record_every": 3}
    Simulation(BOX_DROP, **overrides).run(sinks=[SinkMcap(tmp_path / "whole.mcap")])
    Simulation(BOX_DROP, **overrides).run(sinks=[SinkMcap(tmp_path / "full.mcap")])
    data = (tmp_path / "full.mcap").read_bytes()
    killed = tmp_path / "run.partial.mcap"
    killed.write_bytes(data[: len(data) * 3 // 5])
    plan = plan_resume(killed)
    assert plan.log_status == "truncated" and 0 < plan.checkpoint.step < plan.total_steps
    everything = read_mcap_resume_point(tmp_path / "full.mcap").checkpoint
    assert everything is not None and everything.step == plan.total_steps  # the last one is at the end
    resume_run(plan, [SinkMcap(tmp_path / "resumed.mcap")])
    assert_same_log(tmp_path / "resumed.mcap", tmp_path / "whole.mcap")


def test_logs_that_cannot_resume_say_why(tmp_path):
    done = tmp_path / "done.mcap"
    Simulation(BOX_DROP, duration=0.3, record_every=1).run(sinks=[SinkMcap(done)])
    with pytest.raises(ResumeError, match="completed; nothing to resume"):
        plan_resume(done)
    cut = tmp_path / "cut.partial.mcap"
    data = done.read_bytes()
    cut.write_bytes(data[: len(data) // 2])  # killed before any checkpoint (the only one is at the end)
    with pytest.raises(ResumeError, match="no checkpoint"):
        plan_resume(cut)
    rrd = tmp_path / "x.rrd"
    rrd.write_bytes(b"RRF2")
    with pytest.raises(ResumeError, match=r"only \.mcap logs hold checkpoints"):
        plan_resume(rrd)
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"not an mcap file at all")
    with pytest.raises(ResumeError, match="not an MCAP file"):
        plan_resume(junk)


def test_checkpoint_restore_continues_bitwise_and_checks_the_layout():
    sim = Simulation(BOX_DROP, duration=0.8)
    sim.step(640)  # the brick lands at about 0.3 s and lies flat from about 0.62 s
    saved = sim.checkpoint()
    sim.step(50)
    after = sim.checkpoint()
    other = Simulation(BOX_DROP, duration=0.8)
    other.restore(saved)
    other.step(50)
    again = other.checkpoint()
    assert again.step == after.step == 690
    for name, array in after.arrays.items():
        assert same_bits(again.arrays[name], array), name
    assert after.arrays["contact.hist_count"].any()  # the history really is carried (the brick is down)
    plate = Simulation(PLATE)
    with pytest.raises(ValueError, match="checkpoint arrays do not fit this run"):
        plate.restore(saved)


GRID = """\
name: resume-grid
simulation: {dt: 0.001, duration: 150.0, integrator: split2, record: {every: 100}}
gravity: [0, 0, -9.81]
bodies:
  - grid:
      name: b
      count: [8, 8, 1]
      spacing: [1.0, 1.0, 1.0]
      template:
        particles: {positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]], masses: [1.0, 0.5, 0.5, 0.25]}
        angular_momentum: [0.02, 0.05, 0.01]
"""


def test_cli_resume_after_sigterm_is_bitwise_the_uninterrupted_run(tmp_path):
    """A real `rbsim run` stopped by SIGTERM (exit 143), then `rbsim run --resume LOG`: exit 0, a new log
    equal bit for bit to the same run done in one go in another process."""
    scene = tmp_path / "grid.yaml"
    scene.write_text(GRID)
    whole = tmp_path / "whole.mcap"
    cmd = [sys.executable, "-m", "rbcli", "run"]
    done = subprocess.run([*cmd, str(scene), "-o", str(whole), "-q"], cwd=ROOT, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    log = tmp_path / "out" / "run.mcap"
    proc = subprocess.Popen([*cmd, str(scene), "-o", str(log), "-q"], cwd=ROOT, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 120.0  # kernels may compile on a cold cache
    while not partial_path(log).is_file():  # the sink is open: the run loop is (about to be) running
        assert proc.poll() is None, proc.communicate()
        assert time.monotonic() < deadline, "the run did not start"
        time.sleep(0.01)
    proc.send_signal(signal.SIGTERM)
    _, stderr = proc.communicate(timeout=60)
    if proc.returncode == 0:
        pytest.fail(f"the run ended before SIGTERM arrived; make GRID longer ({stderr})")
    assert proc.returncode == 143, stderr
    usage = subprocess.run([*cmd, str(scene), "--resume", str(log)], cwd=ROOT, capture_output=True, text=True)
    assert usage.returncode == 2 and "drop SCENE" in usage.stderr
    resumed = subprocess.run([*cmd, "--resume", str(log)], cwd=ROOT, capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stderr
    assert "resuming" in resumed.stderr and "completed" in resumed.stderr
    assert_same_log(log.with_name("run.resumed.mcap"), whole)
    again = subprocess.run([*cmd, "--resume", str(whole)], cwd=ROOT, capture_output=True, text=True)
    assert again.returncode == 1 and "nothing to resume" in again.stderr and "Traceback" not in again.stderr
