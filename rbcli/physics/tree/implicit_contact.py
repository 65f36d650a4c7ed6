"""Linearly implicit contact in joint coordinates: `reduced-implicit`'s correction of the contact forces.

Why: an explicit step resolves a contact spring only below its stable step, 2 / w with w^2 = k / m_eff;
with the stiffness that stops a falling assembly within a few per cent of a part's size (the landing
rule, docs/contact.md) the lightest part's own frequency sets it, and the capsule ragdoll needed 22
sub-steps of a 1 ms step. Backward Euler in the contact springs and dashpots is stable at any step
(Baraff & Witkin 1998, "Large steps in cloth simulation", sec. 4.1; MuJoCo's contact solver is implicit
for the same reason), so only the contacts' travel (a sphere found within a quarter radius of its first
touch) sets the sub-steps.

The method. reduced-euler's step has applied every contact's force f_a (law.py at the start of the step,
its clamps included) and advanced the rates explicitly, rate_e = rate + h qdd. The law before its clamps,
f0 = (k d - c_n v_n) n - k_t u - c_t v_t, is linear in the relative velocity u of the bodies at the
contact point and in the springs' stretch, which grows by h u' over the step, so at the end of the step
(linearised about the start, Baraff & Witkin's eq. 6)

    f' = f0 - W u' + C u,        W = h K + C   (per contact, in its basis n, t1, t2: k, k_t and c_n, c_t)

where u' = u_e + h A (f' - f_a) is the end velocity (u_e: at rate_e) and A = J M^-1 J^T is the contacts'
inverse inertia in the trees' joint coordinates (J: the contact points' velocities from the rates, M the
trees' mass matrix with the implicit joint dampers: the ABA factors of the step). Hence, for the change
d = f' - f_a,

    (W^-1 + h A) d = W^-1 (f0 - f_a) + W^-1 C u - u_e,

symmetric positive definite (W diagonal and positive, A positive semidefinite), over the rows: a contact's
normal and, with friction, its two tangent directions. A's columns come from ABA's unit responses
(limits.py `tree_response`: M^-1 J^T e, each link's velocity change), O(links + rows) each. Then the laws
that are not linear, on the forces at the end of the step: the normal force does not pull (f'_n >= 0),
the tangential force stays within mu f'_n (a disc: the contact slides where it would leave it); and the
joint limits at or past a bound (limits.py's rows) take part as hard rows (1/w = 0, their impulse pushing
into the range only), else a limb pressed against its limit would be pushed by a contact force sized for
the limb alone. The rows are solved by Cholesky without those bounds, then by projected Gauss-Seidel from
that solution (the bounds; a rigid body's corners couple through a matrix of rank 6, on which Gauss-Seidel
alone converges slowly: a box held on a slope crept). The rates then take h M^-1 J^T d; limits.py's own
stage follows as in reduced-euler. At rest nothing changes (u = u_e = 0, f0 = f_a: d = 0), so a body
resting on its springs sinks exactly as under the explicit law; in motion the method damps what the step
cannot resolve (a bounce at h w >> 1 keeps less than its restitution: docs/contact.md).
"""

from __future__ import annotations

import math

import numba
from numba.extending import overload

from rbcli.physics.contact.implicit_rows import (
    IMP_CN,
    IMP_CT,
    IMP_FN,
    IMP_FN_LAW,
    IMP_FT,
    IMP_FT_LAW,
    IMP_KN,
    IMP_KT,
    IMP_MU,
    IMP_NORMAL,
    IMP_POINT,
    IMP_ROWS,
    IMP_VN,
    IMP_VT,
)
from rbcli.physics.contact.law import push  # a force at a point on a body: force, torque about its centre
from rbcli.physics.dispatch import DISPATCH_OPTIONS, absent, kernel_only, member
from rbcli.physics.joints.drives import LIMIT_CONTACT
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL
from rbcli.physics.tree.aba import forward_kinematics
from rbcli.physics.tree.limits import (
    generalized_momentum,
    limit_add_along,
    limit_along,
    limit_value,
    tree_response,
)
from rbcli.physics.tree.table import LIMIT_LOWER, LIMIT_UPPER, MOTOR

PGS_SWEEPS = 300  # with joint limits in the solve: projected Gauss-Seidel sweeps at most

