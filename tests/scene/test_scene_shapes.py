"""Shape and mesh sampling: mass and inertia of the particle lattice converge to the solid's.

Each lattice particle stands for a cube of side s (mass rho s^3, radius s/2). Two errors remain:
cells cut by a curved surface (mass and inertia error O(s / size), oscillating with how the lattice
meets the surface) and the particles' own inertia (O(s^2 / size^2); exact for a box: the point lattice
misses M s^2 / 6 per axis, the solid-sphere term 2/5 m (s/2)^2 gives back M s^2 / 10 of it). So we
check the error at a stated spacing and that refining the spacing 4x shrinks it at least 4x.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from rbcli.scene import mesh as mesh_io
from rbcli.scene.shapes import (
    SamplingError,
    inertia_degeneracy,
    mass_properties,
    sample_shape,
    shape_volume,
)

RHO = 1000.0
SCENES = Path(__file__).resolve().parents[2] / "scenes"


def analytic(shape: dict) -> tuple[float, np.ndarray]:
    """Mass [kg] and ascending principal moments [kg m^2] of the solid at density RHO."""
    kind = shape["type"]
    if kind == "box":
        a, b, c = shape["size"]
        m = RHO * a * b * c
        moments = [m * (b * b + c * c) / 12, m * (a * a + c * c) / 12, m * (a * a + b * b) / 12]
    elif kind == "sphere":
        r = shape["radius"]
        m = RHO * 4 / 3 * np.pi * r**3
        moments = [0.4 * m * r * r] * 3
    elif kind == "cylinder":
        r, h = shape["radius"], shape["height"]
        m = RHO * np.pi * r * r * h
        moments = [m * r * r / 2, m * (3 * r * r + h * h) / 12, m * (3 * r * r + h * h) / 12]
    elif kind == "ellipsoid":
        a, b, c = shape["radii"]
        m = RHO * 4 / 3 * np.pi * a * b * c
        moments = [m * (b * b + c * c) / 5, m * (a * a + c * c) / 5, m * (a * a + b * b) / 5]
    return m, np.sort(moments)


def sampled_errors(shape: dict, spacing: float) -> tuple[float, float]:
    """Relative error of the lattice's mass and (worst) principal moment against the solid."""
    points = sample_shape(shape, spacing)
    masses = np.full(len(points), RHO * spacing**3)
    props = mass_properties(points, masses, np.full(len(points), spacing / 2))
    mass, moments = analytic(shape)
    assert np.allclose(props.centre_of_mass, 0.0, atol=1e-12)  # the lattice is symmetric about the origin
    return abs(props.mass / mass - 1), float(np.max(np.abs(props.principal_moments / moments - 1)))


@pytest.mark.parametrize(
    "shape, coarse, mass_bound, inertia_bound",
    [
        # edges multiples of the spacing: the mass is exact, the inertia error is M s^2 / 15 per axis
        ({"type": "box", "size": [0.3, 0.2, 0.1]}, 0.02, 1e-12, 7e-3),
        ({"type": "sphere", "radius": 0.1}, 0.02, 0.06, 0.11),
        ({"type": "cylinder", "radius": 0.05, "height": 0.2, "axis": "y"}, 0.02, 0.08, 0.15),
        ({"type": "ellipsoid", "radii": [0.1, 0.15, 0.2]}, 0.02, 0.03, 0.06),
    ],
)
def test_mass_and_inertia_converge_to_the_solid(shape, coarse, mass_bound, inertia_bound):
    mass_err, inertia_err = sampled_errors(shape, coarse)
    assert mass_err <= mass_bound and inertia_err <= inertia_bound
    fine_mass_err, fine_inertia_err = sampled_errors(shape, coarse / 4)
    assert fine_inertia_err < inertia_err / 4
    assert fine_mass_err <= max(mass_err / 4, 1e-12)


def test_box_inertia_error_is_the_predicted_cell_term():
    # lattice: Ixx = M (b^2 + c^2 - 2 s^2) / 12 + M s^2 / 10 = exact - M s^2 / 15
    shape, s = {"type": "box", "size": [0.4, 0.2, 0.1]}, 0.01
    points = sample_shape(shape, s)
    props = mass_properties(points, np.full(len(points), RHO * s**3), np.full(len(points), s / 2))
    mass, moments = analytic(shape)
    assert np.allclose(props.principal_moments, moments - mass * s * s / 15, rtol=1e-12)


def test_capsule_volume_and_symmetry():
    shape = {"type": "capsule", "radius": 0.05, "height": 0.2, "axis": "x"}
    s = 0.005
    points = sample_shape(shape, s)
    assert len(points) * s**3 == pytest.approx(shape_volume(shape), rel=0.01)
    assert np.ptp(points[:, 0]) == pytest.approx(0.3 - s, abs=2 * s)  # total length height + 2 radius


def test_shape_mass_split_evenly_when_total_mass_is_given():
    from rbcli.scene.load import load_scene_text

    text = "simulation: {dt: 0.1, duration: 1}\nbodies:\n  - {name: b, shape: {type: sphere, radius: 1}, spacing: 0.25, mass: 3}\n"  # noqa: E501
    body = load_scene_text(text).bodies[0]
    assert body.particle_mass.sum() == pytest.approx(3.0) and np.ptp(body.particle_mass) == 0.0


