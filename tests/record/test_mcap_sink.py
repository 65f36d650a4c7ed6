"""SinkMcap: what goes in comes back out, read with the mcap, protobuf and foxglove libraries themselves."""

from __future__ import annotations

import hashlib
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from record_synthetic import (  # noqa: F401 - pytest fixtures
    BODY_NAMES,
    INVARIANT_NAMES,
    SCENE_TEXT,
    concat,
    make_blocks,
    make_header,
    mcap_path_fixture,
    synthetic_fixture,
    write_run,
)

from rbcli.record import mcap_encoders, mcap_layout, mcap_messages
from rbcli.record.frame import FrameBlock
from rbcli.record.mcap_sink import SinkMcap
from rbcli.record.read import read_mcap

SCHEMAS = Path(__file__).resolve().parents[2] / "schemas"


def _raw_messages(path: Path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        return [(channel.topic, message) for _, channel, message in reader.iter_messages(log_time_order=False)]


def test_state_round_trips_exactly(mcap_path, synthetic):
    """/rbsim/state decoded with the file's own schema equals the float64 input bit for bit (NaN included)."""
    _, blocks = synthetic
    run = read_mcap(mcap_path)
    assert run.body_names == BODY_NAMES
    for attr in ("step", "t", "x", "q", "v", "omega", "P", "L"):
        np.testing.assert_array_equal(getattr(run, attr), concat(blocks, attr), err_msg=attr)
    for name in INVARIANT_NAMES:
        np.testing.assert_array_equal(run.invariants[name], np.concatenate([b.invariants[name] for b in blocks]))


def test_rerun_mcap_check_finds_no_issue(mcap_path):
    """An independent structural check: `rerun mcap check` (chunk indexes, summary, time ranges)."""
    out = subprocess.run(
        [sys.executable, "-m", "rerun", "mcap", "check", str(mcap_path)], capture_output=True, text=True
    )
    assert out.returncode == 0, out.stdout + out.stderr
    assert "ok" in out.stdout and "/tf" in out.stdout


def test_message_counts_per_channel(mcap_path, synthetic):
    frames = sum(len(b) for b in synthetic[1])
    counts = read_mcap(mcap_path).message_counts
    expected = {"/rbsim/state": frames, "/tf": frames, "/rbsim/invariants": frames}
    expected |= {f"/bodies/{name}/particles": 1 for name in BODY_NAMES}
    assert counts == expected


def test_metadata_attachment_and_summary(mcap_path, synthetic):
    header, _ = synthetic
    run = read_mcap(mcap_path)
    assert run.scene_text == SCENE_TEXT  # the attachment, byte for byte
    meta = run.metadata
    assert float(meta["dt"]) == header.dt and float(meta["duration"]) == header.duration
    assert meta["integrator"] == "euler-matrix" and meta["scene_sha256"] == header.scene_sha256
    assert meta["quaternion_order"] == "wxyz" and meta["units"].startswith("SI")
    assert meta["record_every"] == "1" and meta["seed"] == "7" and meta["rbsim_version"] == "0.1.0"
    assert run.summary["status"] == "diverged" and run.summary["frames"] == str(run.frames)
    assert "non-finite" in run.summary["message"]


def test_time_stamps_are_simulated_time(mcap_path, synthetic):
    """log_time = publish_time = round(t * 1e9) for every message; t = 0 for the particle clouds."""
    t_ns = {int(s): round(float(t) * 1e9) for b in synthetic[1] for s, t in zip(b.step, b.t, strict=True)}
    for topic, message in _raw_messages(mcap_path):
        assert message.publish_time == message.log_time
        if topic.endswith("/particles"):
            assert message.log_time == 0
        else:
            assert message.log_time == t_ns[message.sequence], topic


def test_identical_runs_give_identical_bytes(tmp_path, synthetic):
    """No wall clock anywhere: two writes of the same run hash the same."""
    digests = []
    for i in range(2):
        path = tmp_path / f"run{i}.mcap"
        write_run(SinkMcap(path), *synthetic)
        digests.append(hashlib.sha256(path.read_bytes()).hexdigest())
    assert digests[0] == digests[1]


def test_state_encoder_matches_the_protobuf_serializer(synthetic):
    """The numpy wire encoder gives exactly SerializeToString of the runtime class (canonical form)."""
    _, blocks = synthetic
    state_class = mcap_messages.message_class(mcap_messages.state_file_proto())
    encoded = mcap_encoders.StateEncoder(len(BODY_NAMES)).encode(blocks[0])
    for k, data in enumerate(encoded):
        arrays = {name: getattr(blocks[0], attr)[k].ravel() for attr, name, _, _ in mcap_layout.STATE_FIELDS}
        msg = state_class(step=int(blocks[0].step[k]), time=float(blocks[0].t[k]), **arrays)
        assert data == msg.SerializeToString(), k


def test_transforms_decode_with_foxglove_classes(mcap_path, synthetic):
    """Each /tf message: one transform per body, world -> body, exact translation, rotation as xyzw."""
    from foxglove_schemas_protobuf.FrameTransforms_pb2 import FrameTransforms

    x, q = concat(synthetic[1], "x"), concat(synthetic[1], "q")
    messages = [m for topic, m in _raw_messages(mcap_path) if topic == "/tf"]
    assert len(messages) == len(x)
    for k, message in enumerate(messages):
        tf = FrameTransforms.FromString(message.data)
        assert sorted(t.child_frame_id for t in tf.transforms) == sorted(BODY_NAMES)
        for tr in tf.transforms:
            i = BODY_NAMES.index(tr.child_frame_id)
            assert tr.parent_frame_id == "world"
            assert tr.timestamp.ToNanoseconds() == message.log_time
            np.testing.assert_array_equal([tr.translation.x, tr.translation.y, tr.translation.z], x[k, i])
            np.testing.assert_array_equal(
                [tr.rotation.x, tr.rotation.y, tr.rotation.z, tr.rotation.w], q[k, i, [1, 2, 3, 0]]
            )


def test_point_clouds_hold_the_particle_offsets(mcap_path, synthetic):
    header, _ = synthetic
    run = read_mcap(mcap_path)
    for got, want in zip(run.particle_offset, header.body_particle_offset, strict=True):
        np.testing.assert_array_equal(got, want)  # float64 points: exact


def test_the_rerun_mcap_decoder_sees_frames_and_clouds(mcap_path):
    """Rerun's own MCAP reader (what its viewer uses) turns /tf into transforms between named frames
    and places each cloud in its body's frame, so the clouds follow the bodies there too."""
    from rerun.chunk import McapReader

    child_frames, cloud_frames = set(), {}
    for chunk in McapReader(mcap_path, timeline_type="duration_ns").stream():
        if chunk.is_static:
            continue
        batch = chunk.to_record_batch()
        if chunk.entity_path == "/tf":
            child_frames |= {row[0] for row in batch.column("Transform3D:child_frame").to_pylist()}
            assert {row[0] for row in batch.column("Transform3D:parent_frame").to_pylist()} == {"world"}
        if chunk.entity_path.endswith("/particles"):
            cloud_frames[chunk.entity_path] = batch.column("CoordinateFrame:frame").to_pylist()[0][0]
    assert child_frames == set(BODY_NAMES)
    assert sorted(cloud_frames.values()) == sorted(BODY_NAMES)


def _proto_fields(text: str) -> dict[str, list[tuple[str, str, int, bool]]]:
    """{message: [(type, name, number, repeated)]} from .proto text (the subset the project uses)."""
    messages = {}
    for name, body in re.findall(r"message\s+(\w+)\s*\{(.*?)\n\}", text, flags=re.S):
        body = re.sub(r"//[^\n]*", "", body)
        fields = re.findall(r"(repeated\s+)?(\w+)\s+(\w+)\s*=\s*(\d+)\s*;", body)
        messages[name] = [(ftype, fname, int(num), bool(rep)) for rep, ftype, fname, num in fields]
    return messages


def _descriptor_fields(fdp) -> list[tuple[str, str, int, bool]]:
    names = {1: "double", 4: "uint64", 9: "string", 12: "bytes"}  # FieldDescriptorProto.Type numbers
    return [(names[f.type], f.name, f.number, f.label == 3) for f in fdp.message_type[0].field]


def test_state_proto_text_matches_the_runtime_descriptor():
    text = (SCHEMAS / "rbsim_state.proto").read_text()
    assert "package rbsim;" in text and 'syntax = "proto3";' in text
    assert _proto_fields(text) == {"State": _descriptor_fields(mcap_messages.state_file_proto())}


def test_checkpoint_proto_text_matches_the_runtime_descriptor():
    text = (SCHEMAS / "rbsim_checkpoint.proto").read_text()
    assert _proto_fields(text) == {"Checkpoint": _descriptor_fields(mcap_messages.checkpoint_file_proto())}


def test_invariants_proto_text_matches_the_runtime_descriptor():
    """Fields 1-2 as in the text; then one double per invariant, numbered from 3 in header order."""
    text = (SCHEMAS / "rbsim_invariants.proto").read_text()
    fixed = _proto_fields(text)["Invariants"]
    generated = _descriptor_fields(mcap_messages.invariants_file_proto(INVARIANT_NAMES))
    assert generated[:2] == fixed
    assert generated[2:] == [("double", n, 3 + i, False) for i, n in enumerate(INVARIANT_NAMES)]


def test_invariant_field_names_are_valid_and_distinct():
    assert mcap_messages.invariant_field_names(["|L|", "2nd", "energy"]) == ("_L_", "f_2nd", "energy")
    with pytest.raises(ValueError, match="twice"):
        mcap_messages.invariant_field_names(["a-b", "a_b"])
    with pytest.raises(ValueError):
        mcap_messages.invariant_field_names(["time"])


def test_interrupted_before_any_frame_still_gives_a_readable_file(tmp_path):
    header = make_header()
    path = tmp_path / "empty.mcap"
    write_run(SinkMcap(path), header, [], status="interrupted")
    run = read_mcap(path)
    assert run.frames == 0 and run.summary["status"] == "interrupted"
    assert run.message_counts.get("/rbsim/state", 0) == 0


def test_no_invariants_means_no_invariant_channel(tmp_path):
    header = make_header(invariant_names=())
    path = tmp_path / "plain.mcap"
    write_run(SinkMcap(path), header, make_blocks(header, sizes=(3,), diverge=False), status="completed")
    run = read_mcap(path)
    assert "/rbsim/invariants" not in run.message_counts and run.invariants == {}
    assert run.frames == 3


def test_close_is_idempotent_and_write_after_close_fails(tmp_path, synthetic):
    header, blocks = synthetic
    sink = SinkMcap(tmp_path / "twice.mcap")
    summary = write_run(sink, header, blocks[:1])
    sink.close(summary)
    with pytest.raises(RuntimeError):
        sink.write(blocks[1])
    assert read_mcap(tmp_path / "twice.mcap").frames == len(blocks[0])


def test_particles_stream_is_a_world_point_cloud_per_frame(tmp_path):
    """With the particles stream on, /particles holds every particle's world position per frame, exactly."""
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

    header = make_header()
    blocks = make_blocks(header, sizes=(2, 3), diverge=False)
    for b in blocks:
        b.particle_position = np.random.default_rng(3).normal(size=(len(b), 11, 3))
    path = tmp_path / "particles.mcap"
    write_run(SinkMcap(path), header, blocks, status="completed")
    clouds = [PointCloud.FromString(m.data) for topic, m in _raw_messages(path) if topic == "/particles"]
    assert len(clouds) == 5 and {c.frame_id for c in clouds} == {"world"}
    got = np.stack([mcap_messages.cloud_points(c) for c in clouds])
    np.testing.assert_array_equal(got, concat(blocks, "particle_position"))


# edge values of the vectorised varint and head encoders, against the protobuf classes themselves
EDGE_STEPS = [0, 1, 127, 128, 300, 16383, 16384, 2**21 - 1, 2**21, 2**28, 2**35 + 5, 2**56, 2**63 - 1]
EDGE_TIMES = [0.0, -0.0, 5e-324, 1e-9, 0.3, 2.5, -7.0, 1e300, math.inf, math.nan]


def test_vectorised_varints_equal_the_scalar_encoder():
    digits, lengths = mcap_encoders._varints(np.array(EDGE_STEPS, dtype=np.uint64))
    for value, row, length in zip(EDGE_STEPS, digits, lengths, strict=True):
        assert row[:length].tobytes() == mcap_encoders._varint(value), value


def test_invariants_encoder_decodes_to_the_values_including_zeros_and_non_finite():
    names = ("energy_total", "momentum_x", "quaternion_norm_defect")
    cls = mcap_messages.message_class(mcap_messages.invariants_file_proto(names))
    k = len(EDGE_TIMES)
    steps = np.array(EDGE_STEPS[:k], dtype=np.int64)
    values = {n: np.roll(np.array(EDGE_TIMES), i) for i, n in enumerate(names)}
    block = FrameBlock(step=steps, t=np.array(EDGE_TIMES), x=np.zeros((k, 0, 3)), q=np.zeros((k, 0, 4)),
                       v=np.zeros((k, 0, 3)), omega=np.zeros((k, 0, 3)), P=np.zeros((k, 0, 3)),
                       L=np.zeros((k, 0, 3)), invariants=values)  # fmt: skip
    for i, data in enumerate(mcap_encoders.InvariantsEncoder(names).encode(block)):
        msg = cls.FromString(data)
        assert msg.step == steps[i]
        got = [msg.time] + [getattr(msg, f) for f in mcap_messages.invariant_field_names(names)]
        want = [EDGE_TIMES[i]] + [values[n][i] for n in names]
        assert np.array_equal(np.array(got), np.array(want), equal_nan=True), i
        assert [math.copysign(1, g) for g in got] == [math.copysign(1, w) for w in want], i  # -0.0 kept
        # the step/time head is canonical: the same bytes as the class serialises for those two fields
        head = cls(step=int(steps[i]), time=EDGE_TIMES[i]).SerializeToString()
        assert data.startswith(head) and len(data) == len(head) + 9 * len(names), i


def test_timestamp_payloads_equal_protobuf_timestamps():
    from google.protobuf.timestamp_pb2 import Timestamp

    ns = np.array([0, 1, 999_999_999, 1_000_000_000, 1_000_000_001, 59 * 10**9 + 7, 2**40, 10**18 + 3])
    for value, data in zip(ns.tolist(), mcap_encoders._timestamp_payloads(ns), strict=True):
        seconds, nanos = divmod(value, 10**9)
        assert data == Timestamp(seconds=seconds, nanos=nanos).SerializeToString(), value


def rerun_binary() -> str | None:
    """The `rerun` CLI that ships with rerun-sdk: next to this interpreter, else on PATH."""
    import shutil

    beside = Path(sys.executable).parent / "rerun"
    return str(beside) if beside.is_file() else shutil.which("rerun")


def test_rerun_loads_the_mcap_into_a_recording_that_verifies(tmp_path):
    """`rerun x.mcap --save y.rrd` (Rerun's own MCAP loader, what `rerun x.mcap` and `rbsim replay x.mcap`
    use) then `rerun rrd verify y.rrd`: every foxglove message rbsim writes (the clouds' poses included)
    must become a recording Rerun itself accepts. Before the pose was written out in full, verify failed
    on `InstancePoses3D:translations` (a null translation)."""
    import os

    binary = rerun_binary()
    if binary is None:
        assert not os.environ.get("CI"), "the rerun binary must exist in CI"
        pytest.skip("no rerun binary next to the interpreter or on PATH")
    header = make_header()
    blocks = make_blocks(header, sizes=(3, 4), diverge=False)
    for b in blocks:
        b.particle_position = np.random.default_rng(5).normal(size=(len(b), 9, 3))
    mcap = tmp_path / "x.mcap"
    write_run(SinkMcap(mcap), header, blocks, status="completed")
    rrd = tmp_path / "y.rrd"
    load = subprocess.run([binary, str(mcap), "--save", str(rrd)], capture_output=True, text=True, timeout=120)
    assert load.returncode == 0 and rrd.is_file(), load.stdout + load.stderr
    verify = subprocess.run([binary, "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120)
    assert verify.returncode == 0, verify.stdout + verify.stderr


def test_cloud_poses_are_written_in_full(mcap_path):
    """Each cloud's pose carries its position (present, zero) and orientation (identity) on the wire, as
    Foxglove's schema gives them; a reader that treats an absent position as null still gets (0, 0, 0)."""
    from foxglove_schemas_protobuf.PointCloud_pb2 import PointCloud

    clouds = [PointCloud.FromString(m.data) for topic, m in _raw_messages(mcap_path) if topic.endswith("/particles")]
    assert len(clouds) == len(BODY_NAMES)
    for cloud in clouds:
        assert cloud.HasField("pose") and cloud.pose.HasField("position") and cloud.pose.HasField("orientation")
        position, rotation = cloud.pose.position, cloud.pose.orientation
        assert (position.x, position.y, position.z) == (0.0, 0.0, 0.0)
        assert (rotation.w, rotation.x, rotation.y, rotation.z) == (1.0, 0.0, 0.0, 0.0)
