"""The limits of a step, solved together: the position stage's pushes onto the bounds and the velocity
stage's stops (what each does for one limit: joints/drives.py's docstring).

Limits of one chain couple: a push at a wrist moves the elbow and the shoulder. Taken one after another
(a Gauss-Seidel sweep per stage) they converge slowly where the coupling is strong, and a step could end
with a limit still past its bound (1.3e-4 measured on a thrown 3-link chain, tests/physics/
test_tree_limits.py's CHAIN). Here the active limits of a stage are solved together, as the trees' limits
are (physics/tree/limits.py): with the joints held, an impulse lambda_b along limit b's row J_b changes
limit a's rate by

    K_ab lambda_b,   K_ab = J_a W J_b^T - (G W J_a^T)^T A^-1 (G W J_b^T)

(the joints' projection with the stage's factor of A = G W G^T; K_aa is drives.py's k). The impulses
solve K lambda = target within each limit's sign (a limit only pushes into its range: the impulse it
gave in this step stays of that sign, so a later round may take back what an earlier one pushed too far,
never more), a small mixed complementarity problem, by projected Gauss-Seidel on the dense K to round-off.

- Position stage (`limit_positions`, between the joints' Newton rounds of joints/rattle.py): the limits
  beyond a bound at the end of the step, those pushed earlier in this step (held onto their bound from
  either side) and those at their bound (within round-off), with h K lambda = bound - c at the start
  configuration. The start's K is off the true response by ~ h |omega|, so each round lands that
  fraction short; the rounds (drift, joints' Newton, limits again) converge geometrically, to round-off
  in three or four.
- Velocity stage (`limit_stops`, after the motors and dampers): a limit pushed in this step is stopped
  (its rate to 0), one at its bound (within LIMIT_CONTACT) may not move out (rate >= 0 into the range,
  lambda of its sign, complementary), K at the end configuration.

The active limits are taken in blocks of at most LIMIT_BLOCK (joints/tables.py), each block solved
together and the blocks one after another: every scene shipped or tested has far fewer, and the scratch
(LimitScratch, allocated with the run's work: the stages allocate nothing) stays O(block x rows).
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.joints.drives import LIMIT_CONTACT, effective_inverse, limit_bounds, limit_rate, limit_row, weigh
from rbcli.physics.joints.impulses import apply_body_impulses, gather_impulses
from rbcli.physics.joints.tables import LIMIT_BLOCK
from rbcli.physics.kernel_link import separately_compiled

# projected Gauss-Seidel sweeps at most: one limit converges in one sweep, coupled limits geometrically
# (a chain's few in tens); the sweep stops when no lambda changes by more than round-off of the largest
PGS_SWEEPS = 500


@numba.njit(cache=True)
def _end_coupling(work, body, jac, other_body, other_jac) -> float:  # noqa: ANN001
    """jac W other_jac^T where the two ends are the same moving body, else 0."""
    if body < 0 or body != other_body:
        return 0.0
    w = weigh(work, other_body, other_jac)
    return jac[0] * w[0] + jac[1] * w[1] + jac[2] * w[2] + jac[3] * w[3] + jac[4] * w[4] + jac[5] * w[5]


@numba.njit(cache=True, inline="always")
def _jacobians(jacs, a):  # noqa: ANN001, ANN202
    j = jacs[a]
    return (j[0], j[1], j[2], j[3], j[4], j[5]), (j[6], j[7], j[8], j[9], j[10], j[11])


@numba.njit(cache=True, inline="always")
def _enter(table, s, a, j, slot, ja, jb, target, low, high) -> None:  # noqa: ANN001
    """Limit (j, slot) with its row (ja, jb) and K lambda's target and bounds as row a of the block."""
    s.ends[a, 0], s.ends[a, 1], s.ends[a, 2], s.ends[a, 3] = j, table.body_a[j], table.body_b[j], slot
    for c in range(6):
        s.jacs[a, c], s.jacs[a, 6 + c] = ja[c], jb[c]
    s.bounds[a, 0], s.bounds[a, 1], s.bounds[a, 2] = target, low, high