# implicit_row's columns: the row's contact (or -1 - k for limit row k), its direction (world), 1 / w
# (0: a limit, a hard row), c / w, u (start), u_e (after the explicit step), the solution d [N], d's
# bounds, the right side b, and the law's force before its clamps less the force applied, along the row,
# over w
ROW_CONTACT, ROW_DIR, ROW_INV_W, ROW_C_OVER_W, ROW_U, ROW_UE, ROW_D = 0, 1, 4, 5, 6, 7, 8
ROW_LO, ROW_HI, ROW_B, ROW_LAW = 9, 10, 11, 12  # (contact/tables.py IMPLICIT_ROW_COLUMNS holds them: tested)


@numba.njit(cache=True, inline="always")
def _tangents(n0, n1, n2):  # noqa: ANN001, ANN202
    """Two unit vectors completing n to a right-handed orthonormal basis (any: the solve does not care)."""
    if abs(n0) < 0.57735:
        a0, a1, a2 = 0.0, n2, -n1  # n x e_x
    else:
        a0, a1, a2 = -n2, 0.0, n0  # n x e_y
    inv = 1.0 / math.sqrt(a0 * a0 + a1 * a1 + a2 * a2)
    a0, a1, a2 = a0 * inv, a1 * inv, a2 * inv
    return a0, a1, a2, n1 * a2 - n2 * a1, n2 * a0 - n0 * a2, n0 * a1 - n1 * a0


@numba.njit(cache=True, inline="always")
def _link_point_velocity(link, velocity, x, body, p0, p1, p2):  # noqa: ANN001, ANN202
    """The velocity (or velocity change) of body `body`'s material point at p from its link's spatial
    velocity (omega, v at its centre of mass) in `velocity`; zero for a body that is no link."""
    i = link[body]
    if i < 0:
        return 0.0, 0.0, 0.0
    r0, r1, r2 = p0 - x[body, 0], p1 - x[body, 1], p2 - x[body, 2]
    w0, w1, w2 = velocity[i, 0], velocity[i, 1], velocity[i, 2]
    v0, v1, v2 = velocity[i, 3], velocity[i, 4], velocity[i, 5]
    return v0 + w1 * r2 - w2 * r1, v1 + w2 * r0 - w0 * r2, v2 + w0 * r1 - w1 * r0


@numba.njit(cache=True, inline="always")
def _point_velocity(link, velocity, x, body, bodies_v, bodies_w, p0, p1, p2):  # noqa: ANN001, ANN202
    """The velocity of body `body`'s material point at p: from its link's spatial velocity (omega, v at
    its centre of mass), or for a body that is no link (static, kinematic) its velocity at the evaluation."""
    if link[body] >= 0:
        return _link_point_velocity(link, velocity, x, body, p0, p1, p2)
    r0, r1, r2 = p0 - x[body, 0], p1 - x[body, 1], p2 - x[body, 2]
    w0, w1, w2 = bodies_w[body, 0], bodies_w[body, 1], bodies_w[body, 2]
    v0, v1, v2 = bodies_v[body, 0], bodies_v[body, 1], bodies_v[body, 2]
    return v0 + w1 * r2 - w2 * r1, v1 + w2 * r0 - w0 * r2, v2 + w0 * r1 - w1 * r0


@numba.njit(cache=True, inline="always")
def _clear_wrench(force, torque, body) -> None:  # noqa: ANN001
    for k in range(3):
        force[body, k] = 0.0
        torque[body, k] = 0.0


