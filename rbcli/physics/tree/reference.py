"""Numpy reference of the tree kernels: forward kinematics, the joint-space mass matrix by the composite-
rigid-body algorithm (CRBA), bias forces by recursive Newton-Euler (RNEA), accelerations by a dense solve.

Written with explicit 6 x 6 Plucker matrices (Featherstone, Rigid Body Dynamics Algorithms, 2008: ch. 2
for the algebra, 5.3 RNEA, 6.2 CRBA), rotations from Rodrigues' formula rather than quaternion
products, so it shares the conventions of table.py and none of aba.py's code. O(n^2) and slow: tests.

    M(q) qdd + b(q, rate) = tau,   b = RNEA(q, rate, qdd = 0) with the external forces taken off

qdd is the rates' time derivative (a ball's relative angular velocity in the link frame, a free root's
(omega, v) in its own frame), tau the joint forces (dual to the rates: power tau . rate).
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.joints.tables import JOINT_BALL, JOINT_HINGE, JOINT_SLIDER
from rbcli.physics.rotation import quat_to_matrix
from rbcli.physics.tree.table import TREE_FREE, TreeTable, tree_dof_count


def skew(v: np.ndarray) -> np.ndarray:
    """[v], with [v] w = v x w."""
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def axis_angle_matrix(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues: cos t 1 + sin t [a] + (1 - cos t) a a^T."""
    return np.cos(angle) * np.eye(3) + np.sin(angle) * skew(axis) + (1.0 - np.cos(angle)) * np.outer(axis, axis)


