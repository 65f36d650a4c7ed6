"""Compiled one-body rotation kernels (numba) used inside step kernels; numpy twins in rotation.py."""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics import kernel_cache

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True, inline="always")
def quat_to_matrix_nb(q: np.ndarray, R: np.ndarray) -> None:
    """Write the rotation matrix of unit quaternion q (w, x, y, z) into R (3, 3)."""
    w, x, y, z = q[0], q[1], q[2], q[3]
    R[0, 0] = 1.0 - 2.0 * (y * y + z * z)
    R[0, 1] = 2.0 * (x * y - w * z)
    R[0, 2] = 2.0 * (x * z + w * y)
    R[1, 0] = 2.0 * (x * y + w * z)
    R[1, 1] = 1.0 - 2.0 * (x * x + z * z)
    R[1, 2] = 2.0 * (y * z - w * x)
    R[2, 0] = 2.0 * (x * z - w * y)
    R[2, 1] = 2.0 * (y * z + w * x)
    R[2, 2] = 1.0 - 2.0 * (x * x + y * y)


@numba.njit(cache=True, inline="always")
def matrix_to_quat_nb(R: np.ndarray, q: np.ndarray) -> None:
    """Write the unit quaternion (w >= 0) of rotation matrix R into q.

    Shepperd (1978): build q from the largest of w^2, x^2, y^2, z^2 so no division is by a small number.
    """
    tr = R[0, 0] + R[1, 1] + R[2, 2]
    if tr >= R[0, 0] and tr >= R[1, 1] and tr >= R[2, 2]:
        s = np.sqrt(1.0 + tr) * 2.0
        w, x, y, z = 0.25 * s, (R[2, 1] - R[1, 2]) / s, (R[0, 2] - R[2, 0]) / s, (R[1, 0] - R[0, 1]) / s
    elif R[0, 0] >= R[1, 1] and R[0, 0] >= R[2, 2]:
        s = np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2]) * 2.0
        w, x, y, z = (R[2, 1] - R[1, 2]) / s, 0.25 * s, (R[0, 1] + R[1, 0]) / s, (R[0, 2] + R[2, 0]) / s
    elif R[1, 1] >= R[2, 2]:
        s = np.sqrt(1.0 + R[1, 1] - R[0, 0] - R[2, 2]) * 2.0
        w, x, y, z = (R[0, 2] - R[2, 0]) / s, (R[0, 1] + R[1, 0]) / s, 0.25 * s, (R[1, 2] + R[2, 1]) / s
    else:
        s = np.sqrt(1.0 + R[2, 2] - R[0, 0] - R[1, 1]) * 2.0
        w, x, y, z = (R[1, 0] - R[0, 1]) / s, (R[0, 2] + R[2, 0]) / s, (R[1, 2] + R[2, 1]) / s, 0.25 * s
    n = np.sqrt(w * w + x * x + y * y + z * z)
    if w < 0.0:
        n = -n
    q[0] = w / n
    q[1] = x / n
    q[2] = y / n
    q[3] = z / n


@numba.njit(cache=True)
def rotate_inverse(w, x, y, z, vx, vy, vz):  # noqa: ANN001, ANN201 - numba scalars
    """R(q)^T v for a unit quaternion q = (w, x, y, z): v - w t + u x t with t = 2 u x v, u = (x, y, z)."""
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx - w * tx + (y * tz - z * ty),
        vy - w * ty + (z * tx - x * tz),
        vz - w * tz + (x * ty - y * tx),
    )


@numba.njit(cache=True)
def rotate(w, x, y, z, vx, vy, vz):  # noqa: ANN001, ANN201
    """R(q) v for a unit quaternion q = (w, x, y, z): v + w t + u x t with t = 2 u x v (Rodrigues)."""
    tx = 2.0 * (y * vz - z * vy)
    ty = 2.0 * (z * vx - x * vz)
    tz = 2.0 * (x * vy - y * vx)
    return (
        vx + w * tx + (y * tz - z * ty),
        vy + w * ty + (z * tx - x * tz),
        vz + w * tz + (x * ty - y * tx),
    )
