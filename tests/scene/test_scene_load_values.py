"""What valid scenes resolve to: the walking-skeleton scene exactly, orientations, motion forms,
defaults, generators, compounds, simulation settings."""

from __future__ import annotations

import textwrap

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rbcli.physics.rotation import quat_to_matrix
from rbcli.scene.load import load_scene, load_scene_text
from rbcli.scene.shapes import mass_properties

SKELETON = """\
name: t-handle
simulation: {dt: 0.001, duration: 20.0, integrator: euler-matrix}
gravity: [0, 0, -9.81]          # optional, default none
bodies:
  - name: handle
    particles:
      positions: [[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]]   # body frame, m
      masses: [1.0, 0.5, 0.5, 0.25]        # kg, one per particle (or a scalar for all)
    position: [0, 0, 1]          # world position of the centre of mass, m
    velocity: [0, 0, 0]          # m/s (or momentum: [...], kg m/s)
    orientation: {wxyz: [1, 0, 0, 0]}   # unit quaternion, scalar first; also {xyzw: [...]} or {matrix: 3x3}
    angular_momentum: [0, 0, 0]  # world frame, kg m^2/s (or angular_velocity: world frame, rad/s)
"""

SIM = "simulation: {dt: 0.001, duration: 1.0}\n"
PARTICLES = "particles: {positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]], masses: 1.0}"


def one_body(extra: str, *, sim: str = SIM):
    return load_scene_text(sim + "bodies:\n  - name: b\n    " + PARTICLES + "\n" + textwrap.indent(extra, "    "))


def test_walking_skeleton_scene_exactly(tmp_path):
    path = tmp_path / "t_handle.yaml"
    path.write_text(SKELETON)
    spec = load_scene(path)
    assert spec.name == "t-handle" and spec.source_text == SKELETON and spec.source_path == str(path)
    assert (spec.simulation.dt, spec.simulation.duration, spec.simulation.integrator) == (0.001, 20.0, "euler-matrix")
    assert spec.gravity.tolist() == [0, 0, -9.81]
    (body,) = spec.bodies
    assert body.name == "handle"
    assert body.particle_position.tolist() == [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]]
    assert body.particle_mass.tolist() == [1.0, 0.5, 0.5, 0.25]
    assert body.particle_radius is None
    assert body.position.tolist() == [0, 0, 1] and body.velocity.tolist() == [0, 0, 0]
    assert body.orientation_wxyz.tolist() == [1, 0, 0, 0] and body.angular_momentum.tolist() == [0, 0, 0]
    assert body.momentum is None and body.angular_velocity is None
    assert (body.location.line, body.location.column) == (5, 5)
    assert spec.warnings == () and spec.forces == ()


def test_defaults_when_optional_keys_are_left_out():
    spec = load_scene_text(SIM + "bodies:\n  - name: b\n    " + PARTICLES + "\n", "dir/my_scene.yaml")
    assert spec.name == "my_scene" and spec.gravity is None
    body = spec.bodies[0]
    assert body.position.tolist() == [0, 0, 0] and body.orientation_wxyz.tolist() == [1, 0, 0, 0]
    assert body.velocity is None and body.momentum is None
    assert body.angular_momentum is None and body.angular_velocity is None
    assert body.particle_mass.tolist() == [1.0] * 4  # a scalar mass for every particle
    sim = spec.simulation
    assert (sim.record.every, sim.record.streams, sim.seed, sim.output, sim.tolerance) == (
        1,
        ("bodies", "invariants"),
        0,
        None,
        None,
    )


def test_arrays_are_read_only():
    body = one_body("velocity: [1, 2, 3]\n").bodies[0]
    for array in (body.particle_position, body.particle_mass, body.position, body.velocity, body.orientation_wxyz):
        with pytest.raises(ValueError):
            array[0] = 1.0


# ---- orientation forms, checked against scipy -------------------------------------------------------------
def scipy_wxyz(rotation: Rotation) -> np.ndarray:
    x, y, z, w = rotation.as_quat()
    q = np.array([w, x, y, z])
    return q if q[0] >= 0 else -q


def same_rotation(q: np.ndarray, expected: np.ndarray) -> bool:
    return abs(abs(float(np.dot(q, expected))) - 1.0) < 1e-12


