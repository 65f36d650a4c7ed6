"""Recordings of more bodies than one channel (MCAP) or one entity (Rerun) per body allows.

MCAP channel ids are 16-bit, so a file holds at most 65,535 channels; rbsim gave every body's particle
cloud a channel, and 65,536 bodies ended in a struct.error and a cut-off file. Rerun's reader refuses
the footer of an .rrd with an entity per body from ~18,700 bodies ("TooManyTables"). Past those limits
the sinks switch layouts (all clouds on one MCAP channel; all bodies in one Rerun entity); these tests
write scenes just past them and read them back with the mcap library, rerun's own reader and the
`rbcli.record.read` functions, and check each layout switch happens where its limit says.
"""

from __future__ import annotations

import io
import subprocess
import sys

import numpy as np
import pytest
from conftest import make_body, make_scene
from mcap.reader import make_reader

from rbcli.record.frame import Checkpoint, FrameBlock, RunHeader, RunSummary
from rbcli.record.mcap_layout import (
    BODY_CHANNELS_MAX,
    TOPIC_BODY_PARTICLES,
    particle_channels_shared,
    particle_topic,
)
from rbcli.record.mcap_sink import SinkMcap
from rbcli.record.mcap_writer import MAX_ID, McapChunkWriter
from rbcli.record.read import read_mcap, read_rrd
from rbcli.record.rerun_sink import BODY_ENTITIES_MAX, SinkRerun, bodies_in_one_entity, body_entity, read_rrd_file

# Rerun stores centres and quaternions as float32: |error| <= 2^-24 |value|, and 1e-7 relative leaves
# room for the xyzw -> wxyz reorder only (as in test_rerun_sink.py). Positions here reach 128 m.
FLOAT32_RTOL = 1e-7
BODIES = 65_536  # more bodies than fit one channel each (2^16)
HANDLE = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]])


@pytest.fixture(scope="module")
def big_run(tmp_path_factory):
    """A 65,536-body scene (4 particles each, spinning, under gravity) run three steps: in memory and to
    .mcap and .rrd. At this size the runner's frame buffers hold one frame (frame_capacity), so every
    recorded frame is its own block."""
    from rbcli.api import prepare, run_to_file, simulate

    cell = np.stack(np.unravel_index(np.arange(BODIES), (256, 256)), axis=1)
    positions = np.column_stack([0.5 * cell, np.zeros(BODIES)])
    bodies = [
        make_body(
            f"g_{i}", particle_position=HANDLE, position=positions[i], angular_momentum=np.array([0.0, 0.01, 0.02])
        )
        for i in range(BODIES)
    ]
    scene = make_scene(bodies, dt=0.01, duration=0.03, integrator="split2", gravity=np.array([0.0, 0.0, -9.81]))
    out = tmp_path_factory.mktemp("many")
    compiled = prepare(scene)
    summaries = {ext: run_to_file(compiled, out / f"run{ext}") for ext in (".mcap", ".rrd")}
    return simulate(scene), out / "run.mcap", out / "run.rrd", summaries


def test_the_scene_is_past_both_limits():
    assert particle_channels_shared(BODIES) and BODIES > BODY_CHANNELS_MAX
    assert particle_channels_shared(BODY_CHANNELS_MAX + 1) and not particle_channels_shared(BODY_CHANNELS_MAX)
    assert bodies_in_one_entity(BODIES)


def test_mcap_of_65536_bodies_reads_back_exactly(big_run):
    """Every recorded state comes back bit for bit (MCAP holds exact float64)."""
    trajectory, mcap_path, _, summaries = big_run
    assert summaries[".mcap"].status == "completed" and summaries[".mcap"].frames == 4
    run = read_mcap(mcap_path)
    assert run.body_names == trajectory.body_names and len(run.body_names) == BODIES
    for name in ("step", "t", "x", "q", "P", "L"):
        assert np.array_equal(getattr(run, name), getattr(trajectory, name)), name
    assert run.summary["status"] == "completed"
    # the clouds are back too, keyed by frame_id: the body frame, about the centre of mass
    centred = HANDLE - (HANDLE * np.array([1.0, 0.5, 0.5, 0.25])[:, None]).sum(axis=0) / 2.25
    assert len(run.particle_offset) == BODIES
    np.testing.assert_allclose(run.particle_offset[-1], centred, rtol=0, atol=1e-15)


