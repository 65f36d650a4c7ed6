"""The adaptive loop: error-controlled dopri5 steps between the grid times, with the stages of a step
(physics/pipeline.py) where this loop's structure puts them.

The method (error per unit step, the controller, contact's step limit and floor) is physics/adaptive.py;
the runner calls this loop instead of the fixed-step one (physics/chunk_loop.py) with the same
arguments when the scene has a tolerance (`IntegratorInfo.adaptive_chunk`). Where each stage runs:
the step-start stage (impulses) at the chunk's start and at each grid index where it has work, the
loop landing there (then k_1 is evaluated afresh: the stage may have changed the state); the sub-step
stages before the update (contact_begin, kinematic_begin) before each attempt, and contact_begin also,
with h = 0, before each evaluation of k_1; kinematic_begin reports whether it moved a body, and then k_1
is evaluated again; the sub-step stages after the update (kinematic_end, contact_commit) only after an
accepted attempt; the step-end stages (contact_record, record) at every grid index the loop lands on.
Joints refuse a tolerance (integrators.check_integrator): no joint stages here.
"""

import numba
import numpy as np

from rbcli.physics.adaptive import (
    CONTACT_STEP_FLOOR,
    CONTROL_REJECTED_LAST,
    CONTROL_STEP,
    COUNT_ACCEPTED,
    COUNT_REJECTED,
    FAC_MAX,
    FAC_MIN,
    SAFETY,
    STATUS_STEP_TOO_SMALL,
    STEP_MIN_RELATIVE,
    initial_step,
)
from rbcli.physics.integrators.dopri5 import accept, advance, begin, error_norm, restore
from rbcli.physics.kernel_handle import opened
from rbcli.physics.stages import (
    contact_begin_stage,
    contact_commit_due,
    contact_commit_stage,
    contact_record_stage,
    contact_step_limit,
    impulse_stage,
    kinematic_begin_stage,
    kinematic_end_stage,
    next_impulse_step_stage,
    schedule_step_floor,
)
from rbcli.physics.step import CHUNK_KERNEL, STATUS_OK, chunk_status, model_bodies, record_if_due

__all__ = ["run_chunk"]


