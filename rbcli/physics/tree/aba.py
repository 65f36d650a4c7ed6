"""Compiled tree kernels: forward kinematics and the articulated-body algorithm, O(n) over links.

Featherstone, Rigid Body Dynamics Algorithms (2008), Table 7.1 (ABA), written in scalars over the tree
table's flat arrays (table.py has the joint model and the frames). Coordinates: each link's spatial
vectors are taken at its centre of mass with world-parallel axes ("link-centred, world-aligned": the
coordinates MuJoCo's com-based quantities use, but at each link's own centre of mass). Then

- the transform between a parent's and a child's coordinates is a pure translation by
  r = x_child - x_parent (world): X = [[1, 0], [-[r], 1]], X^T I X in ~50 multiplications instead of the
  ~200 a rotation and a translation take (the link's own rotation enters once, in R diag(I) R^T and S);
- external forces and torques (world, about the centre of mass: the state's F, tau) enter as they are;
- every quantity is about a point of its own link, so a chain 1 km from the origin loses no digits
  (world-origin coordinates, Pinocchio's, would cancel m |x|^2 against m d^2 in D).

S (the motion subspace) rotates with the link, S = X S_body with S_body constant (table.py), so
dS/dt = v x S and the velocity-product term is c = v x (S rate) as in body coordinates (the cross product
is covariant under Plucker transforms): qdd is the time derivative of the rates as table.py defines
them (a ball's relative angular velocity in the link frame, a free root's (omega, v) in its own frame).

    forward_kinematics   coordinates, rates -> each link's x, q, P, L (the state arrays) and the
                         work ABA reads: r, S, v, c, R diag(I) R^T
    tree_accelerations   F, tau (world, per body), joint forces -> qdd (ABA's passes 1b, 2, 3)

Both are STEP_KERNEL (no NRT: no allocation) and stage-sized, so compiled once and called by symbol
(kernel_link.py); every array lives in TreeTable / TreeWork. The numpy
reference (reference.py: body frames, 6 x 6 Plucker matrices, CRBA + RNEA and a dense solve) is what
tests/physics/test_tree_aba.py checks them against.
"""

from __future__ import annotations

import math

import numba
from numba.extending import overload

from rbcli.physics import kernel_cache
from rbcli.physics.dispatch import DISPATCH_OPTIONS, absent, kernel_only
from rbcli.physics.joints.tables import JOINT_BALL, JOINT_HINGE, JOINT_SLIDER
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL
from rbcli.physics.tree.table import SYM6_INDEX, TREE_FREE

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True, inline="always")
def _cross(ax, ay, az, bx, by, bz):  # noqa: ANN001, ANN202 - numba scalars
    return ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx


@numba.njit(cache=True, inline="always")
def _dot6(a, v0, v1, v2, v3, v4, v5):  # noqa: ANN001, ANN202
    """a . v for a 6-vector a (an array row) and v in scalars."""
    return a[0] * v0 + a[1] * v1 + a[2] * v2 + a[3] * v3 + a[4] * v4 + a[5] * v5


@numba.njit(cache=True, inline="always")
def _store6(a, v0, v1, v2, v3, v4, v5) -> None:  # noqa: ANN001
    """a[0:6] = v (a an array row)."""
    a[0], a[1], a[2], a[3], a[4], a[5] = v0, v1, v2, v3, v4, v5


@numba.njit(cache=True, inline="always")
def _sym3_times(k00, k01, k02, k11, k12, k22, x, y, z):  # noqa: ANN001, ANN202
    """K v for a symmetric 3 x 3 K in scalars."""
    return k00 * x + k01 * y + k02 * z, k01 * x + k11 * y + k12 * z, k02 * x + k12 * y + k22 * z


@numba.njit(cache=True, inline="always")
def _sym6_times(A, i, v0, v1, v2, v3, v4, v5):  # noqa: ANN001, ANN202
    """A[i] v for a packed symmetric 6 x 6 A[i] (table.py SYM6: upper triangle row by row)."""
    a = A[i]
    return (
        a[0] * v0 + a[1] * v1 + a[2] * v2 + a[3] * v3 + a[4] * v4 + a[5] * v5,
        a[1] * v0 + a[6] * v1 + a[7] * v2 + a[8] * v3 + a[9] * v4 + a[10] * v5,
        a[2] * v0 + a[7] * v1 + a[11] * v2 + a[12] * v3 + a[13] * v4 + a[14] * v5,
        a[3] * v0 + a[8] * v1 + a[12] * v2 + a[15] * v3 + a[16] * v4 + a[17] * v5,
        a[4] * v0 + a[9] * v1 + a[13] * v2 + a[16] * v3 + a[18] * v4 + a[19] * v5,
        a[5] * v0 + a[10] * v1 + a[14] * v2 + a[17] * v3 + a[19] * v4 + a[20] * v5,
    )


