"""SinkRerun: the .rrd read back with rerun's own chunk reader, and checked by `rerun rrd verify`."""

from __future__ import annotations

import subprocess
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
    rrd_path_fixture,
    synthetic_fixture,
    write_run,
)

from rbcli.record.read import read_rrd
from rbcli.record.rerun_sink import (
    SinkRerun,
    body_entity,
    particle_display_radii,
    particle_display_radius,
    read_rrd_file,
    verify_rrd_command,
)

# Rerun stores translations and quaternions as float32: a round trip is exact to half an ulp,
# |error| <= 2^-24 |value| (relative 6e-8); 1e-7 leaves room for the quaternion reorder only.
FLOAT32_RTOL = 1e-7


def _verify(path) -> subprocess.CompletedProcess:
    return subprocess.run(verify_rrd_command(path), capture_output=True, text=True, timeout=60)


def test_rrd_verifies(rrd_path):
    out = _verify(rrd_path)
    assert out.returncode == 0, out.stderr


def test_entity_paths(rrd_path):
    paths = set(read_rrd_file(rrd_path).entity_paths)
    for name in BODY_NAMES:
        assert {f"/{body_entity(name)}", f"/{body_entity(name)}/particles"} <= paths
    assert {f"/invariants/{n}" for n in INVARIANT_NAMES} <= paths
    assert {"/scene", "/run", "/summary", "/trajectories"} <= paths


def test_one_transform_per_recorded_step_and_body(rrd_path, synthetic):
    """Rows: exactly the recorded steps, on both timelines; values equal to float32 rounding."""
    _, blocks = synthetic
    contents = read_rrd_file(rrd_path)
    step, t = concat(blocks, "step"), concat(blocks, "t")
    x, q = concat(blocks, "x"), concat(blocks, "q")
    for i, name in enumerate(BODY_NAMES):
        entity = f"/{body_entity(name)}"
        np.testing.assert_array_equal(contents.body_step[entity], step)
        np.testing.assert_allclose(contents.body_time[entity], t, rtol=0, atol=1e-9)  # integer ns
        np.testing.assert_allclose(contents.body_translation[entity], x[:, i], rtol=FLOAT32_RTOL, atol=0)
        np.testing.assert_allclose(contents.body_quaternion[entity], q[:, i], rtol=FLOAT32_RTOL, atol=0)


def test_read_rrd_stacks_bodies_in_header_order(rrd_path, synthetic):
    header, blocks = synthetic
    run = read_rrd(rrd_path)
    assert run.format == "rrd" and run.body_names == BODY_NAMES
    assert run.x.shape == concat(blocks, "x").shape and run.q.shape == concat(blocks, "q").shape
    np.testing.assert_allclose(run.x, concat(blocks, "x"), rtol=FLOAT32_RTOL, atol=0)
    assert run.v is None  # an .rrd holds transforms only
    for got, want in zip(run.particle_offset, header.body_particle_offset, strict=True):
        np.testing.assert_allclose(got, want, rtol=FLOAT32_RTOL, atol=1e-7 * np.abs(want).max())


def test_invariants_are_float64_series(rrd_path, synthetic):
    _, blocks = synthetic
    contents = read_rrd_file(rrd_path)
    for name in INVARIANT_NAMES:
        np.testing.assert_array_equal(contents.invariants[name], np.concatenate([b.invariants[name] for b in blocks]))
        np.testing.assert_allclose(contents.invariant_time[name], concat(blocks, "t"), rtol=0, atol=1e-9)


def test_properties_scene_and_summary(rrd_path, synthetic):
    header, _ = synthetic
    run = read_rrd(rrd_path)
    assert run.scene_text == SCENE_TEXT
    assert float(run.metadata["dt"]) == header.dt and run.metadata["integrator"] == header.integrator
    assert run.summary["status"] == "diverged" and int(run.summary["frames_written"]) == run.frames


def test_file_has_a_default_blueprint(rrd_path):
    from rerun.chunk import RrdReader

    assert RrdReader(rrd_path).blueprints(), "no blueprint store in the file"


def test_frames_stream_out_before_close(tmp_path, synthetic):
    """Blocks are sent once `flush_frames` have gathered, not held until close."""
    header, blocks = synthetic
    sink = SinkRerun(tmp_path / "stream.rrd", flush_frames=len(blocks[0]))
    sink.open(header)
    sink.write(blocks[0])
    assert sink.frames_written == len(blocks[0])
    sink.write(blocks[1])
    sink.close(_summary(blocks[:2]))
    assert read_rrd(tmp_path / "stream.rrd").frames == len(blocks[0]) + len(blocks[1])


def _summary(blocks):
    from rbcli.record.frame import RunSummary

    frames = sum(len(b) for b in blocks)
    return RunSummary("interrupted", int(blocks[-1].step[-1]), frames, float(blocks[-1].t[-1]), "Ctrl-C")


