"""The `joint_forces` stream (issue 27 item 2): each joint's reaction force and torque per recorded frame,
in MCAP (exact float64, read back with the mcap library), in memory (rbcli.simulate) and in Rerun.

The checks are physical, not the code's own numbers: with every step recorded, a pendulum bob's momentum
changes over each step by exactly (gravity + the recorded joint force) dt, and its angular momentum about
its centre of mass by the recorded torque dt (the only other force, gravity, has no torque there). The
stream must also equal Simulation.joint_reactions at the same steps, hold NaN where no step led to a frame
(a run's first), continue bit for bit through a resumed run, and warn in a scene without joints.
"""

from __future__ import annotations

import os
import signal
from pathlib import Path

import numpy as np
import pytest

import rbcli
import rbcli.runner.loop as loop
from rbcli.record.mcap_layout import TOPIC_JOINT_FORCES
from rbcli.record.mcap_sink import SinkMcap
from rbcli.record.read import read_mcap, read_trajectory
from rbcli.runner.resume import plan_resume, resume_run
from rbcli.runner.simulation import Simulation
from rbcli.scene.load import check_scene

ROOT = Path(__file__).resolve().parents[2]
SCHEMAS = ROOT / "schemas"


def pendulum_scene(tmp_path: Path, every: int = 1, duration: float = 0.2) -> Path:
    """scenes/joints/pendulum.yaml with the joint_forces stream (rod on a hinge to the world)."""
    text = (ROOT / "scenes" / "joints" / "pendulum.yaml").read_text()
    old = "record: {every: 10}}"
    assert old in text
    text = text.replace(old, f"record: {{every: {every}, streams: [bodies, invariants, joint_forces]}}}}")
    text = text.replace("duration: 5.0", f"duration: {duration}, integrator: split2")  # the maximal joints' impulses
    path = tmp_path / "pendulum.yaml"
    path.write_text(text)
    return path


def test_every_step_the_momentum_changes_by_gravity_and_the_recorded_joint_force(tmp_path):
    scene = pendulum_scene(tmp_path)
    out = tmp_path / "p.mcap"
    summary = rbcli.run_to_file(rbcli.prepare(scene), out)
    assert summary.status == "completed"
    run = read_mcap(out)
    assert run.joint_names == ("pivot",) and run.message_counts[TOPIC_JOINT_FORCES] == run.frames == 201
    force = run.joint_force
    assert force.shape == (201, 1, 12)
    assert np.isnan(force[0]).all()  # no step led to the first frame
    assert np.isfinite(force[1:]).all() and not force[1:, 0, 6:].any()  # the world's side is zero
    dt, mass = 1e-3, 1.0
    gravity = np.array([0.0, 0.0, -9.81])
    dP = np.diff(run.P[:, 0], axis=0) / dt  # (T-1, 3) [N]
    expected = mass * gravity + force[1:, 0, 0:3]
    assert np.max(np.abs(dP - expected)) < 1e-9 * np.max(np.abs(expected))
    dL = np.diff(run.L[:, 0], axis=0) / dt  # about the centre of mass: gravity has no torque there
    torque = force[1:, 0, 3:6]
    assert np.max(np.abs(dL - torque)) < 1e-9 * np.max(np.abs(torque))
    # the rod's tension is the pendulum's: m (g cos theta + v^2 / d) at the centre of mass, 0.6 m out,
    # within the step's mean against the end state (O(dt))
    arm = run.x[1:, 0] - np.array([0.0, 0.0, 1.0])
    d = np.linalg.norm(arm, axis=1)
    along = -np.einsum("ki,ki->k", force[1:, 0, 0:3], arm / d[:, None])
    speed2 = np.sum(run.v[1:, 0] ** 2, axis=1)
    cos_theta = -arm[:, 2] / d
    tension = mass * (9.81 * cos_theta + speed2 / d)
    assert np.max(np.abs(along - tension)) < 2e-2 * np.max(tension)


def test_the_stream_is_simulation_joint_reactions_in_memory_and_on_disk(tmp_path):
    scene = pendulum_scene(tmp_path, every=25, duration=0.2)
    trajectory = rbcli.simulate(scene)
    rbcli.run_to_file(rbcli.prepare(scene), tmp_path / "p.mcap")
    on_disk = read_trajectory(tmp_path / "p.mcap")
    sim = Simulation(scene)
    expected = []
    for _ in range(8):
        sim.step(25)
        expected.append(sim.joint_reactions["pivot"])
    for recorded in (trajectory, on_disk):
        assert recorded.step.tolist() == [0, 25, 50, 75, 100, 125, 150, 175, 200]
        assert np.isnan(recorded.joint_reactions["pivot"][0]).all()
        assert np.array_equal(recorded.joint_reactions["pivot"][1:], np.array(expected))
    npz = tmp_path / "p.npz"
    trajectory.to_npz(npz)
    again = rbcli.Trajectory.from_npz(npz)
    assert again.joint_names == ("pivot",) and np.array_equal(again.joint_force, trajectory.joint_force, equal_nan=True)


