"""The joint stages of a step: the velocity projection after it, the kick check before it, and the
factor of A = G W G^T they and the position stage share.

A split2 step of a scene with joints is RATTLE (joints/rattle.py has the method and why): the forces'
half kick, the joints' impulse at the start configuration found by Newton through split2's real drift,
the forces' half kick at the end, then `joint_velocity` here: the momenta projected so that the end
velocities satisfy the hidden constraint G_end V = 0 (one linear solve), mu = A_end^-1 G_end V,
(P, L) -= G_end^T mu; then the motors, dampers and limit stops (drives.py). Both multipliers summed are
the step's joint impulse (work.impulse), the reaction force being impulse / h.

One factor per step: the velocity stage factors A at the end configuration, and the next step's
position stage needs A at its start configuration, the same one. `factor_at` keeps the configuration a
factor belongs to (work.x_factor, work.q_factor) and reuses the factor when the state is bitwise that
configuration, which is then bitwise what factoring again would give: a checkpointed run continues
bitwise, and a state changed from outside (set_state, a kinematic body's pose) is factored afresh.

Static and kinematic bodies act as the world (W = 0, nothing applied to them) but their anchors move
with their pose; a kinematic body's velocity enters G V. Stats go to work.stats (tables.STAT_*).

The chunk loop calls the stages directly with the joint table and work (the model's joint table,
Model.kernel().joint, and Data.joint), which are None in a scene without joints, and the body arrays
alone as `model` (KernelBodies: one type for every scene, so a stage compiled for one kind of jointed
scene serves every other). Each stage begins with `if table is None or work is None: return`, and
numba prunes a branch on an argument's `is None` when it compiles (its dead-branch pruning, before
typing): in a jointless scene each stage compiles to an empty function and none of the rows, solver or
drive kernels is compiled. The stages take the step kernels' options (STEP_KERNEL: no reference
counting): compiled with numba's defaults they halved a 10-link chain's rate. Not through a
`numba.extending.overload` dispatcher, as the force stages are: the dispatcher's implementation was a
compiled level of its own between the loop and the stage, and each level links and re-optimises the
whole solver below it (~2 s of LLVM per stage, measured: 5.7 s of the pendulum's first compile).
"""

from __future__ import annotations

import numba

from rbcli.physics.joints.drives import drive_velocities
from rbcli.physics.joints.impulses import apply_body_impulses, body_weights, gather_impulses, row_velocities
from rbcli.physics.joints.limit_solve import limit_stops
from rbcli.physics.joints.rows import joint_rows
from rbcli.physics.joints.solver import factor_rows, solve_rows
from rbcli.physics.joints.tables import STAT_VELOCITY
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL

# joint_begin projects the velocities when some row's rate |G V| exceeds this [m/s or rad/s]: the velocity
# stage leaves ~1e-16 to 1e-14 (a loop with dropped rows and motors), a kick or a velocity given without
# regard to the joints leaves orders of magnitude more
VELOCITY_SLACK = 1e-12


@separately_compiled
@numba.njit(**STEP_KERNEL)
def joint_velocity(model, table, work, h, x, q, P, L) -> None:  # noqa: ANN001
    """The velocity stage: (P, L) -= G^T mu with G V = 0 after it, G at the end configuration; then the
    motors and dampers (drives.py), then the limits that are reached, together (limit_solve.py)."""
    if table is None or work is None:
        return
    project_momenta(model, table, work, x, q, P, L)
    # each is a call passing the joint table and work (~100 arrays, ~100 ns): only where the scene has any
    if _has_drives(table):
        drive_velocities(model, table, work, h, x, q, P, L)
    if work.limit_scratch.lam.shape[0] > 0:  # the scratch is sized by the scene's limits (tables.py)
        limit_stops(model, table, work, x, q, P, L)
    work.stats[STAT_VELOCITY] = row_velocities(model, table, work, q, P, L)
    for b in range(P.shape[0]):
        for c in range(3):
            work.P_left[b, c] = P[b, c]
            work.L_left[b, c] = L[b, c]


