"""The contact search on threads (physics/contact/threaded.py, issue 28 item 1): the same contacts, forces,
history and statistics as the serial search, bit for bit, at any thread count; a block that finds more
contacts than its rows is searched again serially in its place; the work really splits; and only scenes
large enough take it (runner/threads.py).

Why bitwise and not a tolerance: the threaded search must do the serial sums in the serial order
(threaded.py's apply pass), so any difference is a bug (a record lost, a block applied twice or out of
order, a race). The piles are sized to hold several blocks of RECORD_BLOCK walkers, and are compared
through the steps where the layers land on each other (many new contacts, each with a history).
"""

from __future__ import annotations

import time
from pathlib import Path

import numba
import numpy as np
import pytest

import rbcli.runner.threads as threads_module
from rbcli.physics.contact.tables import COUNT_CONTACTS
from rbcli.runner.simulation import Simulation

ROOT = Path(__file__).resolve().parents[2]

two_threads = pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="numba has one thread on this machine")

# 216 balls (4 blocks of walkers) and 48 four-sphere clouds (192 spheres, 3 blocks) dropped into a box
BALL_PILE = """
name: ball-pile
simulation: {dt: 0.002, duration: 0.8, integrator: split2}
gravity: [0, 0, -9.81]
contact:
  container: {min: [-0.4, -0.4, 0], max: [0.4, 0.4, 2]}
bodies:
  - grid:
      name: ball
      count: [6, 6, 6]
      spacing: [0.12, 0.12, 0.12]
      origin: [-0.3, -0.3, 0.3]
      jitter: [0.01, 0.01, 0]
      seed: 0
      template:
        particles: {positions: [[0, 0, 0]], masses: [0.5236], radius: [0.05]}
"""

CLOUD_PILE = """
name: cloud-pile
simulation: {dt: 0.002, duration: 0.8, integrator: split2}
gravity: [0, 0, -9.81]
contact:
  container: {min: [-0.35, -0.35, 0], max: [0.35, 0.35, 2]}
bodies:
  - grid:
      name: cloud
      count: [4, 4, 3]
      spacing: [0.16, 0.16, 0.16]
      origin: [-0.24, -0.24, 0.3]
      jitter: [0.01, 0.01, 0]
      seed: 1
      template:
        particles:
          positions: [[0, 0, 0], [0.05, 0, 0], [0, 0.04, 0], [0, 0, 0.03]]
          masses: [0.3, 0.1, 0.1, 0.1]
          radius: [0.03, 0.02, 0.02, 0.02]
        angular_momentum: [0.001, -0.002, 0.0005]
"""


@pytest.fixture
def threaded_contact(monkeypatch):
    """Every contact scene takes the threaded search when given two threads."""
    monkeypatch.setattr(threads_module, "CONTACT_PARALLEL_MIN_SPHERES", 1)
    monkeypatch.delenv(threads_module.ENV, raising=False)


def _scene(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "pile.yaml"
    path.write_text(text)
    return path


def _assert_same(serial: Simulation, threaded: Simulation) -> None:
    """Every array a step carries (state, history, statistics, counters), and the last evaluation's
    forces, equal bit for bit."""
    mine, theirs = serial.data.carried(), threaded.data.carried()
    for name, value in mine.items():
        assert np.array_equal(value, theirs[name]), f"{name} differs"
    assert np.array_equal(serial.data.F, threaded.data.F) and np.array_equal(serial.data.tau, threaded.data.tau)


@two_threads
@pytest.mark.parametrize("text", [BALL_PILE, CLOUD_PILE], ids=["balls", "clouds"])
def test_threaded_search_gives_the_bits_of_the_serial_one(text, tmp_path, threaded_contact):
    scene = _scene(tmp_path, text)
    serial = Simulation(scene, threads=1)
    threaded = Simulation(scene, threads=2)
    assert serial.contact_threads == 1 and threaded.contact_threads == 2
    assert threaded.data.force.contact.record_count.shape[0] >= 3  # several blocks of walkers
    for steps in (1, 100, 150):  # the lowest layer lands at ~0.2 s; steps 100-250 are full of new contacts
        serial.step(steps)
        threaded.step(steps)
        _assert_same(serial, threaded)
    assert threaded.data.force.contact.counters[COUNT_CONTACTS] > 2000  # compared through many contacts
    one = Simulation(scene, threads=2)  # the threaded search on one thread: the same bits
    numba.set_num_threads(1)
    try:
        one._run_chunk(0, 251, 2**62, one._no_frames, 0)  # the runner's call (kernel handles): its loop
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    one.data.state.step = 251
    _assert_same(serial, one)


@two_threads
def test_blocks_that_overflow_their_rows_are_searched_again_in_place(tmp_path, threaded_contact):
    """With one row per block every block holding two or more contacts overflows: the apply pass then
    searches it again with the serial sink, in its place in the order, and the bits stay the serial ones
    (the overflow path removed, or run out of order, changes them)."""
    scene = _scene(tmp_path, BALL_PILE)
    serial = Simulation(scene, threads=1)
    threaded = Simulation(scene, threads=2)
    work = threaded.data.force.contact
    blocks = work.record_count.shape[0]
    narrow = work._replace(
        record_int=np.zeros((blocks, work.record_int.shape[1]), dtype=np.int64),
        record_float=np.zeros((blocks, work.record_float.shape[1])),
    )
    threaded.data.force = threaded.data.force._replace(contact=narrow)
    threaded._kdata = threaded.data.kernel()
    serial.step(200)
    threaded.step(200)
    assert (narrow.record_count > 1).sum() >= 2  # overflowing blocks beside ones that fit
    _assert_same(serial, threaded)


@two_threads
def test_the_threaded_search_runs_on_a_second_thread(tmp_path, threaded_contact):
    """Another thread does part of the search: the process's CPU time outgrows the calling thread's
    (CPU time, so a loaded machine does not change the split). A search whose prange was lost would
    leave the second thread idle."""
    sim = Simulation(ROOT / "scenes/contact/sphere_pile.yaml", threads=2)
    assert sim.threads == 1 and sim.contact_threads == 2  # the serial loop, the search on threads
    sim.step(300)  # the pile has landed: the search is most of each step
    process, own = time.process_time(), time.thread_time()
    sim.step(300)
    process, own = time.process_time() - process, time.thread_time() - own
    assert process - own > 0.15 * process, f"other threads used {process - own:.3f} s of {process:.3f} s CPU"


def test_only_scenes_large_enough_search_on_threads(tmp_path, monkeypatch):
    monkeypatch.delenv(threads_module.ENV, raising=False)
    small = ROOT / "scenes/verification/contact_pile.yaml"  # 64 balls
    assert Simulation(small, threads=2).contact_threads == 1
    assert Simulation(small, threads=2).data.force.contact.record_int is None  # no threaded kernel compiled
    pile = ROOT / "scenes/contact/sphere_pile.yaml"  # 1,000 balls
    assert Simulation(pile, threads=1).contact_threads == 1
    if numba.config.NUMBA_NUM_THREADS >= 2:
        assert Simulation(pile, threads=2).contact_threads == 2
    assert threads_module.contact_threads(2, threads_module.CONTACT_PARALLEL_MIN_SPHERES - 1) == 1
    assert threads_module.contact_threads(2, threads_module.CONTACT_PARALLEL_MIN_SPHERES) == 2
