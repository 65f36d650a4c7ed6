"""Kinematics derived from the state: outputs in the user's frame, and particle world positions.

Particle update (tutorial, step 3): r_i = R r0_i, x_i = x + r_i, v_i = v + omega x r_i. Computed
only when something consumes particles (a particle force, contact, or the particles stream).
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.model import Model
from rbcli.physics.rotation import quat_conjugate, quat_multiply, quat_to_matrix


def body_velocity(model: Model, P: np.ndarray) -> np.ndarray:
    """v = P / M [m/s], any leading axes (..., body_count, 3)."""
    return P / model.body_mass[:, None]


def body_angular_velocity(model: Model, q: np.ndarray, L: np.ndarray) -> np.ndarray:
    """omega = R diag(1/I) R^T L [rad/s], world; q world-from-principal; (..., body_count, 3)."""
    R = quat_to_matrix(q)
    L_body = np.einsum("...ji,...j->...i", R, L)
    return np.einsum("...ij,...j->...i", R, L_body / model.body_inertia)


def user_orientation(model: Model, q: np.ndarray) -> np.ndarray:
    """World-from-user-frame quaternion from the internal world-from-principal q (w >= 0)."""
    out = quat_multiply(q, quat_conjugate(model.body_frame_q))
    return np.where(out[..., :1] < 0.0, -out, out)


def internal_orientation(model: Model, q_user: np.ndarray) -> np.ndarray:
    """World-from-principal quaternion from a world-from-user one (w >= 0)."""
    out = quat_multiply(q_user, model.body_frame_q)
    return np.where(out[..., :1] < 0.0, -out, out)


def particle_world(
    model: Model, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """World positions x_i [m] and velocities v_i [m/s] of all particles, (..., particle_count, 3)."""
    body_of = np.repeat(np.arange(model.body_count), model.body_particle_count)
    R = quat_to_matrix(q)[..., body_of, :, :]
    r = np.einsum("...ij,...j->...i", R, model.particle_offset)
    omega = body_angular_velocity(model, q, L)[..., body_of, :]
    v = body_velocity(model, P)[..., body_of, :]
    return x[..., body_of, :] + r, v + np.cross(omega, r)
