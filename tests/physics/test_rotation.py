"""Quaternion and matrix conversions: exact identities (round-off tolerances)."""

import numpy as np

from rbcli.physics.rotation import (
    gram_schmidt,
    matrix_to_quat,
    quat_multiply,
    quat_normalize,
    quat_rotate,
    quat_to_matrix,
    skew,
)


def random_quats(n, seed=1):
    return quat_normalize(np.random.default_rng(seed).normal(size=(n, 4)))


def test_matrix_round_trip_covers_all_shepperd_branches():
    q = random_quats(2000)
    # include rotations by ~pi about each axis (the branches where w is small)
    q = np.concatenate([q, [[0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [1e-9, 1, 1e-9, 0]]])
    q = quat_normalize(q)
    back = matrix_to_quat(quat_to_matrix(q))
    np.testing.assert_allclose(back, q, atol=2e-15 * 10)


def test_matrix_is_orthonormal_rotation():
    R = quat_to_matrix(random_quats(100))
    np.testing.assert_allclose(R @ np.swapaxes(R, -1, -2), np.broadcast_to(np.eye(3), R.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)


def test_product_composes_rotations():
    a, b = random_quats(50, 2), random_quats(50, 3)
    np.testing.assert_allclose(quat_to_matrix(quat_multiply(a, b)), quat_to_matrix(a) @ quat_to_matrix(b),
                               atol=1e-14)  # fmt: skip
    v = np.random.default_rng(4).normal(size=(50, 3))
    np.testing.assert_allclose(quat_rotate(a, v), np.einsum("bij,bj->bi", quat_to_matrix(a), v), atol=1e-14)


def test_skew_is_cross_product_and_gram_schmidt_orthonormalises():
    w, r = np.array([0.3, -1.2, 2.0]), np.array([1.0, 0.5, -0.25])
    np.testing.assert_allclose(skew(w) @ r, np.cross(w, r), atol=1e-15)
    A = quat_to_matrix(random_quats(10)) + 1e-3 * np.random.default_rng(5).normal(size=(10, 3, 3))
    B = gram_schmidt(A)
    np.testing.assert_allclose(B @ np.swapaxes(B, -1, -2), np.broadcast_to(np.eye(3), B.shape), atol=1e-14)
    np.testing.assert_allclose(B[..., :, 0], A[..., :, 0] / np.linalg.norm(A[..., :, 0], axis=-1)[:, None])
