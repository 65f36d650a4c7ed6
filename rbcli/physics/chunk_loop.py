"""The fixed-step chunk loop: the stages of a step (physics/pipeline.py) around an integrator's update,
for many steps. Written once; compiled once per integrator.

Where the loops of two integrators differ, `run_chunk` names a module-level constant of this module:
`integrator_step` (the integrator module's `step`, or `step_parallel` for the loop on threads),
`HOLDS_JOINTS` (split2, the one integrator that holds joints: the joint stages `joint_begin` ...
`joint_record` run, bound only into its loop, and a scene with joints steps by `joint_update`, RATTLE,
instead of the plain update), `DEFERS` with `integrator_materialise` (exact, which
defers the state of torque-free bodies: its `materialise` runs) and `HOLDS_TREE` with `tree_step` (the
reduced integrators, physics/tree/: the trees' step in joint coordinates replaces the update).
`fixed_step_loop` compiles the function with its own copy of the module's globals, those names bound
for one integrator, so numba sees constants: it prunes the other integrators' `if HOLDS_JOINTS:`, `if DEFERS:`
and `if HOLDS_TREE:` branches before it types the loop (its dead-branch pruning of global constants) and
inlines the one `step` (STEP_ENTRY,
physics/step.py), exactly as in a loop written for that integrator alone. A scene's first run compiles
its own integrator and nothing of the others, and each integrator's loop has cache files of its own
(its qualified name: `run_chunk[split2]`, ...).

Why not the integrator as an argument: numba cannot cache a loop that takes the step as an argument
(its cache index would hold a dispatcher object that does not exist in the next process); an integer
choosing at run time compiles every integrator's step (numba compiles both sides of a branch); and an
integrator passed as an empty named tuple that a `numba.extending.overload` resolves to its step
costs a call per step, every array passed by value, or, inlined, a second compile of the whole step
(docs/performance.md, "The chunk loop as code").

The optional stages (physics/stages.py) are chosen by the types of the model's and the force tables
instead (None where the scene lacks them: physics/dispatch.py). The runner (runner/loop.py) owns time,
chunk sizes, sinks and interrupts; a chunk loop never prints, writes files or allocates.
"""

from __future__ import annotations

import functools
import importlib
import types
from typing import Any, NamedTuple

import numba

from rbcli.physics.kernel_handle import opened
from rbcli.physics.stages import (
    contact_begin_stage,
    contact_commit_due,
    contact_commit_stage,
    contact_record_stage,
    impulse_stage,
    kinematic_begin_stage,
    kinematic_end_stage,
)
from rbcli.physics.step import CHUNK_KERNEL, STATUS_OK, chunk_status, model_bodies, record_if_due


def _unbound(*_args: object) -> None:
    raise TypeError("run_chunk runs as compiled by fixed_step_loop, which binds its integrator")


# What run_chunk calls that depends on the integrator, bound per integrator by `fixed_step_loop` (the
# values here stand for no integrator: run_chunk is never compiled with them)
integrator_step: Any = _unbound  # the integrator module's `step`, or `step_parallel` for the loop on threads
integrator_materialise: Any = _unbound  # its `materialise`, where DEFERS
HOLDS_JOINTS = False  # the joint stages run (split2, the one integrator that holds joints)
DEFERS = False  # the step defers bodies' states and integrator_materialise writes them (exact)
# physics/joints/stages.py's stages and rattle.py's step, where HOLDS_JOINTS: imported only for the loops
# that run them (the import is ~20 ms of every other integrator's start-up)
joint_begin: Any = _unbound
joint_update: Any = _unbound
joint_velocity: Any = _unbound
joint_record: Any = _unbound
# the reduced integrators (physics/tree/: the state of the trees is their joint coordinates and rates):
# their step replaces the update, and the joint stages do not run (the joints hold by construction)
HOLDS_TREE = False
tree_step: Any = _unbound
tree_record: Any = _unbound
tree_kick: Any = _unbound


