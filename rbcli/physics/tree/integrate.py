"""Integrators in joint coordinates: the state of a tree is its coordinates and rates (TreeData.coord,
.rate); the bodies' x, q, P, L are what forward kinematics makes of them (aba.py), so the force pass,
contact, recording and every output read the state arrays as in maximal coordinates.

    reduced-euler   semi-implicit (symplectic) Euler, MuJoCo's default: one force pass and one ABA a step.
                    rate += h qdd(coord, rate);  coord advanced along the NEW rate: angles and travels
                    + h rate, a ball's u <- u exp(h omega / 2) (omega in the link frame: right
                    multiplication, du/dt = u (0, omega) / 2), a free root's x += h R v, q <- q exp(h omega / 2)
    reduced-rk4     the classical Runge-Kutta method on y = (coord, rate), dy/dt = (coord_rate(coord, rate),
                    qdd): four force passes and four ABAs a step; quaternion coordinates are summed in
                    R^4 and normalised at each stage and at the end (a projection onto |u| = 1, which
                    keeps the order: the exact flow stays on the sphere)

The joints' dampers (-c rate on each rate) are implicit in reduced-euler, as MuJoCo's joint damping:
(M + h C) qdd = f - C rate, so rate_new = rate + h qdd solves M (rate_new - rate) / h = f - C rate_new
(backward Euler in the damper: stable at any c h), by adding h c to D = S^T I^A S in ABA (the armature
term, work.armature); explicit in reduced-rk4 (stable while c h is below ~2.8 of the joint's inertia).

First order / fourth order (tests/physics/test_tree_integrate.py measures both on the compound pendulum's
exact period). Neither is symplectic: in joint coordinates the Hamiltonian H = p^T M(q)^-1 p / 2 + V(q) is
not separable, so no explicit splitting keeps it (Leimkuhler-Reich ch. 4); semi-implicit Euler is
symplectic only where M is constant (one hinge), and a free root's rotation under it is the explicit
gyroscopic update that `semi-implicit-gyro` shows to gain |L| at fast spin (docs/trees.md says where each
is the better choice). Maximal coordinates with split2 + RATTLE stay the structure-preserving option.

`TreeData.fk_state[0]` is 1 when the state arrays and the tree work hold forward kinematics of (coord,
rate) exactly: every step ends so, and a step starts without recomputing it; anything that changes the
coordinates from outside (Data.clear_work, set_state) sets it to 0.
"""

from __future__ import annotations

import math

import numba

from rbcli.physics import kernel_cache
from rbcli.physics.forces.wrench import accumulate_wrench
from rbcli.physics.joints.tables import JOINT_BALL, JOINT_HINGE, JOINT_SLIDER
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_ENTRY, STEP_KERNEL
from rbcli.physics.tree.aba import forward_kinematics, tree_accelerations
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


@numba.njit(cache=True, inline="always")
def damper_forces(damping, rate, joint_force, armature, implicit_h) -> None:  # noqa: ANN001
    """The joints' dampers: joint_force = -c rate, and armature = implicit_h c (the module docstring: an
    implicit damper when implicit_h is the step, explicit with 0). Its arrays alone, inlined: passing the
    tree's tables to a call cost ~10 % of a 10-link chain's step."""
    for k in range(rate.shape[0]):
        c = damping[k]
        joint_force[k] = -c * rate[k]
        armature[k] = implicit_h * c


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
                tree_data.reaction[i, k] = value
            else:
                tree_data.reaction[i, k] += value


