"""The optional stages of a step that the chunk loops call (physics/pipeline.py lists them), each through a
dispatcher that compiles to nothing when the scene does not have it (physics/dispatch.py): impulses,
contact_begin, kinematic_begin, kinematic_end, contact_commit (and its test contact_commit_due),
contact_record; and for adaptive stepping the contacts' step limit, the next step that holds an impulse
and the schedules' step floor.

Each takes the table it needs by name: the model's contact or kinematic table (`model.contact`,
`model.kinematic`: None in `Model.kernel()` where the scene lacks them) or the force tables (impulses,
schedules: None or 0 rows), with the body arrays as `model` (KernelBodies: one type for every scene).
Each dispatcher's real implementation keeps the row test it had, so a full table with 0 rows (what
tests and benchmarks pass when they call kernels directly) still works, compiles the stage and skips it
at run time. The results are bitwise the same either way: a stage that runs does what it did, and one
compiled away had no rows to process. The joint stages prune themselves instead (joints/stages.py).

A scene always gets the same combination of None and tables, so its kernels' types are the same in
every run and numba's on-disk cache serves them (the implementations below are compiled into the
cached caller; they take STEP_KERNEL's options: cached, no reference counting).
"""

from __future__ import annotations

import numpy as np
from numba.extending import overload

from rbcli.physics.contact.force import begin_contact_step, commit_contacts
from rbcli.physics.contact.state import record_contact_state
from rbcli.physics.contact.tables import QUIET_ON
from rbcli.physics.dispatch import DISPATCH_OPTIONS, absent, kernel_only, member
from rbcli.physics.forces.impulse import NO_IMPULSE_STEP, apply_impulses, next_impulse_step
from rbcli.physics.forces.schedule import SCHEDULE_STEP_FLOOR
from rbcli.physics.kinematic import kinematic_begin, kinematic_end


def impulse_stage(model, forces, force_data, t_prev, t_next, x, q, P, L) -> int:  # noqa: ANN001
    """The impulses due in [t_prev, t_next) (forces/impulse.py) when the scene has any; how many."""
    kernel_only()
    return 0


@overload(impulse_stage, jit_options=DISPATCH_OPTIONS)
def _impulse_stage(model, forces, force_data, t_prev, t_next, x, q, P, L):  # noqa: ANN001, ANN202
    if absent(member(forces, "impulse")):
        return lambda model, forces, force_data, t_prev, t_next, x, q, P, L: 0

    def run(model, forces, force_data, t_prev, t_next, x, q, P, L):  # noqa: ANN001, ANN202
        if forces.impulse.body.shape[0]:
            return apply_impulses(model, forces, force_data, t_prev, t_next, x, q, P, L)
        return 0

    return run


def next_impulse_step_stage(forces, dt, index) -> int:  # noqa: ANN001
    """The next grid step after `index` that holds an impulse (forces/impulse.py; where the adaptive loop
    lands to apply it), NO_IMPULSE_STEP when the scene has none."""
    kernel_only()
    return 0


@overload(next_impulse_step_stage, jit_options=DISPATCH_OPTIONS)
def _next_impulse_step_stage(forces, dt, index):  # noqa: ANN001, ANN202
    if absent(member(forces, "impulse")):
        return lambda forces, dt, index: NO_IMPULSE_STEP

    def run(forces, dt, index):  # noqa: ANN001, ANN202
        return next_impulse_step(forces, dt, index)

    return run


def contact_begin_stage(contact, work, t, h) -> None:  # noqa: ANN001
    """Start the contact springs' clock for the (sub-)step [t, t + h) when the scene has contact."""
    kernel_only()


@overload(contact_begin_stage, jit_options=DISPATCH_OPTIONS)
def _contact_begin_stage(contact, work, t, h):  # noqa: ANN001, ANN202
    if absent(contact, work):
        return lambda contact, work, t, h: None

    def run(contact, work, t, h):  # noqa: ANN001, ANN202
        if contact.sphere_body.shape[0]:
            begin_contact_step(work, t, h)

    return run


def contact_commit_stage(model, contact, work, x, q, P, L) -> None:  # noqa: ANN001
    """Make the (sub-)step's last contacts the history when the scene has contact."""
    kernel_only()


@overload(contact_commit_stage, jit_options=DISPATCH_OPTIONS)
def _contact_commit_stage(model, contact, work, x, q, P, L):  # noqa: ANN001, ANN202
    if absent(contact, work):
        return lambda model, contact, work, x, q, P, L: None

    def run(model, contact, work, x, q, P, L):  # noqa: ANN001, ANN202
        if contact.sphere_body.shape[0] and work.quiet_state[QUIET_ON] == 0:  # quiet: nothing to commit
            commit_contacts(model, contact, work, x, q, P, L)

    return run


