"""The threaded chunk loop (issue 28 item 1): bitwise the serial loop at any thread count, really split over
threads, and chosen only where a scene is large enough (runner/threads.py, docs/performance.md "Threads").

split2's step_parallel spreads its two passes over the bodies (the drifts and turns, the kicks) over
numba's threads; each body's arithmetic is the serial step's and nothing is summed across bodies, so
the trajectories must be equal bit for bit, with forces between bodies (springs) and contact (evaluated
serially between the passes) as well as free bodies. The size threshold is lowered here so that small
scenes take the threaded loop (each scene kind compiles its threaded loop once: small scenes run fast).
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import numba
import numpy as np
import pytest
from conftest import make_scene, random_bodies

import rbcli.runner.threads as threads_module
from rbcli.runner.simulation import Simulation

ROOT = Path(__file__).resolve().parents[2]

# the process's numba pool must hold two threads (NUMBA_NUM_THREADS defaults to the machine's cores)
two_threads = pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="numba has one thread on this machine")

# clouds and balls piling into a box, some tied by springs-dampers, with drag: the threaded step's forces
# between bodies (springs, whose dampers and the drag are split2's dissipative flow) and contact of
# single-sphere and several-sphere bodies, in one scene (one threaded loop compiled, ~10 CPU-s)
PILE = """
name: mixed-pile
simulation: {dt: 0.002, duration: 0.8, integrator: split2}
gravity: [0, 0, -9.81]
contact:
  container: {min: [-0.3, -0.3, 0], max: [0.3, 0.3, 2]}
bodies:
  - grid:
      name: cloud
      count: [3, 3, 2]
      spacing: [0.16, 0.16, 0.16]
      origin: [-0.16, -0.16, 0.3]
      jitter: [0.01, 0.01, 0]
      seed: 1
      template:
        particles:
          positions: [[0, 0, 0], [0.05, 0, 0], [0, 0.04, 0], [0, 0, 0.03]]
          masses: [0.3, 0.1, 0.1, 0.1]
          radius: [0.03, 0.02, 0.02, 0.02]
        angular_momentum: [0.001, -0.002, 0.0005]
  - grid:
      name: ball
      count: [3, 3, 1]
      spacing: [0.14, 0.14, 0.14]
      origin: [-0.14, -0.14, 0.7]
      jitter: [0.01, 0.01, 0]
      seed: 2
      template:
        particles: {positions: [[0, 0, 0]], masses: [0.5], radius: [0.05]}
forces:
  - {type: spring, bodies: [cloud_0, cloud_1], points: [[0.05, 0, 0], [0, 0, 0]], stiffness: 200, damping: 0.5}
  - {type: spring, bodies: [cloud_13, ball_4], points: [[0, 0.04, 0], [0, 0, 0]], stiffness: 100, damping: 0.2}
  - {type: drag, bodies: all, linear: 0.01, angular_linear: 0.0001}
