"""The joints' reactions in joint coordinates: each link's joint wrench from the Newton-Euler equations
of its subtree, summed from the leaves (the reaction stream, Simulation.joint_reactions; table.py
TreeData.reaction has the layout). `joint_wrenches` takes an evaluation's accelerations (integrate.py),
`impulse_wrenches` a limit's or motor's velocity change over a step (limits.py). Each is called through a
stage that compiles to nothing in a run that records no reactions (TreeData.wrench None:
physics/dispatch.py), and runs while TreeData.reactions_on[0] is 1."""

from __future__ import annotations

import numba
from numba.extending import overload

from rbcli.physics import kernel_cache
from rbcli.physics.dispatch import DISPATCH_OPTIONS, absent, kernel_only
from rbcli.physics.step import STEP_KERNEL

kernel_cache.install()


@numba.njit(**STEP_KERNEL)
def joint_wrenches(tree, tree_data, F, tau, weight, first) -> None:  # noqa: ANN001
    """tree_data.reaction = (first: ) or += weight * each link's joint wrench at the evaluation ABA just
    made (work.acc, its velocities and inertias): the Newton-Euler equations of the link's subtree, summed
    from the leaves, f_i = sum over the subtree of (I a + v x* I v - f_ext) about x_i, with world axes;
    [0:6] (force, torque about its centre of mass) on the link, [6:12] the opposite on its parent (about
    the parent's centre of mass; zero for a root: the world). Dampers and joint forces are in it, as the
    maximal joints' reactions hold their dampers and motors."""
    work, W = tree_data.work, tree_data.wrench
    n = tree.parent.shape[0]
    for i in range(n):
        b, m = tree.body[i], tree.mass[i]
        iw = work.inertia_world[i]
        wx, wy, wz = work.velocity[i, 0], work.velocity[i, 1], work.velocity[i, 2]
        vx, vy, vz = work.velocity[i, 3], work.velocity[i, 4], work.velocity[i, 5]
        ax, ay, az = work.acc[i, 0], work.acc[i, 1], work.acc[i, 2]
        lx = iw[0] * wx + iw[1] * wy + iw[2] * wz
        ly = iw[1] * wx + iw[3] * wy + iw[4] * wz
        lz = iw[2] * wx + iw[4] * wy + iw[5] * wz
        # torque: I alpha + omega x I omega - tau; force: m (a + omega x v) - F (a: the spatial acceleration)
        W[i, 3] = iw[0] * ax + iw[1] * ay + iw[2] * az + wy * lz - wz * ly - tau[b, 0]
        W[i, 4] = iw[1] * ax + iw[3] * ay + iw[4] * az + wz * lx - wx * lz - tau[b, 1]
        W[i, 5] = iw[2] * ax + iw[4] * ay + iw[5] * az + wx * ly - wy * lx - tau[b, 2]
        W[i, 0] = m * (work.acc[i, 3] + wy * vz - wz * vy) - F[b, 0]
        W[i, 1] = m * (work.acc[i, 4] + wz * vx - wx * vz) - F[b, 1]
        W[i, 2] = m * (work.acc[i, 5] + wx * vy - wy * vx) - F[b, 2]
    accumulate_subtrees(tree, work, W, tree_data.reaction, weight, first)


