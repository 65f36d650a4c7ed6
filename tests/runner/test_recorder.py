"""The recording thread: same files as writing inline, bounded memory, errors surface, nothing lost."""

import hashlib
import threading
import time

import numpy as np
import pytest
from conftest import make_scene, random_bodies

import rbcli.runner.loop as loop
import rbcli.runner.recorder as recorder_module
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
        summary = loop.run(compiled, [SinkMcap(path)], threaded=threaded)
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
    monkeypatch.setattr(recorder_module, "empty_buffers", lambda k, n: made.append(k) or real(k, n))
    sink = _SlowSink()
    summary = loop.run(prepare(_scene()), [sink])
    traj = sink.trajectory()
    assert len(made) == recorder_module.POOL_BUFFERS  # every block reused one of a fixed pool
    assert sink.threads == {"rbsim-recorder"}
    assert summary.frames == len(traj.t) == 101 and traj.step.tolist() == list(range(101))
    inline = SinkMemory()
    loop.run(prepare(_scene()), [inline], threaded=False)
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
        loop.run(prepare(_scene(duration=1000.0)), [good, bad], threaded=threaded)
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
    from rbcli.physics.adaptive import run_adaptive_chunk

    kernels = {name: info.load().run_chunk for name, info in INTEGRATORS.items()}
    kernels["adaptive"] = run_adaptive_chunk
    assert {name: k.targetoptions.get("nogil") for name, k in kernels.items()} == dict.fromkeys(kernels, True)


def test_a_run_that_fits_one_buffer_starts_no_thread():
    sink = _SlowSink()
    before = threading.active_count()
    loop.run(prepare(_scene(duration=0.1)), [sink])  # 11 frames: one buffer
    assert sink.threads == {threading.current_thread().name} and threading.active_count() == before
