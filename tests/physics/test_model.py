"""The tutorial's precomputation: M = sum m_i, x_cm = sum m_i x_i / M, I0 = sum m_i (r.r 1 - r r^T)."""

import numpy as np
import pytest

from rbcli.physics.model import build_model, mass_properties
from rbcli.physics.rotation import quat_to_matrix

UNIT_CLOUD = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0], [0.0, 0.0, 3.0]])


def test_mass_properties_match_hand_computation():
    # four unit masses; r0 = x - (0.25, 0.5, 0.75); sums worked out by hand:
    # Ixx = sum(y^2+z^2) = 9.75, Iyy = 7.5, Izz = 3.75, Ixy = -sum(xy) = 0.5, Ixz = 0.75, Iyz = 1.5
    total, centre, inertia = mass_properties(UNIT_CLOUD, np.ones(4))
    assert total == 4.0
    np.testing.assert_allclose(centre, [0.25, 0.5, 0.75], rtol=0, atol=1e-15)
    expected = np.array([[9.75, 0.5, 0.75], [0.5, 7.5, 1.5], [0.75, 1.5, 3.75]])
    np.testing.assert_allclose(inertia, expected, rtol=0, atol=1e-14)


def test_weighted_centre_of_mass():
    total, centre, _ = mass_properties(np.array([[0.0, 0, 0], [3.0, 0, 0]]) + [[0, 1, 0], [0, 0, 1]],
                                       np.array([1.0, 2.0]))  # fmt: skip
    assert total == 3.0
    np.testing.assert_allclose(centre, [2.0, 1 / 3, 2 / 3], atol=1e-15)


def test_principal_frame_diagonalises_inertia_and_is_a_rotation():
    model, centres = build_model(["a"], [UNIT_CLOUD], [np.ones(4)])
    E = quat_to_matrix(model.body_frame_q[0])  # user-from-principal
    np.testing.assert_allclose(E @ E.T, np.eye(3), atol=1e-14)
    assert np.linalg.det(E) == pytest.approx(1.0, abs=1e-14)
    _, _, inertia = mass_properties(UNIT_CLOUD, np.ones(4))
    np.testing.assert_allclose(E @ np.diag(model.body_inertia[0]) @ E.T, inertia, atol=1e-13)
    # particle offsets in the principal frame rotate back to the user frame's r0
    np.testing.assert_allclose(model.particle_offset @ E.T, UNIT_CLOUD - centres[0], atol=1e-14)
    np.testing.assert_allclose(model.particle_offset_user, UNIT_CLOUD - centres[0], atol=0)


def test_scalar_mass_broadcasts_to_every_particle():
    model, _ = build_model(["a"], [UNIT_CLOUD], [np.float64(0.5)])
    assert model.body_mass[0] == 2.0
    np.testing.assert_array_equal(model.particle_mass, [0.5] * 4)


@pytest.mark.parametrize(
    "cloud", [np.array([[0.0, 0, 0], [1, 1, 1], [2, 2, 2]]), np.array([[1.0, 2, 3]])], ids=["collinear", "point"]
)
def test_singular_inertia_is_rejected_naming_the_body(cloud):
    with pytest.raises(ValueError, match="'rod'.*singular"):
        build_model(["rod"], [cloud], [np.ones(len(cloud))])


def test_flat_arrays_index_bodies():
    model, _ = build_model(["a", "b"], [UNIT_CLOUD, UNIT_CLOUD[:3]], [np.ones(4), np.ones(3)])
    assert model.body_particle_start.tolist() == [0, 4]
    assert model.body_particle_count.tolist() == [4, 3]
    assert model.particle_count == 7


def test_particle_radius_adds_a_solid_spheres_inertia():
    """Each particle of radius r is a solid sphere: I0 gains 2/5 m r^2 on the diagonal."""
    cloud = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]])  # collinear: singular without radii
    model, _ = build_model(["rod"], [cloud], [np.ones(3)], [np.float64(0.1)])
    sphere = 0.4 * 3 * 0.1**2
    np.testing.assert_allclose(np.sort(model.body_inertia[0]), [sphere, 2 + sphere, 2 + sphere], rtol=1e-13)
