"""The recording thread: same files as writing inline, bounded memory, errors surface, nothing lost."""

import hashlib
import threading
import time

import numpy as np
import pytest
from conftest import make_scene, random_bodies

import rbcli.runner.loop as loop
import rbcli.runner.recorder as recorder_module
import rbcli.runner.simulation as simulation
from rbcli.api import prepare
from rbcli.physics.integrators import INTEGRATORS
from rbcli.record.mcap_sink import SinkMcap
from rbcli.record.memory_sink import SinkMemory

G = np.array([0.0, 0.0, -9.81])


def _scene(duration=1.0):
    return make_scene(random_bodies(4), dt=0.01, duration=duration, every=1, gravity=G)


def test_threaded_and_inline_recording_write_the_same_bytes(tmp_path, monkeypatch):
    monkeypatch.setattr(loop, "MAX_BLOCK_FRAMES", 7)  # many blocks, so buffers are recycled
    compiled = prepare(_scene())
    digests = []
    for threaded in (True, False):
        path = tmp_path / f"run-{threaded}.mcap"
        summary = simulation.run(compiled, [SinkMcap(path)], threaded=threaded)
        assert summary.frames == 101
        digests.append(hashlib.sha256(path.read_bytes()).hexdigest())
    assert digests[0] == digests[1]


class _SlowSink(SinkMemory):
    """Writes slowly and notes which thread writes and how many blocks were waiting."""

    def __init__(self):
        super().__init__()
        self.threads = set()

    def write(self, block):
        self.threads.add(threading.current_thread().name)
        time.sleep(0.002)
        super().write(block)


def test_a_slow_sink_holds_the_run_back_instead_of_growing_memory(monkeypatch):
    monkeypatch.setattr(loop, "MAX_BLOCK_FRAMES", 2)  # ~50 blocks
    made = []
    real = recorder_module.empty_buffers
    monkeypatch.setattr(recorder_module, "empty_buffers", lambda k, n, j=0: made.append(k) or real(k, n, j))
    sink = _SlowSink()
    summary = simulation.run(prepare(_scene()), [sink])
    traj = sink.trajectory()
    assert len(made) == recorder_module.POOL_BUFFERS  # every block reused one of a fixed pool
    assert sink.threads == {"rbsim-recorder"}
    assert summary.frames == len(traj.t) == 101 and traj.step.tolist() == list(range(101))
    inline = SinkMemory()
    simulation.run(prepare(_scene()), [inline], threaded=False)
    for name in ("x", "q", "v", "omega", "P", "L"):
        assert np.array_equal(getattr(traj, name), getattr(inline.trajectory(), name)), name


class _FailsOnThirdBlock(SinkMemory):
    def write(self, block):
        if len(self.blocks) == 2:
            raise OSError("disk full")
        super().write(block)


@pytest.mark.parametrize("threaded", [True, False])
def test_a_sink_failing_mid_run_stops_it_and_every_sink_keeps_what_was_written(monkeypatch, threaded):
    monkeypatch.setattr(loop, "MAX_BLOCK_FRAMES", 5)
    good, bad = SinkMemory(), _FailsOnThirdBlock()
    started = time.perf_counter()
    with pytest.raises(OSError, match="disk full"):
        simulation.run(prepare(_scene(duration=1000.0)), [good, bad], threaded=threaded)
    assert time.perf_counter() - started < 30  # stopped, not run to the end (100,000 steps)
    for sink in (good, bad):
        assert sink.summary is not None and sink.summary.status == "error"
        assert "disk full" in sink.summary.message
    assert len(bad.blocks) == 2
    frames = np.concatenate([b.step for b in good.blocks])
    assert frames.tolist() == list(range(len(frames))) and len(frames) >= 10  # in order, no gaps
    assert good.summary.frames == len(frames) - 5  # the failed block reached the good sink only


def test_every_chunk_kernel_releases_the_gil():
    """The recording thread only overlaps the integration if the compiled chunk drops the GIL."""
    kernels = {name: info.chunk().run_chunk for name, info in INTEGRATORS.items()}
    kernels.update(
        {f"{name} adaptive": info.adaptive_chunk().run_chunk for name, info in INTEGRATORS.items() if info.adaptive}
    )
    assert {name: k.targetoptions.get("nogil") for name, k in kernels.items()} == dict.fromkeys(kernels, True)


def test_a_run_that_fits_one_buffer_starts_no_thread():
    sink = _SlowSink()
    before = threading.active_count()
    simulation.run(prepare(_scene(duration=0.1)), [sink])  # 11 frames: one buffer
    assert sink.threads == {threading.current_thread().name} and threading.active_count() == before


@pytest.mark.parametrize("suffix", [".mcap", ".rrd"])
def test_an_interrupted_threaded_recording_is_complete_and_readable(tmp_path, monkeypatch, suffix):
    """Ctrl-C while the recording thread (and the MCAP writer's worker) have blocks in flight."""
    import os
    import signal

    from rbcli.record.read import read_mcap, read_rrd
    from rbcli.record.sinks import open_file_sink

    monkeypatch.setattr(loop, "MAX_BLOCK_FRAMES", 3)
    monkeypatch.setattr(loop, "CHUNK_SECONDS", 1e-4)
    compiled = prepare(make_scene(random_bodies(3), dt=1e-4, duration=100.0, every=1, gravity=G))
    calls = []

    def progress(done, total):
        calls.append(done)
        if len(calls) == 20:
            os.kill(os.getpid(), signal.SIGINT)

    path = tmp_path / f"cut{suffix}"
    summary = simulation.run(compiled, [open_file_sink(path)], progress=progress)
    assert summary.status == "interrupted" and 0 < summary.steps < compiled.settings.steps
    recorded = (read_mcap if suffix == ".mcap" else read_rrd)(path)
    assert recorded.summary["status"] == "interrupted"
    assert recorded.step.tolist() == list(range(summary.steps + 1)) == list(range(summary.frames))
    inline = SinkMemory()
    cut = prepare(make_scene(random_bodies(3), dt=1e-4, duration=summary.steps * 1e-4, every=1, gravity=G))
    simulation.run(cut, [inline], threaded=False)
    tolerance = 0 if suffix == ".mcap" else 1e-6  # .rrd transforms are float32
    np.testing.assert_allclose(recorded.x, inline.trajectory().x, rtol=tolerance, atol=tolerance)
