"""`rbcli.read_recording`: a recorded .mcap / .rrd read back through the public API equals the Trajectory
`rbcli.simulate` returns for the same scene (to what each format stores); `Trajectory.to_npz` /
`from_npz` round-trip bit for bit and `to_csv` reads back exactly."""

from __future__ import annotations

import csv

import numpy as np
import pytest

import rbcli

# two bodies, gravity and a spin, a few recorded frames (every 2nd of 12 steps, plus step 0); the second
# name has a comma and a space, which the CSV must quote
SCENE = """\
name: read-back
simulation: {dt: 0.01, duration: 0.12, integrator: split2, record: {every: 2}}
gravity: [0, 0, -9.81]
bodies:
  - name: handle
    particles:
      positions: [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]]
      masses: [1.0, 0.5, 0.5, 0.25]
    position: [0, 0, 1]
    velocity: [0.5, 0, 4.0]
    orientation: {wxyz: [1, 0, 0, 0]}
    angular_momentum: [0.02, 0.05, 0.01]
  - name: "plate, tilted"
    particles:
      positions: [[0.0, 0.0, 0.0], [0.3, 0.0, 0.0], [0.0, 0.2, 0.0], [0.3, 0.2, 0.0]]
      masses: [1.0, 1.0, 1.0, 1.0]
    position: [1.0, -0.5, 2.0]
    velocity: [0, 1.0, 0]
    orientation: {wxyz: [0.9, 0.1, 0.3, -0.2]}
    angular_momentum: [0.3, -0.1, 0.2]
"""

ARRAYS = ("t", "step", "x", "q", "v", "omega", "P", "L")


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """(in-memory Trajectory, {"mcap": path, "rrd": path}) of the same scene."""
    folder = tmp_path_factory.mktemp("read_recording")
    scene = folder / "read_back.yaml"
    scene.write_text(SCENE)
    memory = rbcli.simulate(scene)
    paths = {}
    for fmt in ("mcap", "rrd"):
        paths[fmt] = folder / f"run.{fmt}"
        summary = rbcli.run_to_file(rbcli.prepare(scene), paths[fmt])
        assert summary.status == "completed"
    return memory, paths


def test_mcap_reads_back_exactly(recorded):
    """MCAP stores every state array and the invariants as float64: equal bit for bit."""
    memory, paths = recorded
    traj = rbcli.read_recording(paths["mcap"])
    assert isinstance(traj, rbcli.Trajectory) and traj.not_recorded == ()
    assert traj.body_names == memory.body_names == ("handle", "plate, tilted")
    assert len(traj.t) == 7  # steps 0, 2, ..., 12
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(traj, name), getattr(memory, name), err_msg=name)
    assert list(traj.invariants) == list(memory.invariants) and traj.invariants
    for name, series in memory.invariants.items():
        np.testing.assert_array_equal(traj.invariants[name], series, err_msg=name)
    assert traj.particle_position is None


def test_rrd_reads_back_to_float32(recorded):
    """An .rrd stores x and q as float32 (the sink rounds each float64 to nearest, so the value read back
    is exactly the float32 rounding: relative error <= 2^-24 ~ 6e-8) and t as rint(t * 1e9) integer
    nanoseconds (|error| <= 0.5 ns; 1 ns allows the float64 product's rounding). Invariants are float64
    scalars, exact. v, omega, P, L are not stored: NaN and named in not_recorded."""
    memory, paths = recorded
    traj = rbcli.read_recording(paths["rrd"])
    assert traj.body_names == memory.body_names
    np.testing.assert_array_equal(traj.step, memory.step)
    np.testing.assert_allclose(traj.t, memory.t, rtol=0, atol=1e-9)
    for name in ("x", "q"):
        want = getattr(memory, name)
        np.testing.assert_array_equal(getattr(traj, name), want.astype(np.float32).astype(np.float64), err_msg=name)
        np.testing.assert_allclose(getattr(traj, name), want, rtol=2.0**-24, atol=0, err_msg=name)
    for name, series in memory.invariants.items():
        np.testing.assert_array_equal(traj.invariants[name], series, err_msg=name)
    assert traj.not_recorded == ("v", "omega", "P", "L")
    for name in traj.not_recorded:
        assert getattr(traj, name).shape == memory.x.shape and np.isnan(getattr(traj, name)).all()


@pytest.mark.parametrize("fmt", ["mcap", "rrd"])
def test_header_and_summary_come_back(recorded, fmt):
    memory, paths = recorded
    traj = rbcli.read_recording(paths[fmt])
    got, want = traj.header, memory.header
    assert got is not None and want is not None
    for field in ("scene_name", "scene_text", "scene_sha256", "body_names", "integrator", "dt", "duration"):
        assert getattr(got, field) == getattr(want, field), field
    assert (got.record_every, got.streams, got.invariant_names, got.quaternion_order) == (
        want.record_every,
        want.streams,
        want.invariant_names,
        "wxyz",
    )
    np.testing.assert_array_equal(got.body_mass, want.body_mass)
    for a, b in zip(got.body_particle_offset, want.body_particle_offset, strict=True):
        np.testing.assert_allclose(a, b, rtol=2.0**-24, atol=1e-12)  # float32 in an .rrd
    assert traj.status == memory.status == "completed"
    assert traj.summary is not None and memory.summary is not None
    assert (traj.summary.steps, traj.summary.frames, traj.summary.t_end) == (
        memory.summary.steps,
        memory.summary.frames,
        memory.summary.t_end,
    )


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