@numba.njit(cache=True, inline="always")
def accumulate_subtrees(tree, work, W, reaction, weight, first) -> None:  # noqa: ANN001
    """W (n, 6): each link's own (force, torque about its centre of mass) Newton-Euler residual in; each
    link's joint wrench out, its subtree's summed from the leaves (r = x_i - x_p from work.xpos), and
    reaction (n, 12) = (first: ) or += weight * (on the link [0:6], on its parent [6:12], zero for a root)."""
    n = tree.parent.shape[0]
    for i in range(n - 1, -1, -1):
        p = tree.parent[i]
        rx, ry, rz = work.xpos[i, 0], work.xpos[i, 1], work.xpos[i, 2]
        if p >= 0:  # about the parent's centre of mass: torque + r x force, r = x_i - x_p
            W[p, 0] += W[i, 0]
            W[p, 1] += W[i, 1]
            W[p, 2] += W[i, 2]
            W[p, 3] += W[i, 3] + ry * W[i, 2] - rz * W[i, 1]
            W[p, 4] += W[i, 4] + rz * W[i, 0] - rx * W[i, 2]
            W[p, 5] += W[i, 5] + rx * W[i, 1] - ry * W[i, 0]
        # on the link: W[i]; on its parent: the opposite force, its moment about the parent's centre of
        # mass (r = x_i - x_p now, at this evaluation); a root's other end is the world: nothing
        tx, ty, tz = -W[i, 3], -W[i, 4], -W[i, 5]
        if p >= 0:
            tx -= ry * W[i, 2] - rz * W[i, 1]
            ty -= rz * W[i, 0] - rx * W[i, 2]
            tz -= rx * W[i, 1] - ry * W[i, 0]
        part = (W[i, 0], W[i, 1], W[i, 2], W[i, 3], W[i, 4], W[i, 5], -W[i, 0], -W[i, 1], -W[i, 2], tx, ty, tz)
        root = 0.0 if p >= 0 else 1.0
        for k in range(12):
            value = weight * part[k] * (1.0 - root if k >= 6 else 1.0)
            if first:
                reaction[i, k] = value
            else:
                reaction[i, k] += value


@numba.njit(**STEP_KERNEL)
def impulse_wrenches(tree, tree_data, dacc, scale) -> None:  # noqa: ANN001
    """tree_data.reaction += the joint wrenches that give each link the spatial acceleration scale * dacc
    (n, 6; world-aligned at its centre of mass, as work.acc) with no other force: a velocity change dacc
    over a step of h is scale = 1 / h. The joints' limit and motor impulses are internal to the tree,
    so they appear here as what the joints transmit (as the maximal joints' reactions hold theirs)."""
    work, W = tree_data.work, tree_data.wrench
    for i in range(tree.parent.shape[0]):
        iw, m = work.inertia_world[i], tree.mass[i]
        ax, ay, az = scale * dacc[i, 0], scale * dacc[i, 1], scale * dacc[i, 2]
        W[i, 3] = iw[0] * ax + iw[1] * ay + iw[2] * az
        W[i, 4] = iw[1] * ax + iw[3] * ay + iw[4] * az
        W[i, 5] = iw[2] * ax + iw[4] * ay + iw[5] * az
        W[i, 0], W[i, 1], W[i, 2] = m * scale * dacc[i, 3], m * scale * dacc[i, 4], m * scale * dacc[i, 5]
    accumulate_subtrees(tree, work, W, tree_data.reaction, 1.0, False)


def joint_wrench_stage(wrench, tree, tree_data, F, tau, weight, first) -> None:  # noqa: ANN001
    """joint_wrenches in a run that records the reactions (wrench: TreeData.wrench, None otherwise)."""
    kernel_only()


@overload(joint_wrench_stage, jit_options=DISPATCH_OPTIONS)
def _joint_wrench_stage(wrench, tree, tree_data, F, tau, weight, first):  # noqa: ANN001, ANN202
    if absent(wrench):
        return lambda wrench, tree, tree_data, F, tau, weight, first: None

    def run(wrench, tree, tree_data, F, tau, weight, first):  # noqa: ANN001, ANN202
        if tree_data.reactions_on[0] == 1.0:
            joint_wrenches(tree, tree_data, F, tau, weight, first)

    return run


def impulse_wrench_stage(wrench, tree, tree_data, dacc, scale) -> None:  # noqa: ANN001
    """impulse_wrenches in a run that records the reactions (wrench: TreeData.wrench, None otherwise)."""
    kernel_only()


@overload(impulse_wrench_stage, jit_options=DISPATCH_OPTIONS)
def _impulse_wrench_stage(wrench, tree, tree_data, dacc, scale):  # noqa: ANN001, ANN202
    if absent(wrench):
        return lambda wrench, tree, tree_data, dacc, scale: None

    def run(wrench, tree, tree_data, dacc, scale):  # noqa: ANN001, ANN202
        if tree_data.reactions_on[0] == 1.0:
            impulse_wrenches(tree, tree_data, dacc, scale)

    return run
