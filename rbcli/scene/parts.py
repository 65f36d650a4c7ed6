"""The scene's bodies as parts of the simulated bodies: welded bodies (`fixed` joints) are one simulated
body (scene/welds.py), and every output shows them as the scene wrote them (docs/joints.md, "Welds").

A part i rides on simulated body b = part_body[i] at a fixed pose: its centre of mass at o_i (the body's
principal frame, about the body's centre of mass) and its principal frame turned by r_i from the body's,
so from the body's state (x, q, P, L):

    x_i = x + R o_i,  q_i = q r_i,  v_i = P / M + omega x R o_i,  P_i = m_i v_i,  L_i = R_i diag(I_i) R_i^T omega

(omega = R diag(1 / I) R^T L, R and R_i world-from-principal). A part alone on its body (o = 0, r = 1)
reads the body's state bit for bit. The way back (`merged_state`): each body follows its first part, its
pose (q = q_i r_i^*, x = x_i - R o_i) and its motion (omega from L_i, v = v_i - omega x R o_i). numpy only.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from rbcli.physics.forces.tables import ForceTables
from rbcli.physics.model import Model
from rbcli.physics.rotation import quat_conjugate, quat_multiply, quat_to_matrix


@dataclass(frozen=True)
class PartView:
    """Where each of the scene's bodies (parts) sits on the simulated bodies, and which joints were welds.

    model: the parts as bodies of their own (names, masses, principal inertia and user frames, particles
    about their own centres of mass): what outputs and the recording header show.
    part_body: int64 (part_count,), the simulated body of each part.
    part_offset: [m] (part_count, 3), the part's centre of mass about its body's, the body's principal frame.
    part_rotation: (part_count, 4) wxyz, body-principal-from-part-principal (q_part = q_body part_rotation).
    alone: bool (part_count,), the part is its body's only part (its state is the body's, bit for bit).
    joint_table_index: int64 (joint_count,), per scene joint, its row in the model's JointTable; -1 for
    the welds (and for joints left out because both ends are on one welded body).
    joint_parts: int64 (joint_count, 2), per scene joint, the parts its two reaction rows are for (row 0
    never the world; -1 the world), the order Simulation.joint_reactions reports them in.
    weld_parent: int64 (part_count,), the weld that joins each part to its parent in its body's spanning
    tree of welds (-1: the tree's root, or a part alone).
    weld_order: int64, the parts with a parent weld, leaves first (each before its parent).
    weld_parent_part: int64 (part_count,), that parent part (-1: the world, or none).
    weld_joint: int64, the scene joints that are welds.
    forces, contact_parts: what the welds' reactions need (runner/weld_reactions.py).
    """

    model: Model
    part_body: np.ndarray
    part_offset: np.ndarray
    part_rotation: np.ndarray
    alone: np.ndarray
    joint_table_index: np.ndarray
    joint_parts: np.ndarray
    weld_parent: np.ndarray
    weld_order: np.ndarray
    weld_parent_part: np.ndarray
    weld_joint: np.ndarray
    forces: ForceTables | None = None  # the parts' own force tables: each part's external wrench
    contact_parts: np.ndarray | None = None  # bool (part_count,): parts with contact spheres (scenes with contact)

    @property
    def part_count(self) -> int:
        return int(self.part_body.shape[0])

    @property
    def weld_count(self) -> int:
        return int(np.count_nonzero(self.joint_table_index < 0))


def part_states(
    view: PartView, model: Model, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(x, q, P, L) of every part from the simulated bodies' (..., body_count, k) states: (..., part_count, k),
    q world-from-part-principal, L about the part's centre of mass (see the module docstring)."""
    b = view.part_body
    xb, qb, Pb, Lb = x[..., b, :], q[..., b, :], P[..., b, :], L[..., b, :]
    R = quat_to_matrix(qb)
    r = np.einsum("...ij,...j->...i", R, np.broadcast_to(view.part_offset, xb.shape))
    omega = np.einsum("...ij,...j->...i", R, np.einsum("...ji,...j->...i", R, Lb) / model.body_inertia[b])
    qp = quat_multiply(qb, np.broadcast_to(view.part_rotation, qb.shape))
    Rp = quat_to_matrix(qp)
    inertia = view.model.body_inertia
    v = Pb / model.body_mass[b, None] + np.cross(omega, r)
    Lp = np.einsum("...ij,...j->...i", Rp, inertia * np.einsum("...ji,...j->...i", Rp, omega))
    alone = view.alone[:, None]
    return (
        np.where(alone, xb, xb + r),
        np.where(alone, qb, qp),
        np.where(alone, Pb, view.model.body_mass[:, None] * v),
        np.where(alone, Lb, Lp),
    )


def merged_state(
    view: PartView, model: Model, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(x, q, P, L) of the simulated bodies (body_count, k) from every part's (part_count, k): each body
    follows its first part (its pose, its angular velocity omega = R_i diag(1 / I_i) R_i^T L_i and its
    velocity v_i, so v = v_i - omega x R o_i); a part alone on its body gives the body's state bit for bit.
    For parts that move as one rigid body, this is that body's state (module docstring)."""
    n = model.body_count
    first = np.full(n, -1, dtype=np.int64)
    for i in range(view.part_count - 1, -1, -1):  # once per part, outside any step: the first part wins
        first[view.part_body[i]] = i
    parts = view.model
    qb = quat_multiply(q[first], quat_conjugate(view.part_rotation[first]))
    qb = np.where(qb[:, :1] < 0.0, -qb, qb)
    R = quat_to_matrix(qb)
    r = np.einsum("bij,bj->bi", R, view.part_offset[first])
    Rp = quat_to_matrix(q[first])
    omega = np.einsum("bij,bj->bi", Rp, np.einsum("bji,bj->bi", Rp, L[first]) / parts.body_inertia[first])
    v = P[first] / parts.body_mass[first, None] - np.cross(omega, r)
    Lb = np.einsum("bij,bj->bi", R, model.body_inertia * np.einsum("bji,bj->bi", R, omega))
    alone = view.alone[first][:, None]
    return (
        np.where(alone, x[first], x[first] - r),
        np.where(alone, q[first], qb),
        np.where(alone, P[first], model.body_mass[:, None] * v),
        np.where(alone, L[first], Lb),
    )