@pytest.mark.parametrize("convention", ["xyz", "zyx", "XYZ", "ZYX", "zxz", "ZXZ", "yzy", "XZY"])
def test_euler_conventions_match_scipy(convention):
    angles = [0.3, -1.1, 2.0]
    q = one_body(f"orientation: {{euler: {{angles: {angles}, convention: {convention}}}}}\n").bodies[0].orientation_wxyz
    assert same_rotation(q, scipy_wxyz(Rotation.from_euler(convention, angles)))


def test_euler_degrees():
    q = one_body("orientation: {euler: {angles: [10, 20, 30], convention: ZYX, degrees: true}}\n")
    expected = scipy_wxyz(Rotation.from_euler("ZYX", [10, 20, 30], degrees=True))
    assert same_rotation(q.bodies[0].orientation_wxyz, expected)


def test_xyzw_matrix_axis_angle_forms_agree():
    rotation = Rotation.from_rotvec([0.2, -0.5, 0.9])
    expected = scipy_wxyz(rotation)
    x, y, z, w = (float(c) for c in rotation.as_quat())
    forms = [
        f"{{wxyz: [{w!r}, {x!r}, {y!r}, {z!r}]}}",
        f"{{xyzw: [{x!r}, {y!r}, {z!r}, {w!r}]}}",
        "{matrix: " + str(rotation.as_matrix().tolist()) + "}",
        "{axis_angle: {axis: [0.2, -0.5, 0.9], angle: " + repr(float(np.linalg.norm([0.2, -0.5, 0.9]))) + "}}",
        "{axis_angle: {axis: [0.4, -1.0, 1.8], angle: "
        + repr(float(np.degrees(np.linalg.norm([0.2, -0.5, 0.9]))))
        + ", degrees: true}}",
    ]
    for form in forms:
        q = one_body(f"orientation: {form}\n").bodies[0].orientation_wxyz
        assert same_rotation(q, expected), form
        assert abs(np.linalg.norm(q) - 1.0) < 1e-14


def test_typed_matrix_with_four_decimals_is_orthonormalised_with_a_warning():
    spec = one_body("orientation: {matrix: [[0.7071, -0.7071, 0], [0.7071, 0.7071, 0], [0, 0, 1]]}\n")
    q = spec.bodies[0].orientation_wxyz
    assert same_rotation(q, scipy_wxyz(Rotation.from_euler("z", 45, degrees=True)))
    assert [w.severity for w in spec.warnings] == ["warning"] and "orthonormalised" in spec.warnings[0].message


# ---- motion -----------------------------------------------------------------------------------------------
def test_angular_velocity_forms():
    body = one_body("angular_velocity: [1, 2, 3]\n").bodies[0]
    assert body.angular_velocity.tolist() == [1, 2, 3] and body.angular_velocity_frame == "world"
    body = one_body("angular_velocity: {world: [1, 2, 3]}\n").bodies[0]
    assert body.angular_velocity.tolist() == [1, 2, 3] and body.angular_velocity_frame == "world"
    body = one_body("angular_velocity: {body: [1, 2, 3]}\n").bodies[0]
    assert body.angular_velocity.tolist() == [1, 2, 3] and body.angular_velocity_frame == "body"
    assert body.angular_momentum is None


def test_body_frame_angular_momentum_is_turned_into_the_world_frame():
    # L_world = R L_body; a 90 degree turn about z takes body x to world y
    body = one_body("orientation: {axis_angle: {axis: [0, 0, 1], angle: 90, degrees: true}}\n"
                    "angular_momentum: {body: [1, 0, 0]}\n").bodies[0]  # fmt: skip
    assert np.allclose(body.angular_momentum, [0, 1, 0], atol=1e-15)
    body = one_body("angular_momentum: {world: [1, 0, 0]}\n").bodies[0]
    assert body.angular_momentum.tolist() == [1, 0, 0]


def test_momentum_instead_of_velocity():
    body = one_body("momentum: [4, 0, 0]\n").bodies[0]
    assert body.momentum.tolist() == [4, 0, 0] and body.velocity is None


