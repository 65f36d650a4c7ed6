"""`euler-quat`: explicit Euler with a unit quaternion (the tutorial's method, quaternion form).

  x += dt P/M,  P += dt F,  L += dt tau,  q += dt/2 (0, omega) * q,  q <- q/|q|,
with omega = R diag(1/I) R^T L (world) and F, tau, omega all at the old state. The same first-order
method as `euler-matrix`, but renormalising a quaternion is frame-independent and cheaper than
Gram-Schmidt on a matrix. Not symplectic: the energy of a free body grows every step.
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


@numba.njit(**STEP_ENTRY)
def step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One explicit Euler step of every body, in place."""
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
    for b in range(x.shape[0]):
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        m0, m1, m2 = rotate_inverse(w, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2])
        o0, o1, o2 = rotate(w, qx, qy, qz, m0 * model.body_inertia_inv[b, 0], m1 * model.body_inertia_inv[b, 1],
                            m2 * model.body_inertia_inv[b, 2])  # fmt: skip
        inv_mass = 1.0 / model.body_mass[b]
        for k in range(3):
            x[b, k] += dt * P[b, k] * inv_mass
            P[b, k] += dt * F[b, k]
        if forces.has_torque and forces.torque_body[b]:  # tau = 0 for the other bodies
            for k in range(3):
                L[b, k] += dt * tau[b, k]
        # (0, omega) * q = (-omega . u, w omega + omega x u), u = (qx, qy, qz)
        hh = 0.5 * dt
        nw = w - hh * (o0 * qx + o1 * qy + o2 * qz)
        nx = qx + hh * (w * o0 + o1 * qz - o2 * qy)
        ny = qy + hh * (w * o1 + o2 * qx - o0 * qz)
        nz = qz + hh * (w * o2 + o0 * qy - o1 * qx)
        norm = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = nw * norm, nx * norm, ny * norm, nz * norm


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Plain numpy reference of `step`, vectorised over bodies, in place."""
    F, tau = wrench_numpy(model, forces, t, x, q, P, L)
    omega = angular_velocity_numpy(q, L, model.body_inertia_inv)
    x += dt * P / model.body_mass[:, None]
    P += dt * F
    if forces.has_torque:
        L += dt * tau
    q += 0.5 * dt * quat_multiply(np.concatenate([np.zeros((len(q), 1)), omega], axis=1), q)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