@numba.njit(cache=True)
def _solve(table, work, count) -> None:  # noqa: ANN001
    """lam of the block's first `count` limits: K lam = target within [low, high] (module docstring), K
    from the stage's W, G and factor; the block's y too."""
    s = work.limit_scratch
    K, Y, rows = s.k, s.y, work.rhs.shape[0]
    for a in range(count):
        ja, jb = _jacobians(s.jacs, a)
        K[a, a] = effective_inverse(table, work, s.ends[a, 1], s.ends[a, 2], ja, jb)  # rhs = G W J_a^T
        for r in range(rows):
            Y[a, r] = work.delta[r]
        for b in range(a):  # K_ab = J_a W J_b^T - (G W J_a^T) . y_b
            ka, kb = _jacobians(s.jacs, b)
            direct = 0.0
            for end in range(2):
                body = s.ends[a, 1 + end]
                jac = ja if end == 0 else jb
                direct += _end_coupling(work, body, jac, s.ends[b, 1], ka) + _end_coupling(
                    work, body, jac, s.ends[b, 2], kb
                )
            for r in range(rows):
                direct -= work.rhs[r] * Y[b, r]
            K[a, b] = direct
            K[b, a] = direct
    lam = s.lam
    for a in range(count):
        lam[a] = 0.0
    for _ in range(PGS_SWEEPS):
        change, size = 0.0, 0.0
        for a in range(count):
            if not K[a, a] > 0.0:  # a limit no motion moves (both ends held): no impulse
                continue
            residual = s.bounds[a, 0]
            for b in range(count):
                residual -= K[a, b] * lam[b]
            new = min(max(lam[a] + residual / K[a, a], s.bounds[a, 1]), s.bounds[a, 2])
            change = max(change, abs(new - lam[a]))
            size = max(size, abs(new))
            lam[a] = new
        if change <= 4e-16 * size:
            break


@numba.njit(cache=True)
def _push(table, work, count, P, L) -> None:  # noqa: ANN001
    """sum_a lam_a (J_a^T - G^T y_a) over the block applied to P, L (G V as it was); each limit's J^T part
    to its joint's reaction (work.joint_impulse), the rows' parts to theirs; the rows' multipliers into
    work.impulse."""
    s = work.limit_scratch
    for r in range(work.delta.shape[0]):
        total = 0.0
        for a in range(count):
            total -= s.y[a, r] * s.lam[a]
        work.delta[r] = total
        work.impulse[r] += total
    gather_impulses(table, work, work.delta)
    for a in range(count):
        j, body_a, body_b, lam = s.ends[a, 0], s.ends[a, 1], s.ends[a, 2], s.lam[a]
        for c in range(6):
            work.impulse_body[body_a, c] += s.jacs[a, c] * lam
            work.joint_impulse[j, c] += s.jacs[a, c] * lam
            if body_b >= 0:
                work.impulse_body[body_b, c] += s.jacs[a, 6 + c] * lam
                work.joint_impulse[j, 6 + c] += s.jacs[a, 6 + c] * lam
    apply_body_impulses(table, work, P, L)


@numba.njit(cache=True)
def _position_block(table, work, count, P, L) -> bool:  # noqa: ANN001
    """Solve and push one block of the position stage; each limit's push so far in the step kept (its
    sign the side it holds). True when any limit moved."""
    _solve(table, work, count)
    s, moved = work.limit_scratch, False
    for a in range(count):
        if s.lam[a] != 0.0:
            moved = True
            j, slot = s.ends[a, 0], s.ends[a, 3]
            total = work.limit_push[j, slot] + s.lam[a]
            work.limit_push[j, slot] = total
            # a limit whose push is all taken back is free again; else it holds its bound this step
            work.limit_hit[j, slot] = 0.0 if total == 0.0 else (1.0 if total < 0.0 else -1.0)
    if moved:
        _push(table, work, count, P, L)
    return moved


@numba.njit(cache=True, inline="always")
def _slack(bound) -> float:  # noqa: ANN001
    """How far from a bound [rad, m or 1] is on it: a few ulps (a correction below is round-off)."""
    return 4e-16 * max(1.0, abs(bound))


@numba.njit(cache=True)
def _position_state(work, table, j, slot, x, q):  # noqa: ANN001, ANN202
    """Limit (j, slot) in the position stage at (x, q): (side, c, lower, upper), side +1 / -1 where its
    upper / lower bound holds it in this round (pushed onto it earlier in the step, or at or beyond it),
    0 where it is free or has no bound."""
    lower, upper = limit_bounds(table, j, slot)
    if lower == -math.inf and upper == math.inf:
        return 0, 0.0, lower, upper
    c = limit_row(table, j, slot == 1, x, q)[0]
    hit = work.limit_hit[j, slot]
    if hit > 0.0 or (hit == 0.0 and c >= upper - _slack(upper)):
        return 1, c, lower, upper
    if hit < 0.0 or (hit == 0.0 and c <= lower + _slack(lower)):
        return -1, c, lower, upper
    return 0, c, lower, upper