# ---- simulation ---------------------------------------------------------------------------------------------
def test_steps_instead_of_duration():
    spec = one_body("", sim="simulation: {dt: 0.01, steps: 250}\n")
    assert spec.simulation.duration == pytest.approx(2.5, rel=1e-15)


def test_record_rate_and_streams_and_output():
    sim = (
        "simulation: {dt: 0.001, duration: 1, integrator: rk4, seed: 7, output: out/run.mcap,\n"
        "             record: {rate: 50, streams: [bodies, particles, contacts]}}\n"
    )
    s = one_body("", sim=sim).simulation
    assert s.record.every == 20 and s.record.streams == ("bodies", "particles", "contacts")
    assert (s.integrator, s.seed, s.output) == ("rk4", 7, "out/run.mcap")


def test_adaptive_tolerance():
    s = one_body("", sim="simulation: {dt: 0.01, duration: 1, integrator: dopri5, tolerance: 1.0e-8}\n").simulation
    assert s.tolerance == 1e-8


def test_forces_keep_type_and_location():
    text = (
        SIM
        + "bodies:\n  - name: b\n    "
        + PARTICLES
        + "\nforces:\n  - {type: spring, body: b, anchor: [0, 0, 1], stiffness: 10}\n"
    )
    spec = load_scene_text(text, "s.yaml")
    assert [f.kind for f in spec.forces] == ["spring"] and spec.forces[0].location.line == 6


# ---- defaults, generators, compounds ---------------------------------------------------------------------
def test_defaults_are_merged_and_overridden():
    text = """\
    simulation: {dt: 0.001, duration: 1}
    defaults:
      shape: {type: sphere, radius: 0.1}
      spacing: 0.05
      density: 1000
      velocity: [1, 0, 0]
    bodies:
      - name: a
      - name: b
        mass: 2.0                  # replaces the default density (same group)
        momentum: [0, 3, 0]        # replaces the default velocity
      - name: c
        particles: {positions: [[0, 0, 0], [1, 0, 0], [0, 1, 0]], masses: 1}   # replaces the shape
    """
    a, b, c = load_scene_text(textwrap.dedent(text)).bodies
    assert a.velocity.tolist() == [1, 0, 0] and a.particle_mass[0] == pytest.approx(1000 * 0.05**3)
    assert b.velocity is None and b.momentum.tolist() == [0, 3, 0]
    assert b.particle_mass.sum() == pytest.approx(2.0)
    assert len(c.particle_mass) == 3 and c.particle_radius is None  # sampling defaults skipped for particles


def test_yaml_merge_keys_work_in_scenes():
    text = """\
    simulation: {dt: 0.001, duration: 1}
    bodies:
      - &ball {name: a, shape: {type: sphere, radius: 0.1}, spacing: 0.05, density: 1000}
      - {<<: *ball, name: b, position: [1, 0, 0]}
    """
    a, b = load_scene_text(textwrap.dedent(text)).bodies
    assert b.name == "b" and b.position.tolist() == [1, 0, 0]
    assert np.array_equal(a.particle_position, b.particle_position)


def test_grid_generator():
    text = """\
    simulation: {dt: 0.001, duration: 1}
    bodies:
      - grid:
          name: box
          count: [3, 2, 1]
          spacing: [1.0, 2.0, 3.0]
          origin: [10, 0, 0]
          template:
            shape: {type: box, size: [0.2, 0.2, 0.2]}
            spacing: 0.05
            density: 500
            velocity: [0, 0, 1]
    """
    bodies = load_scene_text(textwrap.dedent(text)).bodies
    assert [b.name for b in bodies] == [f"box_{n}" for n in range(6)]
    # n = i + nx (j + ny k): i (x) fastest
    assert [b.position.tolist() for b in bodies] == [
        [10, 0, 0], [11, 0, 0], [12, 0, 0], [10, 2, 0], [11, 2, 0], [12, 2, 0],
    ]  # fmt: skip
    assert all(b.velocity.tolist() == [0, 0, 1] for b in bodies)
    assert bodies[0].particle_position is bodies[5].particle_position  # one cloud, shared read-only
    assert all(b.location.line == 3 for b in bodies)