def test_the_rerun_file_plots_each_joints_force_and_torque(tmp_path):
    from rbcli.record.rerun_sink import read_rrd_file

    scene = pendulum_scene(tmp_path, every=10)
    rbcli.run_to_file(rbcli.prepare(scene), tmp_path / "p.rrd")
    contents = read_rrd_file(tmp_path / "p.rrd", bodies=False)
    assert {"/joint_forces/pivot/force", "/joint_forces/pivot/torque"} <= set(contents.entity_paths)


def test_a_resumed_run_records_the_joint_forces_of_the_run_never_stopped(tmp_path, monkeypatch):
    monkeypatch.setattr(loop, "CHUNK_SECONDS", 0.002)  # many chunks, so the stop falls mid-run
    scene = pendulum_scene(tmp_path, every=7, duration=0.6)
    Simulation(scene).run(sinks=[SinkMcap(tmp_path / "whole.mcap")])
    calls = []

    def progress(done: int, total: int) -> None:
        calls.append(done)
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGINT)

    summary = Simulation(scene).run(sinks=[SinkMcap(tmp_path / "cut.mcap")], progress=progress)
    assert summary.status == "interrupted"
    plan = plan_resume(tmp_path / "cut.mcap")
    assert 0 < plan.checkpoint.step < plan.total_steps
    resume_run(plan, [SinkMcap(tmp_path / "resumed.mcap")])
    a, b = read_mcap(tmp_path / "resumed.mcap"), read_mcap(tmp_path / "whole.mcap")
    assert a.step.tolist() == b.step.tolist()
    assert a.joint_force.tobytes() == b.joint_force.tobytes()


def test_a_stream_without_its_section_warns(tmp_path):
    for stream, what in (("joint_forces", "joints"), ("contacts", "contact")):
        path = tmp_path / f"{stream}.yaml"
        path.write_text(
            "name: lone\n"
            f"simulation: {{dt: 0.01, duration: 0.1, record: {{streams: [bodies, {stream}]}}}}\n"
            "bodies:\n  - {name: b, particles: {positions: [[0, 0, 0], [1, 0, 0], [0, 1, 0]], masses: 1}}\n"
        )
        issues = check_scene(path)
        assert [i.severity for i in issues] == ["warning"], issues
        assert f"`{what}:`" in issues[0].message and issues[0].location.line == 2


def test_joint_forces_proto_text_matches_the_runtime_descriptor():
    from rbcli.record import mcap_messages

    text = (SCHEMAS / "rbsim_joint_forces.proto").read_text()
    assert "package rbsim;" in text and 'syntax = "proto3";' in text
    assert "repeated double reaction = 3;" in text and "uint64 step = 1;" in text and "double time = 2;" in text
    fields = [(f.name, f.number, f.label == 3) for f in mcap_messages.joint_forces_file_proto().message_type[0].field]
    assert fields == [("step", 1, False), ("time", 2, False), ("reaction", 3, True)]


@pytest.mark.parametrize("every", [1, 3])
def test_recorded_frames_decode_with_the_files_own_schema(tmp_path, every):
    """The hand-written wire format decodes with the generated class of the embedded schema."""
    from mcap.reader import make_reader
    from mcap_protobuf.decoder import DecoderFactory

    scene = pendulum_scene(tmp_path, every=every, duration=0.03)
    out = tmp_path / "p.mcap"
    rbcli.run_to_file(rbcli.prepare(scene), out)
    run = read_mcap(out)
    with open(out, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        messages = [m for _, _, _, m in reader.iter_decoded_messages(topics=[TOPIC_JOINT_FORCES])]
    assert [m.step for m in messages] == run.step.tolist()
    decoded = np.array([list(m.reaction) for m in messages]).reshape(run.joint_force.shape)
    assert np.array_equal(decoded, run.joint_force, equal_nan=True)


def test_a_checkpoint_without_the_joint_impulses_still_restores(tmp_path):
    """Logs written before checkpoints carried the joints' last impulses still resume: the reactions of
    the first resumed frame are then unknown (NaN), and every later step is the same."""
    from rbcli.physics.data import JOINT_REACTIONS

    scene = pendulum_scene(tmp_path, every=5, duration=0.05)
    sim = Simulation(scene)
    sim.step(20)
    checkpoint = sim.checkpoint()
    assert JOINT_REACTIONS in checkpoint.arrays and checkpoint.arrays[JOINT_REACTIONS].any()
    old = rbcli.Simulation(scene)
    old.restore(
        type(checkpoint)(
            checkpoint.step, checkpoint.t, {k: v for k, v in checkpoint.arrays.items() if k != JOINT_REACTIONS}
        )
    )
    assert not old.reactions_known and not old.joint_reactions["pivot"].any()
    new = rbcli.Simulation(scene)
    new.restore(checkpoint)
    assert new.reactions_known and np.array_equal(new.joint_reactions["pivot"], sim.joint_reactions["pivot"])
    for s in (sim, old, new):
        s.step(10)
    assert np.array_equal(old.state.x, sim.state.x) and np.array_equal(
        new.joint_reactions["pivot"], sim.joint_reactions["pivot"]
    )
