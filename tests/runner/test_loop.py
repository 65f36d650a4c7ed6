"""The run loop: recording cadence, block boundaries, divergence, interrupts and sink failures."""

import os
import signal

import numpy as np
import pytest
from conftest import make_body, make_scene, random_bodies

import rbcli.runner.loop as loop
import rbcli.runner.simulation as simulation
from rbcli.api import SimulationDiverged, prepare, simulate
from rbcli.record.memory_sink import SinkMemory

G = np.array([0.0, 0.0, -9.81])


def test_records_every_nth_step_and_always_the_final_state():
    traj = simulate(make_scene(random_bodies(2), dt=0.01, duration=0.95, every=10))
    assert traj.step.tolist() == [0, 10, 20, 30, 40, 50, 60, 70, 80, 90, 95]
    np.testing.assert_allclose(traj.t, traj.step * 0.01, rtol=0, atol=0)


def test_block_and_chunk_boundaries_do_not_change_results(monkeypatch):
    scene = make_scene(random_bodies(3), dt=0.01, duration=2.0, every=3, gravity=G)
    reference = simulate(scene)
    monkeypatch.setattr(loop, "MAX_BLOCK_FRAMES", 4)  # many small blocks
    monkeypatch.setattr(loop, "CHUNK_SECONDS", 1e-7)  # tiny chunks
    chopped = simulate(scene)
    for name in ("step", "x", "q", "P", "L", "omega"):
        assert np.array_equal(getattr(reference, name), getattr(chopped, name)), name


def test_divergence_stops_cleanly_with_every_frame_before_it(monkeypatch):
    # gravity of 1e98 m/s^2 pushes |x| past the 1e100 blow-up limit after a few steps
    scene = make_scene([make_body("rock")], dt=1.0, duration=100.0, gravity=np.array([0.0, 0.0, -1e98]))
    with pytest.raises(SimulationDiverged, match="diverged at step") as info:
        simulate(scene)
    partial = info.value.trajectory
    assert partial.status == "diverged"
    assert 1 < len(partial.t) < 101
    assert np.isfinite(partial.x).all() and np.abs(partial.x).max() < 1e100
    again = simulate(scene, on_diverge="return")
    assert again.summary.steps == partial.summary.steps


def test_interrupt_between_chunks_keeps_a_complete_log(monkeypatch):
    monkeypatch.setattr(loop, "CHUNK_SECONDS", 1e-4)
    compiled = prepare(make_scene(random_bodies(2), dt=1e-4, duration=100.0, every=7))
    memory = SinkMemory()
    calls = []

    def progress(done, total):
        calls.append(done)
        if len(calls) == 3:
            os.kill(os.getpid(), signal.SIGINT)  # what Ctrl-C does

    summary = simulation.run(compiled, [memory], progress=progress)
    traj = memory.trajectory()
    assert summary.status == "interrupted"
    assert 0 < summary.steps < compiled.settings.steps
    assert traj.step[-1] == summary.steps  # the state at the interruption is the last frame
    assert np.all(np.diff(traj.step) > 0)


class _FailingSink(SinkMemory):
    def write(self, block):
        raise OSError("disk full")


def test_a_failing_sink_still_closes_the_others():
    good, bad = SinkMemory(), _FailingSink()
    with pytest.raises(OSError, match="disk full"):
        simulation.run(prepare(make_scene(random_bodies(1))), [good, bad])
    assert good.summary is not None and good.summary.status == "error"


def test_invariants_are_the_textbook_formulas():
    """T = |P|^2/2M + L.w/2, V = -M g.x, angular momentum about the origin sum(x x P + L)."""
    traj = simulate(make_scene(random_bodies(3), dt=0.01, duration=0.1, gravity=G))
    compiled = prepare(make_scene(random_bodies(3), gravity=G))
    M = compiled.model.body_mass
    T = (np.sum(traj.P**2, -1) / (2 * M)).sum(-1) + 0.5 * np.einsum("tbi,tbi->t", traj.L, traj.omega)
    V = -(M * (traj.x @ G)).sum(-1)
    np.testing.assert_allclose(traj.invariants["energy_kinetic"], T, rtol=1e-13)
    np.testing.assert_allclose(traj.invariants["energy_potential"], V, rtol=1e-13)
    ang = (np.cross(traj.x, traj.P) + traj.L).sum(1)
    np.testing.assert_allclose(traj.invariants["angular_momentum_z"], ang[:, 2], rtol=1e-13, atol=1e-15)


def test_particles_stream_follows_the_bodies():
    traj = simulate(make_scene(random_bodies(2), duration=0.01, streams=("bodies", "particles")))
    assert traj.particle_position.shape == (len(traj.t), 10, 3)
    assert traj.invariants == {}
    # the mass-weighted mean of each body's particles is its centre of mass
    compiled = prepare(make_scene(random_bodies(2)))
    m = compiled.model.particle_mass
    com = (traj.particle_position[:, :5] * m[:5, None]).sum(1) / m[:5].sum()
    np.testing.assert_allclose(com, traj.x[:, 0], atol=1e-13)


def test_quaternion_norm_defect_is_recorded_and_at_round_off():
    traj = simulate(make_scene(random_bodies(3), dt=0.01, duration=1.0))
    defect = traj.invariants["quaternion_norm_defect"]
    assert defect.shape == traj.t.shape
    assert defect.max() < 1e-15 * 10  # every integrator renormalises q each step


@pytest.mark.parametrize("integrator", ["split2", "dopri5"])
@pytest.mark.parametrize("every", [1, 3])
def test_one_frame_buffers_record_every_frame(monkeypatch, integrator, every):
    """A buffer of one frame (what 40,330+ bodies get from BLOCK_BYTES) must be handed over before each
    chunk: the initial state fills it, so a chunk started on it would write frame 1 past its end."""
    scene = make_scene(random_bodies(2), dt=0.01, duration=0.5, every=every, gravity=G)
    kwargs = {"tolerance": 1e-6} if integrator == "dopri5" else {}
    reference = simulate(scene, integrator=integrator, **kwargs)
    assert loop.frame_capacity(40_329) == 2 and loop.frame_capacity(40_330) == 1  # the reported edge
    monkeypatch.setattr(loop, "frame_capacity", lambda body_count: 1)
    single = simulate(scene, integrator=integrator, **kwargs)
    assert single.step.tolist() == reference.step.tolist()
    for name in ("x", "q", "P", "L"):
        assert np.array_equal(getattr(reference, name), getattr(single, name)), name


def test_a_chunk_given_a_full_buffer_writes_nothing():
    """The kernel's own guard: called with no room left, it reports STATUS_NO_ROOM and leaves memory alone."""
    from rbcli.physics.step import STATUS_NO_ROOM, empty_buffers
    from rbcli.runner.simulation import Simulation

    sim = Simulation(make_scene(random_bodies(2), dt=0.01, duration=1.0, every=1, integrator="split2"))
    frames = empty_buffers(2, sim.model.body_count)
    frames.step[:] = -7  # sentinel: must survive
    assert sim.advance(5, 1, frames, 2) == (1, 2, STATUS_NO_ROOM)
    assert frames.step.tolist() == [-7, -7]
