"""The quiet skin: a scene with a `contact:` section whose bodies are all far from each other and from
every plane skips the contact stages until one of them has strayed far enough to touch (issue 28 item 2:
contact when nothing touches costs <= 1.2x the same scene without a `contact:` section).

A Verlet list one level up (Verlet 1967; the skin of molecular dynamics' neighbour lists), Galilean:
when a (sub-)step ends with no contact held (commit_contacts found no trial contact, so no body keeps a
history) at time t0, every colliding body b notes its position x0_b and velocity v0_b and gets a skin
s_b [m] and a window [t0, t0 + T]. The body's contact spheres lie in the cube of half side rho_b
(max |offset| + r, body_phase.py) about x_b whatever its rotation, so if the boxes that the cubes of half
side rho_b + s_b sweep along the straight paths

    x0_b + v0_b tau,  0 <= tau <= T,   for every body,   tested pairwise and against every plane,

meet nothing (pairs of two bodies that cannot move, or of a joint, never collide and are not tested),
then at any time t of the window at which every body is within its skin of its path,
|x_b - (x0_b + v0_b (t - t0))|_inf <= s_b, no body box meets another or a plane (the boxes lie in the
swept ones), the body phase would flag nothing, and the force evaluation would add nothing. So a force
evaluation only tests the deviations (`contact_quiet`: a few ns per body, inlined into the force pass
with a few of the contact work's arrays, where a call of the contact stage passes ~74 by value), and the
commit and the recorded statistics skip their work. The state is bitwise what the full stages give. The
first evaluation past a skin or past the window runs the full stages and ends the quiet.

Why paths, not fixed points: bodies falling or flying side by side move far but keep their gaps; a skin
about a fixed point must grow with the speed, and two bricks falling 5 m apart stopped fitting past
~400 m/s (benchmarks/bench_contact.py far: 3.7x the scene without contact in its later blocks, 1.1x now).

Sure windows: where every body's linear acceleration is steady, the same vector a_b at every time and
in every state (gravity, constant world-frame forces, any torque; ContactTable.body_steady_accel, from
scene/compile_contact.py steady_accelerations; a static body and a kinematic one at constant velocity
have a_b = 0), how far the body can be from its straight path is known beforehand, and no evaluation
needs to look. Every integrator here moves a body of constant acceleration a as x_n = x0 + v0 t_n +
1/2 a t_n^2 + beta h a t_n (beta = 0 for the second- and higher-order ones, 1/2 for the Euler steps),
and evaluates its forces at stages t_n + c h, 0 <= c <= 1, whose positions lie within |a| (c h t_n +
sigma h^2) of that path (x_n + c h v_n + sigma h^2 a; sigma = sum_j a_ij c_j = c^2 / 2 for the Runge-Kutta
stages, dopri5's included, <= 2 for split4's, whose middle drift runs backwards), so at any evaluation of
the window at time t0 + tau

    |x - (x0 + v0 tau)| <= |a| (tau + 3 h)^2     (plus the roundings: `steady_drift`),

and a skin at least that makes the window sure (QUIET_SURE): an evaluation tests only that it is within
the window (two loads), where the paths' test costs ~6-10 ns at 2 bodies, more than the rest of a step
of euler-quat (issue 47 item 6). The bound holds for steps of the h the window was set at: a step of
another h (adaptive stepping, a call with another dt) ends the sureness (force.begin_contact_step), and
the paths are tested again. A scene with a spring, drag, a joint, an impulse or a scheduled force on
any body has no sure windows: its quiet tests the paths as before.

The window: the longest of WINDOW_STEPS (1024, 128, 16 steps) whose swept boxes fit. The skin: twice
the drift 1/2 |a| T^2 of the body's acceleration over the last window (the change of its velocity over
the time since the last try), at least SKIN_FLOOR rho_b (a body at rest, or the first try). A try that
fails at every window (bodies near each other without touching) waits RETRY_STEPS commits before the
next, so a dense scene pays the test rarely. A restored checkpoint or a state set from outside ends the
quiet and forgets the accelerations (data.py).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from rbcli.physics.contact.body_phase import box_clearance, box_pairs
from rbcli.physics.contact.tables import COUNT_EVALUATIONS, QUIET_ARMED, QUIET_ON, QUIET_SURE, QUIET_WAIT
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL

WINDOW_STEPS = np.array([1024.0, 128.0, 16.0])  # the windows tried, longest first
SKIN_FLOOR = 0.05  # of rho_b: the least skin (a body at rest, or whose acceleration is not known yet)
RETRY_STEPS = 16  # commits to wait after a try that found bodies within their swept boxes
_EPS = 2.220446049250313e-16
# the roundings a sure window allows for, per step of the window, in ulps of the largest position: up to
# 7 force evaluations a step (dopri5), each rounding x and P once, and P's errors carried into x
SURE_STEPS_ROUNDED = 64.0
_GUARD = 1e-9  # of rho_b, beside 8 ulps of |x| + |v| (|t0| + T): the roundings of the box and the test


@numba.njit(cache=True, inline="always")
def on_paths(work, x, t) -> bool:  # noqa: ANN001
    """Whether the quiet is on, t is within its window and every body is within its skin of its straight
    path x0 + v0 (t - t0) (max norm; NaN: not)."""
    if work.quiet_state[QUIET_ON] == 0 or not t <= work.quiet_window[1]:
        return False
    if work.quiet_state[QUIET_SURE]:  # the skins hold every body's steady drift: nothing to test
        return True
    tau = t - work.quiet_window[0]
    ref, vel, skin = work.quiet_reference, work.quiet_velocity, work.quiet_skin
    for b in range(ref.shape[0]):
        s = skin[b]
        d0 = x[b, 0] - (ref[b, 0] + vel[b, 0] * tau)
        d1 = x[b, 1] - (ref[b, 1] + vel[b, 1] * tau)
        d2 = x[b, 2] - (ref[b, 2] + vel[b, 2] * tau)
        if not (abs(d0) <= s and abs(d1) <= s and abs(d2) <= s):
            return False
    return True


@numba.njit(cache=True, inline="always")
def quiet_at_step_end(work, x) -> bool:  # noqa: ANN001
    """`on_paths` for the state at the end of the (sub-)step the contact clock holds (the recorded state)."""
    return on_paths(work, x, work.clock[0] + work.clock[1])


@numba.njit(cache=True, inline="always")
def contact_quiet(work, x, t) -> bool:  # noqa: ANN001
    """The force pass's test before the contact stage: True when the state x at time t cannot touch
    anything (module docstring), the evaluation then counted and its offset noted as the stage would;
    False (and the quiet ended) when the contact stage must run."""
    if not on_paths(work, x, t):
        work.quiet_state[QUIET_ON] = 0
        return False
    work.counters[COUNT_EVALUATIONS] += 1
    work.clock[2] = t - work.clock[0]
    return True


@separately_compiled
@numba.njit(**STEP_KERNEL)  # a call of its own: it runs rarely (inlined, ~2 s more compile of each contact loop)
def try_quiet(contact, work, x) -> None:  # noqa: ANN001
    """At the end of a (sub-)step that holds no contact (commit_contacts), with work.body_velocity the
    end-of-step velocities and work.clock the (sub-)step: start the quiet with the longest of the
    WINDOW_STEPS whose swept boxes meet nothing (module docstring); else wait RETRY_STEPS commits. Uses
    work.body_lo, body_hi and the body grid's scratch, which every body phase rebuilds."""
    state = work.quiet_state
    if state[QUIET_WAIT] > 0:
        state[QUIET_WAIT] -= 1
        return
    state[QUIET_ON] = state[QUIET_SURE] = 0
    now, h = work.clock[0] + work.clock[1], work.clock[1]
    sure = _steady(contact)
    v, ref, vel, accel = work.body_velocity, work.quiet_reference, work.quiet_velocity, work.quiet_accel
    # each body's acceleration [m/s^2] over the last window (0 before the first): its skin's scale
    elapsed = now - work.quiet_window[0]
    for b in range(ref.shape[0]):
        accel[b] = 0.0
        if state[QUIET_ARMED] and elapsed > 0.0:
            d0, d1, d2 = v[b, 0] - vel[b, 0], v[b, 1] - vel[b, 1], v[b, 2] - vel[b, 2]
            accel[b] = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2) / elapsed
        ref[b, 0], ref[b, 1], ref[b, 2] = x[b, 0], x[b, 1], x[b, 2]
        vel[b, 0], vel[b, 1], vel[b, 2] = v[b, 0], v[b, 1], v[b, 2]
    work.quiet_window[0], work.quiet_window[2] = now, h
    state[QUIET_ARMED] = 1
    for level in range(WINDOW_STEPS.shape[0]):
        span = WINDOW_STEPS[level] * h
        cell = _swept_boxes(contact, work, span, h if sure else -1.0)
        if not cell >= 0.0:  # a non-finite state: the full stages deal with it
            return
        if cell == 0.0:
            continue  # a box reaches a plane: a shorter window may not
        found, _ = box_pairs(
            contact.body_inv_contact_mass, contact.body_large, contact.excluded_pair, work.body_lo, work.body_hi,
            cell, work.body_active, work.body_cell, work.body_bucket, work.body_bucket_start,
            work.body_sorted, work.body_pair_none, False,
        )  # fmt: skip
        if not found:
            work.quiet_window[1] = now + span
            state[QUIET_ON] = 1
            state[QUIET_SURE] = 1 if sure else 0
            return
    state[QUIET_WAIT] = RETRY_STEPS