@separately_compiled
@numba.njit(**STEP_KERNEL)
def forward_kinematics(tree, coord, rate, work, x, q, P, L) -> None:  # noqa: ANN001
    """Each link's pose and velocity from the joint coordinates `coord` (C,) and rates `rate` (D,).

    Writes the state rows of the links' bodies: x [m] (centre of mass), q (wxyz, world-from-link), P [kg
    m/s], L [kg m^2/s] (world, about the centre of mass), and in `work`: rotation R, the offset r from the
    parent's centre of mass (world), the rates' motion columns S, the spatial velocity v = (omega, v_com)
    = v_parent shifted by r + S rate, c = v x (S rate), and R diag(I) R^T (packed xx, xy, xz, yy, yz, zz).
    A world quaternion is the product of the relative ones down the tree (a unit quaternion's product
    keeps |q| = 1 to round-off, so no renormalisation per link).
    """
    R, motion, velocity = work.rotation, work.motion, work.velocity
    for i in range(tree.parent.shape[0]):
        p, kind, c0, d0, b = tree.parent[i], tree.kind[i], tree.coord_start[i], tree.dof_start[i], tree.body[i]
        # the link's rotation relative to its parent, parent-from-link
        if kind == JOINT_HINGE:
            half = 0.5 * coord[c0]
            ch, sh = math.cos(half), math.sin(half)
            uw = ch * tree.rest_q[i, 0] + sh * tree.rest_axis_q[i, 0]
            ux = ch * tree.rest_q[i, 1] + sh * tree.rest_axis_q[i, 1]
            uy = ch * tree.rest_q[i, 2] + sh * tree.rest_axis_q[i, 2]
            uz = ch * tree.rest_q[i, 3] + sh * tree.rest_axis_q[i, 3]
        elif kind == JOINT_BALL:
            aw, ax, ay, az = tree.rest_q[i, 0], tree.rest_q[i, 1], tree.rest_q[i, 2], tree.rest_q[i, 3]
            bw, bx, by, bz = coord[c0], coord[c0 + 1], coord[c0 + 2], coord[c0 + 3]
            uw = aw * bw - ax * bx - ay * by - az * bz
            ux = aw * bx + ax * bw + ay * bz - az * by
            uy = aw * by - ax * bz + ay * bw + az * bx
            uz = aw * bz + ax * by - ay * bx + az * bw
        elif kind == TREE_FREE:
            uw, ux, uy, uz = coord[c0 + 3], coord[c0 + 4], coord[c0 + 5], coord[c0 + 6]
        else:
            uw, ux, uy, uz = tree.rest_q[i, 0], tree.rest_q[i, 1], tree.rest_q[i, 2], tree.rest_q[i, 3]
        # world orientation q = q_parent u
        if p >= 0:
            pb = tree.body[p]
            aw, ax, ay, az = q[pb, 0], q[pb, 1], q[pb, 2], q[pb, 3]
            qw = aw * uw - ax * ux - ay * uy - az * uz
            qx = aw * ux + ax * uw + ay * uz - az * uy
            qy = aw * uy - ax * uz + ay * uw + az * ux
            qz = aw * uz + ax * uy - ay * ux + az * uw
        else:
            qw, qx, qy, qz = uw, ux, uy, uz
        q[b, 0], q[b, 1], q[b, 2], q[b, 3] = qw, qx, qy, qz
        r00 = 1.0 - 2.0 * (qy * qy + qz * qz)
        r01 = 2.0 * (qx * qy - qw * qz)
        r02 = 2.0 * (qx * qz + qw * qy)
        r10 = 2.0 * (qx * qy + qw * qz)
        r11 = 1.0 - 2.0 * (qx * qx + qz * qz)
        r12 = 2.0 * (qy * qz - qw * qx)
        r20 = 2.0 * (qx * qz - qw * qy)
        r21 = 2.0 * (qy * qz + qw * qx)
        r22 = 1.0 - 2.0 * (qx * qx + qy * qy)
        R[i, 0, 0], R[i, 0, 1], R[i, 0, 2] = r00, r01, r02
        R[i, 1, 0], R[i, 1, 1], R[i, 1, 2] = r10, r11, r12
        R[i, 2, 0], R[i, 2, 1], R[i, 2, 2] = r20, r21, r22
        # the joint point from the centre of mass (world) c_w = R c; the hinge or slider axis a_w = R a
        cx, cy, cz = tree.anchor_child[i, 0], tree.anchor_child[i, 1], tree.anchor_child[i, 2]
        cwx = r00 * cx + r01 * cy + r02 * cz
        cwy = r10 * cx + r11 * cy + r12 * cz
        cwz = r20 * cx + r21 * cy + r22 * cz
        ax, ay, az = tree.axis[i, 0], tree.axis[i, 1], tree.axis[i, 2]
        awx = r00 * ax + r01 * ay + r02 * az
        awy = r10 * ax + r11 * ay + r12 * az
        awz = r20 * ax + r21 * ay + r22 * az
        # centre of mass: the joint point (the parent's anchor, world) - c_w (+ travel a_w)
        if kind == TREE_FREE:
            rx, ry, rz = coord[c0], coord[c0 + 1], coord[c0 + 2]
        else:
            ex, ey, ez = tree.anchor_parent[i, 0], tree.anchor_parent[i, 1], tree.anchor_parent[i, 2]
            if p >= 0:
                px, py, pz = ex, ey, ez
                ex = R[p, 0, 0] * px + R[p, 0, 1] * py + R[p, 0, 2] * pz
                ey = R[p, 1, 0] * px + R[p, 1, 1] * py + R[p, 1, 2] * pz
                ez = R[p, 2, 0] * px + R[p, 2, 1] * py + R[p, 2, 2] * pz
            rx, ry, rz = ex - cwx, ey - cwy, ez - cwz
            if kind == JOINT_SLIDER:
                travel = coord[c0]
                rx, ry, rz = rx + travel * awx, ry + travel * awy, rz + travel * awz
        work.xpos[i, 0], work.xpos[i, 1], work.xpos[i, 2] = rx, ry, rz
        if p >= 0:
            pb = tree.body[p]
            x[b, 0], x[b, 1], x[b, 2] = x[pb, 0] + rx, x[pb, 1] + ry, x[pb, 2] + rz
        else:
            x[b, 0], x[b, 1], x[b, 2] = rx, ry, rz
        # S, world-aligned at the centre of mass: hinge (a_w, c_w x a_w), slider (0, a_w), ball the columns
        # (R e_k, c_w x R e_k), free blockdiag(R, R)
        if kind == JOINT_HINGE:
            motion[d0, 0], motion[d0, 1], motion[d0, 2] = awx, awy, awz
            motion[d0, 3], motion[d0, 4], motion[d0, 5] = _cross(cwx, cwy, cwz, awx, awy, awz)
        elif kind == JOINT_SLIDER:
            motion[d0, 0], motion[d0, 1], motion[d0, 2] = 0.0, 0.0, 0.0
            motion[d0, 3], motion[d0, 4], motion[d0, 5] = awx, awy, awz
        elif kind == JOINT_BALL:  # S' (the rates' world-aligned basis, below): columns (e_k, c_w x e_k)
            motion[d0, 0], motion[d0, 1], motion[d0, 2], motion[d0, 3], motion[d0, 4], motion[d0, 5] = (
                1.0,
                0.0,
                0.0,
                0.0,
                cwz,
                -cwy,
            )
            motion[d0 + 1, 0], motion[d0 + 1, 1], motion[d0 + 1, 2] = 0.0, 1.0, 0.0
            motion[d0 + 1, 3], motion[d0 + 1, 4], motion[d0 + 1, 5] = -cwz, 0.0, cwx
            motion[d0 + 2, 0], motion[d0 + 2, 1], motion[d0 + 2, 2] = 0.0, 0.0, 1.0
            motion[d0 + 2, 3], motion[d0 + 2, 4], motion[d0 + 2, 5] = cwy, -cwx, 0.0
        elif kind == TREE_FREE:
            for k in range(3):
                for j in range(3):
                    motion[d0 + k, j], motion[d0 + k, 3 + j] = R[i, j, k], 0.0
                    motion[d0 + 3 + k, j], motion[d0 + 3 + k, 3 + j] = 0.0, R[i, j, k]
        # v = the parent's velocity at this centre of mass + S rate; c = v x (S rate)
        if p >= 0:
            wx, wy, wz = velocity[p, 0], velocity[p, 1], velocity[p, 2]
            tx, ty, tz = _cross(rx, ry, rz, wx, wy, wz)
            vx, vy, vz = velocity[p, 3] - tx, velocity[p, 4] - ty, velocity[p, 5] - tz
        else:
            wx = wy = wz = vx = vy = vz = 0.0
        if kind == JOINT_BALL:  # the joint's velocity (R omega, c_w x R omega)
            o0, o1, o2 = rate[d0], rate[d0 + 1], rate[d0 + 2]
            jw0, jw1, jw2 = (
                r00 * o0 + r01 * o1 + r02 * o2,
                r10 * o0 + r11 * o1 + r12 * o2,
                r20 * o0 + r21 * o1 + r22 * o2,
            )
            jv0, jv1, jv2 = _cross(cwx, cwy, cwz, jw0, jw1, jw2)
        else:
            jw0 = jw1 = jw2 = jv0 = jv1 = jv2 = 0.0
            for k in range(d0, tree.dof_start[i + 1]):
                s = rate[k]
                jw0 += motion[k, 0] * s
                jw1 += motion[k, 1] * s
                jw2 += motion[k, 2] * s
                jv0 += motion[k, 3] * s
                jv1 += motion[k, 4] * s
                jv2 += motion[k, 5] * s
        wx, wy, wz, vx, vy, vz = wx + jw0, wy + jw1, wz + jw2, vx + jv0, vy + jv1, vz + jv2
        velocity[i, 0], velocity[i, 1], velocity[i, 2] = wx, wy, wz
        velocity[i, 3], velocity[i, 4], velocity[i, 5] = vx, vy, vz
        c0_, c1_, c2_ = _cross(wx, wy, wz, jw0, jw1, jw2)
        t0, t1, t2 = _cross(wx, wy, wz, jv0, jv1, jv2)
        u0, u1, u2 = _cross(vx, vy, vz, jw0, jw1, jw2)
        work.bias_acc[i, 0], work.bias_acc[i, 1], work.bias_acc[i, 2] = c0_, c1_, c2_
        work.bias_acc[i, 3], work.bias_acc[i, 4], work.bias_acc[i, 5] = t0 + u0, t1 + u1, t2 + u2
        # R diag(I) R^T, and the momenta P = m v, L = (R diag(I) R^T) omega
        i0, i1, i2 = tree.inertia[i, 0], tree.inertia[i, 1], tree.inertia[i, 2]
        g00, g01, g02 = r00 * i0, r01 * i1, r02 * i2
        g10, g11, g12 = r10 * i0, r11 * i1, r12 * i2
        g20, g21, g22 = r20 * i0, r21 * i1, r22 * i2
        jxx = g00 * r00 + g01 * r01 + g02 * r02
        jxy = g00 * r10 + g01 * r11 + g02 * r12
        jxz = g00 * r20 + g01 * r21 + g02 * r22
        jyy = g10 * r10 + g11 * r11 + g12 * r12
        jyz = g10 * r20 + g11 * r21 + g12 * r22
        jzz = g20 * r20 + g21 * r21 + g22 * r22
        iw = work.inertia_world
        iw[i, 0], iw[i, 1], iw[i, 2], iw[i, 3], iw[i, 4], iw[i, 5] = jxx, jxy, jxz, jyy, jyz, jzz
        m = tree.mass[i]
        P[b, 0], P[b, 1], P[b, 2] = m * vx, m * vy, m * vz
        L[b, 0] = jxx * wx + jxy * wy + jxz * wz
        L[b, 1] = jxy * wx + jyy * wy + jyz * wz
        L[b, 2] = jxz * wx + jyz * wy + jzz * wz


