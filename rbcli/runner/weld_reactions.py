"""The welds' reactions: the force and torque each weld puts on its parts to keep them on their welded
body's motion (docs/joints.md, "Welds"), over the step that led to a state, from the states before and
after it. Welded bodies are one simulated body (scene/welds.py), so nothing in a step computes these:
they are the parts' Newton-Euler equations read off the body's motion.

Over a step of length h from state 0 to state 1, part i's momentum p_i = m_i v_i changes by
p_i1 - p_i0 and its angular momentum about its own centre of mass, l_i = R_i I_i R_i^T omega, by
l_i1 - l_i0. What its welds must supply, as the step's mean force [N] and torque [N m]:

    f_i = (p_i1 - p_i0) / h - F_ext,i - F_joint,i,    t_i = (l_i1 - l_i0) / h - tau_ext,i - tau_joint,i

F_ext the part's own force terms (wrench_numpy on the parts' own force tables) as the mean of their
values at both ends (exact for constant forces: gravity, uniform fields, constant world-frame point
forces; second order otherwise), F_joint the step's reactions of the part's other joints (the joint
stages', their torque moved to the part's centre of mass at the step's end). A weld joins a part to its
parent in its body's spanning tree of welds and carries what the part's subtree needs,
W_i = (f_i, t_i) + sum over children c of (W_c^f, W_c^t + (x_c - x_i) x W_c^f), and the opposite on the
parent (its torque moved to the parent's centre of mass), so a part's welds add up to exactly (f_i, t_i):
each part's momentum and angular momentum balance to round-off. At the tree's root the whole body's
balance closes the sum: to round-off in force where F_ext is exact, to O(h^2) in torque. Over a finite
step the parts' moments of momentum about the body's centre do not add up exactly: the sum's change is
sum (r_i1 x p_i1 - r_i0 x p_i0) = sum (rbar_i x dp_i + dr_i x pbar_i), and the last sum, zero for a rigid
motion to first order, is O(h^3) with the mean lever rbar = (r_0 + r_1) / 2 used for the moves above: the
root's torque is off by O(h^2) relative (3e-6 at omega h = 4e-3; with the end's lever, O(h): 2 %). Other
joints on the parts add an O(h) share there (their torques are moved with the end's lever). A weld that closes a loop
carries nothing (a loop of welds is statically indeterminate); a weld to the world carries what the
world does. Welded bodies with contact spheres (scenes with contact): NaN, because the contact force on
each part is not known from the states. numpy only, in the recording thread.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.forces.wrench import wrench_numpy
from rbcli.physics.model import Model
from rbcli.scene.parts import PartView, part_states


def joint_reactions(
    view: PartView,
    model: Model,
    dt: float,
    step: np.ndarray,
    before: np.ndarray | None,
    after: tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray],
    table: np.ndarray,
) -> np.ndarray:
    """(K, joint_count, 12): every scene joint's reaction over the step that led to each of K states, in
    the layout of Simulation.joint_reactions ([0:6] force [N] and torque [N m] about the centre of mass of
    the joint's first part, [6:12] its second's; zeros for the world), scene joint order.

    step (K,): each state's grid index (the step is (step - 1) dt .. step dt). before: (K, body_count, 13)
    the simulated bodies' states one step earlier (x, q, P, L), NaN where unknown (its welds then NaN);
    None: all unknown. after: the states (x, q, P, L), (K, body_count, k). table: (K, table_joints, 12) the
    joint stages' reactions (torques about the simulated bodies' centres of mass)."""
    x1, q1, P1, L1 = after
    k = x1.shape[0]
    joints = view.joint_table_index.shape[0]
    out = np.zeros((k, joints, 12))
    xp1, qp1, Pp1, Lp1 = part_states(view, model, x1, q1, P1, L1)
    # the other joints: their rows, torques moved from the body's centre of mass to the part's
    rows = view.joint_table_index >= 0
    part_force = np.zeros((k, view.part_count, 3))
    part_torque = np.zeros((k, view.part_count, 3))
    for j in np.flatnonzero(rows):
        reaction = table[:, view.joint_table_index[j]]
        for end in range(2):
            part = int(view.joint_parts[j, end])
            if part < 0:
                continue  # the world: zeros
            force, torque = reaction[:, 6 * end : 6 * end + 3], reaction[:, 6 * end + 3 : 6 * end + 6]
            torque = torque - np.cross(xp1[:, part] - x1[:, view.part_body[part]], force)
            out[:, j, 6 * end : 6 * end + 3] = force
            out[:, j, 6 * end + 3 : 6 * end + 6] = torque
            part_force[:, part] += force
            part_torque[:, part] += torque
    welds = view.weld_joint
    if not welds.size:
        return out
    if before is None:
        out[:, welds] = np.nan
        return out
    x0, q0, P0, L0 = before[..., 0:3], before[..., 3:7], before[..., 7:10], before[..., 10:13]
    xp0, qp0, Pp0, Lp0 = part_states(view, model, x0, q0, P0, L0)
    h = dt
    external_force = np.zeros((k, view.part_count, 3))
    external_torque = np.zeros((k, view.part_count, 3))
    if view.forces is not None:
        for frame in range(k):  # the numpy force pass, once per recorded frame and end
            for time, state in ((step[frame] - 1) * dt, (xp0, qp0, Pp0, Lp0)), (step[frame] * dt, (xp1, qp1, Pp1, Lp1)):
                if not np.all(np.isfinite(state[0][frame])):
                    continue  # unknown: the reaction is NaN anyway
                F, tau = wrench_numpy(view.model, view.forces, float(time), *(a[frame] for a in state))
                external_force[frame] += 0.5 * F
                external_torque[frame] += 0.5 * tau
    f = (Pp1 - Pp0) / h - external_force - part_force
    t = (Lp1 - Lp0) / h - external_torque - part_torque
    # the spanning trees, leaves first: each part's weld to its parent carries its subtree's needs; torques
    # move between parts' centres with the step's mean lever (x_0 + x_1) / 2: the root's balance O(h^2)
    lever = 0.5 * (xp0 + xp1)
    for i in view.weld_order:
        up = int(view.weld_parent_part[i])
        if up >= 0:
            f[:, up] += f[:, i]
            t[:, up] += t[:, i] + np.cross(lever[:, i] - lever[:, up], f[:, i])
    for child in np.flatnonzero(view.weld_parent >= 0):
        weld = int(view.weld_parent[child])
        parent = int(view.weld_parent_part[child])
        on_child = np.concatenate([f[:, child], t[:, child]], axis=1)
        on_parent = np.zeros((k, 6))
        if parent >= 0:
            moment = np.cross(lever[:, child] - lever[:, parent], f[:, child])
            on_parent = np.concatenate([-f[:, child], -t[:, child] - moment], axis=1)
        first = int(view.joint_parts[weld, 0]) == child
        out[:, weld, 0:6], out[:, weld, 6:12] = (on_child, on_parent) if first else (on_parent, on_child)
    if view.contact_parts is not None and view.contact_parts.any():
        touched = np.zeros(model.body_count, dtype=bool)
        touched[view.part_body[view.contact_parts]] = True
        for j in welds:
            if touched[view.part_body[int(view.joint_parts[j, 0])]]:
                out[:, j] = np.nan
    return out