@separately_compiled
@numba.njit(**STEP_KERNEL)
def implicit_contact(tree, tree_data, cw, x, q, P, L, h) -> None:  # noqa: ANN001
    """The correction of the module docstring, after reduced-euler's explicit rates (tree_data.rate) and
    before its coordinates advance; clears the kept contacts."""
    count = min(cw.implicit_count[0], cw.implicit_float.shape[0])
    cw.implicit_count[0] = 0
    if count == 0:
        return
    work, rw = tree_data.work, tree_data.response
    link, force, torque = cw.implicit_link, cw.implicit_force, cw.implicit_torque
    ints, vals, rows = cw.implicit_int, cw.implicit_float, cw.implicit_row
    A, factor = cw.implicit_matrix[0], cw.implicit_matrix[1]
    for b in range(link.shape[0]):
        link[b] = -1
    for i in range(tree.parent.shape[0]):
        link[tree.body[i]] = i
    # the rows: each contact's normal, and with friction its two tangents
    R = 0
    for c in range(count):
        v = vals[c]
        n0, n1, n2 = v[IMP_NORMAL], v[IMP_NORMAL + 1], v[IMP_NORMAL + 2]
        a0, a1, a2, b0, b1, b2 = _tangents(n0, n1, n2)
        for j in range(int(v[IMP_ROWS])):
            row = rows[R]
            row[ROW_CONTACT] = c
            if j == 0:
                e0, e1, e2, k, damp, u = n0, n1, n2, v[IMP_KN], v[IMP_CN], v[IMP_VN]
            else:
                if j == 1:
                    e0, e1, e2 = a0, a1, a2
                else:
                    e0, e1, e2 = b0, b1, b2
                k, damp = v[IMP_KT], v[IMP_CT]
                u = v[IMP_VT] * e0 + v[IMP_VT + 1] * e1 + v[IMP_VT + 2] * e2
            row[ROW_DIR], row[ROW_DIR + 1], row[ROW_DIR + 2] = e0, e1, e2
            w = h * k + damp
            row[ROW_INV_W] = 1.0 / w
            row[ROW_C_OVER_W] = damp / w
            row[ROW_U] = u
            # the law before its clamps less the force applied, along the row (the module docstring's b)
            if j == 0:
                row[ROW_LAW] = (v[IMP_FN_LAW] - v[IMP_FN]) / w
            else:
                row[ROW_LAW] = (
                    (v[IMP_FT_LAW] - v[IMP_FT]) * e0
                    + (v[IMP_FT_LAW + 1] - v[IMP_FT + 1]) * e1
                    + (v[IMP_FT_LAW + 2] - v[IMP_FT + 2]) * e2
                ) / w
            row[ROW_D] = 0.0
            row[ROW_LO] = -v[IMP_FN] if j == 0 else -math.inf  # no pull at the end of the step
            row[ROW_HI] = math.inf
            R += 1
    contact_rows = R
    # u_e: the contact points' velocities at the explicit rates (forward kinematics at the same coordinates)
    forward_kinematics(tree, tree_data.coord, tree_data.rate, work, x, q, P, L)
    velocity = work.velocity
    for r in range(R):
        c = int(rows[r, ROW_CONTACT])
        ba, bb = ints[c, 0], ints[c, 1]
        p0, p1, p2 = vals[c, IMP_POINT], vals[c, IMP_POINT + 1], vals[c, IMP_POINT + 2]
        w0, w1, w2 = _point_velocity(link, velocity, x, ba, cw.body_velocity, cw.body_omega, p0, p1, p2)
        if bb >= 0:
            z0, z1, z2 = _point_velocity(link, velocity, x, bb, cw.body_velocity, cw.body_omega, p0, p1, p2)
            w0, w1, w2 = w0 - z0, w1 - z1, w2 - z2
        rows[r, ROW_UE] = w0 * rows[r, ROW_DIR] + w1 * rows[r, ROW_DIR + 1] + w2 * rows[r, ROW_DIR + 2]
        rows[r, ROW_B] = rows[r, ROW_LAW] + rows[r, ROW_C_OVER_W] * rows[r, ROW_U] - rows[r, ROW_UE]
    # the joint limits at or past a bound join the solve as hard rows (else a limb pressed against its
    # limit would be pushed by a contact force sized for the limb alone: limits.py acts only after)
    R = limit_rows(tree.limits, tree, tree_data, rows, R, h)
    # h A, column by column: the unit force along row r's direction (on a, minus on b), its velocity change
    for r in range(contact_rows):
        c = int(rows[r, ROW_CONTACT])
        ba, bb = ints[c, 0], ints[c, 1]
        p0, p1, p2 = vals[c, IMP_POINT], vals[c, IMP_POINT + 1], vals[c, IMP_POINT + 2]
        e0, e1, e2 = rows[r, ROW_DIR], rows[r, ROW_DIR + 1], rows[r, ROW_DIR + 2]
        push(x, ba, p0, p1, p2, e0, e1, e2, force, torque)
        if bb >= 0:
            push(x, bb, p0, p1, p2, -e0, -e1, -e2, force, torque)
        generalized_momentum(tree, work, force, torque, rw.tau)
        _response_column(tree, work, rw, link, x, ints, vals, rows, contact_rows, A, r, h)
        limit_column(tree.limits, tree, tree_data, rows, contact_rows, R, A, r, h)
        _clear_wrench(force, torque, ba)
        if bb >= 0:
            _clear_wrench(force, torque, bb)
    for r in range(contact_rows, R):  # the limit rows' columns
        limit_unit(tree.limits, tree, tree_data, rows, r, rw.tau)
        _response_column(tree, work, rw, link, x, ints, vals, rows, contact_rows, A, r, h)
        limit_column(tree.limits, tree, tree_data, rows, contact_rows, R, A, r, h)
    _unbounded_solve(A, factor, rows, R)
    _projected_gauss_seidel(A, rows, vals, R)
    # the end-of-step forces: the normal at >= 0, the tangential within mu f_n; their change on the bodies
    r = 0
    while r < contact_rows:
        c = int(rows[r, ROW_CONTACT])
        v = vals[c]
        span = int(v[IMP_ROWS])
        n0, n1, n2 = v[IMP_NORMAL], v[IMP_NORMAL + 1], v[IMP_NORMAL + 2]
        fn0 = v[IMP_FN]
        fn = max(0.0, fn0 + rows[r, ROW_D])
        t0, t1, t2 = v[IMP_FT], v[IMP_FT + 1], v[IMP_FT + 2]
        if span == 3:
            for j in range(1, 3):
                d = rows[r + j, ROW_D]
                t0 += d * rows[r + j, ROW_DIR]
                t1 += d * rows[r + j, ROW_DIR + 1]
                t2 += d * rows[r + j, ROW_DIR + 2]
        else:  # frictionless: no tangential force
            t0 = t1 = t2 = 0.0
        cap = v[IMP_MU] * fn
        length2 = t0 * t0 + t1 * t1 + t2 * t2
        if length2 > cap * cap:
            scale = cap / math.sqrt(length2) if length2 > 0.0 else 0.0
            t0, t1, t2 = t0 * scale, t1 * scale, t2 * scale
        d0 = (fn - fn0) * n0 + t0 - v[IMP_FT]
        d1 = (fn - fn0) * n1 + t1 - v[IMP_FT + 1]
        d2 = (fn - fn0) * n2 + t2 - v[IMP_FT + 2]
        p0, p1, p2 = v[IMP_POINT], v[IMP_POINT + 1], v[IMP_POINT + 2]
        ba, bb = ints[c, 0], ints[c, 1]
        push(x, ba, p0, p1, p2, d0, d1, d2, force, torque)
        if bb >= 0:
            push(x, bb, p0, p1, p2, -d0, -d1, -d2, force, torque)
        r += span
    generalized_momentum(tree, work, force, torque, rw.tau)
    limit_apply(tree.limits, tree, tree_data, rows, contact_rows, R, rw.tau)
    tree_response(tree, work, rw.tau, rw.delta, rw.force, rw.acc)
    rate = tree_data.rate
    for k in range(rate.shape[0]):
        rate[k] += h * rw.delta[k]
    for c in range(count):
        _clear_wrench(force, torque, ints[c, 0])
        if ints[c, 1] >= 0:
            _clear_wrench(force, torque, ints[c, 1])