@numba.njit(cache=True, inline="always")
def _add_to_parent(work, i, p) -> None:  # noqa: ANN001
    """I^A_p += X^T I^a_i X and p^A_p += X^T p^a_i for X = [[1, 0], [-[r], 1]], r = x_i - x_p, with I^a_i
    and p^a_i in work.inertia_art[i], work.bias_force[i].

    With I^a = [[B, H], [H^T, M]] (3 x 3 blocks, B and M symmetric): X^T I^a X = [[B', H'], [H'^T, M]],
    H' = H + [r] M, B' = B + [r] H^T - H [r] - [r] M [r] = B - H [r] + [r] H'^T; row a of H [r] is
    H_a x r and ([r] H'^T)_ab = (r x H'_b)_a (H'_b row b). Forces: (n + r x f, f).
    """
    a, A = work.inertia_art[i], work.inertia_art[p]
    rx, ry, rz = work.xpos[i, 0], work.xpos[i, 1], work.xpos[i, 2]
    h00, h01, h02, h10, h11, h12, h20, h21, h22 = a[3], a[4], a[5], a[8], a[9], a[10], a[12], a[13], a[14]
    m00, m01, m02, m11, m12, m22 = a[15], a[16], a[17], a[18], a[19], a[20]
    # H' = H + [r] M, [r] = [[0, -rz, ry], [rz, 0, -rx], [-ry, rx, 0]]
    n00, n01, n02 = h00 - rz * m01 + ry * m02, h01 - rz * m11 + ry * m12, h02 - rz * m12 + ry * m22
    n10, n11, n12 = h10 + rz * m00 - rx * m02, h11 + rz * m01 - rx * m12, h12 + rz * m02 - rx * m22
    n20, n21, n22 = h20 - ry * m00 + rx * m01, h21 - ry * m01 + rx * m11, h22 - ry * m02 + rx * m12
    # H_a x r (rows of H [r]) and r x H'_b (columns of [r] H'^T)
    k00, k01, k02 = _cross(h00, h01, h02, rx, ry, rz)
    k10, k11, k12 = _cross(h10, h11, h12, rx, ry, rz)
    k20, k21, k22 = _cross(h20, h21, h22, rx, ry, rz)
    l00, l10, l20 = _cross(rx, ry, rz, n00, n01, n02)  # (r x H'_0)_a = ([r] H'^T)_a0
    l01, l11, l21 = _cross(rx, ry, rz, n10, n11, n12)
    l02, l12, l22 = _cross(rx, ry, rz, n20, n21, n22)
    A[0] += a[0] - k00 + l00
    A[1] += a[1] - k01 + l01
    A[2] += a[2] - k02 + l02
    A[6] += a[6] - k11 + l11
    A[7] += a[7] - k12 + l12
    A[11] += a[11] - k22 + l22
    A[3] += n00
    A[4] += n01
    A[5] += n02
    A[8] += n10
    A[9] += n11
    A[10] += n12
    A[12] += n20
    A[13] += n21
    A[14] += n22
    A[15] += m00
    A[16] += m01
    A[17] += m02
    A[18] += m11
    A[19] += m12
    A[20] += m22
    f, F = work.bias_force[i], work.bias_force[p]
    tx, ty, tz = _cross(rx, ry, rz, f[3], f[4], f[5])
    F[0] += f[0] + tx
    F[1] += f[1] + ty
    F[2] += f[2] + tz
    F[3] += f[3]
    F[4] += f[4]
    F[5] += f[5]