@separately_compiled
@numba.njit(**STEP_KERNEL)
def tree_record(tree, tree_data, frames, filled, due) -> None:  # noqa: ANN001
    """On a recording step, each joint's reaction over the step just taken into the frame the record stage
    is about to fill (frames.joint (K, J, 12): on body_a [0:6] and body_b [6:12], (force [N], torque [N m]
    about each body's centre of mass), world: Simulation.joint_reactions' layout); NaN while reactions are
    off. Only into buffers made for them."""
    out = frames.joint
    if not due or filled >= out.shape[0] or out.shape[1] == 0:
        return
    known = tree_data.reactions_on[0] == 1.0
    for i in range(tree.parent.shape[0]):
        j, side = tree.joint[i], tree.joint_side[i]
        if j < 0 or j >= out.shape[1]:
            continue
        shift = 0 if side > 0 else 6  # the link's part [0:6] is body_a's when the link is body_a
        for k in range(12):
            out[filled, j, (k + shift) % 12] = tree_data.reaction[i, k] if known else math.nan


@numba.njit(**STEP_ENTRY)
def _accelerations(model, forces, contact, force_data, tree, tree_data, t, coord, rate, x, q, P, L, F, tau):  # noqa: ANN001, ANN202
    """qdd at (coord, rate) and time t into tree_data.qdd: forward kinematics (the state arrays), the force
    pass, ABA. One call site per integrator, so the force pass is inlined once."""
    forward_kinematics(tree, coord, rate, tree_data.work, x, q, P, L)
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
    damper_forces(tree.damping, rate, tree_data.joint_force, tree_data.work.armature, 0.0)
    tree_accelerations(tree, tree_data.work, F, tau, tree_data.joint_force, tree_data.qdd)


@numba.njit(**STEP_ENTRY)
def step_euler(model, forces, contact, force_data, tree, tree_data, t, h, x, q, P, L, F, tau) -> None:  # noqa: ANN001
    """One semi-implicit Euler step of every tree (module docstring), in place: the coordinates, rates and
    the links' x, q, P, L."""
    coord, rate, qdd = tree_data.coord, tree_data.rate, tree_data.qdd
    work = tree_data.work
    if tree_data.fk_state[0] != 1.0:
        forward_kinematics(tree, coord, rate, work, x, q, P, L)
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
    damper_forces(tree.damping, rate, tree_data.joint_force, work.armature, h)  # implicit: (M + h C) qdd = f - C rate
    tree_accelerations(tree, work, F, tau, tree_data.joint_force, qdd)
    if tree_data.reactions_on[0] == 1.0:  # the step's accelerations are constant over it: its mean
        joint_wrenches(tree, tree_data, F, tau, 1.0, True)
    for k in range(rate.shape[0]):
        rate[k] += h * qdd[k]
    advance_coords(tree, coord, rate, h)
    forward_kinematics(tree, coord, rate, work, x, q, P, L)
    tree_data.fk_state[0] = 1.0


@numba.njit(**STEP_ENTRY)
def step_rk4(model, forces, contact, force_data, tree, tree_data, t, h, x, q, P, L, F, tau) -> None:  # noqa: ANN001
    """One classical RK4 step of every tree (module docstring), in place. Stage s evaluates qdd and the
    coordinates' rate at y_s = y0 + a_s h k_{s-1} (a = 0, 1/2, 1/2, 1), its forces at t + a_s h; the
    step is y0 + h (k1 + 2 k2 + 2 k3 + k4) / 6, quaternions normalised at each stage and at the end."""
    coord, rate, qdd, dcoord = tree_data.coord, tree_data.rate, tree_data.qdd, tree_data.dcoord
    coord0, rate0, coord_sum, rate_sum = tree_data.coord0, tree_data.rate0, tree_data.coord_sum, tree_data.rate_sum
    nc, nd = coord.shape[0], rate.shape[0]
    for k in range(nc):
        coord0[k] = coord[k]
        coord_sum[k] = 0.0
    for k in range(nd):
        rate0[k] = rate[k]
        rate_sum[k] = 0.0
    for stage in range(4):
        a = 0.0 if stage == 0 else (1.0 if stage == 3 else 0.5)
        weight = 2.0 if stage == 1 or stage == 2 else 1.0
        if stage > 0:  # y_s = y0 + a h k_{s-1} (dcoord, qdd hold k_{s-1})
            for k in range(nc):
                coord[k] = coord0[k] + a * h * dcoord[k]
            for k in range(nd):
                rate[k] = rate0[k] + a * h * qdd[k]
            normalise_quaternions(tree, coord)
        # the first stage's forward kinematics is the state's own, kept from the last step
        if stage == 0 and tree_data.fk_state[0] == 1.0:
            accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau)
            damper_forces(tree.damping, rate, tree_data.joint_force, tree_data.work.armature, 0.0)
            tree_accelerations(tree, tree_data.work, F, tau, tree_data.joint_force, qdd)
        else:
            _accelerations(model, forces, contact, force_data, tree, tree_data, t + a * h, coord, rate, x, q, P, L,
                           F, tau)  # fmt: skip
        if tree_data.reactions_on[0] == 1.0:  # the mean over the step, with the stages' weights
            joint_wrenches(tree, tree_data, F, tau, weight / 6.0, stage == 0)
        coord_rate(tree, coord, rate, dcoord)
        for k in range(nc):
            coord_sum[k] += weight * dcoord[k]
        for k in range(nd):
            rate_sum[k] += weight * qdd[k]
    sixth = h / 6.0
    for k in range(nc):
        coord[k] = coord0[k] + sixth * coord_sum[k]
    for k in range(nd):
        rate[k] = rate0[k] + sixth * rate_sum[k]
    normalise_quaternions(tree, coord)
    forward_kinematics(tree, coord, rate, tree_data.work, x, q, P, L)
    tree_data.fk_state[0] = 1.0