@numba.njit(cache=True)
def _response_column(tree, work, rw, link, x, ints, vals, rows, contact_rows, A, col, h) -> None:  # noqa: ANN001
    """Column `col` of h A over the contact rows: M^-1 of the generalized force in rw.tau (ABA's unit
    response: rw.delta the rates', rw.acc the links' velocity change), seen along each contact row's
    direction at its point."""
    tree_response(tree, work, rw.tau, rw.delta, rw.force, rw.acc)
    acc = rw.acc
    for s in range(contact_rows):
        c = int(rows[s, ROW_CONTACT])
        ba, bb = ints[c, 0], ints[c, 1]
        p0, p1, p2 = vals[c, IMP_POINT], vals[c, IMP_POINT + 1], vals[c, IMP_POINT + 2]
        w0, w1, w2 = _link_point_velocity(link, acc, x, ba, p0, p1, p2)
        if bb >= 0:
            z0, z1, z2 = _link_point_velocity(link, acc, x, bb, p0, p1, p2)
            w0, w1, w2 = w0 - z0, w1 - z1, w2 - z2
        A[s, col] = h * (w0 * rows[s, ROW_DIR] + w1 * rows[s, ROW_DIR + 1] + w2 * rows[s, ROW_DIR + 2])


@numba.njit(cache=True)
def _unbounded_solve(A, L, rows, count) -> None:  # noqa: ANN001
    """d of (diag(1/w) + h A) d = b without bounds, by Cholesky (L: its scratch), clamped into each row's
    bounds: the start of the projected Gauss-Seidel, which then only resolves the rows whose bounds act (a
    rigid body's corners couple through a matrix of rank 6, on which Gauss-Seidel alone converges
    slowly: a box held on a slope crept). d = 0 where the factor fails (rows that are not independent)."""
    for r in range(count):
        for c in range(r + 1):
            L[r, c] = A[r, c] + (rows[r, ROW_INV_W] if c == r else 0.0)
    for j in range(count):
        d = L[j, j]
        for k in range(j):
            d -= L[j, k] * L[j, k]
        if not d > 1e-14 * (abs(L[j, j]) + 1e-300):
            for r in range(count):
                rows[r, ROW_D] = 0.0
            return
        d = math.sqrt(d)
        L[j, j] = d
        for i in range(j + 1, count):
            v = L[i, j]
            for k in range(j):
                v -= L[i, k] * L[j, k]
            L[i, j] = v / d
    for r in range(count):  # L y = b
        v = rows[r, ROW_B]
        for c in range(r):
            v -= L[r, c] * rows[c, ROW_D]
        rows[r, ROW_D] = v / L[r, r]
    for r in range(count - 1, -1, -1):  # L^T d = y
        v = rows[r, ROW_D]
        for c in range(r + 1, count):
            v -= L[c, r] * rows[c, ROW_D]
        rows[r, ROW_D] = v / L[r, r]
    for r in range(count):
        rows[r, ROW_D] = min(max(rows[r, ROW_D], rows[r, ROW_LO]), rows[r, ROW_HI])