# ---- the ball and the fixed / free links' passes, each compiled only into trees that have such links ----
# (TreeTable.balls, .others: None where a tree has none, physics/dispatch.py): a hinge chain's ABA then
# compiles neither, ~2 s of a first run (docs/trees.md, "Start-up"). The ball passes are inlined (a call
# per ball link cost ~11 % of a 10-link ball chain's step); the fixed / free ones (a root, once a tree)
# are called, which compiles faster


def _ball_backward(balls, work, i, p, d0, e0, joint_force) -> None:  # noqa: ANN001
    """Pass 2 at ball link i (tree_accelerations)."""
    kernel_only()


@overload(_ball_backward, jit_options=DISPATCH_OPTIONS, inline="always")
def _ball_backward_impl(balls, work, i, p, d0, e0, joint_force):  # noqa: ANN001, ANN202
    if absent(balls):
        return lambda balls, work, i, p, d0, e0, joint_force: None

    def run(balls, work, i, p, d0, e0, joint_force):  # noqa: ANN001, ANN202
        IA, pA, motion, U, u, dinv = work.inertia_art, work.bias_force, work.motion, work.U, work.u, work.dinv
        c = work.bias_acc[i]
        cx, cy, cz = motion[d0 + 1, 5], -motion[d0, 5], motion[d0, 4]
        a = IA[i]
        h00, h01, h02, h10, h11, h12, h20, h21, h22 = a[3], a[4], a[5], a[8], a[9], a[10], a[12], a[13], a[14]
        m00, m01, m02, m11, m12, m22 = a[15], a[16], a[17], a[18], a[19], a[20]
        # U' = I^A S' = [[B + H [c]], [H^T + M [c]]] (row a of X [c] is X_a x c): T on top, W below
        t00, t01, t02 = _cross(h00, h01, h02, cx, cy, cz)
        t10, t11, t12 = _cross(h10, h11, h12, cx, cy, cz)
        t20, t21, t22 = _cross(h20, h21, h22, cx, cy, cz)
        t00, t01, t02, t10, t11, t12 = t00 + a[0], t01 + a[1], t02 + a[2], t10 + a[1], t11 + a[6], t12 + a[7]
        t20, t21, t22 = t20 + a[2], t21 + a[7], t22 + a[11]
        w00, w01, w02 = _cross(m00, m01, m02, cx, cy, cz)
        w10, w11, w12 = _cross(m01, m11, m12, cx, cy, cz)
        w20, w21, w22 = _cross(m02, m12, m22, cx, cy, cz)
        w00, w01, w02, w10, w11, w12 = w00 + h00, w01 + h10, w02 + h20, w10 + h01, w11 + h11, w12 + h21
        w20, w21, w22 = w20 + h02, w21 + h12, w22 + h22
        # D' = S'^T U' = T - [c] W (column j: T_j - c x W_j), symmetric; its inverse by cofactors
        z00, z10, z20 = _cross(cx, cy, cz, w00, w10, w20)
        z01, z11, z21 = _cross(cx, cy, cz, w01, w11, w21)
        z02, z12, z22 = _cross(cx, cy, cz, w02, w12, w22)
        d00, d01, d02, d11, d12, d22 = t00 - z00, t01 - z01, t02 - z02, t11 - z11, t12 - z12, t22 - z22
        # a ball's armature is isotropic (one damper on its relative spin), so the basis does not matter
        d00, d11, d22 = d00 + work.armature[d0], d11 + work.armature[d0 + 1], d22 + work.armature[d0 + 2]
        k00, k01, k02 = d11 * d22 - d12 * d12, d02 * d12 - d01 * d22, d01 * d12 - d02 * d11
        k11, k12, k22 = d00 * d22 - d02 * d02, d01 * d02 - d00 * d12, d00 * d11 - d01 * d01
        det = 1.0 / (d00 * k00 + d01 * k01 + d02 * k02)
        k00, k01, k02, k11, k12, k22 = k00 * det, k01 * det, k02 * det, k11 * det, k12 * det, k22 * det
        dinv[e0], dinv[e0 + 1], dinv[e0 + 2] = k00, k01, k02
        dinv[e0 + 3], dinv[e0 + 4], dinv[e0 + 5] = k01, k11, k12
        dinv[e0 + 6], dinv[e0 + 7], dinv[e0 + 8] = k02, k12, k22
        _store6(U[d0], t00, t10, t20, w00, w10, w20)
        _store6(U[d0 + 1], t01, t11, t21, w01, w11, w21)
        _store6(U[d0 + 2], t02, t12, t22, w02, w12, w22)
        # u' = R tau - S'^T p^A, S'^T p = p_top - c x p_bottom
        f, Rm = pA[i], work.rotation[i]
        o0, o1, o2 = joint_force[d0], joint_force[d0 + 1], joint_force[d0 + 2]
        g0, g1, g2 = _cross(cx, cy, cz, f[3], f[4], f[5])
        u[d0] = Rm[0, 0] * o0 + Rm[0, 1] * o1 + Rm[0, 2] * o2 - f[0] + g0
        u[d0 + 1] = Rm[1, 0] * o0 + Rm[1, 1] * o1 + Rm[1, 2] * o2 - f[1] + g1
        u[d0 + 2] = Rm[2, 0] * o0 + Rm[2, 1] * o1 + Rm[2, 2] * o2 - f[2] + g2
        if p < 0:
            return
        # p^a = p^A + I^A c + U' D'^-1 (u' - U'^T c), then I^a = I^A - (U' D'^-1) U'^T
        a0, a1, a2, a3, a4, a5 = _sym6_times(IA, i, c[0], c[1], c[2], c[3], c[4], c[5])
        g0 = u[d0] - _dot6(U[d0], c[0], c[1], c[2], c[3], c[4], c[5])
        g1 = u[d0 + 1] - _dot6(U[d0 + 1], c[0], c[1], c[2], c[3], c[4], c[5])
        g2 = u[d0 + 2] - _dot6(U[d0 + 2], c[0], c[1], c[2], c[3], c[4], c[5])
        g0, g1, g2 = k00 * g0 + k01 * g1 + k02 * g2, k01 * g0 + k11 * g1 + k12 * g2, k02 * g0 + k12 * g1 + k22 * g2
        f[0] += a0 + t00 * g0 + t01 * g1 + t02 * g2
        f[1] += a1 + t10 * g0 + t11 * g1 + t12 * g2
        f[2] += a2 + t20 * g0 + t21 * g1 + t22 * g2
        f[3] += a3 + w00 * g0 + w01 * g1 + w02 * g2
        f[4] += a4 + w10 * g0 + w11 * g1 + w12 * g2
        f[5] += a5 + w20 * g0 + w21 * g1 + w22 * g2
        for row in range(6):  # constant trip counts: unrolled, SYM6_INDEX folded
            x0, x1, x2 = U[d0, row], U[d0 + 1, row], U[d0 + 2, row]
            y0, y1, y2 = _sym3_times(k00, k01, k02, k11, k12, k22, x0, x1, x2)
            for col in range(row, 6):
                a[SYM6_INDEX[row, col]] -= y0 * U[d0, col] + y1 * U[d0 + 1, col] + y2 * U[d0 + 2, col]

    return run