def test_mcap_of_65536_bodies_with_the_mcap_library(big_run):
    """Read with the mcap library alone: 16-bit channel ids, one cloud message per body on the shared
    topic, each in its body's frame and ordered by sequence = body index."""
    _, mcap_path, _, _ = big_run
    with open(mcap_path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        topics = {c.id: c.topic for c in summary.channels.values()}
        assert max(topics) <= MAX_ID
        assert sorted(topics.values()) == sorted(
            ["/rbsim/state", "/tf", "/rbsim/invariants", TOPIC_BODY_PARTICLES, "/rbsim/checkpoint"]
        )
        counts = {topics[c]: n for c, n in summary.statistics.channel_message_counts.items()}
        assert counts[TOPIC_BODY_PARTICLES] == BODIES and counts["/rbsim/state"] == 4
        from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

        sequence, frame_ids = [], []
        for _, _, message in reader.iter_messages(topics=[TOPIC_BODY_PARTICLES]):
            cloud = PointCloud.FromString(message.data)
            sequence.append(message.sequence)
            frame_ids.append(cloud.frame_id)
    assert sequence == list(range(BODIES)) and frame_ids == [f"g_{i}" for i in range(BODIES)]
    check = subprocess.run([sys.executable, "-m", "rerun", "mcap", "check", str(mcap_path)], capture_output=True)
    assert check.returncode == 0, check.stdout + check.stderr


def test_rrd_of_65536_bodies_reads_back(big_run):
    """One `bodies` entity, readable by rerun's own reader and `rerun rrd verify`; values to float32."""
    trajectory, _, rrd_path, summaries = big_run
    assert summaries[".rrd"].status == "completed" and summaries[".rrd"].frames == 4
    run = read_rrd(rrd_path)
    assert run.body_names == trajectory.body_names
    assert run.step.tolist() == trajectory.step.tolist()
    np.testing.assert_allclose(run.x, trajectory.x, rtol=FLOAT32_RTOL, atol=0)
    np.testing.assert_allclose(run.q, trajectory.q, rtol=FLOAT32_RTOL, atol=1e-7)
    paths = set(run.entity_paths)
    assert "/bodies" in paths and f"/{body_entity('g_0')}" not in paths
    assert len(run.particle_offset) == BODIES and run.particle_offset[0].shape == (4, 3)
    verify = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(rrd_path)], capture_output=True)
    assert verify.returncode == 0, verify.stdout + verify.stderr


def _header(body_count: int, streams=("bodies", "invariants")) -> RunHeader:
    """A run header with clouds of 1 to 3 particles and no physics behind it; body 0 is one particle at
    its centre of mass (a cloud that spans nothing)."""
    offsets = (np.zeros((1, 3)), *(np.eye(3)[: 1 + i % 3] for i in range(1, body_count)))
    return RunHeader(
        scene_name="many",
        scene_text="name: many\n",
        scene_path=None,
        scene_sha256="0" * 64,
        body_names=tuple(f"b{i}" for i in range(body_count)),
        body_mass=np.ones(body_count),
        body_particle_offset=offsets,
        integrator="split2",
        dt=0.01,
        duration=0.01,
        record_every=1,
        streams=streams,
        rbsim_version="0",
        invariant_names=("energy_total",) if "invariants" in streams else (),
        joint_names=("hinge",) if "joint_forces" in streams else (),
    )


def _write(sink, header: RunHeader, frames: int = 2) -> FrameBlock:
    """Random states for `frames` frames written through `sink`; returns the block."""
    rng = np.random.default_rng(1)
    n = len(header.body_names)
    q = rng.normal(size=(frames, n, 4))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    x = rng.normal(size=(frames, n, 3))
    block = FrameBlock(np.arange(frames), 0.01 * np.arange(frames), x, q, x, x, x, x)
    block.invariants = {name: rng.normal(size=frames) for name in header.invariant_names}
    if "particles" in header.streams:
        block.particle_position = rng.normal(size=(frames, 3, 3))
    if "contacts" in header.streams:
        block.contact_point = [rng.normal(size=(2, 3)) for _ in range(frames)]
        block.contact_force = [rng.uniform(size=2) for _ in range(frames)]
    if header.joint_names:
        block.joint_force = rng.normal(size=(frames, len(header.joint_names), 12))
    sink.open(header)
    sink.write(block)
    if hasattr(sink, "write_checkpoint"):  # as a run's last block has: the checkpoint channel too
        sink.write_checkpoint(Checkpoint(frames - 1, 0.01 * (frames - 1), {"x": x[-1]}))
    sink.close(RunSummary("completed", frames - 1, frames, 0.01 * (frames - 1)))
    return block


