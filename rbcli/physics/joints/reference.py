"""Plain numpy twins of the joint kernels: the rows (rows.py) and a whole split2 step of a scene with
joints (rattle.py and the velocity stage, stages.py). Tests compare the kernels with them;
scene/compile_joints.py uses the rows and matrices once, at compile time, to find redundant rows (a
loop that constrains a direction twice) and warn about them.

Written for clarity, one joint at a time, with a dense numpy solve; the compiled stages must agree with
them to round-off.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.joints.tables import (
    JOINT_BALL,
    JOINT_DISTANCE,
    JOINT_FIXED,
    JOINT_HINGE,
    JOINT_SLIDER,
    JointTable,
)
from rbcli.physics.rotation import quat_conjugate, quat_multiply, quat_to_matrix, skew


def joint_rows_numpy(table: JointTable, x: np.ndarray, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(g (R,), G_a (R, 6), G_b (R, 6)) at the configuration (x, q): rows.joint_rows in numpy."""
    rows = int(table.row_count.sum())
    g, ga, gb = np.zeros(rows), np.zeros((rows, 6)), np.zeros((rows, 6))
    R = quat_to_matrix(q)
    for j in range(table.kind.shape[0]):
        a, b, r, kind = int(table.body_a[j]), int(table.body_b[j]), int(table.row_start[j]), int(table.kind[j])
        ra = R[a] @ table.anchor_a[j]
        Rb = R[b] if b >= 0 else np.eye(3)
        qb = q[b] if b >= 0 else np.array([1.0, 0.0, 0.0, 0.0])
        rb = Rb @ table.anchor_b[j] if b >= 0 else np.zeros(3)
        d = x[a] + ra - (x[b] + rb if b >= 0 else table.anchor_b[j])

        def linear(r: int, n: np.ndarray, turn: np.ndarray, ra: np.ndarray = ra, rb: np.ndarray = rb) -> None:
            ga[r] = np.concatenate([n, np.cross(ra, n)])
            gb[r] = np.concatenate([-n, -np.cross(rb, n) + turn])

        if kind in (JOINT_BALL, JOINT_HINGE, JOINT_FIXED):
            for i, e in enumerate(np.eye(3)):
                g[r] = d[i]
                linear(r, e, np.zeros(3))
                r += 1
        if kind == JOINT_DISTANCE:
            length = np.linalg.norm(d)
            g[r] = length - table.length[j]
            linear(r, d / length, np.zeros(3))
            r += 1
        if kind in (JOINT_FIXED, JOINT_SLIDER):
            e = quat_multiply(quat_multiply(q[a], quat_conjugate(table.relative_q[j])), quat_conjugate(qb))
            e = -e if e[0] < 0 else e
            for i in range(3):
                g[r] = 2.0 * e[1 + i]
                ga[r, 3:] = e[0] * np.eye(3)[i] - skew(e[1:])[i]
                gb[r, 3:] = -(e[0] * np.eye(3)[i] + skew(e[1:])[i])
                r += 1
        if kind == JOINT_HINGE:
            u = R[a] @ table.axis_a[j]
            for k in range(2):
                n = Rb @ table.normal_b[j, k]
                g[r] = u @ n
                ga[r, 3:], gb[r, 3:] = np.cross(u, n), -np.cross(u, n)
                r += 1
        if kind == JOINT_SLIDER:
            for k in range(2):
                n = Rb @ table.normal_b[j, k]
                g[r] = d @ n
                linear(r, n, np.cross(n, d))
                r += 1
    return g, ga, gb


def joint_violations_numpy(model, table: JointTable, x, q, P, L) -> np.ndarray:  # noqa: ANN001
    """violation.joint_violations in numpy: (K, 2), each frame's max |g| and max |G V| (every body's own
    velocity, ground bodies' too) of the (K, N, ...) states; model: a Model or KernelModel."""
    out = np.zeros((x.shape[0], 2))
    for k in range(x.shape[0]):
        g, ga, gb = joint_rows_numpy(table, x[k], q[k])
        R = quat_to_matrix(q[k])
        omega = np.einsum("bij,bj,bkj,bk->bi", R, 1.0 / model.body_inertia, R, L[k])
        V = np.concatenate([P[k] / model.body_mass[:, None], omega], axis=1)  # (N, 6): (v, omega)
        rows = np.repeat(np.arange(table.kind.shape[0]), table.row_count)
        a, b = table.body_a[rows], table.body_b[rows]
        gv = np.einsum("rc,rc->r", ga, V[a]) + np.where(b >= 0, np.einsum("rc,rc->r", gb, V[np.maximum(b, 0)]), 0.0)
        out[k] = (np.abs(g).max(initial=0.0), np.abs(gv).max(initial=0.0))
    return out


