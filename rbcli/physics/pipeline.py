"""What a step is: the one list of stages, and the chunk loop generated from it for each integrator.

A step from grid index n (t = n dt) to n + 1 runs, in this order (STEP_STAGES):

    impulses        exact jumps P += J, L += r x J of the impulses due in [t, t + dt)  (forces/impulse.py)
    joint_begin     (split2, scenes with joints) velocities that break the joints' rows (a kick, initial
                    velocities given so) projected onto G V = 0: the exact impulsive reaction
    then data.substeps times (1 unless contact sub-stepping is on), over [ts, ts + h), h = dt / substeps:
      contact_begin   the contact springs' clock: the (sub-)step being taken            (contact/force.py)
      kinematic_begin kinematic bodies at their exact pose, at their mean velocity   (contact/kinematic.py)
      update          the integrator's maths (integrators/<name>.py `step`); every force evaluation it
                      needs is the force pass `forces/wrench.accumulate_wrench`, itself a list of force
                      stages (gravity, fields, point forces, torques, springs, drag, contact), each
                      present only when the scene has rows for it
      kinematic_end   kinematic bodies at their exact state at the end of the (sub-)step
      joint_position  (split2, scenes with joints) the joints' impulse at the kick, by Newton, so the
                      end configuration satisfies the joints to round-off               (joints/stages.py)
      joint_velocity  (split2, scenes with joints) momenta projected onto the joints' velocity rows
      contact_commit  the last evaluation's contacts and tangential springs become the history
    record          on recording steps: the divergence check, then the state copied into the next frame

Each optional stage is present only when the scene needs it, decided when numba compiles the loop, not
at run time: the loop takes `ForceTables.kernel()`, in which a force type's table is None when the scene
has none of it, and calls the stage through a dispatcher of forces/stages.py (a `numba.extending.
overload`) that compiles to nothing for a None table and to the stage otherwise. A run-time test
(`if forces.impulse.body.shape[0]:`, as these loops had) skips the work but still compiles the stage
(numba compiles both sides of a branch), so a gravity-only scene's first run compiled the impulses and
the contact stage too. A scene always gets the same combination of None and tables, so numba's cache
holds one loop per scene kind; a loop called with a plain ForceTables (tests, benchmarks) compiles every
stage and skips the empty ones at run time.

The runner (runner/loop.py) owns time, chunk sizes, sinks and interrupts; a chunk loop never prints,
writes files or allocates.

Why generated code: numba cannot cache a loop that receives the integrator's step as an argument (the
cache index would hold dispatcher objects that do not exist in the next process), and one loop that
chooses among all integrators by an integer would compile all ten on a first run (~20 s) when a scene
needs one. So `chunk_source` renders the same template once per integrator into
`physics/chunks/<module>.py` (plain modules, cached by numba like any other); a test fails when the
committed files differ from the template, and regenerates them with

    python tests/physics/test_pipeline.py --regenerate

Adding a stage: one entry in STEP_STAGES (this file), the stage's own module (with a dispatcher in
forces/stages.py when only some scenes have it), and the regeneration.
Adaptive runs (a tolerance instead of dt) step between output times under error control: their loop is
`physics/adaptive.py` (dopri5 only), which runs the same update and record stages;
`runner/simulation.py` applies impulses between its chunks.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Stage:
    """One stage of a step, as code inside the chunk loop.

    Names the code may use: model, forces, data (KernelData), x, q, P, L, F, tau, scratch (data's
    arrays), force_data (data.force), contact and contact_work (forces.contact and force_data.contact,
    None without contact), dt, index (the grid step being taken), t = index * dt, k (steps done in this
    chunk), frames, filled, record_every; `integrator_step` is the integrator's update. Use the names,
    not `data.F` or `data.force`: the loop takes them out of their tuples once, before it starts (each
    `data.force` inside the loop increfs and decrefs every array the tuple holds, every step).
    Consecutive sub-step stages form one loop run data.substeps times (contact sub-stepping, 1
    otherwise), where ts and h are the sub-step's start time and length. A stage that ends the chunk
    returns (k + 1, filled, status). A stage that only some scenes have calls a dispatcher
    (forces/stages.py) that compiles to nothing without it.
    """

    name: str
    why: str  # the one-line comment written above the stage
    imports: tuple[str, ...]
    code: str  # lines of the loop body, without indentation
    substep: bool = False  # runs data.substeps times per step, at ts = t + sub h, h = dt / data.substeps
    integrators: tuple[str, ...] = ()  # the integrator modules whose loops have it (empty: every one)


STEP_STAGES: tuple[Stage, ...] = (
    Stage(
        "impulses",
        "impulses: exact jumps of P and L at the start of the step that holds them",
        ("from rbcli.physics.forces.stages import impulse_stage",),
        "impulse_stage(model, forces, force_data, t, t + dt, x, q, P, L)",
    ),
    Stage(
        "joint_begin",
        "joint_begin: velocities that break the joints (a kick, or given so) projected: the exact impulsive reaction",
        ("from rbcli.physics.joints.stages import joint_begin_stage",),
        "joint_begin_stage(model, forces, force_data, x, q, P, L)",
        integrators=("split2",),
    ),
    Stage(
        "contact_begin",
        "contact_begin: the contact springs measure time from the start of this (sub-)step",
        ("from rbcli.physics.forces.stages import contact_begin_stage",),
        "contact_begin_stage(contact, contact_work, ts, h)",
        substep=True,
    ),
    Stage(
        "kinematic_begin",
        "kinematic_begin: kinematic bodies at their exact pose, moving at their mean velocity over the (sub-)step",
        ("from rbcli.physics.forces.stages import kinematic_begin_stage",),
        "kinematic_begin_stage(model, forces, ts, h, x, q, P, L)",
        substep=True,
    ),
    Stage(
        "update",
        "update: the integrator's maths, its force evaluations through forces.wrench.accumulate_wrench",
        (),
        "integrator_step(model, forces, force_data, ts, h, x, q, P, L, F, tau, scratch)",
        substep=True,
    ),
    Stage(
        "kinematic_end",
        "kinematic_end: kinematic bodies at their exact state at the end of the (sub-)step (closed form)",
        ("from rbcli.physics.forces.stages import kinematic_end_stage",),
        "kinematic_end_stage(model, forces, ts + h, x, q, P, L)",
        substep=True,
    ),
    Stage(
        "joint_position",
        "joint_position: the joints' impulse at the kick that puts the end configuration on g = 0 (RATTLE)",
        ("from rbcli.physics.joints.stages import joint_position_stage",),
        "joint_position_stage(model, forces, force_data, h, x, q, P, L)",
        substep=True,
        integrators=("split2",),
    ),
    Stage(
        "joint_velocity",
        "joint_velocity: the momenta projected so that the joints' rows have zero rate, G V = 0",
        ("from rbcli.physics.joints.stages import joint_velocity_stage",),
        "joint_velocity_stage(model, forces, force_data, h, x, q, P, L)",
        substep=True,
        integrators=("split2",),
    ),
    Stage(
        "contact_commit",
        "contact_commit: the (sub-)step is complete: its last evaluation's contacts become the history",
        ("from rbcli.physics.forces.stages import contact_commit_stage",),
        "contact_commit_stage(model, contact, contact_work, x, q, P, L)",
        substep=True,
    ),
    Stage(
        "materialise",
        "materialise: exact defers torque-free bodies under constant forces; write them when due",
        ("from rbcli.physics.integrators.exact import materialise",),
        "materialise(model, forces, t, dt, x, q, P, L, scratch, {due})",
        integrators=("exact",),
    ),
    Stage(
        "contact_record",
        "contact_record: on recording steps, the step's contact count, deepest overlap and energy",
        ("from rbcli.physics.forces.stages import contact_record_stage",),
        "contact_record_stage(contact_work, frames, filled, (index + 1) % record_every == 0)",
    ),
    Stage(
        "record",
        "record: on recording steps, the divergence check and the state copied into the next frame",
        ("from rbcli.physics.step import STATUS_OK, record_if_due",),
        "filled, status = record_if_due(index + 1, record_every, x, q, P, L, frames, filled)\n"
        "if status != STATUS_OK:\n"
        "    return k + 1, filled, status",
    ),
)

_HEADER = '''"""Chunk loop of `{name}`, generated by rbcli.physics.pipeline from STEP_STAGES: do not edit.