def _general_backward(others, work, i, p, d0, d1, e0, joint_force) -> None:  # noqa: ANN001
    """Pass 2 at a fixed or free link i (tree_accelerations)."""
    kernel_only()


@overload(_general_backward, jit_options=DISPATCH_OPTIONS)
def _general_backward_impl(others, work, i, p, d0, d1, e0, joint_force):  # noqa: ANN001, ANN202
    if absent(others):
        return lambda others, work, i, p, d0, d1, e0, joint_force: None

    def run(others, work, i, p, d0, d1, e0, joint_force):  # noqa: ANN001, ANN202
        IA, pA, motion, U, u, dinv = work.inertia_art, work.bias_force, work.motion, work.U, work.u, work.dinv
        c = work.bias_acc[i]
        k = d1 - d0
        for j in range(d0, d1):
            s = motion[j]
            s0, s1, s2, s3, s4, s5 = s[0], s[1], s[2], s[3], s[4], s[5]
            U[j, 0], U[j, 1], U[j, 2], U[j, 3], U[j, 4], U[j, 5] = _sym6_times(IA, i, s0, s1, s2, s3, s4, s5)
            u[j] = joint_force[j] - _dot6(pA[i], s0, s1, s2, s3, s4, s5)
        for j in range(k):
            for l in range(k):
                s = U[d0 + l]
                dinv[e0 + j * k + l] = _dot6(motion[d0 + j], s[0], s[1], s[2], s[3], s[4], s[5])
            dinv[e0 + j * k + j] += work.armature[d0 + j]
        for j in range(k):
            pivot = dinv[e0 + j * k + j]
            dinv[e0 + j * k + j] = 1.0
            for l in range(k):
                dinv[e0 + j * k + l] /= pivot
            for row in range(k):
                if row != j:
                    factor = dinv[e0 + row * k + j]
                    dinv[e0 + row * k + j] = 0.0
                    for l in range(k):
                        dinv[e0 + row * k + l] -= factor * dinv[e0 + j * k + l]
        if p < 0:
            return
        # p^a = p^A + I^A c + U D^-1 (u - U^T c), then I^a = I^A - U D^-1 U^T (same as p^A + I^a c + U D^-1 u)
        a0, a1, a2, a3, a4, a5 = _sym6_times(IA, i, c[0], c[1], c[2], c[3], c[4], c[5])
        pA[i, 0] += a0
        pA[i, 1] += a1
        pA[i, 2] += a2
        pA[i, 3] += a3
        pA[i, 4] += a4
        pA[i, 5] += a5
        for j in range(k):
            g = 0.0
            for l in range(k):
                g += dinv[e0 + j * k + l] * (u[d0 + l] - _dot6(U[d0 + l], c[0], c[1], c[2], c[3], c[4], c[5]))
            for col in range(6):
                pA[i, col] += U[d0 + j, col] * g
        for row in range(6):
            for col in range(row, 6):
                total = 0.0
                for j in range(k):
                    w = 0.0
                    for l in range(k):
                        w += dinv[e0 + j * k + l] * U[d0 + l, col]
                    total += U[d0 + j, row] * w
                IA[i, SYM6_INDEX[row, col]] -= total

    return run


