"""A split2 step of a scene with joints: RATTLE with split2's exact drift, symmetric and symplectic.

With H = T(P, L, q) + V(x, q) and the rows g(x, q) = 0 (G their Jacobian), the step from a state on the
joints (g = 0, G V = 0) at t is (Hairer-Lubich-Wanner VII.1.4 RATTLE, Leimkuhler-Reich ch. 7, with the
free-body drift of split2 in place of the particles' x += h v):

    K(h/2)   P += h/2 F(t, x, q), L += h/2 tau                (forces at the step's start)
    I        (P, L) += G(x, q)^T Lambda                       (the joints' impulse, at the start configuration)
    D(h)     the free drift of split2 over h                  (split2.free_drift: D_x, T_a T_b T_c T_b T_a)
    K(h/2)   P += h/2 F(t + h, x', q'), L += h/2 tau'         (forces at the end)
    Pi       (P, L) -= G(x', q')^T mu, G(x', q') V' = 0       (the velocity stage, stages.joint_velocity)

with Lambda such that g(x', q') = 0 where the drift really ends. Psi = K D K is split2's own splitting
in velocity-Verlet order (symmetric, symplectic on T*SO(3) x R^3 per body), and for any symmetric
symplectic Psi the map Pi Psi I is symmetric and symplectic on the joints' manifold: run at -h from the
end it retraces the same two impulses in reverse (each multiplier is fixed by the same condition), and
each impulse along G^T changes the symplectic form only by d lambda ^ dg, zero on g = 0 (Reich 1996,
SIAM J. Numer. Anal. 33; Leimkuhler & Skeel 1994). So the energy error is bounded, without drift, for
any bodies; the method is second order. Forces are evaluated at the start and at the end of the step
(two evaluations; the one at the end is not reused by the next step, which may follow an impulse, a
kinematic update or a checkpoint).

Lambda by simplified Newton: Lambda += -(1/h) A^-1 g(x', q'), A = G W G^T at the start configuration,
each iteration re-running the drift of every body the impulse moved from the start with its new
momenta, until |g| is at round-off (ROUNDOFF_ULPS ulps of the largest body position) or stops falling
(each iteration gains a factor ~ h |omega|). A is the factor the last velocity stage built at this very
configuration (stages.factor_at reuses it when the state is bitwise that configuration), so a step
factors once. The first iterate extrapolates Lambda from the last steps' by a polynomial of degree 0 to
GUESS_ORDER (5), the degree that predicted the last step's best (`_first_iterate`, `_remember`): on the
10-link chains of bench_joints the line through the last two took 4.33 iterations a step, the chosen
degree 2.90 (a smooth motion takes a high degree; an impact or a limit one that overshoots less: the
shipped particle ragdoll 3.59 -> 2.08). One that does not reach round-off is dropped and the Newton runs
again from the free drift, as a run's first step does. The iterate does not change the step's map: the
Newton stops at the same root, to round-off (the reversibility and energy tests hold either way).

A limit beyond its bound at the end is pushed back by an impulse along its coordinate's row at the
start, h k lambda = bound - c, the active limits together, alternating with the joints' Newton
(limit_solve.limit_positions).

Kinematic bodies are put at their exact end pose (kinematic_end) before the Newton, so the rows close
on the prescribed pose; static and kinematic bodies take no impulse (W = 0). Dampers and drag (the
dissipative terms) act as their own flow on the joints' tangent space at both ends (joints/dissipation.py):
D(h/2) on the momenta the last velocity stage left, then the conservative RATTLE step, then at the end
the momenta projected onto G V = 0 and D(h/2) again, a palindrome: second order (symplectic only in the
conservative part, as split2). Their free flow (forces/damping.py) applied to the drift's momenta, which
break the velocity rows by O(h), made the step first order (docs/integrators.md, "Limitations").
"""

from __future__ import annotations

import math

import numba
import numpy as np
from numba.extending import overload

from rbcli.physics.dispatch import DISPATCH_OPTIONS, absent, kernel_only
from rbcli.physics.forces.damping import dissipation_present
from rbcli.physics.forces.wrench import accumulate_wrench
from rbcli.physics.integrators.split2 import free_drift
from rbcli.physics.joints.dissipation import joint_dissipation
from rbcli.physics.joints.impulses import apply_body_impulses, body_impulses, gather_impulses, joint_impulses
from rbcli.physics.joints.limit_solve import limit_positions
from rbcli.physics.joints.rows import joint_rows
from rbcli.physics.joints.solver import solve_rows
from rbcli.physics.joints.stages import at_factor, factor_at, project_momenta
from rbcli.physics.joints.tables import (
    GUESS_ORDER,
    STAT_FLOOR,
    STAT_ITERATIONS,
    STAT_POSITION,
    STAT_REDUNDANT,
    STAT_RESTARTS,
)
from rbcli.physics.kernel_link import empty_without, separately_compiled
from rbcli.physics.stages import kinematic_end_stage
from rbcli.physics.step import STEP_KERNEL