@numba.njit(**STEP_KERNEL)
def generalized_momentum(tree, work, P, L, out) -> None:  # noqa: ANN001
    """out (D,) = J^T h: each rate's share of the bodies' momenta P, L (world, L about the centre of mass),
    the momentum dual to the rates (Featherstone 2.12), at the configuration `forward_kinematics` last
    saw. A backward pass: each link's subtree momentum about its centre of mass (its own plus its
    children's shifted, L + r x P), then S^T of it; a ball's rows are turned into its link frame (its
    motion columns are world-aligned: aba.py)."""
    n = tree.parent.shape[0]
    H = work.bias_force  # scratch (n, 6): the subtree's (angular about x_i, linear) momentum
    for i in range(n):
        b = tree.body[i]
        H[i, 0], H[i, 1], H[i, 2] = L[b, 0], L[b, 1], L[b, 2]
        H[i, 3], H[i, 4], H[i, 5] = P[b, 0], P[b, 1], P[b, 2]
    for i in range(n - 1, -1, -1):
        p = tree.parent[i]
        d0, d1 = tree.dof_start[i], tree.dof_start[i + 1]
        for k in range(d0, d1):
            s = work.motion[k]
            out[k] = s[0] * H[i, 0] + s[1] * H[i, 1] + s[2] * H[i, 2] + s[3] * H[i, 3] + s[4] * H[i, 4] + s[5] * H[i, 5]
        if tree.kind[i] == JOINT_BALL:  # world-aligned rows -> the link frame: R^T
            R = work.rotation[i]
            o0, o1, o2 = out[d0], out[d0 + 1], out[d0 + 2]
            out[d0] = R[0, 0] * o0 + R[1, 0] * o1 + R[2, 0] * o2
            out[d0 + 1] = R[0, 1] * o0 + R[1, 1] * o1 + R[2, 1] * o2
            out[d0 + 2] = R[0, 2] * o0 + R[1, 2] * o1 + R[2, 2] * o2
        if p >= 0:  # about the parent's centre of mass: L + r x P, r = x_i - x_p
            rx, ry, rz = work.xpos[i, 0], work.xpos[i, 1], work.xpos[i, 2]
            H[p, 0] += H[i, 0] + ry * H[i, 5] - rz * H[i, 4]
            H[p, 1] += H[i, 1] + rz * H[i, 3] - rx * H[i, 5]
            H[p, 2] += H[i, 2] + rx * H[i, 4] - ry * H[i, 3]
            H[p, 3] += H[i, 3]
            H[p, 4] += H[i, 4]
            H[p, 5] += H[i, 5]
