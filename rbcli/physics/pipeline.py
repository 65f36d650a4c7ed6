"""What a step is: the one list of its stages, in the order the chunk loops run them.

The loops are code: the fixed-step loop physics/chunk_loop.py `run_chunk` (one function, compiled per
integrator) and the error-controlled loop physics/adaptive_loop.py `run_chunk` (adaptive runs). This
list names each stage, the function each loop calls for it and where it runs, and
tests/physics/test_pipeline.py checks it against the loops' source (the calls, their order, which sit
in the sub-step loop and which only some integrators run), so the list and the loops cannot drift apart.

A step from grid index n (t = n dt) to n + 1 runs, in this order:

    impulses        exact jumps P += J, L += r x J of the impulses due in [t, t + dt)  (forces/impulse.py)
    tree_kick       (reduced-euler, reduced-rk4) after an impulse: the links' momenta projected onto the
                    trees' rates, M rate = J^T h: the joints' exact impulsive reaction (tree/integrate.py)
    joint_begin     (split2, scenes with joints) velocities that break the joints' rows (a kick, initial
                    velocities given so) projected onto G V = 0: the exact impulsive reaction
    then data.substeps times (1 unless contact sub-stepping is on), over [ts, ts + h), h = dt / substeps:
      contact_begin   the contact springs' clock: the (sub-)step being taken            (contact/force.py)
      kinematic_begin kinematic bodies at their exact pose, at their mean velocity  (physics/kinematic.py)
      joint_update    (split2, scenes with joints) the step is RATTLE instead of `update`: a half kick, the
                      joints' impulse by Newton through split2's exact drift so the end configuration
                      satisfies the joints to round-off, a half kick at the end        (joints/rattle.py)
      tree_update     (reduced-euler, reduced-rk4) the step is the trees' own instead of `update`: their
                      joint coordinates and rates advanced by ABA's accelerations, each force evaluation
                      the force pass below at the links' x, q, P, L from forward kinematics (physics/tree/)
      update          the integrator's maths (integrators/<name>.py `step`); every force evaluation it
                      needs is the force pass `forces/wrench.accumulate_wrench`, the stages of its own
                      list of force stages (forces/stage_list.py FORCE_STAGES: gravity, fields, point
                      forces, torques, springs, drag, contact), each present only when the scene has it
      kinematic_end   kinematic bodies at their exact state at the end of the (sub-)step
      joint_velocity  (split2, scenes with joints) momenta projected onto the joints' velocity rows
      contact_commit  the last evaluation's contacts and tangential springs become the history
    materialise     (exact) the torque-free bodies it defers, written on recording steps and at the
                    chunk's end (the stages after it read the state only on recording steps)
    contact_record  on recording steps: the step's contact statistics into the next frame
    joint_record    (split2, scenes with joints) on recording steps: the joints' reactions into the next frame
    tree_record     (the reduced integrators) the same, from the trees' joint wrenches (tree/integrate.py)
    record          on recording steps: the divergence check, then the state copied into the next frame

Only some integrators' loops run a stage marked `only`: the integrators whose IntegratorInfo has that
flag (`joints`: split2; `defers`: exact; `tree`: the reduced ones, IntegratorInfo.reduced); chunk_loop.py
compiles those stages out of the other loops.
Each optional stage is also present only when the scene needs it, decided when numba compiles the
loop, not at run time: the loop takes `Model.kernel()` and `ForceTables.kernel()`, in which the model's
contact, joint and kinematic tables and each force type's table are None when the scene has none of
it, and calls the stage through a dispatcher of physics/stages.py (a `numba.extending.overload`,
physics/dispatch.py) that compiles to nothing for a None table and to the stage otherwise (the joint
stages prune themselves instead: joints/stages.py). A run-time test (`if forces.impulse.body.shape[0]:`)
would skip the work but still compile the stage (numba compiles both sides of a branch). A scene
always gets the same combination of None and tables, so numba's cache holds one loop per integrator
and scene kind; a loop called with a plain ForceTables (tests, benchmarks) compiles every force stage
and skips the empty ones at run time. Before its first step a loop takes the model apart: its tables
by name (`contact`, `joint`, `kinematic`) and its body arrays alone (`model_bodies`, physics/step.py)
as `model`, one numba type for every kind of scene, so each stage kernel below the loop is compiled
once for all of them.

The adaptive loop (physics/adaptive.py has the method) runs the stages that have an `adaptive` call
where its structure puts them (its docstring): impulses at the grid steps that hold them (it lands
there), contact_begin and kinematic_begin before each attempt, kinematic_end and contact_commit after
an accepted one, contact_record and record at the grid times it lands on. Joints refuse a tolerance
(integrators.check_integrator), and dopri5 defers nothing: no joint stages, no materialise.

Adding a stage: its own module (with a dispatcher in physics/stages.py when only some scenes have it),
its call in the loops that run it, and its entry here, where the test wants it.
"""