# the Newton iteration stops when |g| falls by less than this factor in one iteration (round-off
# reached), or after NEWTON_ITERATIONS (a step far too long for its joints: the stats show it)
NEWTON_STALL = 0.5
NEWTON_ITERATIONS = 50
# ... or when |g| is at round-off: ROUNDOFF_ULPS ulps of the largest body position, the scale of the
# anchors' world positions whose differences the rows are (below it |g| comes in multiples of 2^-54
# that halve by chance, and iterating on costs ~15 % of a chain's step for nothing)
ROUNDOFF_ULPS = 16.0
EPS = 2.220446049250313e-16
# rounds of (limits onto their bounds together, joints again) in one position stage at most: each round
# gains the simplified Newton's factor ~ h |omega| on both, so three or four reach round-off
LIMIT_ROUNDS = 12
# the Newton's first iterate extrapolates Lambda by a polynomial of degree <= GUESS_ORDER (tables.py)
# through the last steps' (`_first_iterate`); measured on the 10-link chains of bench_joints, each degree
# fixed: 1 (the line) 4.33 Newton iterations a step, 2: 3.86, 3: 3.48, 4: 3.15, 5: 2.87
# backward-difference extrapolation weights, row d: (-1)^k C(d + 1, k + 1), k = 0..d
EXTRAPOLATION = np.array([[(-1.0) ** k * math.comb(d + 1, k + 1) if k <= d else 0.0 for k in range(GUESS_ORDER + 1)]
                          for d in range(GUESS_ORDER + 1)])  # fmt: skip


@empty_without("table", "work")
@separately_compiled
@numba.njit(**STEP_KERNEL)
def joint_update(
    model, forces, contact, force_data, table, work, kinematic, schedule, t, h, x, q, P, L, F, tau
) -> bool:  # noqa: ANN001
    """The split2 step over [t, t + h) of a scene with joints, up to the velocity stage (module
    docstring); False, doing nothing, without joints (numba prunes the rest: the caller then runs the
    plain split2 step)."""
    if table is None or work is None:
        return False
    work.joint_impulse[:, :] = 0.0  # this step's reactions, gathered by the stages below
    work.limit_hit[:, :] = 0.0
    work.limit_push[:, :] = 0.0
    for b in range(x.shape[0]):
        for c in range(3):
            work.x_start[b, c] = x[b, c]
        for c in range(4):
            work.q_start[b, c] = q[b, c]
    # the factor the last velocity stage left is this configuration's (stages.factor_at), checked here
    # first: the call passes the joint table and work (~100 ns)
    if at_factor(work, work.x_start, work.q_start):
        redundant = int(work.factor_state[1])
    else:
        redundant = factor_at(model, table, work, work.x_start, work.q_start)
    dissipative = dissipation_present(forces.spring, forces.drag)
    if dissipative:  # D(h/2) on the joints' tangent space, on the momenta the last velocity stage left
        joint_dissipation(model, forces.spring, forces.drag, table, work, 0.5 * h, x, q, P, L)
    accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau, not dissipative)
    _kick(forces.has_torque, 0.5 * h, P, L, F, tau)
    guessed = _first_iterate(table, work, P, L, redundant)
    for b in range(x.shape[0]):
        free_drift(model, b, h, work.x_start, work.q_start, P, L, x, q)
    kinematic_end_stage(model, kinematic, schedule, t + h, x, q, P, L)
    joint_position(model, table, work, h, x, q, P, L, guessed)
    work.stats[STAT_REDUNDANT] = redundant
    accumulate_wrench(model, forces, contact, force_data, t + h, x, q, P, L, F, tau, not dissipative)
    _kick(forces.has_torque, 0.5 * h, P, L, F, tau)
    if dissipative:  # the mirror of the start: onto G V = 0 at the end, then D(h/2) there
        project_momenta(model, table, work, x, q, P, L)
        joint_dissipation(model, forces.spring, forces.drag, table, work, 0.5 * h, x, q, P, L)
    return True


