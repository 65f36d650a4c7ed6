"""`semi-implicit`: the game-engine update (semi-implicit / symplectic Euler, as in Bullet and Box2D).

  P += dt F;  L += dt tau;  x += dt P/M  (the NEW velocity);
  omega = R diag(1/I) R^T L  with the CURRENT R (and the new L);  q <- exp(dt omega / 2) * q,
exp((0, v)) = (cos|v|, sin|v| v/|v|) the quaternion exponential, so q stays a unit quaternion.
For the centre of mass this is symplectic Euler (first order, bounded energy error under conservative
forces). For the rotation it is the Lie-Euler method: first order and NOT symplectic: the body
rotates for a whole step about the axis omega of the start of the step, so the body-frame angular
momentum picks up an O(dt) error per unit time, the energy drifts, and at game-size steps the
intermediate-axis (Dzhanibekov) flip comes out at the wrong times or not at all (docs/integrators.md).
L itself is held exactly when torque-free (the engines that integrate omega instead of L lose that
too). The variant that integrates omega with the explicit gyroscopic term is `semi-implicit-gyro`.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.forces.wrench import accumulate_wrench, wrench_numpy
from rbcli.physics.integrators.kinematics import angular_velocity_numpy, rotate, rotate_inverse
from rbcli.physics.rotation import quat_multiply
from rbcli.physics.step import STEP_ENTRY

SCRATCH_WIDTH = 0

# below this |v| = dt |omega| / 2, sin|v|/|v| = 1 - |v|^2/6 to round-off (the next term is |v|^4/120)
SMALL_ROTATION = 1e-4


@numba.njit(cache=True)
def exp_rotation(v0, v1, v2):  # noqa: ANN001, ANN201 - numba scalars
    """The quaternion exponential exp((0, v)) = (cos|v|, sin|v| v/|v|): a turn by 2|v| about v."""
    angle = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    if angle < SMALL_ROTATION:
        sinc = 1.0 - angle * angle / 6.0
    else:
        sinc = math.sin(angle) / angle
    return math.cos(angle), sinc * v0, sinc * v1, sinc * v2


@numba.njit(**STEP_ENTRY)
def step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One semi-implicit Euler step of every body, in place."""
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
    for b in range(x.shape[0]):
        inv_mass = 1.0 / model.body_mass[b]
        for k in range(3):
            P[b, k] += dt * F[b, k]
            x[b, k] += dt * P[b, k] * inv_mass
        if forces.has_torque and forces.torque_body[b]:  # tau = 0 for the other bodies
            for k in range(3):
                L[b, k] += dt * tau[b, k]
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        m0, m1, m2 = rotate_inverse(w, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2])
        o0, o1, o2 = rotate(w, qx, qy, qz, m0 * model.body_inertia_inv[b, 0], m1 * model.body_inertia_inv[b, 1],
                            m2 * model.body_inertia_inv[b, 2])  # fmt: skip
        hh = 0.5 * dt
        ew, ex, ey, ez = exp_rotation(hh * o0, hh * o1, hh * o2)
        nw = ew * w - ex * qx - ey * qy - ez * qz  # e * q (world-frame turn: left multiplication)
        nx = ew * qx + ex * w + ey * qz - ez * qy
        ny = ew * qy - ex * qz + ey * w + ez * qx
        nz = ew * qz + ex * qy - ey * qx + ez * w
        norm = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)  # round-off only
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = nw * norm, nx * norm, ny * norm, nz * norm


def exp_rotation_numpy(v: np.ndarray) -> np.ndarray:
    """exp((0, v)) for v (body_count, 3)."""
    angle = np.linalg.norm(v, axis=1)
    sinc = np.where(angle < SMALL_ROTATION, 1.0 - angle**2 / 6.0, np.sin(angle) / np.maximum(angle, 1e-300))
    return np.concatenate([np.cos(angle)[:, None], sinc[:, None] * v], axis=1)


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Plain numpy reference of `step`, vectorised over bodies, in place."""
    F, tau = wrench_numpy(model, forces, t, x, q, P, L)
    P += dt * F
    x += dt * P / model.body_mass[:, None]
    if forces.has_torque:
        L += dt * tau
    omega = angular_velocity_numpy(q, L, model.body_inertia_inv)
    q[:] = quat_multiply(exp_rotation_numpy(0.5 * dt * omega), q)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