@numba.njit(cache=True, inline="always")
def _steady(contact) -> bool:  # noqa: ANN001
    """Whether every body's linear acceleration is known and steady (ContactTable.body_steady_accel)."""
    steady = contact.body_steady_accel
    if steady.shape[0] != contact.body_bound_radius.shape[0]:
        return False
    for b in range(steady.shape[0]):
        if not steady[b] < math.inf:
            return False
    return True


@numba.njit(cache=True, inline="always")
def steady_drift(accel, span, h, size, speed) -> float:  # noqa: ANN001
    """How far [m] a body of steady acceleration `accel` [m/s^2] can be from its straight path x0 + v0 tau
    at any force evaluation of a window of `span` [s] stepped at (sub-)step h [s] (module docstring, "Sure
    windows"): accel (tau + 3 h)^2, plus the roundings of SURE_STEPS_ROUNDED stages a step over the
    window's steps, relative to the largest position (size + speed span + accel span^2 [m])."""
    steps = span / h
    reach = size + speed * span + accel * span * span
    return accel * (span + 3.0 * h) * (span + 3.0 * h) + SURE_STEPS_ROUNDED * steps * _EPS * reach


@numba.njit(cache=True)
def _swept_boxes(contact, work, span, h) -> float:  # noqa: ANN001
    """For a window of `span` seconds: each body's skin (twice the drift 1/2 |a| span^2 of its
    acceleration over the last window, work.quiet_accel, at least SKIN_FLOOR rho_b; where h >= 0, the
    window sure at (sub-)step h, at least its steady drift, `steady_drift`) and the box
    its cube of half side rho_b + skin sweeps along x0 + v0 tau, 0 <= tau <= span, into work.body_lo,
    body_hi. Returns the grid cell for box_pairs (the widest box of the bodies that are not large); 0:
    a movable body's box reaches a plane; -1: a box is not finite."""
    rho, inv_mass = contact.body_bound_radius, contact.body_inv_contact_mass
    lo, hi, ref, vel, skin = work.body_lo, work.body_hi, work.quiet_reference, work.quiet_velocity, work.quiet_skin
    accel = work.quiet_accel
    widest = 0.0
    t0 = abs(work.quiet_window[0])
    for b in range(ref.shape[0]):
        if not rho[b] >= 0.0:  # no contact spheres: never touches, moves as it likes
            skin[b] = math.inf
            for k in range(3):
                lo[b, k], hi[b, k] = math.inf, -math.inf
            continue
        skin[b] = max(SKIN_FLOOR * rho[b], accel[b] * span * span)
        speed = max(abs(vel[b, 0]), abs(vel[b, 1]), abs(vel[b, 2]))
        size = max(abs(ref[b, 0]), abs(ref[b, 1]), abs(ref[b, 2]))
        if h >= 0.0:
            skin[b] = max(skin[b], steady_drift(contact.body_steady_accel[b], span, h, size, speed))
        half = rho[b] + skin[b] + _GUARD * rho[b] + 8.0 * _EPS * (size + speed * (t0 + span))
        if not half < math.inf:
            return -1.0
        extent = 0.0
        for k in range(3):
            end = ref[b, k] + vel[b, k] * span
            lo[b, k], hi[b, k] = min(ref[b, k], end) - half, max(ref[b, k], end) + half
            extent = max(extent, hi[b, k] - lo[b, k])
        if not contact.body_large[b]:
            widest = max(widest, extent)
        if inv_mass[b] == 0.0:  # static or kinematic: planes do not stop it
            continue
        c0, c1, c2 = 0.5 * (lo[b, 0] + hi[b, 0]), 0.5 * (lo[b, 1] + hi[b, 1]), 0.5 * (lo[b, 2] + hi[b, 2])
        h0, h1, h2 = 0.5 * (hi[b, 0] - lo[b, 0]), 0.5 * (hi[b, 1] - lo[b, 1]), 0.5 * (hi[b, 2] - lo[b, 2])
        for p in range(contact.plane_point.shape[0]):
            if not box_clearance(contact, p, c0, c1, c2, h0, h1, h2) > 0.0:
                return 0.0
    return widest if widest > 0.0 else 1.0