@separately_compiled
@numba.njit(cache=True)
def limit_positions(table, work, h, x, q, P, L) -> bool:  # noqa: ANN001
    """The position stage's limits (module docstring) at the end configuration (x, q), their impulses at
    the start (work.x_start, q_start, whose factor is the stage's) applied to P and L; True when any was
    pushed (the caller then drifts the bodies again, restores the joints and calls again)."""
    off = False
    for j in range(table.kind.shape[0]):
        for slot in range(2):
            side, c, lower, upper = _position_state(work, table, j, slot, x, q)
            if side != 0:
                bound = upper if side > 0 else lower
                off = off or abs(c - bound) > _slack(bound)
    if not off:
        return False
    count, moved = 0, False
    for j in range(table.kind.shape[0]):
        for slot in range(2):
            side, c, lower, upper = _position_state(work, table, j, slot, x, q)
            if side == 0:
                continue
            _, ja, jb = limit_row(table, j, slot == 1, work.x_start, work.q_start)
            pushed = work.limit_push[j, slot]  # this step's impulse so far: the total keeps its sign
            if side > 0:
                _enter(table, work.limit_scratch, count, j, slot, ja, jb, (upper - c) / h, -math.inf, -pushed)
            else:
                _enter(table, work.limit_scratch, count, j, slot, ja, jb, (lower - c) / h, -pushed, math.inf)
            count += 1
            if count == LIMIT_BLOCK:
                moved = _position_block(table, work, count, P, L) or moved
                count = 0
    if count > 0:
        moved = _position_block(table, work, count, P, L) or moved
    return moved


# what holds a limit in the velocity stage (`_stop_state`)
FREE, STOPPED, AT_UPPER, AT_LOWER = 0, 1, 2, 3


@numba.njit(cache=True)
def _stop_state(model, table, work, j, slot, x, q, P, L):  # noqa: ANN001, ANN202
    """Limit (j, slot) in the velocity stage at the end configuration: (state, J_a, J_b, rate), state
    STOPPED where it was pushed back in this step, AT_UPPER / AT_LOWER within LIMIT_CONTACT of a bound,
    else FREE (also where it has no bound)."""
    lower, upper = limit_bounds(table, j, slot)
    if lower == -math.inf and upper == math.inf:  # no limit: its row is not even evaluated (a hinge has no cone)
        none = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
        return FREE, none, none, 0.0
    c, ja, jb = limit_row(table, j, slot == 1, x, q)
    if work.limit_hit[j, slot] != 0.0:
        state = STOPPED
    elif c >= upper - LIMIT_CONTACT:
        state = AT_UPPER
    elif c <= lower + LIMIT_CONTACT:
        state = AT_LOWER
    else:
        return FREE, ja, jb, 0.0
    return state, ja, jb, limit_rate(model, q, P, L, table.body_a[j], table.body_b[j], ja, jb)


@separately_compiled
@numba.njit(cache=True)
def limit_stops(model, table, work, x, q, P, L) -> None:  # noqa: ANN001
    """The velocity stage's stops (module docstring) at the end configuration, with its W, G and factor: a
    limit pushed back in this step is stopped (the push alone would reflect it, a bounce); one at a bound
    may not move out, and is not pulled. Nothing where no limit is stopped or moving out."""
    moving = False
    for j in range(table.kind.shape[0]):
        for slot in range(2):
            state, _, _, rate = _stop_state(model, table, work, j, slot, x, q, P, L)
            moving = (
                moving or state == STOPPED or (state == AT_UPPER and rate > 0.0) or (state == AT_LOWER and rate < 0.0)
            )
    if not moving:
        return
    count = 0
    for j in range(table.kind.shape[0]):
        for slot in range(2):
            state, ja, jb, rate = _stop_state(model, table, work, j, slot, x, q, P, L)
            if state == FREE:
                continue
            low = -math.inf if state != AT_LOWER else 0.0
            high = math.inf if state != AT_UPPER else 0.0
            _enter(table, work.limit_scratch, count, j, slot, ja, jb, -rate, low, high)
            count += 1
            if count == LIMIT_BLOCK:
                _solve(table, work, count)
                _push(table, work, count, P, L)
                count = 0
    if count > 0:
        _solve(table, work, count)
        _push(table, work, count, P, L)
