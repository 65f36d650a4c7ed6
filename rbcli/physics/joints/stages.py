"""The joint stages of a step: RATTLE-type position and velocity stages after split2's update.

After the unconstrained split2 step (all forces; D(h/2) K(h) D(h/2), docs/integrators.md) the state is
(x~, q~, P~, L~). The constraint force acts as an impulse Lambda at the kick, in the direction of the
rows' Jacobian G at the step's midpoint configuration (SHAKE at the midpoint, Hairer-Lubich-Wanner
VII.1; Leimkuhler-Reich ch. 7):

    P = P~ + G_mid^T Lambda,  and the second half drift moves the bodies by
    x = x~ + h/2 M^-1 dP,   q = exp(h/2 I_w^-1 dL) q~           (dP, dL: body b's part of G_mid^T Lambda)

with Lambda such that g(x, q) = 0 at the end of the step. `joint_position` solves that by simplified
Newton, Lambda += -(2/h) A^-1 g(x, q), A = G_mid W G_mid^T factored once per step, until |g| is at
round-off (ROUNDOFF_ULPS ulps of the largest body position) or stops falling (each iteration gains a
factor ~ h |omega|: 2-8 iterations at dt = 1e-3, more as a chain whips faster). Not warm-started from
the last step's impulse: extrapolated (2 L_n-1 - L_n-2) it saved a few per cent more and made a 100-link
hinge chain diverge after 5 s (measured 2026-12-04).
The translation part is exact (the drift is linear in P); the rotation part is the first-order response
of the turns to dL, an O(h^3) local difference, so the method keeps order 2.

The midpoint configuration comes from the end state without a saved copy: x_mid = x~ - h/2 P~/M
exactly (the second drift used the kicked P~), and q_mid = exp(-h/2 omega~) q~, omega~ = I_w^-1 L~,
the second half turn undone to O(h^2) (exact for isotropic bodies, whose half turn it is).

`joint_velocity` then projects the momenta so that the end velocities satisfy the hidden constraint
G_end V = 0 (one linear solve): mu = A_end^-1 G_end V, (P, L) -= G_end^T mu. Both multipliers summed
are the step's joint impulse (work.impulse), the reaction force being impulse / h.

Why the midpoint (measured, docs/joints.md): with G at the end (a plain post-projection) the
projection removes the velocity's normal part at the end, which shortens the tangential speed by a
factor cos(h omega) per step: first order and dissipative (energy falls steadily); with G at the
midpoint the impulse's tangential part at the end, Lambda sin(h omega / 2), restores it to O(h^3), and
the period error is second order with the energy error bounded.

Static and kinematic bodies act as the world (W = 0, nothing applied to them) but their anchors move
with their pose; a kinematic body's velocity enters G V. Stats go to work.stats (tables.STAT_*).

The chunk loop calls the three stages directly with the joint table and work (ForceTables.joint,
ForceData.joint), which are None in a scene without joints. Each stage begins with `if table is None or
work is None: return`, and numba prunes a branch on an argument's `is None` when it compiles (its
dead-branch pruning, before typing): in a jointless scene each stage compiles to an empty function and
none of the rows, solver or drive kernels is compiled. The three take the step kernels' options
(STEP_KERNEL: no reference counting), as the dispatchers' implementations did: compiled with numba's
defaults they halved a 10-link chain's rate (hinge 4.0e5 -> 2.3e5 link-steps/s). Not through a
`numba.extending.overload` dispatcher, as the force stages are: the dispatcher's implementation was a
compiled level of its own between the loop and the stage, and each level links and re-optimises the
whole solver below it (~2 s of LLVM per stage, measured: 5.7 s of the pendulum's first compile).
"""

from __future__ import annotations

import numba