@numba.njit(**STEP_KERNEL)
def _kick(has_torque, s, P, L, F, tau) -> None:  # noqa: ANN001
    """P += s F, and L += s tau when some force term has a torque (tau is otherwise never written)."""
    for b in range(P.shape[0]):
        P[b, 0] += s * F[b, 0]
        P[b, 1] += s * F[b, 1]
        P[b, 2] += s * F[b, 2]
        if has_torque:
            L[b, 0] += s * tau[b, 0]
            L[b, 1] += s * tau[b, 1]
            L[b, 2] += s * tau[b, 2]


@numba.njit(cache=True, inline="always")
def _extrapolate(guess, order, r) -> float:  # noqa: ANN001
    """Row r's next Lambda from the polynomial of degree `order` through the last order + 1 steps' (guess
    row 0 the last): sum_k (-1)^k C(order + 1, k + 1) Lambda_k, the backward-difference extrapolation."""
    total = 0.0
    for k in range(order + 1):
        total += EXTRAPOLATION[order, k] * guess[k, r]
    return total


@numba.njit(**STEP_KERNEL)
def _first_iterate(table, work, P, L, redundant) -> bool:  # noqa: ANN001
    """The Newton's first iterate: Lambda extrapolated from the last steps' by the polynomial whose degree
    (0 to GUESS_ORDER) predicted the last step's Lambda best (`_remember`), applied to (P, L) along G at
    the start configuration (the factor's rows); the kicked momenta are kept in work.P_kicked, L_kicked
    for a restart. False, applying nothing, on a run's first step, and where the start's factor dropped
    rows as redundant (a loop): the guess would push along a dropped row, which the Newton can only
    offset through the rows nearly parallel to it, with multipliers of 1e6-1e8 that cancel (measured on
    the four-bar, whose dropped set changes from step to step) and bury the reactions in round-off."""
    work.impulse[:] = 0.0
    if work.guess_count[0] == 0.0 or redundant != 0:
        return False
    order = int(work.guess_count[1])
    for r in range(work.delta.shape[0]):
        work.delta[r] = _extrapolate(work.guess, order, r)
        work.impulse[r] = work.delta[r]
    for b in range(P.shape[0]):
        for c in range(3):
            work.P_kicked[b, c] = P[b, c]
            work.L_kicked[b, c] = L[b, c]
    body_impulses(table, work, work.delta)
    apply_body_impulses(table, work, P, L)
    return True


@separately_compiled
@numba.njit(**STEP_KERNEL)
def joint_position(model, table, work, h, x, q, P, L, guessed) -> None:  # noqa: ANN001
    """The joints' impulse at the start configuration (work.x_start, work.q_start, whose factor is in
    work.solver) that puts the end of the drift on g = 0, then each limit beyond its bound pushed back the
    same way (drives.py); (x, q) is the drift's end with the first iterate's impulse (already in work.impulse
    and (P, L): `_first_iterate`). A first iterate that does not converge to round-off (a step unlike the
    two before it: an impact, a limit reached) is dropped and the Newton runs again from the free drift,
    as a run's first step does; the converged Lambda is then the next step's guess."""
    scale = 0.0
    for b in range(x.shape[0]):
        scale = max(scale, abs(x[b, 0]), abs(x[b, 1]), abs(x[b, 2]))
    floor = ROUNDOFF_ULPS * EPS * scale
    work.stats[STAT_FLOOR] = floor
    worst, iterations = _newton(model, table, work, h, x, q, P, L, False)
    if guessed and worst > floor:  # the guess misled the simplified Newton: from the free drift instead
        work.stats[STAT_RESTARTS] += 1.0
        work.impulse[:] = 0.0
        work.joint_impulse[:, :] = 0.0
        for b in range(x.shape[0]):
            if table.body_ground[b]:
                continue
            for c in range(3):
                P[b, c] = work.P_kicked[b, c]
                L[b, c] = work.L_kicked[b, c]
            free_drift(model, b, h, work.x_start, work.q_start, P, L, x, q)
        worst, more = _newton(model, table, work, h, x, q, P, L, False)
        iterations += more
    joint_impulses(table, work, work.impulse)  # the rows' Lambda on each joint's bodies, once
    _remember(work)
    # limits reached in this step: onto their bounds, then the joints again (a scene without limits has
    # an empty scratch, tables.py, and makes no call)
    for _ in range(LIMIT_ROUNDS if work.limit_scratch.lam.shape[0] > 0 else 0):
        if not limit_positions(table, work, h, x, q, P, L):
            break
        for b in range(x.shape[0]):
            if not table.body_ground[b]:
                free_drift(model, b, h, work.x_start, work.q_start, P, L, x, q)
        worst, more = _newton(model, table, work, h, x, q, P, L, True)
        iterations += more
    work.stats[STAT_ITERATIONS] = iterations
    work.stats[STAT_POSITION] = worst