def test_interrupted_before_any_frame_still_verifies(tmp_path):
    path = tmp_path / "empty.rrd"
    write_run(SinkRerun(path), make_header(), [], status="interrupted")
    assert _verify(path).returncode == 0
    assert read_rrd(path).summary["status"] == "interrupted"


def test_trajectory_points_stay_bounded(tmp_path):
    """Paths are thinned by 2 when over budget, so memory stays flat however long the run."""
    header = make_header()
    sink = SinkRerun(tmp_path / "paths.rrd", trajectory_points=8)
    sink.open(header)
    for block in make_blocks(header, sizes=(5, 5, 5, 5), diverge=False):
        sink.write(block)
        assert sum(len(p) for p in sink._path_points) <= 8
    sink.close(_summary(make_blocks(header, sizes=(20,), diverge=False)))


def test_particle_display_radius_is_half_the_spacing():
    h = 0.25
    grid = h * np.stack(np.meshgrid(*[np.arange(3)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    assert particle_display_radius(grid, fallback=1.0) == pytest.approx(h / 2)
    assert particle_display_radius(grid[:1], fallback=0.3) == 0.3


def test_particles_stream_is_one_entity_per_frame(tmp_path):
    from rerun.chunk import RrdReader

    header = make_header()
    blocks = make_blocks(header, sizes=(2, 3), diverge=False)
    for b in blocks:
        b.particle_position = np.random.default_rng(3).normal(size=(len(b), 11, 3))
    path = tmp_path / "particles.rrd"
    write_run(SinkRerun(path), header, blocks, status="completed")
    rows = sum(c.num_rows for c in RrdReader(path).stream() if c.entity_path == "/particles" and not c.is_static)
    assert rows == 5


@pytest.mark.filterwarnings("error")
def test_values_beyond_float32_are_written_quietly(tmp_path):
    """A diverging run (x = 1e300, NaN) still gives a valid file, and no overflow warning to the user."""
    header = make_header()
    blocks = make_blocks(header, sizes=(3,), diverge=True)
    blocks[-1].x[-1, 1] = 1e300
    path = tmp_path / "huge.rrd"
    write_run(SinkRerun(path), header, blocks)
    assert _verify(path).returncode == 0
    assert np.isinf(read_rrd(path).x[-1, 1]).all()


def test_batched_display_radii_equal_the_one_cloud_estimate():
    rng = np.random.default_rng(5)
    clouds = [rng.normal(size=(n, 3)) for n in (1, 2, 8, 8, 8, 30, 600, 0)]
    clouds.append(np.vstack([clouds[3], clouds[3][:2]]))  # exact duplicate points
    clouds.append(np.zeros((4, 3)))  # all points coincide: no finite spacing
    expected = [particle_display_radius(c, fallback=0.7) if len(c) else 0.7 for c in clouds]
    assert particle_display_radii(clouds, fallback=0.7).tolist() == pytest.approx(expected, rel=1e-12)


def test_packed_colours_are_rerun_own_encoding():
    import rerun as rr

    from rbcli.record.rerun_sink import PALETTE, _rgba32

    columns = rr.Points3D.columns(positions=np.zeros((len(PALETTE), 3)), colors=PALETTE)
    colors = next(c for c in columns if "colors" in c.component_descriptor().component)
    assert np.asarray(colors.component_batch.as_arrow_array()).tolist() == _rgba32(PALETTE).tolist()


def test_a_run_killed_right_after_open_keeps_its_parameters(tmp_path):
    """SinkRerun.open flushes the run's parameters and scene to disk: a process SIGKILLed before any frame
    leaves an .rrd whose truncated read still names the scene, bodies and dt (rerun's batcher used to hold
    them until its first flush, seconds into a run)."""
    import os
    import sys

    from rbcli.record.read import summarize

    path = tmp_path / "run.rrd"
    script = (
        "import os, sys\n"
        "from rbcli.api import prepare\n"
        "from rbcli.record.rerun_sink import SinkRerun\n"
        "from rbcli.runner.loop import run_header\n"
        "sink = SinkRerun(sys.argv[2])  # kept: a collected RecordingStream flushes as it goes\n"
        "sink.open(run_header(prepare(sys.argv[1])))\n"
        "os.kill(os.getpid(), 9)\n"
    )
    scene = Path(__file__).resolve().parents[2] / "scenes" / "tutorial.yaml"
    # rerun's batcher told never to flush by itself, as when a run is killed before its first flush tick
    never = {
        "RERUN_FLUSH_TICK_SECS": "1000",
        "RERUN_FLUSH_NUM_BYTES": "1000000000",
        "RERUN_FLUSH_NUM_ROWS": "1000000000",
    }
    env = {**os.environ, **never}
    done = subprocess.run(
        [sys.executable, "-c", script, str(scene), str(path)], capture_output=True, timeout=120, env=env
    )
    assert done.returncode == -9, done.stderr
    info = summarize(path)
    assert info.frames == 0 and info.scene_name == "t-handle"
    assert info.body_names == ("handle",) and info.dt == 0.001
    assert "name: t-handle" in read_rrd(path, bodies=False).scene_text
