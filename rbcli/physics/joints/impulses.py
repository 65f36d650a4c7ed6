"""Shared pieces of the joint stages: body weights W at a configuration, the rows' momentum changes per
body, and the rows' rates G V.

W_b = blockdiag(I3 / M_b, R_b I0_b^-1 R_b^T) (0 for ground bodies, which act as the world); an impulse
(dP, dL) changes P and L by it (the position stage then drifts the body again: joints/rattle.py).
"""

from __future__ import annotations

import numba

from rbcli.physics.integrators.kinematics import rotate, rotate_inverse


@numba.njit(cache=True)
def body_weights(model, table, work, q) -> None:  # noqa: ANN001
    """inv_mass and world inverse inertia R I0^-1 R^T of every body at orientations q (0: ground)."""
    for b in range(q.shape[0]):
        if table.body_ground[b]:
            work.inv_mass[b] = 0.0
            for i in range(3):
                for k in range(3):
                    work.inv_inertia[b, i, k] = 0.0
            continue
        work.inv_mass[b] = 1.0 / model.body_mass[b]
        w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
        c00, c01, c02 = rotate(w, x, y, z, 1.0, 0.0, 0.0)
        c10, c11, c12 = rotate(w, x, y, z, 0.0, 1.0, 0.0)
        c20, c21, c22 = rotate(w, x, y, z, 0.0, 0.0, 1.0)
        i0, i1, i2 = model.body_inertia_inv[b, 0], model.body_inertia_inv[b, 1], model.body_inertia_inv[b, 2]
        # columns c_k = R e_k: (R D R^T)_ik = sum_k D_k c_k[i] c_k[m]
        col = ((c00, c01, c02), (c10, c11, c12), (c20, c21, c22))
        for i in range(3):
            for m in range(3):
                work.inv_inertia[b, i, m] = (
                    i0 * col[0][i] * col[0][m] + i1 * col[1][i] * col[1][m] + (i2 * col[2][i] * col[2][m])
                )


@numba.njit(cache=True, inline="always")
def body_omega(model, q, L, b):  # noqa: ANN001, ANN202
    """omega = R I0^-1 R^T L [rad/s], world."""
    w, x, y, z = q[b, 0], q[b, 1], q[b, 2], q[b, 3]
    m0, m1, m2 = rotate_inverse(w, x, y, z, L[b, 0], L[b, 1], L[b, 2])
    inv = model.body_inertia_inv
    return rotate(w, x, y, z, inv[b, 0] * m0, inv[b, 1] * m1, inv[b, 2] * m2)


@numba.njit(cache=True)
def gather_impulses(table, work, multipliers) -> None:  # noqa: ANN001
    """impulse_body = G^T multipliers per body (ground bodies and the world get nothing); each joint's part
    is also added to work.joint_impulse (its bodies' momentum change by this joint, for the reactions)."""
    body_impulses(table, work, multipliers)
    joint_impulses(table, work, multipliers)


@numba.njit(cache=True)
def body_impulses(table, work, multipliers) -> None:  # noqa: ANN001
    """impulse_body = G^T multipliers per body, without the per-joint parts (`gather_impulses` adds those):
    the position stage's Newton iterations, whose sum goes to the joints once (joints/rattle.py)."""
    impulse = work.impulse_body
    impulse[:, :] = 0.0
    for j in range(table.kind.shape[0]):
        a, b = table.body_a[j], table.body_b[j]
        for r in range(table.row_start[j], table.row_start[j] + table.row_count[j]):
            m = multipliers[r]
            for c in range(6):
                impulse[a, c] += work.jac_a[r, c] * m
                if b >= 0:
                    impulse[b, c] += work.jac_b[r, c] * m


@numba.njit(cache=True)
def joint_impulses(table, work, multipliers) -> None:  # noqa: ANN001
    """work.joint_impulse += each joint's part of G^T multipliers on its two bodies (the reactions)."""
    by_joint = work.joint_impulse
    for j in range(table.kind.shape[0]):
        b = table.body_b[j]
        for r in range(table.row_start[j], table.row_start[j] + table.row_count[j]):
            m = multipliers[r]
            for c in range(6):
                by_joint[j, c] += work.jac_a[r, c] * m
                if b >= 0:
                    by_joint[j, 6 + c] += work.jac_b[r, c] * m


@numba.njit(cache=True)
def apply_body_impulses(table, work, P, L) -> None:  # noqa: ANN001
    """P, L += work.impulse_body of every moving body."""
    for b in range(P.shape[0]):
        if table.body_ground[b]:
            continue
        d = work.impulse_body[b]
        P[b, 0] += d[0]
        P[b, 1] += d[1]
        P[b, 2] += d[2]
        L[b, 0] += d[3]
        L[b, 1] += d[4]
        L[b, 2] += d[5]


@numba.njit(cache=True)
def row_velocities(model, table, work, q, P, L) -> float:  # noqa: ANN001
    """residual = G V (every body's own velocity, ground bodies' too); returns max |G V|."""
    worst = 0.0
    for j in range(table.kind.shape[0]):
        a, b = table.body_a[j], table.body_b[j]
        inv_a = 1.0 / model.body_mass[a]
        oa0, oa1, oa2 = body_omega(model, q, L, a)
        va = (inv_a * P[a, 0], inv_a * P[a, 1], inv_a * P[a, 2], oa0, oa1, oa2)
        vb = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        if b >= 0:
            inv_b = 1.0 / model.body_mass[b]
            ob0, ob1, ob2 = body_omega(model, q, L, b)
            vb = (inv_b * P[b, 0], inv_b * P[b, 1], inv_b * P[b, 2], ob0, ob1, ob2)
        for r in range(table.row_start[j], table.row_start[j] + table.row_count[j]):
            total = 0.0
            for c in range(6):
                total += work.jac_a[r, c] * va[c] + work.jac_b[r, c] * vb[c]
            work.residual[r] = total
            worst = max(worst, abs(total))
    return worst
