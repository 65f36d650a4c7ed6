"""`semi-implicit-gyro`: a counter-example, kept to show why rbsim integrates L and not omega.

Engines that carry the angular velocity add the gyroscopic term explicitly (Bullet's
"explicit gyroscopic force"): in the body frame
  omega_b += dt diag(1/I) (tau_b - omega_b x I omega_b),
  q <- q * exp(dt omega_b / 2), then L = R(q) I omega_b, the centre of mass as in `semi-implicit`.
This is explicit Euler on Euler's equations, and for those it is unconditionally unstable: with
m = I omega_b the update is m += dt (m x omega_b), orthogonal to m, so |m|^2 grows by
dt^2 |m x omega_b|^2 every step: |L| grows by a factor of up to 1 + (dt |omega|)^2 / 2 per step.
At a fast spin (omega ~ 100 rad/s, dt = 1/60) that is exponential growth to overflow within a few
dozen steps; at slow spins it is a steady energy gain. Bullet clamps the gyroscopic term for that
reason. Use `semi-implicit` instead.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.forces.wrench import accumulate_wrench, wrench_numpy
from rbcli.physics.integrators.kinematics import rotate, rotate_inverse
from rbcli.physics.integrators.semi_implicit import exp_rotation, exp_rotation_numpy
from rbcli.physics.rotation import quat_multiply, quat_rotate, quat_rotate_inverse
from rbcli.physics.step import STEP_ENTRY

SCRATCH_WIDTH = 0


@numba.njit(**STEP_ENTRY)
def step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One step with the explicit gyroscopic term, in place."""
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
    for b in range(x.shape[0]):
        inv_mass = 1.0 / model.body_mass[b]
        for k in range(3):
            P[b, k] += dt * F[b, k]
            x[b, k] += dt * P[b, k] * inv_mass
        i0, i1, i2 = model.body_inertia[b, 0], model.body_inertia[b, 1], model.body_inertia[b, 2]
        w, qx, qy, qz = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        m0, m1, m2 = rotate_inverse(w, qx, qy, qz, L[b, 0], L[b, 1], L[b, 2])
        o0, o1, o2 = m0 / i0, m1 / i1, m2 / i2
        t0, t1, t2 = 0.0, 0.0, 0.0
        # tau = 0 for the bodies torque_body does not flag, and in most steps of a contact body far from
        # anything: turning a zero tau into the body frame gives zeros, up to the sign of a zero, which
        # changes no value that follows (as split2's skipped kick; ~10 ns per body-step)
        if forces.has_torque and forces.torque_body[b] and (tau[b, 0] != 0.0 or tau[b, 1] != 0.0 or tau[b, 2] != 0.0):
            t0, t1, t2 = rotate_inverse(w, qx, qy, qz, tau[b, 0], tau[b, 1], tau[b, 2])
        # omega += dt I^-1 (tau - omega x I omega), all body frame, all at the old state
        n0 = o0 + dt * (t0 - (o1 * m2 - o2 * m1)) / i0
        n1 = o1 + dt * (t1 - (o2 * m0 - o0 * m2)) / i1
        n2 = o2 + dt * (t2 - (o0 * m1 - o1 * m0)) / i2
        hh = 0.5 * dt
        ew, ex, ey, ez = exp_rotation(hh * n0, hh * n1, hh * n2)
        nw = w * ew - qx * ex - qy * ey - qz * ez  # q * e (body-frame turn: right multiplication)
        nx = w * ex + qx * ew + qy * ez - qz * ey
        ny = w * ey - qx * ez + qy * ew + qz * ex
        nz = w * ez + qx * ey - qy * ex + qz * ew
        norm = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
        nw, nx, ny, nz = nw * norm, nx * norm, ny * norm, nz * norm
        L[b, 0], L[b, 1], L[b, 2] = rotate(nw, nx, ny, nz, i0 * n0, i1 * n1, i2 * n2)  # L = R_new I omega_new
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = nw, nx, ny, nz


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Plain numpy reference of `step`, vectorised over bodies, in place."""
    F, tau = wrench_numpy(model, forces, t, x, q, P, L)
    P += dt * F
    x += dt * P / model.body_mass[:, None]
    inertia = model.body_inertia
    m = quat_rotate_inverse(q, L)
    omega = m / inertia
    tau_b = quat_rotate_inverse(q, tau) if forces.has_torque else np.zeros_like(L)
    omega = omega + dt * (tau_b - np.cross(omega, m)) / inertia
    q[:] = quat_multiply(q, exp_rotation_numpy(0.5 * dt * omega))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    L[:] = quat_rotate(q, inertia * omega)