def run_chunk(model, forces, data, dt, step0, n_steps, record_every, frames, filled):  # noqa: ANN001, ANN201
    """Steps step0 .. step0 + n_steps - 1 of every body with recording; (steps done, frames filled, status).

    model, forces: `Model.kernel()` and `ForceTables.kernel()` (None for the tables the scene lacks);
    data: `Data.kernel()`. status: STATUS_OK (ran n_steps), STATUS_FULL (the frame buffers are full: hand
    them over and call again), STATUS_DIVERGED (the last step left a non-finite or blown-up state, not
    recorded), STATUS_NO_ROOM (called with full buffers: nothing was written). model, forces, data and
    frames may each come as a KernelHandle (the runner's calls: one pointer each instead of ~120 arrays to
    convert: physics/kernel_handle.py).
    """
    model, forces, data, frames = opened(model), opened(forces), opened(data), opened(frames)
    # taken out of their tuples once: inside the loop each would be increfed and decrefed every step
    x, q, P, L, F, tau, scratch = data.x, data.q, data.P, data.L, data.F, data.tau, data.scratch
    force_data = data.force
    contact, joint, kinematic, schedule = model.contact, model.joint, model.kinematic, forces.schedule
    contact_work, joint_work = force_data.contact, data.joint
    tree, tree_data = model.tree, data.tree
    # from here on `model` is the model's body arrays alone (KernelBodies): one numba type for every
    # kind of scene, so each stage kernel below is compiled once for all of them; tables go by name
    model = model_bodies(model)
    substeps = data.substeps
    h = dt / substeps
    for k in range(n_steps):
        index = step0 + k
        t = index * dt
        # impulses: exact jumps of P and L at the start of the step that holds them
        kicked = impulse_stage(model, forces, force_data, t, t + dt, x, q, P, L)
        if HOLDS_TREE:
            if kicked:
                # tree_kick: the kicked links' momenta projected onto the trees' rates (the joints' impulsive reaction)
                tree_kick(forces, tree, tree_data, x, q, P, L, F, tau)
        if HOLDS_JOINTS:
            # joint_begin: velocities that break the joints (a kick, given so) projected: the exact impulsive reaction
            joint_begin(model, joint, joint_work, x, q, P, L)
        # h = dt / 1 and ts = t + 0 * h are exactly dt and t: one sub-step is bitwise the plain step
        for sub in range(substeps):
            ts = t + sub * h
            # contact_begin: the contact springs measure time from the start of this (sub-)step
            contact_begin_stage(contact, contact_work, ts, h)
            # kinematic_begin: kinematic bodies at their exact pose, moving at their mean velocity over the (sub-)step
            kinematic_begin_stage(model, kinematic, schedule, ts, h, x, q, P, L)
            stepped = False
            if HOLDS_JOINTS:
                # joint_update: with joints the step is RATTLE, joints/rattle.py (else False: update runs)
                stepped = joint_update(model, forces, contact, force_data, joint, joint_work, kinematic, schedule,
                                       ts, h, x, q, P, L, F, tau)  # fmt: skip
            if HOLDS_TREE:
                # tree_update: the trees' step in joint coordinates, the links' x, q, P, L by forward kinematics
                tree_step(model, forces, contact, force_data, tree, tree_data, ts, h, x, q, P, L, F, tau)
            elif not stepped:
                # update: the integrator's maths, its force evaluations through forces.wrench.accumulate_wrench
                integrator_step(model, forces, contact, force_data, ts, h, x, q, P, L, F, tau, scratch)
            # kinematic_end: kinematic bodies at their exact state at the end of the (sub-)step (closed form)
            kinematic_end_stage(model, kinematic, schedule, ts + h, x, q, P, L)
            if HOLDS_JOINTS:
                # joint_velocity: the momenta projected so that the joints' rows have zero rate, G V = 0
                joint_velocity(model, joint, joint_work, h, x, q, P, L)
            # contact_commit: the (sub-)step is complete: its last evaluation's contacts become the history
            if contact_commit_due(contact_work):  # else the quiet skin holds: nothing to commit
                contact_commit_stage(model, contact, contact_work, x, q, P, L)
        if DEFERS:
            # materialise: exact defers torque-free bodies under constant forces; write them when due: on
            # recording steps and at the chunk's end (the stages below read the state only when recording)
            due = (index + 1) % record_every == 0 or k + 1 == n_steps
            integrator_materialise(model, forces, contact, t, dt, x, q, P, L, scratch, due)
        due = (index + 1) % record_every == 0
        if due:  # a call passes the contact table and work by value (~130 arrays): on recording steps only
            # contact_record: on recording steps, the state's contact count, deepest overlap and energy
            contact_record_stage(contact, contact_work, x, q, frames, filled, due)
        if HOLDS_JOINTS:
            if due:  # a call passes the joint tables by value (~100 arrays): on recording steps only
                # joint_record: on recording steps, each joint's reaction over the last (sub-)step into the next frame
                joint_record(joint, joint_work, h, frames, filled, due)
        if HOLDS_TREE:
            if due:  # likewise the trees' (~45 arrays)
                # tree_record: on recording steps, each joint's reaction over the last (sub-)step into the next frame
                tree_record(tree, tree_data, frames, filled, due)
        # record: on recording steps, the divergence check and the state copied into the next frame
        filled, status = record_if_due(index + 1, record_every, x, q, P, L, frames, filled)
        if status != STATUS_OK:
            return k + 1, filled, status
    return n_steps, filled, chunk_status(x, q, P, L)


