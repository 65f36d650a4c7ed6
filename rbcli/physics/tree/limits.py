"""Joint limits and velocity motors in joint coordinates: impulses on the rates, solved together.

What a row acts on (TreeTable.limits; scene/compile_trees.py builds them from the
joints' limits, cones and motors):
- LIMIT_COORD: a hinge's angle or a slider's travel, the coordinate itself, between two bounds;
- LIMIT_TWIST, LIMIT_SWING: a ball joint's twist angle between bounds and its swing measure below 1, the
  functions of the relative rotation Q of the joint's frames that physics/joints/cone.py defines (the
  maximal joints' cone). From the ball's coordinate u: Q = A u B where the link is the joint's body_a
  (side +1), Q = A u^* B where it is body_b (side -1), A and B constant (compile_trees.py); the row over
  the ball's rates (omega, link frame) is R(A u)^T j (side +1) or -R(A)^T j (side -1), j cone.py's row in
  b's joint frame;
- MOTOR: a hinge's or slider's rate brought to a speed by at most cap h of impulse a step.

Each row is a function c of the coordinates with a row j over its link's rates (dc/dt = j . rate). An
impulse lambda on rows J changes the rates by M^-1 J^T lambda (M the tree's mass matrix with the
armature of the implicit dampers, integrate.py), computed by the articulated-body algorithm's force
passes on the factors the step's last ABA left (`tree_response`: O(n), no new factor). The rows act
after the integrator's smooth step (coord_f, rate_f) as impulses at the step's start would: rates change
by Delta = M^-1 J^T lambda and the coordinates by h Delta (for semi-implicit Euler exactly what an
impulse before its update gives), in two stages as the maximal joints' limits (joints/drives.py):

- position stage: a limit row whose coordinate c_f lies beyond a bound is put back onto it, h j . Delta
  = bound - c_f (exact for an angle or a travel: linear in the coordinates; a ball's swing and twist
  to second order, the rest in the next step), lambda pushing into the range only; a motor row brings
  its rate to its speed, |lambda| <= cap h. Rows are solved together: the dense A = J M^-1 J^T over the
  active rows (one response pass per row) by projected Gauss-Seidel to round-off (a small mixed
  complementarity problem: a ragdoll's few limits couple through the tree); a limit that this pushes
  past its own bound joins the active set and the solve runs again;
- velocity stage: a limit row at its bound (within LIMIT_CONTACT) with its rate pointing out of the range
  is stopped (j . rate = 0: an inelastic stop; the position stage alone would leave the rate that carried
  it there), motors held at their speed with what is left of their cap.

In semi-implicit Euler the motor is then implicit (a rate at its speed from the first step the cap
allows) and a limit holds its coordinate exactly; in RK4 the rows act once per step after the smooth
step, so a run is first order while a limit or a capped motor acts (fourth order between). The impulses
are internal to the tree: the reactions hold them (reactions.py `impulse_wrenches`, the stage's mean
force lambda / h).
"""

from __future__ import annotations

import math

import numba
from numba.extending import overload

from rbcli.physics import kernel_cache
from rbcli.physics.dispatch import DISPATCH_OPTIONS, absent, kernel_only
from rbcli.physics.joints.cone import swing_measure_row, twist_angle_row
from rbcli.physics.joints.drives import LIMIT_CONTACT
from rbcli.physics.joints.rows import quaternion_product
from rbcli.physics.joints.tables import JOINT_BALL
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.rotation_kernels import rotate_inverse
from rbcli.physics.step import STEP_KERNEL
from rbcli.physics.tree.aba import ball_forward, general_forward
from rbcli.physics.tree.flow import advance_coords
from rbcli.physics.tree.reactions import impulse_wrench_stage
from rbcli.physics.tree.table import (
    LIMIT_A,
    LIMIT_B,
    LIMIT_CAP,
    LIMIT_COORD,
    LIMIT_HALF_ANGLES,
    LIMIT_LOWER,
    LIMIT_SIDE,
    LIMIT_TWIST,
    LIMIT_UPPER,
    MOTOR,
)

kernel_cache.install()

