"""Rotations: unit quaternions (w, x, y, z) and 3x3 matrices, world-from-body; the one home of the
conversions (matrix, axis-angle, Euler angles, uniformly random rotations) that scenes parse into.

Vectorised numpy functions over leading axes (I/O, analysis, tests); their compiled one-body twins
for the step kernels live in `rotation_kernels.py` (so importing this module never imports numba).
Formulas follow
Shoemake 1985 ("Animating rotation with quaternion curves") and the tutorial's skew operator
omega* with omega* r = omega x r.
"""

from __future__ import annotations

import numpy as np


def quat_normalize(q: np.ndarray) -> np.ndarray:
    """q / |q|, with the sign fixed so that w >= 0 (q and -q are the same rotation)."""
    q = np.asarray(q, dtype=np.float64)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b (rotation b first, then a)."""
    aw, ax, ay, az = np.moveaxis(np.asarray(a, dtype=np.float64), -1, 0)
    bw, bx, by, bz = np.moveaxis(np.asarray(b, dtype=np.float64), -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_conjugate(q: np.ndarray) -> np.ndarray:
    """Inverse rotation of a unit quaternion."""
    q = np.asarray(q, dtype=np.float64)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion, shape (..., 3, 3)."""
    w, x, y, z = np.moveaxis(np.asarray(q, dtype=np.float64), -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        axis=-2,
    )


def matrix_to_quat(R: np.ndarray) -> np.ndarray:
    """Unit quaternion (w >= 0) of a rotation matrix, shape (..., 4).

    Shepperd's method (1978): take the largest of the four squared components for stability.
    """
    R = np.asarray(R, dtype=np.float64)
    r00, r11, r22 = R[..., 0, 0], R[..., 1, 1], R[..., 2, 2]
    # 4 w^2, 4 x^2, 4 y^2, 4 z^2 (up to the same constant); pick the largest per rotation
    squares = np.stack([1 + r00 + r11 + r22, 1 + r00 - r11 - r22, 1 - r00 + r11 - r22, 1 - r00 - r11 + r22], -1)
    pick = np.argmax(squares, axis=-1)
    s = 2.0 * np.sqrt(np.maximum(np.take_along_axis(squares, pick[..., None], -1)[..., 0], 1e-300))
    d21, d02, d10 = R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]
    s01, s02, s12 = R[..., 0, 1] + R[..., 1, 0], R[..., 0, 2] + R[..., 2, 0], R[..., 1, 2] + R[..., 2, 1]
    candidates = np.stack(
        [
            np.stack([0.25 * s, d21 / s, d02 / s, d10 / s], -1),
            np.stack([d21 / s, 0.25 * s, s01 / s, s02 / s], -1),
            np.stack([d02 / s, s01 / s, 0.25 * s, s12 / s], -1),
            np.stack([d10 / s, s02 / s, s12 / s, 0.25 * s], -1),
        ],
        -2,
    )
    q = np.take_along_axis(candidates, pick[..., None, None], -2)[..., 0, :]
    return quat_normalize(q)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q) v, vectorised over leading axes."""
    return np.einsum("...ij,...j->...i", quat_to_matrix(q), v)


def quat_rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """R(q)^T v, vectorised over leading axes."""
    return np.einsum("...ji,...j->...i", quat_to_matrix(q), v)


def gram_schmidt(R: np.ndarray) -> np.ndarray:
    """Re-orthonormalise the columns of R (the tutorial's b1, b2, b3), vectorised."""
    a1, a2, a3 = R[..., :, 0], R[..., :, 1], R[..., :, 2]
    b1 = a1 / np.linalg.norm(a1, axis=-1, keepdims=True)
    b2 = a2 - np.sum(b1 * a2, axis=-1, keepdims=True) * b1
    b2 = b2 / np.linalg.norm(b2, axis=-1, keepdims=True)
    b3 = a3 - np.sum(b1 * a3, axis=-1, keepdims=True) * b1 - np.sum(b2 * a3, axis=-1, keepdims=True) * b2
    b3 = b3 / np.linalg.norm(b3, axis=-1, keepdims=True)
    return np.stack([b1, b2, b3], axis=-1)


def skew(w: np.ndarray) -> np.ndarray:
    """The tutorial's w*: skew(w) @ r == cross(w, r), shape (..., 3, 3)."""
    w = np.asarray(w, dtype=np.float64)
    z = np.zeros(w.shape[:-1])
    wx, wy, wz = w[..., 0], w[..., 1], w[..., 2]
    return np.stack([np.stack([z, -wz, wy], -1), np.stack([wz, z, -wx], -1), np.stack([-wy, wx, z], -1)], axis=-2)


def quat_from_axis_angle(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rotation by `angle` [rad] about `axis` (normalised here), right-hand rule."""
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis])


_AXES = {"x": np.array([1.0, 0, 0]), "y": np.array([0, 1.0, 0]), "z": np.array([0, 0, 1.0])}


def quat_from_euler(angles: np.ndarray, convention: str) -> np.ndarray:
    """Euler angles [rad] as scipy's `Rotation.from_euler(convention, angles)`.

    Intrinsic (uppercase) 'XYZ' = Rx(a) Ry(b) Rz(c); extrinsic (lowercase) 'xyz' = Rz(c) Ry(b) Rx(a):
    each rotation about the fixed world axis is applied after the previous one.
    """
    parts = [quat_from_axis_angle(_AXES[c.lower()], a) for c, a in zip(convention, angles, strict=True)]
    q = np.array([1.0, 0, 0, 0])
    for p in parts:
        q = quat_multiply(q, p) if convention.isupper() else quat_multiply(p, q)
    return q / np.linalg.norm(q)


def random_unit_quaternions(rng: np.random.Generator, count: int) -> np.ndarray:
    """Uniformly distributed rotations: normalised 4D Gaussian samples (Haar measure on SO(3)), (count, 4)."""
    q = rng.standard_normal((count, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    return q
