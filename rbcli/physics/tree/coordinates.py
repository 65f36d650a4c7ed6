"""The trees' coordinates and rates from the bodies' x, q, P, L: where a run's reduced state starts (the
scene's initial state, `Simulation.set_state`, `reset`).

Coordinates from the poses, link by link: the relative rotation u = rest_q^* q_parent^* q_link gives a
hinge's angle (2 atan2(u_vec . axis, u_w)) and a ball's quaternion, the anchors' offset along the axis a
slider's travel, the body pose a free root's. Rates from the momenta: the joints allow the velocities
V = J rate, and the ones closest to the bodies' in kinetic energy (the exact impulsive reaction of the
joints on velocities that break them, as the maximal joints' joint_begin projects them: docs/joints.md)
solve M(coord) rate = J^T h, h the bodies' momenta. J^T h is one backward pass (integrate.py
`generalized_momentum`) and M^-1 one ABA at zero rates without forces (the bias is then zero). Poses
the joints do not allow (a gap) are replaced by the closest the coordinates reach link by link; the
state arrays are then rewritten by forward kinematics, so they and (coord, rate) agree.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.joints.tables import JOINT_BALL, JOINT_HINGE, JOINT_SLIDER
from rbcli.physics.rotation import quat_conjugate, quat_multiply, quat_rotate
from rbcli.physics.tree.table import TREE_FREE, TreeData, TreeTable


def coords_from_poses(tree: TreeTable, x: np.ndarray, q: np.ndarray) -> np.ndarray:
    """(C,) joint coordinates of the links' poses (state rows tree.body), as the module docstring says."""
    n = tree.parent.shape[0]
    coord = np.zeros(int(tree.coord_start[-1]))
    body, parent = tree.body, tree.parent
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    q_parent = np.array([identity if p < 0 else q[body[p]] for p in parent.tolist()]).reshape(n, 4)
    x_parent = np.array([np.zeros(3) if p < 0 else x[body[p]] for p in parent.tolist()]).reshape(n, 3)
    q_link = q[body]
    relative = quat_multiply(quat_conjugate(tree.rest_q), quat_multiply(quat_conjugate(q_parent), q_link))
    for i, kind in enumerate(tree.kind.tolist()):  # once per link, outside the steps
        c0 = int(tree.coord_start[i])
        if kind == JOINT_HINGE:
            u = relative[i]
            coord[c0] = 2.0 * np.arctan2(float(u[1:] @ tree.axis[i]), float(u[0]))
        elif kind == JOINT_BALL:
            u = relative[i]
            coord[c0 : c0 + 4] = u / np.linalg.norm(u)
        elif kind == JOINT_SLIDER:
            anchor_link = x[body[i]] + quat_rotate(q_link[i][None], tree.anchor_child[i][None])[0]
            anchor_parent = x_parent[i] + quat_rotate(q_parent[i][None], tree.anchor_parent[i][None])[0]
            axis = quat_rotate(q_link[i][None], tree.axis[i][None])[0]
            coord[c0] = float((anchor_link - anchor_parent) @ axis)
        elif kind == TREE_FREE:
            coord[c0 : c0 + 3] = x[body[i]]
            coord[c0 + 3 : c0 + 7] = q_link[i] / np.linalg.norm(q_link[i])
    return coord


def set_from_bodies(tree: TreeTable, data: TreeData, x: np.ndarray, q: np.ndarray, P: np.ndarray,
                    L: np.ndarray) -> None:  # fmt: skip
    """data.coord and data.rate from the bodies' state (module docstring); then the links' rows of x, q,
    P, L rewritten by forward kinematics of them, and data.fk_state set."""
    from rbcli.physics.tree.aba import forward_kinematics, tree_accelerations
    from rbcli.physics.tree.integrate import generalized_momentum

    data.coord[:] = coords_from_poses(tree, x, q)
    momentum = np.zeros_like(data.rate)
    zeros = np.zeros_like(data.rate)
    x_, q_, P_, L_ = x.copy(), q.copy(), P.copy(), L.copy()
    forward_kinematics(tree, data.coord, zeros, data.work, x_, q_, P_, L_)  # the configuration, at rest
    generalized_momentum(tree, data.work, P, L, momentum)
    no_force = np.zeros_like(x)
    data.work.armature[:] = 0.0  # M itself
    tree_accelerations(tree, data.work, no_force, no_force, momentum, data.rate)  # M^-1 J^T h
    forward_kinematics(tree, data.coord, data.rate, data.work, x, q, P, L)
    data.fk_state[0] = 1.0