@numba.njit(cache=True)
def _projected_gauss_seidel(A, rows, vals, count) -> None:  # noqa: ANN001
    """(diag(1/w) + h A) d = b within each row's bounds [lo, hi] and each sticking contact's friction disc
    (its tangential force within mu times its normal force, both at the end of the step), by projected
    Gauss-Seidel from the rows' d (the contacts' rows soft, the limits' hard: 1/w = 0), until no d changes
    by 1e-10 of the largest."""
    for _ in range(PGS_SWEEPS):
        change, size = 0.0, 0.0
        for r in range(count):
            diagonal = A[r, r] + rows[r, ROW_INV_W]
            if diagonal <= 0.0:  # a row nothing moves (a singular cone row): no force
                continue
            residual = rows[r, ROW_B] - rows[r, ROW_INV_W] * rows[r, ROW_D]
            for s in range(count):
                residual -= A[r, s] * rows[s, ROW_D]
            old = rows[r, ROW_D]
            new = min(max(old + residual / diagonal, rows[r, ROW_LO]), rows[r, ROW_HI])
            rows[r, ROW_D] = new
            change = max(change, abs(new - old))
            size = max(size, abs(new))
            c = int(rows[r, ROW_CONTACT])
            if c >= 0 and r >= 2 and rows[r - 2, ROW_CONTACT] == c and rows[r - 1, ROW_CONTACT] == c:
                # the contact's second tangent row: its tangential force (f0_t + d) onto mu f_n's disc
                v = vals[c]
                t0 = (v[IMP_FT] * rows[r - 1, ROW_DIR] + v[IMP_FT + 1] * rows[r - 1, ROW_DIR + 1]
                      + v[IMP_FT + 2] * rows[r - 1, ROW_DIR + 2]) + rows[r - 1, ROW_D]  # fmt: skip
                t1 = (v[IMP_FT] * rows[r, ROW_DIR] + v[IMP_FT + 1] * rows[r, ROW_DIR + 1]
                      + v[IMP_FT + 2] * rows[r, ROW_DIR + 2]) + rows[r, ROW_D]  # fmt: skip
                cap = v[IMP_MU] * (v[IMP_FN] + rows[r - 2, ROW_D])
                length2 = t0 * t0 + t1 * t1
                if length2 > cap * cap:
                    scale = cap / math.sqrt(length2)
                    rows[r - 1, ROW_D] += (scale - 1.0) * t0
                    rows[r, ROW_D] += (scale - 1.0) * t1
        if change <= 1e-10 * size:
            break


def limit_rows(limits, tree, tree_data, rows, start, h) -> int:  # noqa: ANN001
    """Append the limit rows at or past a bound (after the explicit rates) from row `start`; the new count.
    Compiled to `start` where the trees have no limits."""
    kernel_only()
    return start