"""


@pytest.fixture
def small_threshold(monkeypatch):
    """Small scenes take the threaded loop."""
    monkeypatch.setattr(threads_module, "PARALLEL_MIN_BODIES", 2)
    monkeypatch.setattr(threads_module, "THREADED_CONTACT", True)  # contact scenes keep the serial loop in runs
    monkeypatch.delenv(threads_module.ENV, raising=False)


def _state(sim: Simulation) -> tuple[np.ndarray, ...]:
    s = sim.data.state
    return s.x.copy(), s.q.copy(), s.P.copy(), s.L.copy()


def _assert_bitwise(serial: Simulation, threaded: Simulation) -> None:
    for name, a, b in zip("xqPL", _state(serial), _state(threaded), strict=True):
        assert np.array_equal(a, b), f"{name} differs by up to {np.max(np.abs(a - b)):.3g}"


def _scenes(tmp_path: Path) -> dict[str, object]:
    pile = tmp_path / "pile.yaml"
    pile.write_text(PILE)
    free = make_scene(random_bodies(40, seed=3), integrator="split2", gravity=np.array([0.0, 0.0, -9.81]))
    return {"free bodies": free, "pile": pile}


@two_threads
@pytest.mark.parametrize("name", ["free bodies", "pile"])
def test_two_threads_give_the_bits_of_one(name, tmp_path, small_threshold):
    scene = _scenes(tmp_path)[name]
    serial = Simulation(scene, threads=1, integrator="split2")
    threaded = Simulation(scene, threads=2, integrator="split2")
    assert serial.threads == 1 and threaded.threads == 2
    assert threaded._chunk is not serial._chunk
    for steps in (1, 60, 139):  # the pile lands at ~0.23 s: steps 115-200 are full of new contacts
        serial.step(steps)
        threaded.step(steps)
        _assert_bitwise(serial, threaded)
    one = Simulation(scene, threads=2, integrator="split2")  # the threaded loop on one thread: the same bits
    numba.set_num_threads(1)
    try:
        one._run_chunk(0, 200, 2**62, one._no_frames, 0)  # the runner's call (kernel handles): its loop
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    _assert_bitwise(serial, one)


@two_threads
def test_the_threaded_step_runs_on_a_second_thread(small_threshold):
    """Another thread does part of the work: the process's CPU time outgrows the calling thread's (CPU
    time, not wall time, so a loaded machine does not change the split). A loop that lost its prange
    (or whose loop numba could not parallelise) would leave the second thread idle."""
    scene = make_scene(random_bodies(2000, seed=5), integrator="split2", gravity=np.array([0.0, 0.0, -9.81]))
    sim = Simulation(scene, threads=2)
    sim.step(2)
    process, own = time.process_time(), time.thread_time()
    sim.step(400)
    process, own = time.process_time() - process, time.thread_time() - own
    assert process - own > 0.25 * process, f"other threads used {process - own:.3f} s of {process:.3f} s CPU"


def test_small_scenes_contact_one_thread_and_other_integrators_keep_the_serial_loop(monkeypatch):
    monkeypatch.delenv(threads_module.ENV, raising=False)
    small = make_scene(random_bodies(threads_module.PARALLEL_MIN_BODIES - 1), integrator="split2")
    assert Simulation(small, threads=2).threads == 1
    large = make_scene(random_bodies(threads_module.PARALLEL_MIN_BODIES), integrator="split2")
    assert Simulation(large, threads=1).threads == 1
    monkeypatch.setenv(threads_module.ENV, threads_module.WORKER_ENV[threads_module.ENV])  # a sweep worker's
    one = Simulation(large)
    assert one.threads == 1 and one.governor is None
    assert one.threads_report() == f"threads: 1 ({threads_module.ENV}=1)"
    assert Simulation(large, integrator="rk4", threads=2).threads == 1
    assert Simulation(large, integrator="dopri5", tolerance=1e-6, threads=2).threads == 1
    assert threads_module.chunk_threads(2, True, threads_module.PARALLEL_MIN_BODIES) == 2
    assert threads_module.chunk_threads(2, True, threads_module.PARALLEL_MIN_BODIES, contact=True) == 1
    # joints: the RATTLE step (joints/rattle.py) is serial, the threaded loop would only start a pool
    assert threads_module.chunk_threads(2, True, threads_module.PARALLEL_MIN_BODIES, joints=True) == 1
    pile = ROOT / "scenes/contact/sphere_pile.yaml"  # 1,000 balls: contact keeps the serial loop
    assert Simulation(pile, threads=2).threads == 1
    assert Simulation(pile, threads=2).contact_threads == 2  # and searches on threads: 1,000 spheres
    # ten boxes touching as boxes: their 3,080 lattice spheres are their mass only, the search walks none
    stack = ROOT / "scenes/contact/box_stack.yaml"
    assert Simulation(stack, threads=2).contact_threads == 1


class _Alternating:
    """A governor that switches between 1 and 2 threads every slice, slices of 1 to 5 steps."""

    def __init__(self) -> None:
        self.slices = 0

    def plan(self, remaining: int) -> tuple[int, int]:
        self.slices += 1
        return 1 + self.slices % 2, min(remaining, 1 + self.slices % 5)

    def record(self, threads: int, steps: int, seconds: float) -> None:
        pass


@two_threads
@pytest.mark.parametrize("name", ["free bodies", "pile"])
def test_bits_hold_under_a_competing_load_and_switches(name, tmp_path, small_threshold):
    """With a busy process on the cores (whose time slices preempt the threads mid-pass), a fixed 2 threads,
    the default governor, and a governor switching threads every slice all give the serial run's bits:
    the thread count may change between any two steps (runner/governor.py)."""
    scene = _scenes(tmp_path)[name]
    busy = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        serial = Simulation(scene, threads=1, integrator="split2")
        fixed = Simulation(scene, threads=2, integrator="split2")
        auto = Simulation(scene, threads="auto", integrator="split2")
        switching = Simulation(scene, threads="auto", integrator="split2")
        assert auto.governor is not None and fixed.governor is None
        switching.governor = _Alternating()  # type: ignore[assignment]
        for sim in (serial, fixed, auto, switching):
            sim.step(150)
        for sim in (fixed, auto, switching):
            _assert_bitwise(serial, sim)
        assert switching.governor.slices > 40
    finally:
        busy.kill()
        busy.wait()