# projected Gauss-Seidel sweeps at most (one row converges in one; coupled rows geometrically, a few
# tens for a ragdoll's limits); it stops when no lambda changes by more than round-off of the largest
PGS_SWEEPS = 500
# the position stage's passes at most, and how far past a bound [rad or 1] a later pass leaves a row: an
# angle or travel lands on its bound in the first pass; a ball's swing measure, quadratic in the
# correction, within ~1e-5 of it at a hard stop in the first, at round-off in three or four
POSITION_ITERATIONS = 8
POSITION_TOLERANCE = 1e-14


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


@separately_compiled
@numba.njit(**STEP_KERNEL)
def tree_response(tree, work, tau, delta, force, acc) -> None:  # noqa: ANN001
    """delta (D,) = M^-1 tau for a generalized impulse tau (D,), dual to the rates, with the factors of
    the last ABA in `work` (its U, D^-1, S, r: tree_accelerations' passes 2 and 3 with no velocity terms
    and no external force); acc (n, 6): each link's spatial velocity change (world-aligned at its centre
    of mass); force (n, 6): scratch. Overwrites work.u (ABA's, used only within an ABA) with the pass's
    own, so the forward pass is aba.py's ball_forward and general_forward for those links."""
    n = tree.parent.shape[0]
    motion, U, dinv, u = work.motion, work.U, work.dinv, work.u
    for i in range(n):
        for k in range(6):
            force[i, k] = 0.0
    for i in range(n - 1, -1, -1):
        p, d0, d1, e0 = tree.parent[i], tree.dof_start[i], tree.dof_start[i + 1], tree.dinv_start[i]
        f = force[i]
        k = d1 - d0
        if k == 1:
            s = motion[d0]
            uu = tau[d0] - (s[0] * f[0] + s[1] * f[1] + s[2] * f[2] + s[3] * f[3] + s[4] * f[4] + s[5] * f[5])
            u[d0] = uu
            if p >= 0:
                g = uu * dinv[e0]
                for c in range(6):
                    f[c] += U[d0, c] * g
        elif k == 3:  # ball: u' = R tau - S'^T f in the world-aligned basis (aba.py)
            cx, cy, cz = motion[d0 + 1, 5], -motion[d0, 5], motion[d0, 4]
            Rm = work.rotation[i]
            o0, o1, o2 = tau[d0], tau[d0 + 1], tau[d0 + 2]
            g0, g1, g2 = cy * f[5] - cz * f[4], cz * f[3] - cx * f[5], cx * f[4] - cy * f[3]
            u[d0] = Rm[0, 0] * o0 + Rm[0, 1] * o1 + Rm[0, 2] * o2 - f[0] + g0
            u[d0 + 1] = Rm[1, 0] * o0 + Rm[1, 1] * o1 + Rm[1, 2] * o2 - f[1] + g1
            u[d0 + 2] = Rm[2, 0] * o0 + Rm[2, 1] * o1 + Rm[2, 2] * o2 - f[2] + g2
            if p >= 0:
                for j in range(3):
                    g = dinv[e0 + 3 * j] * u[d0] + dinv[e0 + 3 * j + 1] * u[d0 + 1] + dinv[e0 + 3 * j + 2] * u[d0 + 2]
                    for c in range(6):
                        f[c] += U[d0 + j, c] * g
        else:  # fixed (no rate), free root (six)
            for l in range(d0, d1):
                s = motion[l]
                u[l] = tau[l] - (s[0] * f[0] + s[1] * f[1] + s[2] * f[2] + s[3] * f[3] + s[4] * f[4] + s[5] * f[5])
            if p >= 0:
                for j in range(k):
                    g = 0.0
                    for l in range(k):
                        g += dinv[e0 + j * k + l] * u[d0 + l]
                    for c in range(6):
                        f[c] += U[d0 + j, c] * g
        if p >= 0:  # to the parent's centre of mass: (n + r x f, f), r = x_i - x_p
            rx, ry, rz = work.xpos[i, 0], work.xpos[i, 1], work.xpos[i, 2]
            F = force[p]
            F[0] += f[0] + ry * f[5] - rz * f[4]
            F[1] += f[1] + rz * f[3] - rx * f[5]
            F[2] += f[2] + rx * f[4] - ry * f[3]
            F[3] += f[3]
            F[4] += f[4]
            F[5] += f[5]
    for i in range(n):
        p, d0, d1, e0 = tree.parent[i], tree.dof_start[i], tree.dof_start[i + 1], tree.dinv_start[i]
        if p >= 0:  # X a_parent: the linear part shifted to this centre of mass, a_lin - r x alpha
            rx, ry, rz = work.xpos[i, 0], work.xpos[i, 1], work.xpos[i, 2]
            a0, a1, a2 = acc[p, 0], acc[p, 1], acc[p, 2]
            a3 = acc[p, 3] - (ry * a2 - rz * a1)
            a4 = acc[p, 4] - (rz * a0 - rx * a2)
            a5 = acc[p, 5] - (rx * a1 - ry * a0)
        else:
            a0 = a1 = a2 = a3 = a4 = a5 = 0.0
        k = d1 - d0
        if k == 1:
            w = U[d0]
            g = (u[d0] - (w[0] * a0 + w[1] * a1 + w[2] * a2 + w[3] * a3 + w[4] * a4 + w[5] * a5)) * dinv[e0]
            delta[d0] = g
            s = motion[d0]
            a0, a1, a2 = a0 + s[0] * g, a1 + s[1] * g, a2 + s[2] * g
            a3, a4, a5 = a3 + s[3] * g, a4 + s[4] * g, a5 + s[5] * g
        elif k == 3:
            a0, a1, a2, a3, a4, a5 = ball_forward(tree.balls, work, i, d0, e0, a0, a1, a2, a3, a4, a5, delta)
        elif k > 1:
            a0, a1, a2, a3, a4, a5 = general_forward(tree.others, work, d0, d1, e0, a0, a1, a2, a3, a4, a5, delta)
        acc[i, 0], acc[i, 1], acc[i, 2], acc[i, 3], acc[i, 4], acc[i, 5] = a0, a1, a2, a3, a4, a5