def body_weights_numpy(model, table: JointTable, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """(1 / M (N,), R I0^-1 R^T (N, 3, 3)) at orientations q, zero for ground bodies; model: a Model or
    KernelModel (body_mass, body_inertia)."""
    R = quat_to_matrix(q)
    inv_inertia = np.einsum("bij,bj,bkj->bik", R, 1.0 / model.body_inertia, R)
    inv_mass = 1.0 / model.body_mass
    inv_mass[table.body_ground] = 0.0
    inv_inertia[table.body_ground] = 0.0
    return inv_mass, inv_inertia


def rows_matrix_numpy(table: JointTable, ga: np.ndarray, gb: np.ndarray, bodies: int) -> np.ndarray:
    """G (R, 6 N): the rows against every body's (v, omega)."""
    G = np.zeros((ga.shape[0], 6 * bodies))
    for j in range(table.kind.shape[0]):
        rows = slice(int(table.row_start[j]), int(table.row_start[j] + table.row_count[j]))
        a, b = int(table.body_a[j]), int(table.body_b[j])
        G[rows, 6 * a : 6 * a + 6] += ga[rows]
        if b >= 0:
            G[rows, 6 * b : 6 * b + 6] += gb[rows]
    return G


def weight_matrix_numpy(inv_mass: np.ndarray, inv_inertia: np.ndarray) -> np.ndarray:
    """W = blockdiag(I3 / M_b, R_b I0_b^-1 R_b^T) (6 N, 6 N)."""
    n = inv_mass.shape[0]
    W = np.zeros((6 * n, 6 * n))
    for b in range(n):
        W[6 * b : 6 * b + 3, 6 * b : 6 * b + 3] = inv_mass[b] * np.eye(3)
        W[6 * b + 3 : 6 * b + 6, 6 * b + 3 : 6 * b + 6] = inv_inertia[b]
    return W


def rattle_step_numpy(model, forces, table: JointTable, t: float, h: float, x, q, P, L) -> np.ndarray:  # noqa: ANN001
    """rattle.joint_update and the velocity stage without drives or limits, in place: K(h/2), the joints'
    impulse along G at the start found by Newton through split2's free drift, K(h/2) with the end's
    forces, the velocity projection; returns the step's multipliers (R,)."""
    # here, not at the top: scene/compile_joints.py imports this module for the rows alone
    from rbcli.physics.forces.damping import dissipation_flow_numpy
    from rbcli.physics.forces.wrench import wrench_numpy
    from rbcli.physics.integrators.split2 import free_drift_numpy

    n = x.shape[0]
    moving = ~table.body_ground
    drag = forces.drag
    coefficients = np.concatenate([drag.linear, drag.quadratic, drag.angular_linear, drag.angular_quadratic])
    dissipative = bool(np.any(forces.spring.damping != 0.0) or np.any(coefficients != 0.0))
    F, tau = wrench_numpy(model, forces, t, x, q, P, L, dissipative=not dissipative)
    P += 0.5 * h * F
    L += 0.5 * h * tau
    if dissipative:
        dissipation_flow_numpy(model, forces.spring, forces.drag, 0.5 * h, x, q, P, L)
    x0, q0 = x.copy(), q.copy()
    inv_mass, inv_inertia = body_weights_numpy(model, table, q0)
    _, ga, gb = joint_rows_numpy(table, x0, q0)
    G = rows_matrix_numpy(table, ga, gb, n)
    A = G @ weight_matrix_numpy(inv_mass, inv_inertia) @ G.T
    total = np.zeros(G.shape[0])
    x[:], q[:] = free_drift_numpy(model, h, x0, q0, P, L)
    g = joint_rows_numpy(table, x, q)[0]
    for _ in range(50):
        if not np.abs(g).max() > 0.0:
            break
        delta = np.linalg.solve(A, -g / h)
        total += delta
        d = (G.T @ delta).reshape(n, 6) * moving[:, None]
        P += d[:, :3]
        L += d[:, 3:]
        drifted = free_drift_numpy(model, h, x0, q0, P, L)
        x[moving], q[moving] = drifted[0][moving], drifted[1][moving]
        previous, g = np.abs(g).max(), joint_rows_numpy(table, x, q)[0]
        if np.abs(g).max() > 0.5 * previous:
            break
    F, tau = wrench_numpy(model, forces, t + h, x, q, P, L, dissipative=not dissipative)
    if dissipative:
        dissipation_flow_numpy(model, forces.spring, forces.drag, 0.5 * h, x, q, P, L)
    P += 0.5 * h * F
    L += 0.5 * h * tau
    return total - project_velocities_numpy(model, table, x, q, P, L)


def _rates(model, table: JointTable, x, q, P, L):  # noqa: ANN001, ANN202
    """(G (R, 6 N), W (6 N, 6 N), G V (R,)) at (x, q), V every body's own velocity (ground bodies' too)."""
    n = x.shape[0]
    inv_mass, inv_inertia = body_weights_numpy(model, table, q)
    _, ga, gb = joint_rows_numpy(table, x, q)
    G = rows_matrix_numpy(table, ga, gb, n)
    omega = np.einsum("bij,bj->bi", body_weights_numpy(model, table._replace(body_ground=np.zeros(n, bool)), q)[1], L)
    V = np.concatenate([P / model.body_mass[:, None], omega], axis=1).reshape(-1)
    return G, weight_matrix_numpy(inv_mass, inv_inertia), G @ V


def project_velocities_numpy(model, table: JointTable, x, q, P, L) -> np.ndarray:  # noqa: ANN001
    """(P, L) -= G^T mu with mu = (G W G^T)^-1 G V, in place (stages.project_momenta); returns mu."""
    G, W, rate = _rates(model, table, x, q, P, L)
    mu = np.linalg.solve(G @ W @ G.T, rate)
    d = (G.T @ mu).reshape(x.shape[0], 6) * ~table.body_ground[:, None]
    P -= d[:, :3]
    L -= d[:, 3:]
    return mu


def joint_begin_numpy(model, table: JointTable, x, q, P, L) -> None:  # noqa: ANN001
    """stages.joint_begin: the velocities projected when some row's rate exceeds 1e-12."""
    if np.abs(_rates(model, table, x, q, P, L)[2]).max() > 1e-12:
        project_velocities_numpy(model, table, x, q, P, L)