from __future__ import annotations

from typing import NamedTuple


class Stage(NamedTuple):
    """One stage of a step: what the chunk loops call for it, and where."""

    name: str
    why: str  # the one line the loops' comment above its call begins with
    fixed: str | None  # the function chunk_loop.run_chunk calls for it (None: not in the fixed-step loop)
    adaptive: str | None  # the function adaptive_loop.run_chunk calls for it (None: not in the adaptive loop)
    substep: bool = False  # runs data.substeps times per step, at ts = t + sub h, h = dt / data.substeps
    only: str = ""  # an IntegratorInfo flag: only the loops of the integrators that have it run the stage


STEP_STAGES: tuple[Stage, ...] = (
    Stage("impulses", "exact jumps of P and L at the start of the step that holds them",
          "impulse_stage", "impulse_stage"),
    Stage("tree_kick", "the kicked links' momenta projected onto the trees' rates (the joints' impulsive reaction)",
          "tree_kick", None, only="tree"),
    Stage("joint_begin", "velocities that break the joints (a kick, given so) projected: the exact impulsive reaction",
          "joint_begin", None, only="joints"),
    Stage("contact_begin", "the contact springs measure time from the start of this (sub-)step",
          "contact_begin_stage", "contact_begin_stage", substep=True),
    Stage("kinematic_begin", "kinematic bodies at their exact pose, moving at their mean velocity over the (sub-)step",
          "kinematic_begin_stage", "kinematic_begin_stage", substep=True),
    Stage("joint_update", "with joints the step is RATTLE, joints/rattle.py (else False: update runs)",
          "joint_update", None, substep=True, only="joints"),
    Stage("tree_update", "the trees' step in joint coordinates, the links' x, q, P, L by forward kinematics",
          "tree_step", None, substep=True, only="tree"),
    Stage("update", "the integrator's maths, its force evaluations through forces.wrench.accumulate_wrench",
          "integrator_step", "advance", substep=True),
    Stage("kinematic_end", "kinematic bodies at their exact state at the end of the (sub-)step (closed form)",
          "kinematic_end_stage", "kinematic_end_stage", substep=True),
    Stage("joint_velocity", "the momenta projected so that the joints' rows have zero rate, G V = 0",
          "joint_velocity", None, substep=True, only="joints"),
    Stage("contact_commit", "the (sub-)step is complete: its last evaluation's contacts become the history",
          "contact_commit_stage", "contact_commit_stage", substep=True),
    Stage("materialise", "exact defers torque-free bodies under constant forces; write them when due",
          "integrator_materialise", None, only="defers"),
    Stage("contact_record", "on recording steps, the state's contact count, deepest overlap and energy",
          "contact_record_stage", "contact_record_stage"),
    Stage("joint_record", "on recording steps, each joint's reaction over the last (sub-)step into the next frame",
          "joint_record", None, only="joints"),
    Stage("tree_record", "on recording steps, each joint's reaction over the last (sub-)step into the next frame",
          "tree_record", None, only="tree"),
    Stage("record", "on recording steps, the divergence check and the state copied into the next frame",
          "record_if_due", "record_if_due"),
)  # fmt: skip