def ball_forward(balls, work, i, d0, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd):  # noqa: ANN001, ANN202
    """Pass 3 at ball link i from u' in work.u: its qdd, and the link's spatial acceleration (the six e's,
    its parent's shifted on entry) returned. Also limits.py's response pass (the same pass with no bias)."""
    kernel_only()


@overload(ball_forward, jit_options=DISPATCH_OPTIONS, inline="always")
def _ball_forward_overload(balls, work, i, d0, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd):  # noqa: ANN001, ANN202
    if absent(balls):
        return lambda balls, work, i, d0, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd: (e0_, e1_, e2_, e3_, e4_, e5_)

    def run(balls, work, i, d0, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd):  # noqa: ANN001, ANN202
        motion, U, u, dinv = work.motion, work.U, work.u, work.dinv
        g0 = u[d0] - _dot6(U[d0], e0_, e1_, e2_, e3_, e4_, e5_)
        g1 = u[d0 + 1] - _dot6(U[d0 + 1], e0_, e1_, e2_, e3_, e4_, e5_)
        g2 = u[d0 + 2] - _dot6(U[d0 + 2], e0_, e1_, e2_, e3_, e4_, e5_)
        z0 = dinv[e0] * g0 + dinv[e0 + 1] * g1 + dinv[e0 + 2] * g2
        z1 = dinv[e0 + 3] * g0 + dinv[e0 + 4] * g1 + dinv[e0 + 5] * g2
        z2 = dinv[e0 + 6] * g0 + dinv[e0 + 7] * g1 + dinv[e0 + 8] * g2
        cx, cy, cz = motion[d0 + 1, 5], -motion[d0, 5], motion[d0, 4]
        y0, y1, y2 = _cross(cx, cy, cz, z0, z1, z2)
        e0_, e1_, e2_, e3_, e4_, e5_ = e0_ + z0, e1_ + z1, e2_ + z2, e3_ + y0, e4_ + y1, e5_ + y2
        Rm = work.rotation[i]
        qdd[d0] = Rm[0, 0] * z0 + Rm[1, 0] * z1 + Rm[2, 0] * z2
        qdd[d0 + 1] = Rm[0, 1] * z0 + Rm[1, 1] * z1 + Rm[2, 1] * z2
        qdd[d0 + 2] = Rm[0, 2] * z0 + Rm[1, 2] * z1 + Rm[2, 2] * z2
        return e0_, e1_, e2_, e3_, e4_, e5_

    return run