@numba.njit(**CHUNK_KERNEL)
def run_chunk(model, forces, data, dt, step0, n_steps, record_every, frames, filled):  # noqa: ANN001, ANN201
    """Advance from grid index step0 (t = step0 dt) to step0 + n_steps with error-controlled steps.

    data.adaptive (KernelAdaptive) holds the error budget `tolerance` of the whole run, `duration` [s]
    long, and the work, control and counters that persist between calls (counters: accepted and
    rejected attempts). Lands exactly on every grid index that is a multiple of record_every (recorded
    into `frames` as the fixed-step run_chunk does), on each index a step-start stage lands at (the
    steps that hold impulses) and on step0 + n_steps, so the state always ends on the grid. Returns
    (grid steps done, frames filled, status): STATUS_OK, STATUS_FULL (flush and call again),
    STATUS_DIVERGED or STATUS_STEP_TOO_SMALL (both end the run). model, forces, data and frames may each
    come as a KernelHandle, as in the fixed-step loops.
    """
    model, forces, data, frames = opened(model), opened(forces), opened(data), opened(frames)
    # taken out of their tuples once, as in the fixed-step loops
    x, q, P, L, F, tau = data.x, data.q, data.P, data.L, data.F, data.tau
    force_data = data.force
    contact, kinematic, schedule = model.contact, model.kinematic, forces.schedule
    contact_work = force_data.contact
    # from here on `model` is the model's body arrays alone (KernelBodies): one numba type for every
    # kind of scene, so each stage kernel below is compiled once for all of them; tables go by name
    model = model_bodies(model)
    adaptive = data.adaptive
    work, control, counters, tolerance = adaptive.work, adaptive.control, adaptive.counters, adaptive.tolerance
    index = step0
    end = step0 + n_steps
    land = end  # the next grid index a step-start stage needs the loop to stand on
    t = step0 * dt
    h_max = contact_step_limit(contact)  # inf without contact
    # steps shorter than h_floor are allowed the error of one that long: the step across a touch-down
    # or a schedule's window edge (adaptive.py)
    h_floor = max(CONTACT_STEP_FLOOR * h_max if h_max < np.inf else 0.0, schedule_step_floor(forces, dt))
    h_next = control[CONTROL_STEP]  # the step the controller proposes for the next attempt
    rejected_last = control[CONTROL_REJECTED_LAST] > 0.0
    per_time = tolerance / max(adaptive.duration, dt)  # error budget per second of simulated time
    status = STATUS_OK
    restart = True  # run the step-start stages and evaluate k_1: at the start and where a stage landed
    moved = False  # a stage changed the state since k_1 was evaluated
    while index < end and status == STATUS_OK:
        if restart:
            restart, moved = False, False
            land = end
            # impulses: exact jumps of P and L at the start of the step that holds them
            impulse_stage(model, forces, force_data, t, t + dt, x, q, P, L)
            land = min(land, next_impulse_step_stage(forces, dt, index))
            # contact_begin: k_1's evaluation, at offset 0 into a step
            ts, h = t, 0.0
            contact_begin_stage(contact, contact_work, ts, h)
            begin(model, forces, contact, force_data, t, x, q, P, L, F, tau, work)  # y0 and k_1
            if h_next <= 0.0:
                h_next = initial_step(x, q, P, L, work, tolerance, record_every * dt)
            h_next = min(h_next, h_max)
        target = min(land, (index // record_every + 1) * record_every)  # the next grid point to land on
        remaining = target * dt - t
        landing = h_next >= remaining * (1.0 - 1e-12)  # a sliver short of the target counts as landing
        ts = t
        h = remaining if landing else h_next
        te = target * dt if landing else t + h
        # contact_begin: the contact springs measure time from the start of this (sub-)step
        contact_begin_stage(contact, contact_work, ts, h)
        # kinematic_begin: kinematic bodies at their exact pose, moving at their mean velocity over the (sub-)step
        if kinematic_begin_stage(model, kinematic, schedule, ts, h, x, q, P, L):
            moved = True
        if moved:  # the state changed since k_1 was evaluated: evaluate it again
            moved = False
            begin(model, forces, contact, force_data, t, x, q, P, L, F, tau, work)
        # update: one attempt over [ts, ts + h), its 4th-order error estimate against the budget per step
        advance(model, forces, contact, force_data, t, h, x, q, P, L, F, tau, work)
        err = error_norm(model, forces, contact, force_data, t, h, per_time * max(h, h_floor), x, q, P, L, F, tau, work)
        if err <= 1.0:
            counters[COUNT_ACCEPTED] += 1
            accept(x, q, P, L, work)
            # kinematic_end: kinematic bodies at their exact state at the end of the (sub-)step (closed form)
            kinematic_end_stage(model, kinematic, schedule, te, x, q, P, L)
            # contact_commit: the (sub-)step is complete: its last evaluation's contacts become the history
            if contact_commit_due(contact_work):  # else the quiet skin holds: nothing to commit
                contact_commit_stage(model, contact, contact_work, x, q, P, L)
            factor = FAC_MAX if err == 0.0 else min(FAC_MAX, max(FAC_MIN, SAFETY * err**-0.25))
            if rejected_last:
                factor = min(factor, 1.0)
            rejected_last = False
            if not landing:
                h_next = min(h_max, h * factor)
                t += h
                continue
            # a landing step is usually shorter than the controller asked for: keep its proposal
            h_next = min(h_max, max(h_next, h * factor))
            t = target * dt
            index = target
            # contact_record: on recording steps, the state's contact count, deepest overlap and energy
            contact_record_stage(contact, contact_work, x, q, frames, filled, index % record_every == 0)
            # record: on recording steps, the divergence check and the state copied into the next frame
            filled, status = record_if_due(index, record_every, x, q, P, L, frames, filled)
            if index == land and index < end and status == STATUS_OK:
                status = chunk_status(x, q, P, L)  # the check a chunk ending here makes
                restart = True
        else:
            counters[COUNT_REJECTED] += 1
            restore(x, q, P, L, work)
            rejected_last = True
            shrink = SAFETY * err**-0.25 if err < 1e300 else FAC_MIN  # also NaN or overflow: shrink hard
            h_next = h * max(FAC_MIN, shrink)
            if h_next < STEP_MIN_RELATIVE * max(1.0, abs(t)):
                status = STATUS_STEP_TOO_SMALL
    control[CONTROL_STEP] = h_next
    control[CONTROL_REJECTED_LAST] = 1.0 if rejected_last else 0.0
    if status == STATUS_OK:
        status = chunk_status(x, q, P, L)
    return index - step0, filled, status
