"""The optional `contacts` record stream (docs/contact.md "Outputs"): the contact points of each recorded
frame and the normal force at each, read back with the mcap library and with rerun's own reader."""

from __future__ import annotations

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_protobuf.decoder import DecoderFactory
from rerun.chunk import RrdReader

import rbcli
from rbcli.scene.load import load_scene_text

# a 0.1 x 0.1 x 0.05 m box lying on the ground (touching at t = 0): its 8 x 8 bottom lattice spheres
SCENE = """name: resting-box
simulation: {{dt: 0.001, steps: 200, record: {{every: 50, streams: {streams}}}}}
gravity: [0, 0, -9.81]
contact: {{ground: 0.0}}
bodies:
  - {{name: box, shape: {{type: box, size: [0.1, 0.1, 0.05]}}, spacing: 0.0125, density: 500, position: [0, 0, 0.025]}}
"""


def mcap_contacts(path) -> tuple[list[int], list[np.ndarray]]:  # noqa: ANN001
    """(log times [ns], per frame (n, 4) x, y, z, normal_force) of /contacts, with the mcap library."""
    times, frames = [], []
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        for _, _, message, cloud in reader.iter_decoded_messages(topics=["/contacts"]):
            assert [field.name for field in cloud.fields] == ["x", "y", "z", "normal_force"]
            assert cloud.frame_id == "world" and cloud.point_stride == 32
            times.append(message.log_time)
            frames.append(np.frombuffer(cloud.data, "<f8").reshape(-1, 4))
    return times, frames


def rrd_contacts(path) -> tuple[list[int], list[np.ndarray]]:  # noqa: ANN001
    """(steps, per frame (n, 4) x, y, z, normal_force) of the `contacts` entity, with rerun's reader."""
    steps, frames = [], []
    for chunk in RrdReader(path).stream().filter(content="/contacts"):
        batch = chunk.to_record_batch()
        steps += batch.column("step").to_pylist()
        for points, force in zip(batch.column("Points3D:positions").to_pylist(),
                                 batch.column("normal_force").to_pylist(), strict=True):  # fmt: skip
            frames.append(np.column_stack([np.asarray(points, dtype=float).reshape(-1, 3), force]))
    return steps, frames


@pytest.mark.parametrize("suffix", [".mcap", ".rrd"])
def test_contact_points_of_a_box_resting_on_the_ground(tmp_path, suffix):
    """One point per contact (the count invariant's), on z = 0 within the overlap (halfway through it),
    under the box, and the normal forces carry its weight."""
    compiled = rbcli.prepare(load_scene_text(SCENE.format(streams="[bodies, invariants, contacts]")))
    path = tmp_path / f"box{suffix}"
    rbcli.run_to_file(compiled, path)
    run = rbcli.read_recording(path)
    index, frames = mcap_contacts(path) if suffix == ".mcap" else rrd_contacts(path)
    assert index == ([int(round(t * 1e9)) for t in run.t] if suffix == ".mcap" else run.step.tolist())
    weight = float(compiled.model.body_mass[0]) * 9.81
    for k in range(1, len(frames)):  # frame 0's invariants precede the first force evaluation
        points, force = frames[k][:, :3], frames[k][:, 3]
        depth = run.invariants["contact_max_overlap"][k]
        assert len(points) == run.invariants["contact_count"][k] == 64
        assert 0 < depth < 0.01 * 0.00625
        # halfway through the overlap of the recorded state (the invariant's evaluation is mid-step: the
        # box still settles by ~1e-12 m)
        np.testing.assert_allclose(points[:, 2], -depth / 2, atol=1e-3 * depth)
        assert np.abs(points[:, :2]).max() < 0.05  # under the box
        assert force.min() > 0 and force.sum() == pytest.approx(weight, rel=1e-5)


def test_no_contacts_stream_no_contact_points(tmp_path):
    """A scene that does not ask for the stream gets no /contacts channel (and computes no points)."""
    compiled = rbcli.prepare(load_scene_text(SCENE.format(streams="[bodies, invariants]")))
    rbcli.run_to_file(compiled, tmp_path / "box.mcap")
    assert mcap_contacts(tmp_path / "box.mcap") == ([], [])