def contact_commit_due(work) -> bool:  # noqa: ANN001
    """Whether the (sub-)step's contacts must be committed: the scene has contact and the quiet skin is
    off (contact/quiet.py). A test of its own before contact_commit_stage, which takes the contact table
    and work: where LLVM left that stage a call (split4's loop), the quiet steps passed them by value
    every step (~180 ns); this one's body is one load, and is inlined. (numba's own inlining of the
    stage, overload inline="always", changed contact trajectories' bits: not used.)"""
    kernel_only()
    return False


@overload(contact_commit_due, jit_options=DISPATCH_OPTIONS)
def _contact_commit_due(work):  # noqa: ANN001, ANN202
    if absent(work):
        return lambda work: False
    return lambda work: work.quiet_state[QUIET_ON] == 0


def contact_record_stage(contact, work, x, q, frames, filled, due) -> None:  # noqa: ANN001
    """On a recording step, put the contact statistics of the state (count, deepest overlap, stored energy,
    history overflows so far: contact/state.py) in the frame the record stage is about to fill, when the
    scene has contact."""
    kernel_only()


@overload(contact_record_stage, jit_options=DISPATCH_OPTIONS)
def _contact_record_stage(contact, work, x, q, frames, filled, due):  # noqa: ANN001, ANN202
    if absent(contact, work):
        return lambda contact, work, x, q, frames, filled, due: None

    def run(contact, work, x, q, frames, filled, due):  # noqa: ANN001, ANN202
        if due and filled < frames.contact.shape[0] and contact.sphere_body.shape[0]:
            record_contact_state(contact, work, x, q, frames.contact, filled)

    return run


def kinematic_begin_stage(model, kinematic, schedule, t, h, x, q, P, L) -> bool:  # noqa: ANN001
    """Kinematic bodies (the model's kinematic table) at their exact pose at t, moving at their mean
    velocity over [t, t + h) (physics/kinematic.py), when the scene has any; True when it moved something."""
    kernel_only()
    return False


@overload(kinematic_begin_stage, jit_options=DISPATCH_OPTIONS)
def _kinematic_begin_stage(model, kinematic, schedule, t, h, x, q, P, L):  # noqa: ANN001, ANN202
    if absent(kinematic):
        return lambda model, kinematic, schedule, t, h, x, q, P, L: False

    def run(model, kinematic, schedule, t, h, x, q, P, L):  # noqa: ANN001, ANN202
        if kinematic.body.shape[0]:
            kinematic_begin(model, kinematic, schedule, t, h, x, q, P, L)
            return True
        return False

    return run


def kinematic_end_stage(model, kinematic, schedule, t, x, q, P, L) -> None:  # noqa: ANN001
    """Kinematic bodies at their exact x, q, P, L at t (physics/kinematic.py) when the scene has any."""
    kernel_only()


@overload(kinematic_end_stage, jit_options=DISPATCH_OPTIONS)
def _kinematic_end_stage(model, kinematic, schedule, t, x, q, P, L):  # noqa: ANN001, ANN202
    if absent(kinematic):
        return lambda model, kinematic, schedule, t, x, q, P, L: None

    def run(model, kinematic, schedule, t, x, q, P, L):  # noqa: ANN001, ANN202
        if kinematic.body.shape[0]:
            kinematic_end(model, kinematic, schedule, t, x, q, P, L)

    return run


def contact_step_limit(contact) -> float:  # noqa: ANN001
    """The longest step [s] adaptive stepping may take: the contacts' stable step (the model's contact
    table), inf without contact."""
    kernel_only()
    return 0.0


@overload(contact_step_limit, jit_options=DISPATCH_OPTIONS)
def _contact_step_limit(contact):  # noqa: ANN001, ANN202
    if absent(contact):
        return lambda contact: np.inf

    def run(contact):  # noqa: ANN001, ANN202
        return contact.stable_step

    return run


def schedule_step_floor(forces, dt) -> float:  # noqa: ANN001
    """The step [s] below which adaptive stepping judges a step by its error per step, not per unit
    step: SCHEDULE_STEP_FLOOR dt when the scene has schedules (a window edge is a jump of a force or of
    a kinematic body's velocity), 0 without (physics/adaptive.py)."""
    kernel_only()
    return 0.0


@overload(schedule_step_floor, jit_options=DISPATCH_OPTIONS)
def _schedule_step_floor(forces, dt):  # noqa: ANN001, ANN202
    if absent(member(forces, "schedule")):
        return lambda forces, dt: 0.0

    def run(forces, dt):  # noqa: ANN001, ANN202
        return SCHEDULE_STEP_FLOOR * dt if forces.schedule.kind.shape[0] > 0 else 0.0  # full tables: 0 rows

    return run