def general_forward(others, work, d0, d1, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd):  # noqa: ANN001, ANN202
    """Pass 3 at a free link (k > 1: six rates) from u in work.u: its qdd, and its spatial acceleration
    returned. Also limits.py's response pass."""
    kernel_only()


@overload(general_forward, jit_options=DISPATCH_OPTIONS)
def _general_forward_overload(others, work, d0, d1, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd):  # noqa: ANN001, ANN202
    if absent(others):
        return lambda others, work, d0, d1, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd: (e0_, e1_, e2_, e3_, e4_, e5_)

    def run(others, work, d0, d1, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd):  # noqa: ANN001, ANN202
        motion, U, u, dinv = work.motion, work.U, work.u, work.dinv
        k = d1 - d0
        for l in range(d0, d1):  # u becomes u - U^T a' (recomputed by every call)
            u[l] -= _dot6(U[l], e0_, e1_, e2_, e3_, e4_, e5_)
        for j in range(k):
            g = 0.0
            for l in range(k):
                g += dinv[e0 + j * k + l] * u[d0 + l]
            qdd[d0 + j] = g
            s = motion[d0 + j]
            e0_, e1_, e2_ = e0_ + s[0] * g, e1_ + s[1] * g, e2_ + s[2] * g
            e3_, e4_, e5_ = e3_ + s[3] * g, e4_ + s[4] * g, e5_ + s[5] * g
        return e0_, e1_, e2_, e3_, e4_, e5_

    return run