@overload(limit_rows, jit_options=DISPATCH_OPTIONS)
def _limit_rows(limits, tree, tree_data, rows, start, h):  # noqa: ANN001, ANN202
    if absent(limits):
        return lambda limits, tree, tree_data, rows, start, h: start

    def run(limits, tree, tree_data, rows, start, h):  # noqa: ANN001, ANN202
        lw, coord, rate = tree_data.limits, tree_data.coord, tree_data.rate
        count = start
        for k in range(limits.link_kind.shape[0]):
            if limits.link_kind[k, 1] == MOTOR or count >= rows.shape[0]:
                continue  # motors: limits.py's own stage
            value = limit_value(tree, k, coord, lw.row[k])
            speed = limit_along(tree, k, lw.row, rate)
            lower, upper = limits.data[k, LIMIT_LOWER], limits.data[k, LIMIT_UPPER]
            ahead = value + h * speed
            # limits.py's position target: the bound reached at the end of the step, pushing inwards only
            if ahead < lower or value <= lower + LIMIT_CONTACT:
                target, lo, hi = (lower - value) / h, 0.0, math.inf
            elif ahead > upper or value >= upper - LIMIT_CONTACT:
                target, lo, hi = (upper - value) / h, -math.inf, 0.0
            else:
                continue
            row = rows[count]
            row[ROW_CONTACT] = -1.0 - k
            row[ROW_INV_W], row[ROW_C_OVER_W], row[ROW_U], row[ROW_UE] = 0.0, 0.0, 0.0, speed
            row[ROW_D], row[ROW_LO], row[ROW_HI] = 0.0, lo, hi
            row[ROW_B] = target - speed
            count += 1
        return count

    return run


def limit_column(limits, tree, tree_data, rows, start, count, A, col, h) -> None:  # noqa: ANN001
    """Column `col` of h A over the limit rows start..count, from the rates' response in response.delta."""
    kernel_only()


@overload(limit_column, jit_options=DISPATCH_OPTIONS)
def _limit_column(limits, tree, tree_data, rows, start, count, A, col, h):  # noqa: ANN001, ANN202
    if absent(limits):
        return lambda limits, tree, tree_data, rows, start, count, A, col, h: None

    def run(limits, tree, tree_data, rows, start, count, A, col, h):  # noqa: ANN001, ANN202
        delta, row = tree_data.response.delta, tree_data.limits.row
        for s in range(start, count):
            A[s, col] = h * limit_along(tree, -1 - int(rows[s, ROW_CONTACT]), row, delta)

    return run


def limit_unit(limits, tree, tree_data, rows, r, tau) -> None:  # noqa: ANN001
    """tau = J^T of limit row r (its unit force)."""
    kernel_only()


@overload(limit_unit, jit_options=DISPATCH_OPTIONS)
def _limit_unit(limits, tree, tree_data, rows, r, tau):  # noqa: ANN001, ANN202
    if absent(limits):
        return lambda limits, tree, tree_data, rows, r, tau: None

    def run(limits, tree, tree_data, rows, r, tau):  # noqa: ANN001, ANN202
        for d in range(tau.shape[0]):
            tau[d] = 0.0
        limit_add_along(tree, -1 - int(rows[r, ROW_CONTACT]), tree_data.limits.row, 1.0, tau)

    return run


def limit_apply(limits, tree, tree_data, rows, start, count, tau) -> None:  # noqa: ANN001
    """tau += the limit rows' forces d along their J^T."""
    kernel_only()


@overload(limit_apply, jit_options=DISPATCH_OPTIONS)
def _limit_apply(limits, tree, tree_data, rows, start, count, tau):  # noqa: ANN001, ANN202
    if absent(limits):
        return lambda limits, tree, tree_data, rows, start, count, tau: None

    def run(limits, tree, tree_data, rows, start, count, tau):  # noqa: ANN001, ANN202
        for s in range(start, count):
            limit_add_along(tree, -1 - int(rows[s, ROW_CONTACT]), tree_data.limits.row, rows[s, ROW_D], tau)

    return run


def implicit_contact_stage(force_data, tree, tree_data, x, q, P, L, h) -> None:  # noqa: ANN001
    """implicit_contact where the contact work keeps its contacts (reduced-implicit with contact); compiled
    to nothing elsewhere (physics/dispatch.py)."""
    kernel_only()


@overload(implicit_contact_stage, jit_options=DISPATCH_OPTIONS)
def _implicit_contact_stage(force_data, tree, tree_data, x, q, P, L, h):  # noqa: ANN001, ANN202
    cw = member(force_data, "contact")
    if absent(cw) or absent(member(cw, "implicit_float")):
        return lambda force_data, tree, tree_data, x, q, P, L, h: None

    def run(force_data, tree, tree_data, x, q, P, L, h):  # noqa: ANN001, ANN202
        implicit_contact(tree, tree_data, force_data.contact, x, q, P, L, h)

    return run