@pytest.mark.parametrize("source", ["memory", "rrd"])
def test_npz_round_trip_is_bitwise(recorded, tmp_path, source):
    memory, paths = recorded
    traj = memory if source == "memory" else rbcli.read_recording(paths["rrd"])
    path = tmp_path / "run.npz"
    traj.to_npz(path)
    back = rbcli.Trajectory.from_npz(path)
    for name in ARRAYS:
        assert _same_bits(getattr(back, name), getattr(traj, name)), name
    assert list(back.invariants) == list(traj.invariants)
    assert all(_same_bits(back.invariants[n], s) for n, s in traj.invariants.items())
    assert (back.body_names, back.not_recorded, back.summary) == (traj.body_names, traj.not_recorded, traj.summary)
    assert (back.particle_position is None) == (traj.particle_position is None)
    assert back.header is not None and traj.header is not None
    assert back.header.parameters() == traj.header.parameters()
    assert back.header.scene_text == traj.header.scene_text
    for a, b in zip(back.header.body_particle_offset, traj.header.body_particle_offset, strict=True):
        assert _same_bits(a, np.asarray(b, dtype=np.float64))
    assert np.load(path)["x"].shape == traj.x.shape  # plain numpy reads it too


def test_npz_round_trip_with_particles(tmp_path):
    """particle_position (the particles stream) survives too."""
    scene = tmp_path / "particles.yaml"
    scene.write_text(SCENE.replace("record: {every: 2}", "record: {every: 3, streams: [bodies, particles]}"))
    traj = rbcli.simulate(scene)
    assert traj.particle_position is not None
    traj.to_npz(tmp_path / "p.npz")
    back = rbcli.Trajectory.from_npz(tmp_path / "p.npz")
    assert back.particle_position is not None and _same_bits(back.particle_position, traj.particle_position)
    assert _same_bits(back.q, traj.q) and back.summary == traj.summary


@pytest.mark.parametrize("source", ["memory", "rrd"])
def test_csv_reads_back_exactly(recorded, tmp_path, source):
    """One row per (frame, body), SI units in the header; the floats are repr, so they parse back exactly."""
    memory, paths = recorded
    traj = memory if source == "memory" else rbcli.read_recording(paths["rrd"])
    path = tmp_path / "run.csv"
    traj.to_csv(path)
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    header, body = rows[0], rows[1:]
    assert header[:10] == ["time_s", "step", "body", "x_m", "y_m", "z_m", "qw", "qx", "qy", "qz"]
    frames, bodies = traj.x.shape[:2]
    assert len(body) == frames * bodies
    assert [r[2] for r in body] == list(traj.body_names) * frames
    np.testing.assert_array_equal([int(r[1]) for r in body], np.repeat(traj.step, bodies))
    values = np.array([[float(v) for v in (r[0], *r[3:])] for r in body])
    expected = [np.repeat(traj.t, bodies)[:, None], traj.x.reshape(-1, 3), traj.q.reshape(-1, 4)]
    if source == "memory":
        assert header[10:] == [
            *("vx_m_per_s", "vy_m_per_s", "vz_m_per_s"),
            *("omega_x_rad_per_s", "omega_y_rad_per_s", "omega_z_rad_per_s"),
            *("Px_kg_m_per_s", "Py_kg_m_per_s", "Pz_kg_m_per_s"),
            *("Lx_kg_m2_per_s", "Ly_kg_m2_per_s", "Lz_kg_m2_per_s"),
        ]
        expected += [getattr(traj, n).reshape(-1, 3) for n in ("v", "omega", "P", "L")]
    else:
        assert len(header) == 10  # no columns for what an .rrd does not store
    assert _same_bits(values, np.hstack(expected))
    # the numeric columns through numpy alone (the quoted body name is skipped)
    loaded = np.loadtxt(path, delimiter=",", quotechar='"', skiprows=1, usecols=[0, *range(3, len(header))], ndmin=2)
    assert _same_bits(loaded, np.hstack(expected))


def test_missing_file_is_named(tmp_path):
    missing = tmp_path / "nothing.mcap"
    with pytest.raises(FileNotFoundError, match="nothing.mcap"):
        rbcli.read_recording(missing)
    folder = tmp_path / "folder.rrd"
    folder.mkdir()
    with pytest.raises(FileNotFoundError, match="is a directory.*folder.rrd"):
        rbcli.read_recording(folder)


@pytest.mark.parametrize("name", ["run.csv", "run.npz", "run"])
def test_wrong_extension_is_refused(tmp_path, name):
    path = tmp_path / name
    path.write_bytes(b"")
    with pytest.raises(ValueError, match=f"{name}.*expected a .mcap or .rrd"):
        rbcli.read_recording(path)


@pytest.mark.parametrize("fmt", ["mcap", "rrd"])
def test_unreadable_file_is_named(tmp_path, fmt):
    path = tmp_path / f"broken.{fmt}"
    path.write_bytes(b"not a recording at all")
    with pytest.raises(ValueError, match=f"broken.{fmt}.*not a readable rbsim .{fmt} recording"):
        rbcli.read_recording(path)