def test_mcap_keeps_one_topic_per_body_up_to_the_channel_limit(tmp_path):
    """BODY_CHANNELS_MAX bodies with every fixed channel (particles, contacts and joint_forces streams and
    invariants on) fill the channel ids exactly, so the per-body layout is kept right up to the limit and
    read back."""
    header = _header(BODY_CHANNELS_MAX, streams=("bodies", "invariants", "particles", "contacts", "joint_forces"))
    block = _write(SinkMcap(tmp_path / "edge.mcap"), header)
    run = read_mcap(tmp_path / "edge.mcap")
    assert len(run.message_counts) == MAX_ID  # every id used, none past it
    assert run.message_counts[particle_topic(header.body_names[-1])] == 1
    assert TOPIC_BODY_PARTICLES not in run.message_counts
    assert np.array_equal(run.x, block.x) and np.array_equal(run.q, block.q)
    assert run.joint_names == ("hinge",) and np.array_equal(run.joint_force, block.joint_force)
    np.testing.assert_array_equal(run.particle_offset[-1], header.body_particle_offset[-1])


def test_mcap_writer_refuses_a_channel_id_past_16_bits():
    """Past 65,535 channels the writer says so, instead of a struct.error half-way through a record."""
    writer = McapChunkWriter(io.BytesIO())
    writer.start()
    schema = writer.register_schema("s", "protobuf", b"")
    for i in range(MAX_ID):
        writer.register_channel(f"/c{i}", "protobuf", schema)
    with pytest.raises(ValueError, match="at most 65,535 channels"):
        writer.register_channel("/one-too-many", "protobuf", schema)


def test_rrd_keeps_an_entity_per_body_up_to_its_limit(tmp_path):
    """BODY_ENTITIES_MAX bodies still get the per-body layout, and rerun's reader opens the file (its
    footer stays under the reader's table limit); one more body switches to the one-entity layout."""
    assert not bodies_in_one_entity(BODY_ENTITIES_MAX) and bodies_in_one_entity(BODY_ENTITIES_MAX + 1)
    header = _header(BODY_ENTITIES_MAX)
    block = _write(SinkRerun(tmp_path / "edge.rrd"), header)
    contents = read_rrd_file(tmp_path / "edge.rrd")
    assert contents.bodies is None and len(contents.body_translation) == BODY_ENTITIES_MAX
    for i in (0, BODY_ENTITIES_MAX - 1):
        got = contents.body_translation[f"/{body_entity(header.body_names[i])}"]
        np.testing.assert_allclose(got, block.x[:, i], rtol=FLOAT32_RTOL, atol=0)


@pytest.mark.parametrize("body_count", [BODY_ENTITIES_MAX + 1, 100_000])
def test_one_entity_layout_round_trips(tmp_path, body_count):
    """The one-entity layout from just past its switch to 100,000 bodies: centres and orientations to
    float32, clouds exactly (float64), and `read_rrd(bodies=False)` still gives the invariants."""
    header = _header(body_count)
    block = _write(SinkRerun(tmp_path / "one.rrd"), header, frames=3)
    run = read_rrd(tmp_path / "one.rrd")
    assert run.step.tolist() == [0, 1, 2]
    np.testing.assert_allclose(run.x, block.x, rtol=FLOAT32_RTOL, atol=0)
    np.testing.assert_allclose(run.q, block.q, rtol=FLOAT32_RTOL, atol=1e-7)
    for got, want in zip(run.particle_offset, header.body_particle_offset, strict=True):
        assert np.array_equal(got, want)
    light = read_rrd(tmp_path / "one.rrd", bodies=False)
    assert light.x.shape == (3, 0, 3)
    np.testing.assert_array_equal(light.invariants["energy_total"], block.invariants["energy_total"])


def test_one_entity_boxes_hold_each_cloud(tmp_path):
    """Each body's box half sizes are its cloud's max |offset| per axis (so the box holds the particles);
    a cloud that spans nothing gets a small cube, 0.02 of the largest half size, to stay visible."""
    from rerun.chunk import RrdReader

    header = _header(BODY_ENTITIES_MAX + 1)
    _write(SinkRerun(tmp_path / "boxes.rrd"), header)
    static = [c for c in RrdReader(tmp_path / "boxes.rrd").stream() if c.entity_path == "/bodies" and c.is_static]
    half = np.array(static[-1].to_record_batch().column("Boxes3D:half_sizes")[-1].values.to_pylist())
    want = np.array([np.abs(c).max(axis=0) for c in header.body_particle_offset])
    want[0] = 0.02  # body 0: one particle at its centre; the largest half size is 1
    np.testing.assert_array_equal(half, want.astype(np.float32))


def test_mcap_of_100000_bodies_round_trips(tmp_path):
    header = _header(100_000)
    block = _write(SinkMcap(tmp_path / "big.mcap"), header)
    run = read_mcap(tmp_path / "big.mcap")
    assert np.array_equal(run.x, block.x) and np.array_equal(run.q, block.q)
    assert run.message_counts[TOPIC_BODY_PARTICLES] == 100_000
    np.testing.assert_array_equal(run.particle_offset[99_999], header.body_particle_offset[99_999])
