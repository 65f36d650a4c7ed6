"""Compiled kinematics of body-fixed points for the force kernels, allocation-free (scalars in, tuples out).

For body b with unit quaternion q_b (w, u) world-from-principal and a point r0 in the principal frame:
  r = R(q_b) r0 = r0 + 2 w (u x r0) + 2 u x (u x r0)   (Rodrigues for unit quaternions; 15 products,
      cheaper than building R when only one or two vectors turn per row),
  omega = R diag(1/I) R^T L,  world position x + r,  world velocity P / M + omega x r.
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics import kernel_cache

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True)
def rotate(q: np.ndarray, b: int, vx: float, vy: float, vz: float) -> tuple[float, float, float]:
    """R(q_b) v: a principal-frame vector of body b in world axes."""
    w, ux, uy, uz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    return vx + w * tx + (uy * tz - uz * ty), vy + w * ty + (uz * tx - ux * tz), vz + w * tz + (ux * ty - uy * tx)


@numba.njit(cache=True)
def rotate_inverse(q: np.ndarray, b: int, vx: float, vy: float, vz: float) -> tuple[float, float, float]:
    """R(q_b)^T v: a world vector in body b's principal axes (rotation by the conjugate quaternion)."""
    w, ux, uy, uz = q[b, 0], -q[b, 1], -q[b, 2], -q[b, 3]
    tx = 2.0 * (uy * vz - uz * vy)
    ty = 2.0 * (uz * vx - ux * vz)
    tz = 2.0 * (ux * vy - uy * vx)
    return vx + w * tx + (uy * tz - uz * ty), vy + w * ty + (uz * tx - ux * tz), vz + w * tz + (ux * ty - uy * tx)


@numba.njit(cache=True)
def angular_velocity(model, q: np.ndarray, L: np.ndarray, b: int) -> tuple[float, float, float]:  # noqa: ANN001
    """omega = R diag(1/I) R^T L [rad/s], world, of body b."""
    lx, ly, lz = rotate_inverse(q, b, L[b, 0], L[b, 1], L[b, 2])
    inv = model.body_inertia_inv
    return rotate(q, b, lx * inv[b, 0], ly * inv[b, 1], lz * inv[b, 2])


@numba.njit(cache=True)
def point_velocity(
    model,
    q: np.ndarray,
    P: np.ndarray,
    L: np.ndarray,
    b: int,
    rx: float,
    ry: float,
    rz: float,  # noqa: ANN001
) -> tuple[float, float, float]:
    """Velocity [m/s], world, of the point at world offset r from body b's centre of mass: v + omega x r."""
    wx, wy, wz = angular_velocity(model, q, L, b)
    inv_mass = 1.0 / model.body_mass[b]
    return (
        P[b, 0] * inv_mass + (wy * rz - wz * ry),
        P[b, 1] * inv_mass + (wz * rx - wx * rz),
        P[b, 2] * inv_mass + (wx * ry - wy * rx),
    )


@numba.njit(cache=True)
def add_force_at(
    F: np.ndarray, tau: np.ndarray, b: int, rx: float, ry: float, rz: float, fx: float, fy: float, fz: float
) -> None:
    """F_b += f, tau_b += r x f (r the world offset of the point of application from the centre of mass)."""
    F[b, 0] += fx
    F[b, 1] += fy
    F[b, 2] += fz
    tau[b, 0] += ry * fz - rz * fy
    tau[b, 1] += rz * fx - rx * fz
    tau[b, 2] += rx * fy - ry * fx