class ChunkLoop(NamedTuple):
    """A chunk loop as the runner calls it: run_chunk(model, forces, data, dt, step0, n_steps,
    record_every, frames, filled) -> (steps done, frames filled, status) (a numba dispatcher), and the
    scratch columns per body its Data needs (make_data's scratch_width)."""

    run_chunk: Any
    SCRATCH_WIDTH: int  # the integrator modules' name for it


@functools.cache  # one dispatcher per integrator and process: numba compiles or loads each loop once
def fixed_step_loop(
    module: str, *, joints: bool = False, defers: bool = False, threaded: bool = False, reduced: bool = False
) -> ChunkLoop:
    """`run_chunk` compiled for the integrator module `module` (integrators/__init__.py IntegratorInfo:
    its `joints`, `defers`, `reduced`; threaded: its `step_parallel`): the function itself, with its own
    copy of the module's globals in which the integrator's names (above run_chunk) are bound."""
    integrator = importlib.import_module(module)
    bound = {
        "integrator_step": _unbound if reduced else (integrator.step_parallel if threaded else integrator.step),
        "integrator_materialise": integrator.materialise if defers else _unbound,
        "HOLDS_JOINTS": joints,
        "DEFERS": defers,
        "HOLDS_TREE": reduced,
        "tree_step": integrator.step if reduced else _unbound,
    }
    if reduced:
        from rbcli.physics.tree.integrate import tree_kick_stage, tree_record_stage

        bound.update(tree_record=tree_record_stage, tree_kick=tree_kick_stage)
    if joints:
        from rbcli.physics.joints import rattle, stages

        names = ("joint_begin", "joint_velocity", "joint_record")
        bound.update({name: getattr(stages, name) for name in names}, joint_update=rattle.joint_update_stage)
    function = types.FunctionType(run_chunk.__code__, {**run_chunk.__globals__, **bound}, run_chunk.__name__)
    function.__doc__ = run_chunk.__doc__
    # numba names each function's cache files and index after its qualified name (the code is the same)
    function.__qualname__ = f"run_chunk[{module.rsplit('.', 1)[1]}{'_parallel' if threaded else ''}]"
    return ChunkLoop(numba.njit(**CHUNK_KERNEL)(function), integrator.SCRATCH_WIDTH)


def adaptive_loop() -> ChunkLoop:
    """The error-controlled loop (physics/adaptive_loop.py), for a Data made with adaptive=True."""
    from rbcli.physics import adaptive_loop as module

    return ChunkLoop(module.run_chunk, 0)