Regenerate with `python tests/physics/test_pipeline.py --regenerate` after changing the stages.
"""

import numba

{imports}

__all__ = ["SCRATCH_WIDTH", "integrator_step", "run_chunk"]


@numba.njit(**CHUNK_KERNEL)
def run_chunk(model, forces, data, dt, step0, n_steps, record_every, frames, filled):  # noqa: ANN001, ANN201
    """Steps step0 .. step0 + n_steps - 1 of every body with recording; (steps done, frames filled, status).

    status: STATUS_OK (ran n_steps), STATUS_FULL (the frame buffers are full: hand them over and call
    again), STATUS_DIVERGED (the last step left a non-finite or blown-up state, not recorded),
    STATUS_NO_ROOM (called with full buffers: nothing was written).
    """
    # taken out of their tuples once: inside the loop each would be increfed and decrefed every step
    x, q, P, L, F, tau, scratch = data.x, data.q, data.P, data.L, data.F, data.tau, data.scratch
    force_data, contact = data.force, forces.contact
    contact_work = force_data.contact
    substeps = data.substeps
    h = dt / substeps
    for k in range(n_steps):
        index = step0 + k
        t = index * dt
'''

_FOOTER = """    return n_steps, filled, chunk_status(x, q, P, L)
"""


def _indent(code: str, depth: int) -> str:
    return "".join(" " * depth + line + "\n" for line in code.splitlines())


def _import_lines(module: str, stages: tuple[Stage, ...]) -> str:
    """The stages' imports merged per module and sorted as ruff's isort rules want them."""
    names: dict[str, set[str]] = {"rbcli.physics.step": {"CHUNK_KERNEL", "chunk_status"}}
    for line in (line for stage in stages for line in stage.imports):
        source, _, imported = line.removeprefix("from ").partition(" import ")
        names.setdefault(source, set()).update(name.strip() for name in imported.split(","))
    integrator = f"rbcli.physics.integrators.{module}"
    own = sorted({"SCRATCH_WIDTH"} | names.pop(integrator, set()))  # a stage of the integrator's own module
    lines = [(integrator, f"from {integrator} import {', '.join(own)}"),
             (integrator, f"from {integrator} import step as integrator_step")]  # fmt: skip
    for source, found in names.items():
        line = f"from {source} import {', '.join(sorted(found))}"
        if len(line) > 120:  # ruff's line length: one name per line in parentheses, as ruff's isort writes it
            line = f"from {source} import (\n" + "".join(f"    {name},\n" for name in sorted(found)) + ")"
        lines.append((source, line))
    return "\n".join(line for _, line in sorted(lines))


def _state_due(later: tuple[Stage, ...]) -> str:
    """When `materialise` must write a deferred state: on recording steps and at the chunk's end, or at
    every step when a stage after it (other than the recording ones, which read it only when due) may
    read or write the state, as a stage added to the list would."""
    if all(stage.name in ("contact_record", "record") for stage in later):
        return "(index + 1) % record_every == 0 or k + 1 == n_steps"
    return "True"


def chunk_source(module: str, name: str, stages: tuple[Stage, ...] = STEP_STAGES) -> str:
    """The Python source of the chunk loop of integrator module `module` (registry name `name`)."""
    body = []
    in_substeps = False
    stages = tuple(stage for stage in stages if not stage.integrators or module in stage.integrators)
    for i, stage in enumerate(stages):
        if stage.substep and not in_substeps:
            # h = dt / 1 and ts = t + 0 * h are exactly dt and t: one sub-step is bitwise the plain step
            body.append(_indent("for sub in range(substeps):\n    ts = t + sub * h", 8))
        in_substeps = stage.substep
        depth = 12 if stage.substep else 8
        body.append(_indent(f"# {stage.why}", depth))
        body.append(_indent(stage.code.replace("{due}", _state_due(stages[i + 1 :])), depth))
    head = _HEADER.format(name=name, imports=_import_lines(module, stages))
    return head + "".join(body) + _FOOTER
