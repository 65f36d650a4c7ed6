"""What a step is: the one list of stages, and the chunk loops generated from it: one per integrator, and
the error-controlled loop of adaptive runs.

A step from grid index n (t = n dt) to n + 1 runs, in this order (STEP_STAGES):

    impulses        exact jumps P += J, L += r x J of the impulses due in [t, t + dt)  (forces/impulse.py)
    joint_begin     (split2, scenes with joints) velocities that break the joints' rows (a kick, initial
                    velocities given so) projected onto G V = 0: the exact impulsive reaction
    then data.substeps times (1 unless contact sub-stepping is on), over [ts, ts + h), h = dt / substeps:
      contact_begin   the contact springs' clock: the (sub-)step being taken            (contact/force.py)
      kinematic_begin kinematic bodies at their exact pose, at their mean velocity  (physics/kinematic.py)
      update          the integrator's maths (integrators/<name>.py `step`); every force evaluation it
                      needs is the force pass `forces/wrench.accumulate_wrench`, generated from its own
                      list of force stages (forces/stage_list.py FORCE_STAGES: gravity, fields, point
                      forces, torques, springs, drag, contact), each present only when the scene has it;
                      split2 with joints: RATTLE, the joints' impulse by Newton inside it (joints/rattle.py)
    materialise     exact's loop only: the torque-free bodies it defers, written when due
      kinematic_end   kinematic bodies at their exact state at the end of the (sub-)step
      joint_velocity  (split2, scenes with joints) momenta projected onto the joints' velocity rows
      contact_commit  the last evaluation's contacts and tangential springs become the history
    contact_record  on recording steps: the step's contact statistics into the next frame
      joint_record  (split2, scenes with joints) on recording steps: the joints' reactions into the next frame
    record          on recording steps: the divergence check, then the state copied into the next frame

Each optional stage is present only when the scene needs it, decided when numba compiles the loop, not
at run time: the loop takes `Model.kernel()` and `ForceTables.kernel()`, in which the model's contact,
joint and kinematic tables and each force type's table are None when the scene has none of it, and
calls the stage through a dispatcher of physics/stages.py (a `numba.extending.overload`,
physics/dispatch.py) that compiles to nothing for a None table and to the stage otherwise (the joint
stages prune themselves instead: joints/stages.py). A run-time test (`if forces.impulse.body.shape[0]:`,
as these loops had) skips the work but still compiles the stage (numba compiles both sides of a
branch), so a gravity-only scene's first run compiled the impulses and the contact stage too. A scene
always gets the same combination of None and tables, so numba's cache holds one loop per scene kind; a
loop called with a plain ForceTables (tests, benchmarks) compiles every force stage and skips the empty
ones at run time. Before its first step the loop takes the model apart: its tables by name (`contact`,
`joint`, `kinematic`) and its body arrays alone (`model_bodies`, physics/step.py) as `model`, one numba
type for every kind of scene, so each stage kernel below the loop is compiled once for all of them.

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
physics/stages.py when only some scenes have it), and the regeneration. The entry says which loops have
it (`loops`: FIXED, ADAPTIVE or BOTH, the default; `integrators`: the integrator modules, default all)
and, for the adaptive loop, what Stage's docstring lists (`lands_at`, `restarts`, `prepares_evaluation`).
Adaptive runs (a tolerance instead of dt) step between output times under error control: their loop
`physics/chunks/<module>_adaptive.py` (dopri5 only; `adaptive_source`) is generated from the same list,
takes the same arguments, and runs every stage where its structure puts it (Stage's docstring); the
method is physics/adaptive.py. Impulses are its stage too: it lands on the grid steps that hold them.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, replace

FIXED = "fixed"  # the fixed-step chunk loops, one per integrator: physics/chunks/<module>.py
ADAPTIVE = "adaptive"  # the error-controlled loop of an adaptive integrator: physics/chunks/<module>_adaptive.py
BOTH = (FIXED, ADAPTIVE)
UPDATE = "update"  # the integrator's own stage: a step in FIXED loops, an error-controlled attempt in ADAPTIVE


@dataclass(frozen=True)
class Stage:
    """One stage of a step, as code inside the chunk loops.

    Names the code may use: model (the model's body arrays, KernelBodies: one numba type for every scene),
    forces, data (KernelData), x, q, P, L, F, tau, scratch (data's arrays), force_data (data.force), the
    model's tables contact, joint and kinematic (None where the scene lacks them), contact_work
    (force_data.contact) and joint_work (data.joint), schedule (forces.schedule), dt, index (the grid step
    being taken), t = index * dt, frames, filled, record_every, status; `integrator_step` is the
    integrator's update. Use the names, not `data.F`, `data.force` or `model.joint`: the loop takes them
    out of their tuples once, before it starts (each `data.force` inside the loop increfs and decrefs every
    array the tuple holds, every step), and `model` is the body arrays alone by then. Consecutive sub-step
    stages form one loop run data.substeps times (contact sub-stepping, 1 otherwise), where ts and h are
    the sub-step's start time and length. Placeholders, filled per loop: `{te}` the sub-step's end time (ts + h; in the
    adaptive loop exactly the grid time it lands on), `{reached}` the grid index a step-end stage follows
    (index + 1; in the adaptive loop the index it landed on), `{recording}` whether that index is a
    recording step, `{due}` (fixed loops' materialise only). A stage that only some scenes have calls a
    dispatcher (physics/stages.py) that compiles to nothing without it, or a function that takes its table
    itself and prunes its body when numba types that table as None (`if table is None: return`,
    joints/stages.py: no compiled level between the loop and the stage).

    Which loops have it, in one place: `loops` (FIXED, ADAPTIVE or BOTH) and `integrators` (the modules
    whose loops have it; empty: every one). In the ADAPTIVE loop (physics/adaptive.py has the method)
    a stage runs where that loop's structure puts it: sub-step stages before UPDATE run before each
    attempt (ts = t, h = the attempt's length), those after it only after an accepted attempt;
    step-end stages at every grid index the loop lands on (its recording times, the chunk's end, and
    the `lands_at` indices); step-start stages at the chunk's start and at each `lands_at` index, after
    which the loop evaluates dopri5's first stage k_1 afresh (a stage there may change the state).
    """

    name: str
    why: str  # the one-line comment written above the stage
    imports: tuple[str, ...]
    code: str  # lines of the loop body, without indentation
    substep: bool = False  # runs data.substeps times per step, at ts = t + sub h, h = dt / data.substeps
    integrators: tuple[str, ...] = ()  # the integrator modules whose loops have it (empty: every one)
    loops: tuple[str, ...] = BOTH  # FIXED, ADAPTIVE or both
    # ADAPTIVE, a step-start stage: an expression of (forces, dt, index), the next grid index > index at
    # which it has work; the loop lands there. Empty: "index + 1", a landing at every grid step.
    lands_at: str = ""
    # ADAPTIVE, a sub-step stage: its code is one call returning True when it changed the state, so the
    # first-same-as-last rates k_1 are evaluated again before the next attempt
    restarts: bool = False
    # ADAPTIVE, a sub-step stage before UPDATE that prepares force evaluations at (ts, h): it also runs,
    # with h = 0, before each evaluation of k_1 at the chunk's start and after a step-start stage
    prepares_evaluation: bool = False
    # the code sets `status`; the chunk ends when it is not STATUS_OK
    ends_chunk: bool = False
    # (integrator module, code): the loops of that module run this code instead of `code`
    variants: tuple[tuple[str, str], ...] = ()


STEP_STAGES: tuple[Stage, ...] = (
    Stage(
        "impulses",
        "impulses: exact jumps of P and L at the start of the step that holds them",
        ("from rbcli.physics.stages import impulse_stage, next_impulse_step_stage",),
        "impulse_stage(model, forces, force_data, t, t + dt, x, q, P, L)",
        lands_at="next_impulse_step_stage(forces, dt, index)",
    ),
    Stage(
        "joint_begin",
        "joint_begin: velocities that break the joints (a kick, or given so) projected: the exact impulsive reaction",
        ("from rbcli.physics.joints.stages import joint_begin",),
        "joint_begin(model, joint, joint_work, x, q, P, L)",
        integrators=("split2",),
        loops=(FIXED,),  # joints refuse a tolerance (integrators.check_integrator)
    ),
    Stage(
        "contact_begin",
        "contact_begin: the contact springs measure time from the start of this (sub-)step",
        ("from rbcli.physics.stages import contact_begin_stage",),
        "contact_begin_stage(contact, contact_work, ts, h)",
        substep=True,
        prepares_evaluation=True,
    ),
    Stage(
        "kinematic_begin",
        "kinematic_begin: kinematic bodies at their exact pose, moving at their mean velocity over the (sub-)step",
        ("from rbcli.physics.stages import kinematic_begin_stage",),
        "kinematic_begin_stage(model, kinematic, schedule, ts, h, x, q, P, L)",
        substep=True,
        restarts=True,
    ),
    Stage(
        UPDATE,
        "update: the integrator's maths, its force evaluations through forces.wrench.accumulate_wrench",
        ("from rbcli.physics.joints.rattle import joint_update",),
        "integrator_step(model, forces, contact, force_data, ts, h, x, q, P, L, F, tau, scratch)",
        substep=True,
        # a scene with joints: split2's RATTLE step (joint_update returns False, pruned, without them)
        variants=(
            (
                "split2",
                "if not joint_update(\n"
                "    model, forces, contact, force_data, joint, joint_work, kinematic, schedule, ts, h, "
                "x, q, P, L, F, tau\n"
                "):\n"
                "    integrator_step(model, forces, contact, force_data, ts, h, x, q, P, L, F, tau, scratch)",
            ),
        ),  # fmt: skip
    ),
    Stage(
        "kinematic_end",
        "kinematic_end: kinematic bodies at their exact state at the end of the (sub-)step (closed form)",
        ("from rbcli.physics.stages import kinematic_end_stage",),
        "kinematic_end_stage(model, kinematic, schedule, {te}, x, q, P, L)",
        substep=True,
    ),
    Stage(
        "joint_velocity",
        "joint_velocity: the momenta projected so that the joints' rows have zero rate, G V = 0",
        ("from rbcli.physics.joints.stages import joint_velocity",),
        "joint_velocity(model, joint, joint_work, h, x, q, P, L)",
        substep=True,
        integrators=("split2",),
        loops=(FIXED,),  # joints refuse a tolerance (integrators.check_integrator)
    ),
    Stage(
        "contact_commit",
        "contact_commit: the (sub-)step is complete: its last evaluation's contacts become the history",
        ("from rbcli.physics.stages import contact_commit_stage",),
        "contact_commit_stage(model, contact, contact_work, x, q, P, L)",
        substep=True,
    ),
    Stage(
        "materialise",
        "materialise: exact defers torque-free bodies under constant forces; write them when due",
        ("from rbcli.physics.integrators.exact import materialise",),
        "due = {due}\nmaterialise(model, forces, contact, t, dt, x, q, P, L, scratch, due)",
        integrators=("exact",),
        loops=(FIXED,),
    ),
    Stage(
        "contact_record",
        "contact_record: on recording steps, the state's contact count, deepest overlap and energy",
        ("from rbcli.physics.stages import contact_record_stage",),
        "contact_record_stage(contact, contact_work, x, q, frames, filled, {recording})",
    ),
    Stage(
        "joint_record",
        "joint_record: on recording steps, each joint's reaction over the last (sub-)step into the next frame",
        ("from rbcli.physics.joints.stages import joint_record",),
        "joint_record(joint, joint_work, h, frames, filled, {recording})",
        integrators=("split2",),
        loops=(FIXED,),  # joints refuse a tolerance (integrators.check_integrator)
    ),
    Stage(
        "record",
        "record: on recording steps, the divergence check and the state copied into the next frame",
        ("from rbcli.physics.step import STATUS_OK, record_if_due",),
        "filled, status = record_if_due({reached}, record_every, x, q, P, L, frames, filled)",
        ends_chunk=True,
    ),
)

_HEADER = '''"""Chunk loop of {name}, generated by rbcli.physics.pipeline from STEP_STAGES: do not edit.

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
    force_data = data.force
{tables}{bodies}    substeps = data.substeps
    h = dt / substeps
    for k in range(n_steps):
        index = step0 + k
        t = index * dt
'''

_FOOTER = """    return n_steps, filled, chunk_status(x, q, P, L)
"""

_ADAPTIVE_HEADER = '''"""Adaptive loop of `{name}`, generated by rbcli.physics.pipeline from STEP_STAGES: do not edit.

The method (error per unit step, the controller, contact's step limit and floor) is physics/adaptive.py.
Regenerate with `python tests/physics/test_pipeline.py --regenerate` after changing the stages.
"""

import numba
import numpy as np

{imports}

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
    STATUS_DIVERGED or STATUS_STEP_TOO_SMALL (both end the run).
    """
    # taken out of their tuples once, as in the fixed-step loops
    x, q, P, L, F, tau = data.x, data.q, data.P, data.L, data.F, data.tau
    force_data = data.force
{tables}{bodies}    adaptive = data.adaptive
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
{start}            ts, h = t, 0.0  # k_1's evaluation: offset 0 into a step
{prepare}            begin(model, forces, contact, force_data, t, x, q, P, L, F, tau, work)  # y0 and k_1
            if h_next <= 0.0:
                h_next = initial_step(x, q, P, L, work, tolerance, record_every * dt)
            h_next = min(h_next, h_max)
        target = min(land, (index // record_every + 1) * record_every)  # the next grid point to land on
        remaining = target * dt - t
        landing = h_next >= remaining * (1.0 - 1e-12)  # a sliver short of the target counts as landing
        ts = t
        h = remaining if landing else h_next
        te = target * dt if landing else t + h
{before}        if moved:  # the state changed since k_1 was evaluated: evaluate it again
            moved = False
            begin(model, forces, contact, force_data, t, x, q, P, L, F, tau, work)
        # update: one attempt over [ts, ts + h), its 4th-order error estimate against the budget per step
        advance(model, forces, contact, force_data, t, h, x, q, P, L, F, tau, work)
        err = error_norm(model, forces, contact, force_data, t, h, per_time * max(h, h_floor), x, q, P, L, F, tau, work)
        if err <= 1.0:
            counters[COUNT_ACCEPTED] += 1
            accept(x, q, P, L, work)
{after}            factor = FAC_MAX if err == 0.0 else min(FAC_MAX, max(FAC_MIN, SAFETY * err**-0.25))
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
{end}            if index == land and index < end and status == STATUS_OK:
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
'''

# what the adaptive loop's own code imports, besides its stages' imports
_ADAPTIVE_IMPORTS = {
    "rbcli.physics.adaptive": {
        "CONTACT_STEP_FLOOR", "CONTROL_REJECTED_LAST", "CONTROL_STEP", "COUNT_ACCEPTED", "COUNT_REJECTED",
        "FAC_MAX", "FAC_MIN", "SAFETY", "STATUS_STEP_TOO_SMALL", "STEP_MIN_RELATIVE", "initial_step",
    },
    "rbcli.physics.stages": {"contact_step_limit", "schedule_step_floor"},
    "rbcli.physics.step": {"CHUNK_KERNEL", "STATUS_OK", "chunk_status", "model_bodies"},
}  # fmt: skip
_ADAPTIVE_METHOD = ("accept", "advance", "begin", "error_norm", "restore")  # the integrator module's kernels


# What a loop takes out of the model, the force tables and the Data before it starts, where its stages'
# code uses it: the model's tables and the schedules, then the work arrays of contact and joints
_TAKEN = (
    (("contact", "model.contact"), ("joint", "model.joint"), ("kinematic", "model.kinematic"),
     ("schedule", "forces.schedule")),
    (("contact_work", "force_data.contact"), ("joint_work", "data.joint")),
)  # fmt: skip

# then `model` becomes the body arrays alone, what every stage and integrator takes
_BODIES = """\
    # from here on `model` is the model's body arrays alone (KernelBodies): one numba type for every
    # kind of scene, so each stage kernel below is compiled once for all of them; tables go by name
    model = model_bodies(model)
"""


def _taken(code: str) -> str:
    """The header lines that take out of their tuples the names of _TAKEN that `code` uses."""
    used = set(re.findall(r"\w+", code))
    lines = []
    for group in _TAKEN:
        found = [(name, source) for name, source in group if name in used]
        if found:
            lines.append(f"    {', '.join(name for name, _ in found)} = {', '.join(source for _, source in found)}\n")
    return "".join(lines)


def _indent(code: str, depth: int) -> str:
    return "".join(" " * depth + line + "\n" for line in code.splitlines())


def _fill(stage: Stage, te: str, reached: str, recording: str, due: str | None = None) -> str:
    """A stage's code with its placeholders filled (str.replace: the code may hold braces of its own)."""
    if due is None and "{due}" in stage.code:
        raise ValueError(f"stage {stage.name!r} uses {{due}}, which only the fixed-step loops define")
    code = stage.code.replace("{te}", te).replace("{reached}", reached).replace("{recording}", recording)
    return code.replace("{due}", due or "")


def _import_lines(
    names: dict[str, set[str]], stages: tuple[Stage, ...], body: str, own: str | None = None, step: str = "step"
) -> str:
    """The loop's own imports `names` and those of its stages' that `body` uses (a stage's import may
    serve only one loop: `lands_at`), merged per module and sorted as ruff's isort rules want them;
    `own`: the integrator module, whose `step` (or `step_parallel`) is imported as integrator_step."""
    names = {source: set(found) for source, found in names.items()}
    used = set(re.findall(r"\w+", body))
    for line in (line for stage in stages for line in stage.imports):
        source, _, imported = line.removeprefix("from ").partition(" import ")
        found = {name.strip() for name in imported.split(",")} & used
        if found:
            names.setdefault(source, set()).update(found)
    lines = []
    if own is not None:
        lines.append((own, f"from {own} import {', '.join(sorted(names.pop(own)))}"))
        lines.append((own, f"from {own} import {step} as integrator_step"))
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
    if all(stage.name in ("contact_record", "joint_record", "record") for stage in later):
        return "(index + 1) % record_every == 0 or k + 1 == n_steps"
    return "True"


def loop_stages(module: str, loop: str, stages: tuple[Stage, ...] = STEP_STAGES) -> tuple[Stage, ...]:
    """The stages of `loop` (FIXED or ADAPTIVE) of integrator module `module`, in list order, each with
    its code for that module (Stage.variants)."""
    return tuple(
        replace(s, code=dict(s.variants).get(module, s.code))
        for s in stages
        if loop in s.loops and (not s.integrators or module in s.integrators)
    )


def chunk_source(module: str, name: str, stages: tuple[Stage, ...] = STEP_STAGES, parallel: bool = False) -> str:
    """The Python source of the fixed-step chunk loop of integrator module `module` (registry name `name`);
    parallel: the loop calling the module's `step_parallel` (chunks/<module>_parallel.py), the same stages."""
    body, codes = [], []
    in_substeps = False
    stages = loop_stages(module, FIXED, stages)
    for i, stage in enumerate(stages):
        if stage.substep and not in_substeps:
            # h = dt / 1 and ts = t + 0 * h are exactly dt and t: one sub-step is bitwise the plain step
            body.append(_indent("for sub in range(substeps):\n    ts = t + sub * h", 8))
        in_substeps = stage.substep
        depth = 12 if stage.substep else 8
        code = _fill(stage, "ts + h", "index + 1", "(index + 1) % record_every == 0", _state_due(stages[i + 1 :]))
        if stage.ends_chunk:
            code += "\nif status != STATUS_OK:\n    return k + 1, filled, status"
        codes.append(code)
        body.append(_indent(f"# {stage.why}", depth))
        body.append(_indent(code, depth))
    own = f"rbcli.physics.integrators.{module}"
    names = {"rbcli.physics.step": {"CHUNK_KERNEL", "chunk_status", "model_bodies"}, own: {"SCRATCH_WIDTH"}}
    imports = _import_lines(names, stages, "".join(body), own, "step_parallel" if parallel else "step")
    title = f"`{name}` on threads" if parallel else f"`{name}`"
    head = _HEADER.format(name=title, imports=imports, tables=_taken("\n".join(codes)), bodies=_BODIES)
    return head + "".join(body) + _FOOTER


def adaptive_source(module: str, name: str, stages: tuple[Stage, ...] = STEP_STAGES) -> str:
    """The Python source of the error-controlled loop of adaptive integrator module `module` (which
    provides begin, advance, error_norm, accept and restore: integrators/dopri5.py) from the same stage
    list; where each stage runs in it: Stage's docstring."""
    stages = loop_stages(module, ADAPTIVE, stages)
    sub = [i for i, stage in enumerate(stages) if stage.substep]
    update = [i for i, stage in enumerate(stages) if stage.name == UPDATE]
    if len(update) != 1 or not sub or sub != list(range(sub[0], sub[-1] + 1)) or not sub[0] <= update[0] <= sub[-1]:
        raise ValueError("the adaptive loop needs one run of sub-step stages with the update stage among them")
    start, before = stages[: sub[0]], stages[sub[0] : update[0]]
    after, step_end = stages[update[0] + 1 : sub[-1] + 1], stages[sub[-1] + 1 :]

    def render(group: tuple[Stage, ...], depth: int) -> str:
        out = []
        for i, stage in enumerate(group):
            code = _fill(stage, "te", "index", "index % record_every == 0")
            if stage.restarts:
                code = f"if {code}:\n    moved = True"
            if group is start:  # the loop lands where the stage next has work
                code += f"\nland = min(land, {stage.lands_at or 'index + 1'})"
            if stage.ends_chunk and i + 1 < len(group):
                code += "\nif status != STATUS_OK:\n    continue"
            out.append(_indent(f"# {stage.why}", depth) + _indent(code, depth))
        return "".join(out)

    parts = {"start": render(start, 12), "before": render(before, 8), "after": render(after, 12)}
    parts["end"] = render(step_end, 12)
    parts["prepare"] = "".join(
        _indent(_fill(stage, "te", "index", "index % record_every == 0"), 12)
        for stage in before
        if stage.prepares_evaluation
    )
    own = f"rbcli.physics.integrators.{module}"
    imports = _import_lines({**_ADAPTIVE_IMPORTS, own: set(_ADAPTIVE_METHOD)}, stages, "".join(parts.values()))
    # the loop's own code passes `contact` (the step limit, the method's force evaluations)
    codes = ["contact", *(_fill(stage, "te", "index", "index % record_every == 0") for stage in stages)]
    tables = _taken("\n".join(codes))
    return _ADAPTIVE_HEADER.format(name=name, imports=imports, tables=tables, bodies=_BODIES, **parts)