from rbcli.physics.joints.drives import drive_velocities, limit_positions
from rbcli.physics.joints.impulses import (
    apply_body_impulses,
    body_omega,
    body_weights,
    gather_impulses,
    row_velocities,
    turn,
)
from rbcli.physics.joints.rows import joint_rows
from rbcli.physics.joints.solver import factor_rows, solve_rows
from rbcli.physics.joints.tables import STAT_FLOOR, STAT_ITERATIONS, STAT_POSITION, STAT_REDUNDANT, STAT_VELOCITY
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL

# the Newton iteration stops when |g| falls by less than this factor in one iteration (round-off
# reached), or after NEWTON_ITERATIONS (a step far too long for its joints: the stats show it)
NEWTON_STALL = 0.5
NEWTON_ITERATIONS = 50
# ... or when |g| is at round-off: ROUNDOFF_ULPS ulps of the largest body position, the scale of the
# anchors' world positions whose differences the rows are. Without it the iteration ran on through the
# round-off level, whose values come in multiples of 2^-54 and halve by chance (1.1e-16 -> 5.6e-17 ->
# 2.8e-17 passes the stall test); stopping there made the 10- and 100-link chains' whole step ~15 %
# faster (hinge 10 links 4.1e5 -> 4.8e5 link-steps/s) with gaps still ~1e-16 .. 1e-14 m
ROUNDOFF_ULPS = 16.0
EPS = 2.220446049250313e-16
# rounds of (limits onto their bounds, joints again) in one position stage: each round gains the
# simplified Newton's factor ~ h |omega| on both, so a few reach round-off
LIMIT_ROUNDS = 8
# joint_begin projects the velocities when some row's rate |G V| exceeds this [m/s or rad/s]: the velocity
# stage leaves ~1e-16 to 1e-14 (a loop with dropped rows and motors), a kick or a velocity given without
# regard to the joints leaves orders of magnitude more
VELOCITY_SLACK = 1e-12


@separately_compiled
@numba.njit(**STEP_KERNEL)
def joint_position(model, table, work, h, x, q, P, L) -> None:  # noqa: ANN001
    """The position stage: the midpoint impulse that puts the end configuration on g = 0 (module
    docstring), then each violated limit pushed back onto its bound the same way (drives.py)."""
    if table is None or work is None:  # no joints: numba prunes the rest (module docstring)
        return
    half = 0.5 * h
    for b in range(x.shape[0]):  # the midpoint configuration of the step just taken
        inv_m = 1.0 / model.body_mass[b]
        work.x_mid[b, 0] = x[b, 0] - half * inv_m * P[b, 0]
        work.x_mid[b, 1] = x[b, 1] - half * inv_m * P[b, 1]
        work.x_mid[b, 2] = x[b, 2] - half * inv_m * P[b, 2]
        for c in range(4):
            work.q_mid[b, c] = q[b, c]
        w0, w1, w2 = body_omega(model, q, L, b)
        turn(work.q_mid, b, -half * w0, -half * w1, -half * w2)
    body_weights(model, table, work, work.q_mid)
    joint_rows(table, work.x_mid, work.q_mid, work.jac_a, work.jac_b, work.residual, True)
    redundant = factor_rows(table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b,
                            work.jac_a, work.jac_b, work.inv_mass, work.inv_inertia)  # fmt: skip
    work.impulse[:] = 0.0
    work.joint_impulse[:, :] = 0.0
    work.limit_hit[:] = 0.0
    scale = 0.0
    for b in range(x.shape[0]):
        scale = max(scale, abs(x[b, 0]), abs(x[b, 1]), abs(x[b, 2]))
    work.stats[STAT_FLOOR] = ROUNDOFF_ULPS * EPS * scale
    worst, iterations = _newton(table, work, h, x, q, P, L)
    for _ in range(LIMIT_ROUNDS):  # limits reached in this step: onto the bound, then the joints again
        if not limit_positions(table, work, h, x, q, P, L):
            break
        worst, more = _newton(table, work, h, x, q, P, L)
        iterations += more
    work.stats[STAT_ITERATIONS] = iterations
    work.stats[STAT_POSITION] = worst
    work.stats[STAT_REDUNDANT] = redundant


