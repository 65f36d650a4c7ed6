"""The optional stages of a step, each called through a dispatcher that compiles to nothing when the
scene does not have it: numba compiles only what the scene needs.

A kernel's stage tests at run time (`if table.rows:`) skip the work, not the compilation: numba types
and compiles both sides of a branch, so a gravity-only scene's first run compiled every force type,
the impulses and the contact stage (~12 s of a ~20 s first run). So the kernels take
`ForceTables.kernel()` (KernelForceTables, forces/tables.py): a table without rows is None there, and
numba types it as NoneType. Each optional stage is a plain Python function (never called from Python)
with a `numba.extending.overload` that chooses its implementation from the argument types when a kernel
that calls it is compiled: a no-op when the stage's table (or its work arrays) is NoneType, the real
kernel otherwise, behind the same row test as before, so a ForceTables with 0-row tables (what tests
and benchmarks pass when they call kernels directly) still works, compiles every stage and skips empty
ones at run time. The results are bitwise the same either way: a stage that runs does what it did,
and one compiled away had no rows to process.

A scene always gets the same combination of None and tables, so its kernels' types are the same in
every run and numba's on-disk cache serves them (the implementations below are compiled into the
cached caller; they take STEP_KERNEL's options: cached, no reference counting).

Force stages (the force pass forces/wrench_pass.accumulate_wrench, generated from forces/stage_list.py
FORCE_STAGES, each adding its rows to `counts`, the ForceData.term_evaluations counter): one factory,
`force_stage`, makes each stage's dispatcher from the stage's code and the tables it needs. Pipeline
stages (called by the generated chunk loops, physics/pipeline.py):
impulses, contact_begin, kinematic_begin, kinematic_end, contact_commit, contact_record; and for adaptive
stepping the contacts' step limit and the next step that holds an impulse. Gravity has no table (a flag
and a vector) and is not here.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numba.core import types
from numba.extending import overload

from rbcli.physics.contact.force import begin_contact_step, commit_contacts
from rbcli.physics.contact.state import record_contact_state
from rbcli.physics.contact.tables import QUIET_ON
from rbcli.physics.forces.impulse import NO_IMPULSE_STEP, apply_impulses, next_impulse_step
from rbcli.physics.forces.schedule import SCHEDULE_STEP_FLOOR
from rbcli.physics.kinematic import kinematic_begin, kinematic_end
from rbcli.physics.step import STEP_KERNEL

# the dispatchers' implementations compile with the step kernels' options (cached, no reference counting);
# typed Any: numba's stubs type jit_options as a TypedDict without its private `_nrt`
_OPTIONS: Any = STEP_KERNEL


def _absent(*argument_types: types.Type) -> bool:
    """True when any of a stage's tables or work arrays is None (numba's NoneType): the stage is absent."""
    return any(isinstance(t, types.NoneType) for t in argument_types)


def _member(tuple_type: Any, name: str) -> types.Type:  # noqa: ANN401 - a numba NamedTuple type
    """The numba type of field `name` of a named tuple type (ForceTables or KernelForceTables)."""
    return dict(zip(tuple_type.fields, tuple_type.types, strict=True))[name]


def _kernel_only(*_args: object) -> None:
    raise TypeError("a stage dispatcher runs in compiled kernels only (forces/stages.py)")


# ---- force stages: accumulate_wrench's (forces/stage_list.py, generated into forces/wrench_pass.py) --


def _no_force_stage(model, forces, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
    """What a force stage compiles to when one of its tables is None."""


def force_stage(run: Callable[..., None], *tables: str) -> Callable[..., None]:
    """The dispatcher of a force stage: compiles to `run(model, forces, force_data, t, x, q, P, L, F, tau,
    counts, dissipative)` when each of `tables` ("forces.<field>" or "force_data.<field>") is a table
    in the caller's argument types, and to nothing when one is None. `run` is a plain function of the
    generated forces/wrench_pass.py, compiled with the step kernels' options into its caller."""
    owners = tuple(table.split(".", 1) for table in tables)

    def stage(model, forces, force_data, t, x, q, P, L, F, tau, counts, dissipative) -> None:  # noqa: ANN001
        _kernel_only()

    stage.__name__ = stage.__qualname__ = f"{run.__name__.lstrip('_')}_stage"

    @overload(stage, jit_options=_OPTIONS)
    def _stage(model, forces, force_data, t, x, q, P, L, F, tau, counts, dissipative):  # noqa: ANN001, ANN202
        given = {"forces": forces, "force_data": force_data}
        if _absent(*(_member(given[owner], field) for owner, field in owners)):
            return _no_force_stage
        return run

    return stage


# ---- pipeline stages: the generated chunk loops' ---------------------------------------------------


def impulse_stage(model, forces, force_data, t_prev, t_next, x, q, P, L) -> None:  # noqa: ANN001
    """The impulses due in [t_prev, t_next) (forces/impulse.py) when the scene has any."""
    _kernel_only()


@overload(impulse_stage, jit_options=_OPTIONS)
def _impulse_stage(model, forces, force_data, t_prev, t_next, x, q, P, L):  # noqa: ANN001, ANN202
    if _absent(_member(forces, "impulse")):
        return lambda model, forces, force_data, t_prev, t_next, x, q, P, L: None

    def run(model, forces, force_data, t_prev, t_next, x, q, P, L):  # noqa: ANN001, ANN202
        if forces.impulse.body.shape[0]:
            apply_impulses(model, forces, force_data, t_prev, t_next, x, q, P, L)

    return run


def next_impulse_step_stage(forces, dt, index) -> int:  # noqa: ANN001
    """The next grid step after `index` that holds an impulse (forces/impulse.py; where the adaptive loop
    lands to apply it), NO_IMPULSE_STEP when the scene has none."""
    _kernel_only()
    return 0


