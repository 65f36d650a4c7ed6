"""The joint coordinates' kinematics: how coordinates move under rates (table.py has the joint model).
Angles and travels move at their rates; a ball's quaternion u at du/dt = u (0, omega) / 2 (omega, the
rate, in the link frame: right multiplication); a free root's x at R(q) v and q as a ball's. Shared by
the integrators (integrate.py) and the limits' impulses (limits.py)."""

from __future__ import annotations

import math

import numba

from rbcli.physics import kernel_cache
from rbcli.physics.joints.tables import JOINT_BALL, JOINT_HINGE, JOINT_SLIDER
from rbcli.physics.step import STEP_KERNEL
from rbcli.physics.tree.table import TREE_FREE

kernel_cache.install()

# below this |v| = h |omega| / 2 the exponential's sin|v| / |v| = 1 - |v|^2 / 6 to round-off
SMALL_ROTATION = 1e-4


@numba.njit(cache=True, inline="always")
def _times_exp(w, x, y, z, v0, v1, v2):  # noqa: ANN001, ANN202 - numba scalars
    """u exp((0, v)) normalised: u turned by 2 |v| about v in its own frame (right multiplication)."""
    angle = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
    sinc = 1.0 - angle * angle / 6.0 if angle < SMALL_ROTATION else math.sin(angle) / angle
    ew, ex, ey, ez = math.cos(angle), sinc * v0, sinc * v1, sinc * v2
    nw = w * ew - x * ex - y * ey - z * ez
    nx = w * ex + x * ew + y * ez - z * ey
    ny = w * ey - x * ez + y * ew + z * ex
    nz = w * ez + x * ey - y * ex + z * ew
    norm = 1.0 / math.sqrt(nw * nw + nx * nx + ny * ny + nz * nz)
    return nw * norm, nx * norm, ny * norm, nz * norm


@numba.njit(cache=True, inline="always")
def _rotate(w, x, y, z, v0, v1, v2):  # noqa: ANN001, ANN202
    """R(u) v for a unit quaternion u = (w, x, y, z)."""
    tx, ty, tz = 2.0 * (y * v2 - z * v1), 2.0 * (z * v0 - x * v2), 2.0 * (x * v1 - y * v0)
    return v0 + w * tx + y * tz - z * ty, v1 + w * ty + z * tx - x * tz, v2 + w * tz + x * ty - y * tx


@numba.njit(**STEP_KERNEL)
def advance_coords(tree, coord, rate, h) -> None:  # noqa: ANN001
    """coord <- coord moved for a time h at the constant `rate` along each joint's own geometry: angles
    and travels + h rate, a ball's u exp(h omega / 2), a free root's x + h R(q) v and q exp(h omega / 2)."""
    for i in range(tree.parent.shape[0]):
        kind, c0, d0 = tree.kind[i], tree.coord_start[i], tree.dof_start[i]
        if kind == JOINT_HINGE or kind == JOINT_SLIDER:
            coord[c0] += h * rate[d0]
        elif kind == JOINT_BALL:
            hh = 0.5 * h
            coord[c0], coord[c0 + 1], coord[c0 + 2], coord[c0 + 3] = _times_exp(
                coord[c0], coord[c0 + 1], coord[c0 + 2], coord[c0 + 3], hh * rate[d0], hh * rate[d0 + 1],
                hh * rate[d0 + 2],
            )  # fmt: skip
        elif kind == TREE_FREE:
            w, x, y, z = coord[c0 + 3], coord[c0 + 4], coord[c0 + 5], coord[c0 + 6]
            v0, v1, v2 = _rotate(w, x, y, z, rate[d0 + 3], rate[d0 + 4], rate[d0 + 5])
            coord[c0] += h * v0
            coord[c0 + 1] += h * v1
            coord[c0 + 2] += h * v2
            hh = 0.5 * h
            coord[c0 + 3], coord[c0 + 4], coord[c0 + 5], coord[c0 + 6] = _times_exp(
                w, x, y, z, hh * rate[d0], hh * rate[d0 + 1], hh * rate[d0 + 2]
            )


@numba.njit(**STEP_KERNEL)
def coord_rate(tree, coord, rate, dcoord) -> None:  # noqa: ANN001
    """dcoord = d coord / dt at (coord, rate): rate for angles and travels, u (0, omega) / 2 for a ball's
    quaternion, (R(q) v, q (0, omega) / 2) for a free root's pose."""
    for i in range(tree.parent.shape[0]):
        kind, c0, d0 = tree.kind[i], tree.coord_start[i], tree.dof_start[i]
        if kind == JOINT_HINGE or kind == JOINT_SLIDER:
            dcoord[c0] = rate[d0]
            continue
        if kind == JOINT_BALL:
            q0 = c0
            o0, o1, o2 = rate[d0], rate[d0 + 1], rate[d0 + 2]
        elif kind == TREE_FREE:
            q0 = c0 + 3
            o0, o1, o2 = rate[d0], rate[d0 + 1], rate[d0 + 2]
            w, x, y, z = coord[q0], coord[q0 + 1], coord[q0 + 2], coord[q0 + 3]
            dcoord[c0], dcoord[c0 + 1], dcoord[c0 + 2] = _rotate(w, x, y, z, rate[d0 + 3], rate[d0 + 4], rate[d0 + 5])
        else:
            continue
        w, x, y, z = coord[q0], coord[q0 + 1], coord[q0 + 2], coord[q0 + 3]
        dcoord[q0] = 0.5 * (-x * o0 - y * o1 - z * o2)
        dcoord[q0 + 1] = 0.5 * (w * o0 + y * o2 - z * o1)
        dcoord[q0 + 2] = 0.5 * (w * o1 - x * o2 + z * o0)
        dcoord[q0 + 3] = 0.5 * (w * o2 + x * o1 - y * o0)


@numba.njit(**STEP_KERNEL)
def normalise_quaternions(tree, coord) -> None:  # noqa: ANN001
    """Every ball's and free root's quaternion coordinates scaled to unit length."""
    for i in range(tree.parent.shape[0]):
        kind = tree.kind[i]
        if kind != JOINT_BALL and kind != TREE_FREE:
            continue
        q0 = tree.coord_start[i] + (3 if kind == TREE_FREE else 0)
        norm = 1.0 / math.sqrt(coord[q0] ** 2 + coord[q0 + 1] ** 2 + coord[q0 + 2] ** 2 + coord[q0 + 3] ** 2)
        for k in range(4):
            coord[q0 + k] *= norm