@numba.njit(cache=True)
def _evaluate(tree, k, coord, row):  # noqa: ANN001, ANN202
    """Row k's coordinate at `coord` (a motor's: its coordinate, unused) and its row j over its link's
    rates into row (3,) (the module docstring)."""
    link, kind = tree.limits.link_kind[k, 0], tree.limits.link_kind[k, 1]
    c0 = tree.coord_start[link]
    if kind == LIMIT_COORD or kind == MOTOR:
        row[0], row[1], row[2] = 1.0, 0.0, 0.0
        return coord[c0]
    data = tree.limits.data[k]
    side = data[LIMIT_SIDE]
    uw, ux, uy, uz = coord[c0], coord[c0 + 1], coord[c0 + 2], coord[c0 + 3]
    if side < 0.0:
        ux, uy, uz = -ux, -uy, -uz
    A, B = LIMIT_A, LIMIT_B
    au = quaternion_product(data[A], data[A + 1], data[A + 2], data[A + 3], uw, ux, uy, uz)
    Q = quaternion_product(au[0], au[1], au[2], au[3], data[B], data[B + 1], data[B + 2], data[B + 3])
    if Q[0] < 0.0:
        Q = (-Q[0], -Q[1], -Q[2], -Q[3])
    if kind == LIMIT_TWIST:
        c, j = twist_angle_row(Q)
    else:
        c, j = swing_measure_row(Q, data[LIMIT_HALF_ANGLES], data[LIMIT_HALF_ANGLES + 1])
    if side > 0.0:  # R(A u)^T j
        r = rotate_inverse(au[0], au[1], au[2], au[3], j[0], j[1], j[2])
        row[0], row[1], row[2] = r[0], r[1], r[2]
    else:  # -R(A)^T j
        r = rotate_inverse(data[A], data[A + 1], data[A + 2], data[A + 3], j[0], j[1], j[2])
        row[0], row[1], row[2] = -r[0], -r[1], -r[2]
    return c


@numba.njit(cache=True, inline="always")
def _along(tree, k, row, vector) -> float:  # noqa: ANN001
    """j_k . vector over row k's link's rates."""
    link = tree.limits.link_kind[k, 0]
    d0, d1 = tree.dof_start[link], tree.dof_start[link + 1]
    total = 0.0
    for e in range(d1 - d0):
        total += row[k, e] * vector[d0 + e]
    return total