def joint_placement(tree: TreeTable, i: int, coord: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(R_rel, r): parent-from-link rotation and the link's origin in the parent's frame (world for a
    root) at coordinates `coord` (table.py's joint model)."""
    k, c0 = int(tree.kind[i]), int(tree.coord_start[i])
    if k == TREE_FREE:
        u = coord[c0 + 3 : c0 + 7]
        return quat_to_matrix(u / np.linalg.norm(u)), coord[c0 : c0 + 3].copy()
    rotation = quat_to_matrix(tree.rest_q[i])
    travel = 0.0
    if k == JOINT_HINGE:
        rotation = rotation @ axis_angle_matrix(tree.axis[i], coord[c0])
    elif k == JOINT_SLIDER:
        travel = coord[c0]
    elif k == JOINT_BALL:
        rotation = rotation @ quat_to_matrix(coord[c0 : c0 + 4])
    return rotation, tree.anchor_parent[i] + rotation @ (travel * tree.axis[i] - tree.anchor_child[i])


def motion_transform(rotation: np.ndarray, offset: np.ndarray) -> np.ndarray:
    """X, link-from-parent for motion vectors (omega, v): [[E, 0], [-E [r], E]], E = rotation^T."""
    E = rotation.T
    X = np.zeros((6, 6))
    X[:3, :3] = X[3:, 3:] = E
    X[3:, :3] = -E @ skew(offset)
    return X


def motion_cross(v: np.ndarray) -> np.ndarray:
    """v x for motion vectors: [[w], 0], [[v], [w]]]."""
    out = np.zeros((6, 6))
    out[:3, :3] = out[3:, 3:] = skew(v[:3])
    out[3:, :3] = skew(v[3:])
    return out


def spatial_inertia(tree: TreeTable, i: int) -> np.ndarray:
    """Link i's spatial inertia at its centre of mass, link frame: diag(I1, I2, I3, m, m, m)."""
    return np.diag(np.concatenate([tree.inertia[i], np.full(3, tree.mass[i])]))


def motion_subspace(tree: TreeTable, i: int) -> np.ndarray:
    """S (6, k): link i's rates' motion, link frame."""
    return tree.motion[tree.dof_start[i] : tree.dof_start[i + 1]].T


def forward_kinematics(tree: TreeTable, coord: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World-from-link rotations (n, 3, 3) and world centres of mass (n, 3)."""
    n = tree.parent.shape[0]
    rotation, position = np.zeros((n, 3, 3)), np.zeros((n, 3))
    for i in range(n):
        R_rel, r = joint_placement(tree, i, coord)
        p = int(tree.parent[i])
        if p < 0:
            rotation[i], position[i] = R_rel, r
        else:
            rotation[i], position[i] = rotation[p] @ R_rel, position[p] + rotation[p] @ r
    return rotation, position


def transforms(tree: TreeTable, coord: np.ndarray) -> list[np.ndarray]:
    """Each link's X (6, 6), link-from-parent (link-from-world for a root)."""
    return [motion_transform(*joint_placement(tree, i, coord)) for i in range(tree.parent.shape[0])]


def link_velocities(tree: TreeTable, coord: np.ndarray, rate: np.ndarray) -> np.ndarray:
    """Spatial velocities (omega, v) (n, 6), link frame: v_i = X_i v_parent + S_i rate_i."""
    X = transforms(tree, coord)
    n = tree.parent.shape[0]
    v = np.zeros((n, 6))
    for i in range(n):
        p = int(tree.parent[i])
        d0, d1 = tree.dof_start[i], tree.dof_start[i + 1]
        v[i] = (X[i] @ v[p] if p >= 0 else 0.0) + motion_subspace(tree, i) @ rate[d0:d1]
    return v


def world_velocities(tree: TreeTable, coord: np.ndarray, rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centre-of-mass velocities and angular velocities (n, 3) each, world frame."""
    rotation, _ = forward_kinematics(tree, coord)
    v = link_velocities(tree, coord, rate)
    return np.einsum("nij,nj->ni", rotation, v[:, 3:]), np.einsum("nij,nj->ni", rotation, v[:, :3])


def external_wrenches(tree: TreeTable, coord: np.ndarray, force: np.ndarray, torque: np.ndarray) -> np.ndarray:
    """The links' external forces (n, 6) (torque about the centre of mass, force), link frame, from world
    force and torque arrays indexed by body (as the state's F, tau)."""
    rotation, _ = forward_kinematics(tree, coord)
    f, t = force[tree.body], torque[tree.body]
    return np.concatenate([np.einsum("nji,nj->ni", rotation, t), np.einsum("nji,nj->ni", rotation, f)], axis=1)


def inverse_dynamics(
    tree: TreeTable, coord: np.ndarray, rate: np.ndarray, qdd: np.ndarray, f_ext: np.ndarray
) -> np.ndarray:
    """RNEA: the joint forces tau (D,) that give accelerations qdd, external forces f_ext (n, 6) link
    frame: a_i = X_i a_parent + S_i qdd_i + v_i x S_i rate_i, f_i = I a_i + v_i x* I v_i - f_ext_i,
    tau_i = S_i^T f_i, f_parent += X_i^T f_i."""
    X = transforms(tree, coord)
    v = link_velocities(tree, coord, rate)
    n = tree.parent.shape[0]
    a, f = np.zeros((n, 6)), np.zeros((n, 6))
    for i in range(n):
        p = int(tree.parent[i])
        d0, d1 = tree.dof_start[i], tree.dof_start[i + 1]
        S = motion_subspace(tree, i)
        a[i] = (X[i] @ a[p] if p >= 0 else 0.0) + S @ qdd[d0:d1] + motion_cross(v[i]) @ (S @ rate[d0:d1])
        inertia = spatial_inertia(tree, i)
        f[i] = inertia @ a[i] - motion_cross(v[i]).T @ (inertia @ v[i]) - f_ext[i]  # v x* = -(v x)^T
    tau = np.zeros(tree_dof_count(tree))
    for i in range(n - 1, -1, -1):
        p = int(tree.parent[i])
        d0, d1 = tree.dof_start[i], tree.dof_start[i + 1]
        tau[d0:d1] = motion_subspace(tree, i).T @ f[i]
        if p >= 0:
            f[p] += X[i].T @ f[i]
    return tau


def mass_matrix(tree: TreeTable, coord: np.ndarray) -> np.ndarray:
    """CRBA: M (D, D). Composite inertias Ic_parent += X^T Ic X (leaves first); M_ii = S_i^T Ic_i S_i and
    M_ji = S_j^T (X^T ... F), F = Ic_i S_i carried up to each ancestor j."""
    X = transforms(tree, coord)
    n = tree.parent.shape[0]
    composite = [spatial_inertia(tree, i) for i in range(n)]
    M = np.zeros((tree_dof_count(tree),) * 2)
    for i in range(n - 1, -1, -1):
        p = int(tree.parent[i])
        if p >= 0:
            composite[p] = composite[p] + X[i].T @ composite[i] @ X[i]
    for i in range(n):
        rows = slice(tree.dof_start[i], tree.dof_start[i + 1])
        F = composite[i] @ motion_subspace(tree, i)
        M[rows, rows] = motion_subspace(tree, i).T @ F
        j = i
        while tree.parent[j] >= 0:
            F = X[j].T @ F
            j = int(tree.parent[j])
            cols = slice(tree.dof_start[j], tree.dof_start[j + 1])
            M[cols, rows] = motion_subspace(tree, j).T @ F
            M[rows, cols] = M[cols, rows].T
    return M


def accelerations(
    tree: TreeTable,
    coord: np.ndarray,
    rate: np.ndarray,
    joint_force: np.ndarray,
    force: np.ndarray,
    torque: np.ndarray,
) -> np.ndarray:
    """qdd (D,) from M qdd = tau - b: the mass matrix by CRBA, the bias b by RNEA with qdd = 0; the
    external force and torque (world, about each centre of mass) indexed by body as the state's F, tau."""
    f_ext = external_wrenches(tree, coord, force, torque)
    bias = inverse_dynamics(tree, coord, rate, np.zeros_like(rate), f_ext)
    return np.linalg.solve(mass_matrix(tree, coord), joint_force - bias)
