"""The quiet skin: a scene with a `contact:` section whose bodies are all far from each other and from
every plane skips the contact stages until one of them has moved far enough to touch (issue 28 item 2:
contact when nothing touches costs <= 1.2x the same scene without a `contact:` section).

A Verlet list one level up (Verlet 1967; the skin of molecular dynamics' neighbour lists): when a step
ends with no contact held (commit_contacts found no trial contact, so no body keeps a history), every
colliding body b gets a skin s_b [m] and its position x_b is noted. The body's contact spheres lie in the
cube of half side rho_b (max |offset| + r, body_phase.py) about x_b whatever its rotation, so if the cubes
grown by their skins,

    x_b +- (rho_b + s_b)   for every body,   tested pairwise and against every plane,

meet nothing (pairs of two bodies that cannot move, or of a joint, never collide and are not tested),
then as long as no body has moved more than its skin along any axis, |x_b - x_b,noted|_inf <= s_b, the
cubes without skins still meet nothing: no body box meets another or a plane (the boxes lie in the
cubes), the body phase would flag nothing, and the force evaluation would add nothing. So a force
evaluation only tests the displacements (`contact_quiet`: a few ns per body, inlined into the force
pass with three of the contact work's arrays, where a call of the contact stage passes ~60 by value),
and the commit and the recorded statistics skip their work. The state is bitwise what the full stages
give. The first evaluation past a skin runs the full stages and ends the quiet.

The skin: SKIN_STEPS steps of the body's speed at the step's end, at least SKIN_FLOOR rho_b (a body at
rest), so a body falling or flying tests again about every SKIN_STEPS steps. A try that fails (bodies
near each other without touching) waits RETRY_STEPS commits before the next, so a dense scene pays the
test rarely. A restored checkpoint or a state set from outside ends the quiet (data.py).
"""

from __future__ import annotations

import math

import numba

from rbcli.physics.contact.body_phase import box_pairs
from rbcli.physics.contact.tables import COUNT_EVALUATIONS, QUIET_ON, QUIET_WAIT
from rbcli.physics.step import STEP_KERNEL

SKIN_STEPS = 16.0  # steps of its end-of-step speed a body may move before the stages run again
SKIN_FLOOR = 0.05  # of rho_b: the skin of a body at rest
RETRY_STEPS = 16  # commits to wait after a try that found bodies within their skins
_GUARD = 1e-9  # of rho_b, beside 8 ulps of |x|: the roundings of the box and of the displacement test


@numba.njit(cache=True, inline="always")
def within_skins(work, x) -> bool:  # noqa: ANN001
    """Whether the quiet is on and every body is within its skin of its noted position (NaN: not)."""
    if work.quiet_state[QUIET_ON] == 0:
        return False
    ref, skin = work.quiet_reference, work.quiet_skin
    for b in range(ref.shape[0]):
        s = skin[b]
        if not (abs(x[b, 0] - ref[b, 0]) <= s and abs(x[b, 1] - ref[b, 1]) <= s and abs(x[b, 2] - ref[b, 2]) <= s):
            return False
    return True


@numba.njit(cache=True, inline="always")
def contact_quiet(work, x, t) -> bool:  # noqa: ANN001
    """The force pass's test before the contact stage: True when the state x cannot touch anything
    (module docstring), the evaluation then counted and its offset noted as the stage would; False
    (and the quiet ended) when the contact stage must run."""
    if not within_skins(work, x):
        work.quiet_state[QUIET_ON] = 0
        return False
    work.counters[COUNT_EVALUATIONS] += 1
    work.clock[2] = t - work.clock[0]
    return True


@numba.njit(**STEP_KERNEL)  # a call of its own: it runs rarely (inlined, ~2 s more compile of each contact loop)
def try_quiet(contact, work, x) -> None:  # noqa: ANN001
    """At the end of a step that holds no contact (commit_contacts), with work.body_velocity the
    end-of-step velocities and work.clock[1] the step: start the quiet if the grown cubes meet nothing
    (module docstring); else wait RETRY_STEPS commits. Uses work.body_lo, body_hi and the body grid's
    scratch, which every body phase rebuilds."""
    state = work.quiet_state
    if state[QUIET_WAIT] > 0:
        state[QUIET_WAIT] -= 1
        return
    rho, inv_mass = contact.body_bound_radius, contact.body_inv_contact_mass
    lo, hi, ref, skin, v = work.body_lo, work.body_hi, work.quiet_reference, work.quiet_skin, work.body_velocity
    reach = SKIN_STEPS * work.clock[1]
    widest = 0.0
    for b in range(ref.shape[0]):
        ref[b, 0], ref[b, 1], ref[b, 2] = x[b, 0], x[b, 1], x[b, 2]
        if not rho[b] >= 0.0:  # no contact spheres: never touches, moves as it likes
            skin[b] = math.inf
            for k in range(3):
                lo[b, k], hi[b, k] = math.inf, -math.inf
            continue
        speed = math.sqrt(v[b, 0] * v[b, 0] + v[b, 1] * v[b, 1] + v[b, 2] * v[b, 2])
        skin[b] = max(SKIN_FLOOR * rho[b], reach * speed)
        guard = _GUARD * rho[b] + 8.0 * 2.220446049250313e-16 * max(abs(x[b, 0]), abs(x[b, 1]), abs(x[b, 2]))
        half = rho[b] + skin[b] + guard
        if not half < math.inf:  # a non-finite state: the full stages deal with it
            state[QUIET_ON] = 0
            return
        if not contact.body_large[b]:
            widest = max(widest, half)
        for k in range(3):
            lo[b, k], hi[b, k] = x[b, k] - half, x[b, k] + half
        if inv_mass[b] == 0.0:  # static or kinematic: planes do not stop it
            continue
        for p in range(contact.plane_point.shape[0]):
            n0, n1, n2 = contact.plane_normal[p, 0], contact.plane_normal[p, 1], contact.plane_normal[p, 2]
            lowest = (
                (x[b, 0] - contact.plane_point[p, 0]) * n0
                + (x[b, 1] - contact.plane_point[p, 1]) * n1
                + (x[b, 2] - contact.plane_point[p, 2]) * n2
                - (abs(n0) + abs(n1) + abs(n2)) * half
            )
            if not lowest > 0.0:
                state[QUIET_ON] = 0
                state[QUIET_WAIT] = RETRY_STEPS
                return
    found, _ = box_pairs(
        inv_mass, contact.body_large, contact.excluded_pair, lo, hi, 2.0 * widest if widest > 0.0 else 1.0,
        work.body_active, work.body_cell, work.body_bucket, work.body_bucket_start, work.body_sorted,
        work.body_pair_none, False,
    )  # fmt: skip
    if found:
        state[QUIET_ON] = 0
        state[QUIET_WAIT] = RETRY_STEPS
        return
    state[QUIET_ON] = 1