@numba.njit(cache=True, inline="always")
def _add_along(tree, k, row, weight, vector) -> None:  # noqa: ANN001
    """vector += weight j_k over row k's link's rates (J^T's column k: _along's transpose)."""
    link = tree.limits.link_kind[k, 0]
    d0, d1 = tree.dof_start[link], tree.dof_start[link + 1]
    for e in range(d1 - d0):
        vector[d0 + e] += weight * row[k, e]


@numba.njit(cache=True)
def _respond(tree, tree_data, count) -> None:  # noqa: ANN001
    """response.delta = M^-1 J^T lambda for the first `count` active rows' lambda (lw.stage_impulse)."""
    lw, rw = tree_data.limits, tree_data.response
    for d in range(rw.tau.shape[0]):  # element loops: a slice assignment compiles a shape check
        rw.tau[d] = 0.0
    for a in range(count):
        k = lw.active[a]
        _add_along(tree, k, lw.row, lw.stage_impulse[k], rw.tau)
    tree_response(tree, tree_data.work, rw.tau, rw.delta, rw.force, rw.acc)


@numba.njit(cache=True)
def _solve(tree, tree_data, count) -> None:  # noqa: ANN001
    """lambda (lw.stage_impulse) of the first `count` active rows: A lambda = target within [low, high]
    by projected Gauss-Seidel on the dense A = J M^-1 J^T (one response pass per row), then response.delta =
    M^-1 J^T lambda."""
    lw, rw = tree_data.limits, tree_data.response
    A, tau = lw.delassus, rw.tau
    for a in range(count):
        for d in range(tau.shape[0]):
            tau[d] = 0.0
        _add_along(tree, lw.active[a], lw.row, 1.0, tau)
        tree_response(tree, tree_data.work, tau, rw.delta, rw.force, rw.acc)
        for b in range(count):
            A[b, a] = _along(tree, lw.active[b], lw.row, rw.delta)
    lam = lw.stage_impulse
    for a in range(count):
        lam[lw.active[a]] = 0.0
    for _ in range(PGS_SWEEPS):
        change, size = 0.0, 0.0
        for a in range(count):
            k = lw.active[a]
            if A[a, a] <= 0.0:  # a row no rate moves (a singular cone row): no impulse
                continue
            residual = lw.target[k]
            for b in range(count):
                residual -= A[a, b] * lam[lw.active[b]]
            new = min(max(lam[k] + residual / A[a, a], lw.low[k]), lw.high[k])
            change = max(change, abs(new - lam[k]))
            size = max(size, abs(new))
            lam[k] = new
        if change <= 4e-16 * size:
            break
    _respond(tree, tree_data, count)


@numba.njit(cache=True)
def _apply(tree, tree_data, count, h, move) -> None:  # noqa: ANN001
    """rate += delta (and coord moved by h delta when `move`), lambda into lw.impulse, and the impulse's
    share of the reactions while they are recorded."""
    lw, rw = tree_data.limits, tree_data.response
    rate = tree_data.rate
    for d in range(rate.shape[0]):
        rate[d] += rw.delta[d]
    if move:
        advance_coords(tree, tree_data.coord, rw.delta, h)
    for a in range(count):
        k = lw.active[a]
        lw.impulse[k] += lw.stage_impulse[k]
    impulse_wrench_stage(tree_data.wrench, tree, tree_data, rw.acc, 1.0 / h)  # while the reactions are recorded


@numba.njit(cache=True)
def _is_active(lw, count, k) -> bool:  # noqa: ANN001
    for a in range(count):
        if lw.active[a] == k:
            return True
    return False


def limit_stage(limits, tree, tree_data, h) -> None:  # noqa: ANN001
    """The limits' stages (tree_limits) where the tree has limits; compiled to nothing where it has none
    (limits: the tree table's, None then: physics/dispatch.py)."""
    kernel_only()


@overload(limit_stage, jit_options=DISPATCH_OPTIONS)
def _limit_stage(limits, tree, tree_data, h):  # noqa: ANN001, ANN202
    if absent(limits):
        return lambda limits, tree, tree_data, h: None

    def run(limits, tree, tree_data, h):  # noqa: ANN001, ANN202
        tree_limits(tree, tree_data, h)

    return run