@numba.njit(cache=True, inline="always")
def _has_drives(table) -> bool:  # noqa: ANN001
    """Whether any joint has a motor or a damper (drives.py)."""
    for j in range(table.kind.shape[0]):
        if table.motor_cap[j] > 0.0 or table.damping[j] > 0.0:
            return True
    return False


@separately_compiled
@numba.njit(**STEP_KERNEL)
def joint_begin(model, table, work, x, q, P, L) -> None:  # noqa: ANN001
    """Before a step: velocities that break the joints' rows (initial velocities given without regard to
    the joints, or an impulse just applied) are projected onto G V = 0 at the current configuration. For
    ideal joints that projection is the exact impulsive reaction (the W-orthogonal projection of the
    velocity onto the joints' tangent space: the momenta change only along G^T), so a kick on a jointed
    body acts as the joints would take it. Otherwise (every step after the first) it checks G V only,
    with the last velocity stage's rows when the state is still at their configuration, and not even
    that when the momenta too are bitwise those that stage left (its G V is then in the stats: ~0.3 us
    of a 10-link chain's ~17 us step)."""
    if table is None or work is None:
        return
    if not at_factor(work, x, q):
        work.factor_state[0] = 0.0  # the rows below are not the factor's any more
        joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, True)
    elif work.stats[STAT_VELOCITY] <= VELOCITY_SLACK and _momenta_left(work, P, L):
        return  # bitwise the state the last velocity stage left, with G V within the slack
    if row_velocities(model, table, work, q, P, L) > VELOCITY_SLACK:
        project_momenta(model, table, work, x, q, P, L)


@numba.njit(**STEP_KERNEL)
def at_factor(work, x, q) -> bool:  # noqa: ANN001
    """Whether the factor in work is set and belongs to the configuration (x, q), bit for bit."""
    if work.factor_state[0] != 1.0:
        return False
    for b in range(x.shape[0]):
        for c in range(3):
            if x[b, c] != work.x_factor[b, c]:
                return False
        for c in range(4):
            if q[b, c] != work.q_factor[b, c]:
                return False
    return True


@numba.njit(**STEP_KERNEL)
def _momenta_left(work, P, L) -> bool:  # noqa: ANN001
    """Whether (P, L) are bitwise the momenta the last velocity stage left (work.P_left, L_left)."""
    for b in range(P.shape[0]):
        for c in range(3):
            if P[b, c] != work.P_left[b, c] or L[b, c] != work.L_left[b, c]:
                return False
    return True


@separately_compiled
@numba.njit(**STEP_KERNEL)
def factor_at(model, table, work, x, q) -> int:  # noqa: ANN001
    """The factor of A = G W G^T at (x, q) in work.solver, with G (work.jac_a, jac_b) and W (work.inv_mass,
    inv_inertia) there: the one already in work when it belongs to (x, q), else a new one (module
    docstring); returns the rows the factor dropped as redundant."""
    if at_factor(work, x, q):
        return int(work.factor_state[1])
    body_weights(model, table, work, q)
    joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, True)
    redundant = factor_rows(table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b,
                            work.jac_a, work.jac_b, work.inv_mass, work.inv_inertia)  # fmt: skip
    for b in range(x.shape[0]):
        for c in range(3):
            work.x_factor[b, c] = x[b, c]
        for c in range(4):
            work.q_factor[b, c] = q[b, c]
    work.factor_state[0] = 1.0
    work.factor_state[1] = redundant
    return redundant


@separately_compiled
@numba.njit(cache=True)
def project_momenta(model, table, work, x, q, P, L) -> None:  # noqa: ANN001
    """(P, L) -= G^T mu, mu = A^-1 G V at (x, q): G V = 0 after it; mu is added to work.impulse."""
    factor_at(model, table, work, x, q)
    row_velocities(model, table, work, q, P, L)
    solve_rows(table.graph, work.solver, table.row_start, table.row_count, table.body_a, table.body_b,
               work.residual, work.delta)  # fmt: skip
    for r in range(work.delta.shape[0]):
        work.delta[r] = -work.delta[r]
        work.impulse[r] += work.delta[r]
    gather_impulses(table, work, work.delta)
    apply_body_impulses(table, work, P, L)


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