def test_lattice_size_is_bounded_before_allocation():
    with pytest.raises(SamplingError, match="lattice points"):
        sample_shape({"type": "box", "size": [1, 1, 1]}, 1e-4)
    with pytest.raises(SamplingError):
        sample_shape({"type": "sphere", "radius": 1e300}, 1.0)


def test_mass_properties_of_a_known_cloud():
    # two 1 kg points at x = +-1 and two 0.5 kg at y = +-1: I = diag(1, 2, 3)
    props = mass_properties(np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]), np.array([1, 1, 0.5, 0.5]))
    assert props.mass == 3.0 and np.allclose(props.centre_of_mass, 0)
    assert np.allclose(props.principal_moments, [1, 2, 3]) and inertia_degeneracy(props) is None


def test_radius_makes_a_rod_a_rigid_body():
    rod = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])
    assert "one line" in inertia_degeneracy(mass_properties(rod, np.ones(3)))
    props = mass_properties(rod, np.ones(3), np.full(3, 0.1))
    assert inertia_degeneracy(props) is None
    assert props.principal_moments[0] == pytest.approx(3 * 0.4 * 0.01)


# ---- meshes ------------------------------------------------------------------------------------------------
def test_cube_mesh_matches_the_sampled_box_exactly():
    vertices, faces = mesh_io.read_mesh(SCENES / "meshes" / "cube.obj")
    mesh_io.check_closed(faces)
    assert mesh_io.mesh_volume(vertices, faces) == pytest.approx(1.0)
    s = 0.05
    from_mesh = mesh_io.voxelise(vertices, faces, s)
    from_box = sample_shape({"type": "box", "size": [1, 1, 1]}, s) + 0.5
    assert len(from_mesh) == 8000
    assert np.allclose(np.sort(from_mesh, axis=0), np.sort(from_box, axis=0), atol=1e-12)


def test_cube_mesh_mass_properties_within_sampling_error():
    vertices, faces = mesh_io.read_mesh(SCENES / "meshes" / "cube.obj")
    scale, s = 0.3, 0.017  # spacing not a divisor of the edge: cut cells
    points = mesh_io.voxelise(vertices * scale, faces, s)
    props = mass_properties(points, np.full(len(points), RHO * s**3), np.full(len(points), s / 2))
    mass, moments = analytic({"type": "box", "size": [scale] * 3})
    assert props.mass == pytest.approx(mass, rel=3 * s / scale)  # one layer of cells on each face at most
    assert np.allclose(props.centre_of_mass, scale / 2, atol=1e-12)
    assert np.allclose(props.principal_moments, moments, rtol=6 * s / scale)


def test_rotated_tetrahedron_mesh_converges():
    # tetrahedron on the axes: volume 1/6, centroid (1/4, 1/4, 1/4); rotated so no face is axis-aligned
    vertices, faces = mesh_io.read_mesh(SCENES / "meshes" / "tetra.obj")
    turn = np.array([[0.36, 0.48, -0.8], [-0.8, 0.6, 0.0], [0.48, 0.64, 0.6]])
    vertices = vertices @ turn.T
    errors = []
    for s in (0.05, 0.0125):
        points = mesh_io.voxelise(vertices, faces, s)
        volume_err = abs(len(points) * s**3 * 6 - 1)
        centroid_err = float(np.max(np.abs(points.mean(axis=0) - turn @ [0.25, 0.25, 0.25])))
        errors.append((volume_err, centroid_err))
    assert errors[1][0] < 0.02 and errors[1][1] < 0.01
    assert errors[1][0] < errors[0][0] and errors[1][1] < errors[0][1]


def test_builtin_obj_reader_agrees_with_trimesh():
    path = SCENES / "meshes" / "tetra.obj"
    vertices, faces = mesh_io._read_obj(path)
    assert vertices.shape == (4, 3) and faces.shape == (4, 3)
    assert mesh_io.mesh_volume(vertices, faces) == pytest.approx(1 / 6)


def test_obj_reader_fans_polygons_and_rejects_bad_indices(tmp_path):
    quad = tmp_path / "quad.obj"
    quad.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n")
    assert mesh_io._read_obj(quad)[1].tolist() == [[0, 1, 2], [0, 2, 3]]
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nf 1 2 3\n")
    with pytest.raises(mesh_io.MeshError, match="outside"):
        mesh_io._read_obj(bad)


def test_without_trimesh_obj_still_loads_and_other_formats_say_why(monkeypatch, tmp_path):
    monkeypatch.setitem(__import__("sys").modules, "trimesh", None)  # import trimesh -> ImportError
    vertices, faces = mesh_io.read_mesh(SCENES / "meshes" / "cube.obj")
    assert vertices.shape == (8, 3) and faces.shape == (12, 3)
    stl = tmp_path / "part.stl"
    stl.write_text("solid x\nendsolid x\n")
    with pytest.raises(mesh_io.MeshError, match="only .obj"):
        mesh_io.read_mesh(stl)