@numba.njit(cache=True)
def _remember(work) -> None:  # noqa: ANN001
    """The converged Lambda (the joints' alone: the limits' pushes are not rows) into the history
    (work.guess), and the degree for the next step's guess: the one whose extrapolation from the history
    before it came nearest (max over rows) to this Lambda. A smooth motion takes a high degree (each
    degree gains a factor ~ h |omega|), an impact or a limit one that overshoots less."""
    count = int(work.guess_count[0])
    best, best_order = math.inf, 0
    for order in range(min(count, GUESS_ORDER + 1)):
        miss = 0.0
        for r in range(work.impulse.shape[0]):
            miss = max(miss, abs(_extrapolate(work.guess, order, r) - work.impulse[r]))
        if miss < best:
            best, best_order = miss, order
    for r in range(work.impulse.shape[0]):
        for k in range(GUESS_ORDER, 0, -1):
            work.guess[k, r] = work.guess[k - 1, r]
        work.guess[0, r] = work.impulse[r]
    work.guess_count[0] = min(count + 1, GUESS_ORDER + 1)
    # while the history fills, a degree more than any it could fit yet (the next step has the entry for it)
    work.guess_count[1] = best_order if count > GUESS_ORDER else min(best_order + 1, count)


@separately_compiled
@numba.njit(**STEP_KERNEL)
def _newton(model, table, work, h, x, q, P, L, per_joint):  # noqa: ANN001, ANN202
    """Simplified Newton on the end configuration's residual with the start factor; (max |g|, iterations).
    Each iteration's multipliers go to work.impulse, and with `per_joint` to each joint's reaction too
    (else the caller adds the sum once: `joint_impulses`)."""
    worst = joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, False)
    iterations = 0
    scale = -1.0 / h
    floor = work.stats[STAT_FLOOR]
    while worst > floor and iterations < NEWTON_ITERATIONS:
        for r in range(work.rhs.shape[0]):
            work.rhs[r] = scale * work.residual[r]
        solve_rows(table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b,
                   work.rhs, work.delta)  # fmt: skip
        for r in range(work.delta.shape[0]):
            work.impulse[r] += work.delta[r]
        if per_joint:
            gather_impulses(table, work, work.delta)
        else:
            body_impulses(table, work, work.delta)
        for b in range(x.shape[0]):  # each body the impulse moved: its new momenta, its drift again
            if table.body_ground[b]:
                continue
            d = work.impulse_body[b]
            if d[0] == 0.0 and d[1] == 0.0 and d[2] == 0.0 and d[3] == 0.0 and d[4] == 0.0 and d[5] == 0.0:
                continue
            P[b, 0] += d[0]
            P[b, 1] += d[1]
            P[b, 2] += d[2]
            L[b, 0] += d[3]
            L[b, 1] += d[4]
            L[b, 2] += d[5]
            free_drift(model, b, h, work.x_start, work.q_start, P, L, x, q)
        iterations += 1
        previous = worst
        worst = joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, False)
        if worst > NEWTON_STALL * previous:
            break
    return worst, iterations


def joint_update_stage(
    model, forces, contact, force_data, table, work, kinematic, schedule, t, h, x, q, P, L, F, tau
) -> bool:  # noqa: ANN001
    """`joint_update` as split2's loop calls it (chunk_loop.py): the RATTLE step where the scene has
    joints, and False, compiling nothing of it, where the joint table or work is None (a split2 scene
    without joints: joint_update pruned to nothing still cost ~0.5-0.8 CPU-s of numba's front end on
    every such first run; physics/dispatch.py)."""
    kernel_only()
    return False


@overload(joint_update_stage, jit_options=DISPATCH_OPTIONS)
def _joint_update_stage(model, forces, contact, force_data, table, work, kinematic, schedule, t, h, x, q, P, L, F, tau):  # noqa: ANN001, ANN202
    if absent(table, work):

        def no_joints(model, forces, contact, force_data, table, work, kinematic, schedule, t, h, x, q, P, L, F, tau):  # noqa: ANN001, ANN202
            return False  # the loop runs split2's own update

        return no_joints

    def step(model, forces, contact, force_data, table, work, kinematic, schedule, t, h, x, q, P, L, F, tau):  # noqa: ANN001, ANN202
        return joint_update(
            model, forces, contact, force_data, table, work, kinematic, schedule, t, h, x, q, P, L, F, tau
        )

    return step