@separately_compiled
@numba.njit(cache=True)
def _newton(table, work, h, x, q, P, L):  # noqa: ANN001, ANN202
    """Simplified Newton on the end configuration's residual with the midpoint factor; (max |g|, iterations)."""
    worst = joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, False)
    iterations = 0
    scale = -2.0 / h
    floor = work.stats[STAT_FLOOR]
    while worst > floor and iterations < NEWTON_ITERATIONS:
        for r in range(work.rhs.shape[0]):
            work.rhs[r] = scale * work.residual[r]
        solve_rows(table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b,
                   work.rhs, work.delta)  # fmt: skip
        for r in range(work.delta.shape[0]):
            work.impulse[r] += work.delta[r]
        gather_impulses(table, work, work.delta)
        apply_body_impulses(table, work, 0.5 * h, x, q, P, L)
        iterations += 1
        previous = worst
        worst = joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, False)
        if worst > NEWTON_STALL * previous:
            break
    return worst, iterations


@separately_compiled
@numba.njit(**STEP_KERNEL)
def joint_velocity(model, table, work, h, x, q, P, L) -> None:  # noqa: ANN001
    """The velocity stage: (P, L) -= G^T mu with G V = 0 after it, G at the end configuration; then the
    motors and dampers, then the limits that are reached (drives.py)."""
    if table is None or work is None:
        return
    _project(model, table, work, x, q, P, L)
    drive_velocities(model, table, work, h, x, q, P, L)
    work.stats[STAT_VELOCITY] = row_velocities(model, table, work, q, P, L)


@separately_compiled
@numba.njit(**STEP_KERNEL)
def joint_begin(model, table, work, x, q, P, L) -> None:  # noqa: ANN001
    """Before a step: velocities that break the joints' rows (initial velocities given without regard to
    the joints, or an impulse just applied) are projected onto G V = 0 at the current configuration. For
    ideal joints that projection is the exact impulsive reaction (the W-orthogonal projection of the
    velocity onto the joints' tangent space: the momenta change only along G^T), so a kick on a jointed
    body acts as the joints would take it. Otherwise (every step after the first) it checks G V only."""
    if table is None or work is None:
        return
    joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, True)
    if row_velocities(model, table, work, q, P, L) > VELOCITY_SLACK:
        _project(model, table, work, x, q, P, L)


@separately_compiled
@numba.njit(cache=True)
def _project(model, table, work, x, q, P, L) -> None:  # noqa: ANN001
    """(P, L) -= G^T mu, mu = A^-1 G V at (x, q): G V = 0 after it; mu is added to work.impulse."""
    body_weights(model, table, work, q)
    joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, True)
    factor_rows(table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b,
                work.jac_a, work.jac_b, work.inv_mass, work.inv_inertia)  # fmt: skip
    row_velocities(model, table, work, q, P, L)
    solve_rows(table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b,
               work.residual, work.delta)  # fmt: skip
    for r in range(work.delta.shape[0]):
        work.delta[r] = -work.delta[r]
        work.impulse[r] += work.delta[r]
    gather_impulses(table, work, work.delta)
    apply_body_impulses(table, work, 0.0, x, q, P, L)


@separately_compiled
@numba.njit(**STEP_KERNEL)
def joint_record(table, work, h, frames, filled, due) -> None:  # noqa: ANN001
    """On a recording step, each joint's reaction over the (sub-)step just taken, work.joint_impulse / h
    ([N], [N m] about each body's centre of mass, world: Simulation.joint_reactions' layout), into the
    frame the record stage is about to fill; only into buffers made for them (frames.joint (K, J, 12))."""
    if table is None or work is None:
        return
    out = frames.joint
    if not due or filled >= out.shape[0] or out.shape[1] != work.joint_impulse.shape[0]:
        return
    for j in range(out.shape[1]):  # / h, as Simulation.joint_reactions divides: the same bits
        for c in range(12):
            out[filled, j, c] = work.joint_impulse[j, c] / h