@overload(next_impulse_step_stage, jit_options=_OPTIONS)
def _next_impulse_step_stage(forces, dt, index):  # noqa: ANN001, ANN202
    if _absent(_member(forces, "impulse")):
        return lambda forces, dt, index: NO_IMPULSE_STEP

    def run(forces, dt, index):  # noqa: ANN001, ANN202
        return next_impulse_step(forces, dt, index)

    return run


def contact_begin_stage(contact, work, t, h) -> None:  # noqa: ANN001
    """Start the contact springs' clock for the (sub-)step [t, t + h) when the scene has contact."""
    _kernel_only()


@overload(contact_begin_stage, jit_options=_OPTIONS)
def _contact_begin_stage(contact, work, t, h):  # noqa: ANN001, ANN202
    if _absent(contact, work):
        return lambda contact, work, t, h: None

    def run(contact, work, t, h):  # noqa: ANN001, ANN202
        if contact.sphere_body.shape[0]:
            begin_contact_step(work, t, h)

    return run


def contact_commit_stage(model, contact, work, x, q, P, L) -> None:  # noqa: ANN001
    """Make the (sub-)step's last contacts the history when the scene has contact."""
    _kernel_only()


@overload(contact_commit_stage, jit_options=_OPTIONS)
def _contact_commit_stage(model, contact, work, x, q, P, L):  # noqa: ANN001, ANN202
    if _absent(contact, work):
        return lambda model, contact, work, x, q, P, L: None

    def run(model, contact, work, x, q, P, L):  # noqa: ANN001, ANN202
        if contact.sphere_body.shape[0] and work.quiet_state[QUIET_ON] == 0:  # quiet: nothing to commit
            commit_contacts(model, contact, work, x, q, P, L)

    return run


def contact_record_stage(contact, work, x, q, frames, filled, due) -> None:  # noqa: ANN001
    """On a recording step, put the contact statistics of the state (count, deepest overlap, stored energy,
    history overflows so far: contact/state.py) in the frame the record stage is about to fill, when the
    scene has contact."""
    _kernel_only()


@overload(contact_record_stage, jit_options=_OPTIONS)
def _contact_record_stage(contact, work, x, q, frames, filled, due):  # noqa: ANN001, ANN202
    if _absent(contact, work):
        return lambda contact, work, x, q, frames, filled, due: None

    def run(contact, work, x, q, frames, filled, due):  # noqa: ANN001, ANN202
        if due and filled < frames.contact.shape[0] and contact.sphere_body.shape[0]:
            record_contact_state(contact, work, x, q, frames.contact, filled)

    return run


def kinematic_begin_stage(model, forces, t, h, x, q, P, L) -> bool:  # noqa: ANN001
    """Kinematic bodies at their exact pose at t, moving at their mean velocity over [t, t + h)
    (physics/kinematic.py), when the scene has any; True when it moved something."""
    _kernel_only()
    return False


@overload(kinematic_begin_stage, jit_options=_OPTIONS)
def _kinematic_begin_stage(model, forces, t, h, x, q, P, L):  # noqa: ANN001, ANN202
    if _absent(_member(forces, "kinematic")):
        return lambda model, forces, t, h, x, q, P, L: False

    def run(model, forces, t, h, x, q, P, L):  # noqa: ANN001, ANN202
        if forces.kinematic.body.shape[0]:
            kinematic_begin(model, forces.kinematic, forces.schedule, t, h, x, q, P, L)
            return True
        return False

    return run


def kinematic_end_stage(model, forces, t, x, q, P, L) -> None:  # noqa: ANN001
    """Kinematic bodies at their exact x, q, P, L at t (physics/kinematic.py) when the scene has any."""
    _kernel_only()


@overload(kinematic_end_stage, jit_options=_OPTIONS)
def _kinematic_end_stage(model, forces, t, x, q, P, L):  # noqa: ANN001, ANN202
    if _absent(_member(forces, "kinematic")):
        return lambda model, forces, t, x, q, P, L: None

    def run(model, forces, t, x, q, P, L):  # noqa: ANN001, ANN202
        if forces.kinematic.body.shape[0]:
            kinematic_end(model, forces.kinematic, forces.schedule, t, x, q, P, L)

    return run


def contact_step_limit(forces) -> float:  # noqa: ANN001
    """The longest step [s] adaptive stepping may take: the contacts' stable step, inf without contact."""
    _kernel_only()
    return 0.0


@overload(contact_step_limit, jit_options=_OPTIONS)
def _contact_step_limit(forces):  # noqa: ANN001, ANN202
    if _absent(_member(forces, "contact")):
        return lambda forces: np.inf

    def run(forces):  # noqa: ANN001, ANN202
        return forces.contact.stable_step

    return run


def schedule_step_floor(forces, dt) -> float:  # noqa: ANN001
    """The step [s] below which adaptive stepping judges a step by its error per step, not per unit
    step: SCHEDULE_STEP_FLOOR dt when the scene has schedules (a window edge is a jump of the force),
    0 without (physics/adaptive.py)."""
    _kernel_only()
    return 0.0


@overload(schedule_step_floor, jit_options=_OPTIONS)
def _schedule_step_floor(forces, dt):  # noqa: ANN001, ANN202
    if _absent(_member(forces, "schedule")):
        return lambda forces, dt: 0.0

    def run(forces, dt):  # noqa: ANN001, ANN202
        return SCHEDULE_STEP_FLOOR * dt if forces.schedule.kind.shape[0] > 0 else 0.0  # full tables: 0 rows

    return run
