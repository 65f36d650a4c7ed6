"""`euler-matrix`: the tutorial's explicit Euler on (x, P, R, L) with Gram-Schmidt.

Chitalu & Komura, "Rigid body dynamics" tutorial (HKU), simulation step (2):
  x += dt v,  v += dt F/M (i.e. P += dt F),  R += dt omega* R,  L += dt tau,
  then re-orthonormalise R (Gram-Schmidt), with omega = R I0^-1 R^T L evaluated at the old state.
First order; not symplectic; loses the intermediate-axis flip and drifts in energy.
R is carried as a quaternion between steps (converted exactly after Gram-Schmidt). Gram-Schmidt
depends on the frame (it keeps the first column's direction), so it runs on the user-frame matrix
R_user = R E^T exactly as the tutorial would with the user's particles, not on the principal-frame R.
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics.forces.wrench import accumulate_wrench, wrench_numpy
from rbcli.physics.rotation import gram_schmidt, matrix_to_quat, quat_to_matrix, skew
from rbcli.physics.rotation_kernels import matrix_to_quat_nb, quat_to_matrix_nb
from rbcli.physics.step import STEP_ENTRY

# three 3x3 matrices (R, its update, R in the user frame) in row 0: views, so a step allocates nothing
SCRATCH_WIDTH = 27


# STEP_ENTRY (STEP_KERNEL, inlined into the chunk loop): without reference counting, which increfed and
# decrefed every array of the model and the force tables on each call and each scratch view: ~2/3 of a
# one-body step (docs/performance.md)
@numba.njit(**STEP_ENTRY)
def step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One explicit Euler step of every body, in place."""
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
    R = scratch[0, 0:9].reshape((3, 3))
    Rn = scratch[0, 9:18].reshape((3, 3))
    Ru = scratch[0, 18:27].reshape((3, 3))
    for b in range(x.shape[0]):
        quat_to_matrix_nb(q[b], R)
        inv_mass = 1.0 / model.body_mass[b]
        # omega = R diag(1/I) R^T L  (world), at the old state
        lb0 = R[0, 0] * L[b, 0] + R[1, 0] * L[b, 1] + R[2, 0] * L[b, 2]
        lb1 = R[0, 1] * L[b, 0] + R[1, 1] * L[b, 1] + R[2, 1] * L[b, 2]
        lb2 = R[0, 2] * L[b, 0] + R[1, 2] * L[b, 1] + R[2, 2] * L[b, 2]
        wb0 = lb0 * model.body_inertia_inv[b, 0]
        wb1 = lb1 * model.body_inertia_inv[b, 1]
        wb2 = lb2 * model.body_inertia_inv[b, 2]
        w0 = R[0, 0] * wb0 + R[0, 1] * wb1 + R[0, 2] * wb2
        w1 = R[1, 0] * wb0 + R[1, 1] * wb1 + R[1, 2] * wb2
        w2 = R[2, 0] * wb0 + R[2, 1] * wb1 + R[2, 2] * wb2
        for k in range(3):
            x[b, k] += dt * P[b, k] * inv_mass
            P[b, k] += dt * F[b, k]
        if forces.has_torque and forces.torque_body[b]:  # tau = 0 for the other bodies
            for k in range(3):
                L[b, k] += dt * tau[b, k]
        E = model.body_frame[b]
        for i in range(3):  # R_user = R E^T
            for j in range(3):
                Ru[i, j] = R[i, 0] * E[j, 0] + R[i, 1] * E[j, 1] + R[i, 2] * E[j, 2]
        # R_user += dt omega* R_user, column by column: (omega x R_user[:, j])
        for j in range(3):
            c0, c1, c2 = Ru[0, j], Ru[1, j], Ru[2, j]
            Rn[0, j] = c0 + dt * (w1 * c2 - w2 * c1)
            Rn[1, j] = c1 + dt * (w2 * c0 - w0 * c2)
            Rn[2, j] = c2 + dt * (w0 * c1 - w1 * c0)
        _gram_schmidt_nb(Rn)
        for i in range(3):  # back to the principal frame: R = R_user E
            for j in range(3):
                R[i, j] = Rn[i, 0] * E[0, j] + Rn[i, 1] * E[1, j] + Rn[i, 2] * E[2, j]
        matrix_to_quat_nb(R, q[b])


@numba.njit(cache=True, inline="always")
def _gram_schmidt_nb(R: np.ndarray) -> None:
    """The tutorial's Gram-Schmidt on the columns of R, in place."""
    n = np.sqrt(R[0, 0] ** 2 + R[1, 0] ** 2 + R[2, 0] ** 2)
    for i in range(3):
        R[i, 0] /= n
    d = R[0, 0] * R[0, 1] + R[1, 0] * R[1, 1] + R[2, 0] * R[2, 1]
    for i in range(3):
        R[i, 1] -= d * R[i, 0]
    n = np.sqrt(R[0, 1] ** 2 + R[1, 1] ** 2 + R[2, 1] ** 2)
    for i in range(3):
        R[i, 1] /= n
    d0 = R[0, 0] * R[0, 2] + R[1, 0] * R[1, 2] + R[2, 0] * R[2, 2]
    d1 = R[0, 1] * R[0, 2] + R[1, 1] * R[1, 2] + R[2, 1] * R[2, 2]
    for i in range(3):
        R[i, 2] -= d0 * R[i, 0] + d1 * R[i, 1]
    n = np.sqrt(R[0, 2] ** 2 + R[1, 2] ** 2 + R[2, 2] ** 2)
    for i in range(3):
        R[i, 2] /= n


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Plain numpy reference of `step`, vectorised over bodies, in place."""
    F, tau = wrench_numpy(model, forces, t, x, q, P, L)
    R = quat_to_matrix(q)
    omega = np.einsum("bij,bj->bi", R, np.einsum("bji,bj->bi", R, L) * model.body_inertia_inv)
    x += dt * P / model.body_mass[:, None]
    P += dt * F
    L += dt * tau
    R_user = R @ np.swapaxes(model.body_frame, -1, -2)
    q[:] = matrix_to_quat(gram_schmidt(R_user + dt * skew(omega) @ R_user) @ model.body_frame)