@separately_compiled
@numba.njit(**STEP_KERNEL)
def tree_accelerations(tree, work, force, torque, joint_force, qdd) -> None:  # noqa: ANN001
    """qdd (D,), the rates' derivatives, by ABA at the state `forward_kinematics` last saw.

    force, torque: [N], [N m] (bodies, 3), world, torque about each centre of mass (the state's F, tau;
    read at the links' body rows). joint_force: (D,) [N m or N], dual to the rates (power joint_force .
    rate): a hinge's torque, a slider's force, a ball's torque in the link frame, a free root's (torque,
    force) in its own frame.

    Pass 1b: I^A = I (rigid), p^A = v x* I v - f_ext. Pass 2, leaves first: U = I^A S, D = S^T U,
    u = tau - S^T p^A; I^a = I^A - U D^-1 U^T and p^a = p^A + I^a c + U D^-1 u go to the parent. Pass 3,
    roots first: a' = X a_parent + c (a_world = 0: gravity is an external force), qdd = D^-1 (u - U^T a'),
    a = a' + S qdd. After the call work.inertia_art holds each link's I^a (I^A for a root) and work.acc
    its spatial acceleration (world-aligned, at the centre of mass).
    """
    n = tree.parent.shape[0]
    IA, pA, motion, U, u, dinv = work.inertia_art, work.bias_force, work.motion, work.U, work.u, work.dinv
    for i in range(n):
        b, m = tree.body[i], tree.mass[i]
        iw = work.inertia_world[i]
        jxx, jxy, jxz, jyy, jyz, jzz = iw[0], iw[1], iw[2], iw[3], iw[4], iw[5]
        a = IA[i]
        a[0], a[1], a[2], a[6], a[7], a[11] = jxx, jxy, jxz, jyy, jyz, jzz
        a[3] = a[4] = a[5] = a[8] = a[9] = a[10] = a[12] = a[13] = a[14] = 0.0
        a[15], a[16], a[17], a[18], a[19], a[20] = m, 0.0, 0.0, m, 0.0, m
        wx, wy, wz = work.velocity[i, 0], work.velocity[i, 1], work.velocity[i, 2]
        vx, vy, vz = work.velocity[i, 3], work.velocity[i, 4], work.velocity[i, 5]
        lx = jxx * wx + jxy * wy + jxz * wz
        ly = jxy * wx + jyy * wy + jyz * wz
        lz = jxz * wx + jyz * wy + jzz * wz
        nx, ny, nz = _cross(wx, wy, wz, lx, ly, lz)
        fx, fy, fz = _cross(wx, wy, wz, vx, vy, vz)
        pA[i, 0], pA[i, 1], pA[i, 2] = nx - torque[b, 0], ny - torque[b, 1], nz - torque[b, 2]
        pA[i, 3], pA[i, 4], pA[i, 5] = m * fx - force[b, 0], m * fy - force[b, 1], m * fz - force[b, 2]

    for i in range(n - 1, -1, -1):
        p, d0, d1, e0 = tree.parent[i], tree.dof_start[i], tree.dof_start[i + 1], tree.dinv_start[i]
        c = work.bias_acc[i]
        if d1 - d0 == 1:  # hinge, slider: one column, D a scalar
            s = motion[d0]
            s0, s1, s2, s3, s4, s5 = s[0], s[1], s[2], s[3], s[4], s[5]
            U0, U1, U2, U3, U4, U5 = _sym6_times(IA, i, s0, s1, s2, s3, s4, s5)
            inv = 1.0 / (s0 * U0 + s1 * U1 + s2 * U2 + s3 * U3 + s4 * U4 + s5 * U5 + work.armature[d0])
            f = pA[i]
            uu = joint_force[d0] - _dot6(f, s0, s1, s2, s3, s4, s5)
            U[d0, 0], U[d0, 1], U[d0, 2], U[d0, 3], U[d0, 4], U[d0, 5] = U0, U1, U2, U3, U4, U5
            u[d0], dinv[e0] = uu, inv
            if p < 0:
                continue
            # I^a c = I^A c - U (U . c) / D, so the rank-one update and the product share U
            a0, a1, a2, a3, a4, a5 = _sym6_times(IA, i, c[0], c[1], c[2], c[3], c[4], c[5])
            g = (uu - _dot6(c, U0, U1, U2, U3, U4, U5)) * inv
            f[0] += a0 + U0 * g
            f[1] += a1 + U1 * g
            f[2] += a2 + U2 * g
            f[3] += a3 + U3 * g
            f[4] += a4 + U4 * g
            f[5] += a5 + U5 * g
            a = IA[i]
            V0, V1, V2, V3, V4, V5 = U0 * inv, U1 * inv, U2 * inv, U3 * inv, U4 * inv, U5 * inv
            a[0] -= V0 * U0
            a[1] -= V0 * U1
            a[2] -= V0 * U2
            a[3] -= V0 * U3
            a[4] -= V0 * U4
            a[5] -= V0 * U5
            a[6] -= V1 * U1
            a[7] -= V1 * U2
            a[8] -= V1 * U3
            a[9] -= V1 * U4
            a[10] -= V1 * U5
            a[11] -= V2 * U2
            a[12] -= V2 * U3
            a[13] -= V2 * U4
            a[14] -= V2 * U5
            a[15] -= V3 * U3
            a[16] -= V3 * U4
            a[17] -= V3 * U5
            a[18] -= V4 * U4
            a[19] -= V4 * U5
            a[20] -= V5 * U5
        elif d1 - d0 == 3:  # ball, its rates in the world-aligned basis S' = [1; [c_w]] (see the docstring)
            _ball_backward(tree.balls, work, i, p, d0, e0, joint_force)
        else:  # fixed (k = 0), free (6): D k x k, inverted in place (Gauss-Jordan: D is SPD)
            _general_backward(tree.others, work, i, p, d0, d1, e0, joint_force)
        if p < 0:
            continue
        _add_to_parent(work, i, p)

    acc = work.acc
    for i in range(n):
        p, d0, d1, e0 = tree.parent[i], tree.dof_start[i], tree.dof_start[i + 1], tree.dinv_start[i]
        c = work.bias_acc[i]
        if p >= 0:  # a' = X a_parent + c, X a shifts a's linear part to this centre of mass: a_lin - r x alpha
            tx, ty, tz = _cross(work.xpos[i, 0], work.xpos[i, 1], work.xpos[i, 2], acc[p, 0], acc[p, 1], acc[p, 2])
            e0_, e1_, e2_ = acc[p, 0] + c[0], acc[p, 1] + c[1], acc[p, 2] + c[2]
            e3_, e4_, e5_ = acc[p, 3] - tx + c[3], acc[p, 4] - ty + c[4], acc[p, 5] - tz + c[5]
        else:
            e0_, e1_, e2_, e3_, e4_, e5_ = c[0], c[1], c[2], c[3], c[4], c[5]
        k = d1 - d0
        if k == 1:
            g = (u[d0] - _dot6(U[d0], e0_, e1_, e2_, e3_, e4_, e5_)) * dinv[e0]
            qdd[d0] = g
            s = motion[d0]
            e0_, e1_, e2_ = e0_ + s[0] * g, e1_ + s[1] * g, e2_ + s[2] * g
            e3_, e4_, e5_ = e3_ + s[3] * g, e4_ + s[4] * g, e5_ + s[5] * g
        elif k == 3:  # ball: omega'' (world-aligned) = D'^-1 (u' - U'^T a'), a += S' omega'', qdd = R^T omega''
            e0_, e1_, e2_, e3_, e4_, e5_ = ball_forward(tree.balls, work, i, d0, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd)
        elif k > 1:
            e0_, e1_, e2_, e3_, e4_, e5_ = general_forward(
                tree.others, work, d0, d1, e0, e0_, e1_, e2_, e3_, e4_, e5_, qdd
            )
        acc[i, 0], acc[i, 1], acc[i, 2], acc[i, 3], acc[i, 4], acc[i, 5] = e0_, e1_, e2_, e3_, e4_, e5_