def test_random_generator_is_reproducible_and_inside_its_box():
    text = """\
    simulation: {dt: 0.001, duration: 1}
    bodies:
      - random:
          name: rock
          count: 200
          seed: 42
          box: {min: [-1, -2, 0], max: [1, 2, 5]}
          velocity_sigma: 0.5
          random_orientation: true
          template: {shape: {type: sphere, radius: 0.05}, spacing: 0.02, mass: 1.0}
    """
    first = load_scene_text(textwrap.dedent(text)).bodies
    again = load_scene_text(textwrap.dedent(text)).bodies
    positions = np.array([b.position for b in first])
    assert len(first) == 200 and first[199].name == "rock_199"
    assert np.all(positions >= [-1, -2, 0]) and np.all(positions <= [1, 2, 5])
    assert np.array_equal(positions, [b.position for b in again])
    velocities = np.array([b.velocity for b in first])
    assert 0.4 < velocities.std() < 0.6  # sigma = 0.5 per component, 600 samples
    q = np.array([b.orientation_wxyz for b in first])
    assert np.allclose(np.linalg.norm(q, axis=1), 1.0) and len(np.unique(q.round(6), axis=0)) == 200
    other_seed = load_scene_text(textwrap.dedent(text).replace("seed: 42", "seed: 43")).bodies
    assert not np.array_equal(positions, [b.position for b in other_seed])


def test_compound_places_parts_and_sets_masses():
    text = """\
    simulation: {dt: 0.001, duration: 1}
    bodies:
      - name: dumbbell
        spacing: 0.02
        compound:
          - particles: {positions: [[0, 0, 0]], masses: 2.0, radius: 0.05}
            offset: [-0.5, 0, 0]
          - particles: {positions: [[0, 0, 0]], masses: 3.0}
            offset: [0.5, 0, 0]
          - shape: {type: cylinder, radius: 0.02, height: 0.2, axis: z}
            orientation: {axis_angle: {axis: [0, 1, 0], angle: 90, degrees: true}}   # axis z -> x
            mass: 0.5
    """
    body = load_scene_text(textwrap.dedent(text)).bodies[0]
    assert body.particle_mass[:2].tolist() == [2.0, 3.0]
    assert body.particle_position[:2].tolist() == [[-0.5, 0, 0], [0.5, 0, 0]]
    assert body.particle_radius[:2].tolist() == [0.05, 0.0]  # a particle part without radius: 0
    bar = body.particle_position[2:]
    assert body.particle_mass[2:].sum() == pytest.approx(0.5)
    assert np.ptp(bar[:, 0]) > 0.15 and np.ptp(bar[:, 2]) < 0.05  # the cylinder now lies along x


def test_compound_body_mass_goes_to_parts_without_their_own():
    text = """\
    simulation: {dt: 0.001, duration: 1}
    bodies:
      - name: hammer
        spacing: 0.01
        mass: 2.0
        compound:
          - shape: {type: box, size: [0.1, 0.04, 0.04]}
            offset: [0, 0, 0.3]
            density: 7850
          - shape: {type: cylinder, radius: 0.015, height: 0.3}
          - shape: {type: box, size: [0.02, 0.02, 0.02]}
            offset: [0, 0, -0.16]
    """
    body = load_scene_text(textwrap.dedent(text)).bodies[0]
    head = int(round(0.1 * 0.04 * 0.04 / 0.01**3))
    assert body.particle_mass[:head] == pytest.approx(7850 * 0.01**3)
    assert body.particle_mass[head:].sum() == pytest.approx(2.0)
    assert np.ptp(body.particle_mass[head:]) == 0.0  # the body's mass at one density over the other parts


def test_count_sets_the_spacing():
    text = SIM + "bodies:\n  - {name: s, shape: {type: box, size: [1, 1, 1]}, count: 1000, density: 1}\n"
    body = load_scene_text(text).bodies[0]
    assert len(body.particle_mass) == 1000 and body.particle_radius[0] == pytest.approx(0.05)
    assert mass_properties(body.particle_position, body.particle_mass).mass == pytest.approx(1.0)


def test_orientation_of_a_compound_part_rotates_its_particles():
    part_q = one_body("orientation: {axis_angle: {axis: [1, 1, 0], angle: 0.7}}\n").bodies[0].orientation_wxyz
    r = quat_to_matrix(part_q)
    assert np.allclose(r @ r.T, np.eye(3), atol=1e-14)