@separately_compiled
@numba.njit(**STEP_KERNEL)
def tree_limits(tree, tree_data, h) -> None:  # noqa: ANN001
    """The limits' and motors' two stages (module docstring) on the step just taken: tree_data.coord and
    .rate in place, before the step's closing forward kinematics; the factors are its last ABA's."""
    lw = tree_data.limits
    m = tree.limits.link_kind.shape[0]
    coord, rate = tree_data.coord, tree_data.rate
    for k in range(m):
        lw.impulse[k] = 0.0
        lw.value[k] = _evaluate(tree, k, coord, lw.row[k])
    # position stage: limits beyond a bound back onto it, motors to their speed; a ball's swing and twist
    # are not linear in the rates, so the stage repeats (simplified Newton: the same M) until they hold
    for iteration in range(POSITION_ITERATIONS):
        slack = 0.0 if iteration == 0 else POSITION_TOLERANCE
        count = 0
        for k in range(m):
            data = tree.limits.data[k]
            lower, upper = data[LIMIT_LOWER], data[LIMIT_UPPER]
            if iteration > 0:
                lw.value[k] = _evaluate(tree, k, coord, lw.row[k])
            if tree.limits.link_kind[k, 1] == MOTOR:
                if iteration > 0:  # at its speed (or its cap) since the first pass
                    continue
                cap = data[LIMIT_CAP] * h
                lw.target[k], lw.low[k], lw.high[k] = lower - _along(tree, k, lw.row, rate), -cap, cap
            elif lw.value[k] < lower - slack:
                lw.target[k], lw.low[k], lw.high[k] = (lower - lw.value[k]) / h, 0.0, math.inf
            elif lw.value[k] > upper + slack:
                lw.target[k], lw.low[k], lw.high[k] = (upper - lw.value[k]) / h, -math.inf, 0.0
            else:
                continue
            lw.active[count] = k
            count += 1
        if count == 0:
            break
        for _ in range(m):  # until the correction pushes no other limit past its bound
            _solve(tree, tree_data, count)
            grown = count
            for k in range(m):
                if tree.limits.link_kind[k, 1] == MOTOR or _is_active(lw, count, k):
                    continue
                data = tree.limits.data[k]
                moved = lw.value[k] + h * _along(tree, k, lw.row, tree_data.response.delta)
                if moved < data[LIMIT_LOWER]:
                    lw.target[k], lw.low[k], lw.high[k] = (data[LIMIT_LOWER] - lw.value[k]) / h, 0.0, math.inf
                elif moved > data[LIMIT_UPPER]:
                    lw.target[k], lw.low[k], lw.high[k] = (data[LIMIT_UPPER] - lw.value[k]) / h, -math.inf, 0.0
                else:
                    continue
                lw.active[grown] = k
                grown += 1
            if grown == count:
                break
            count = grown
        _apply(tree, tree_data, count, h, True)
    # velocity stage: a limit at its bound and moving out is stopped; motors keep their speed
    count, stops = 0, 0
    for k in range(m):
        data = tree.limits.data[k]
        lower, upper = data[LIMIT_LOWER], data[LIMIT_UPPER]
        lw.value[k] = _evaluate(tree, k, coord, lw.row[k])
        r = _along(tree, k, lw.row, rate)
        if tree.limits.link_kind[k, 1] == MOTOR:
            cap = data[LIMIT_CAP] * h
            lw.target[k], lw.low[k], lw.high[k] = lower - r, -cap - lw.impulse[k], cap - lw.impulse[k]
        elif lw.value[k] <= lower + LIMIT_CONTACT and r < 0.0:
            lw.target[k], lw.low[k], lw.high[k] = -r, 0.0, math.inf
            stops += 1
        elif lw.value[k] >= upper - LIMIT_CONTACT and r > 0.0:
            lw.target[k], lw.low[k], lw.high[k] = -r, -math.inf, 0.0
            stops += 1
        else:
            continue
        lw.active[count] = k
        count += 1
    if stops > 0:
        _solve(tree, tree_data, count)
        _apply(tree, tree_data, count, h, False)


# the row pieces implicit_contact.py shares (its contact solve takes the limits at their bounds in)
limit_value, limit_along, limit_add_along = _evaluate, _along, _add_along
