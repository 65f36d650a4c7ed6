"""The force pass as one list: FORCE_STAGES, the stages of `accumulate_wrench` (forces/wrench_pass.py) in
order, each with the tables it needs and whether it is dissipative; physics/pipeline.py's STEP_STAGES
lists a step's stages the same way.

The pass sets F [N] and tau [N m] (body_count, 3), world frame, about each centre of mass, to the sum of
the scene's force terms at time t: F = sum over stages, tau likewise. Each stage that has a table is
called through a dispatcher (forces/stages.py `force_stage`, a `numba.extending.overload`) that
compiles to nothing when the table is None in `ForceTables.kernel()` (contact: in `Model.kernel()`), so
a scene compiles only the force types it has; behind the same row test as before, so a plain
ForceTables (tests, benchmarks) still works. The pass is written out by hand (wrench_pass.py says why);
tests/physics/test_pipeline.py checks that it calls these stages in this order, dispatched on these
tables, the dissipative ones only when `dissipative`.

Adding a force type: its module (kernel `accumulate_*`, numpy reference, potential when conservative),
its table in forces/tables.py, one entry here and its stage in wrench_pass.py (forces/__init__.py lists
what else names a force type, and why).
This module imports nothing but the standard library.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class ForceStage:
    """One stage of the force pass: `name` (its dispatcher in wrench_pass.py is `<name>_stage`, gravity's
    code is inline), the comment above its call (`why`), the tables it is dispatched on ("forces.<field>",
    "force_data.<field>" or "contact": each must be a table, not None, for the stage to exist; empty:
    always compiled, tested at run time), and whether it is dissipative (called only when the pass's
    `dissipative` is True: the splitting integrators integrate dampers and drag as their own flow)."""

    name: str
    why: str
    tables: tuple[str, ...] = ()
    dissipative: bool = False


FORCE_STAGES: tuple[ForceStage, ...] = (
    ForceStage("gravity", "gravity: M g at every centre of mass (forces/gravity.py)"),
    ForceStage("field", "field: per-particle force or acceleration fields (forces/field.py)", tables=("forces.field",)),
    ForceStage(
        "point_force", "point_force: forces at body points (forces/point_force.py)", tables=("forces.point_force",)
    ),
    ForceStage("torque", "torque: pure couples (forces/torque.py)", tables=("forces.torque",)),
    ForceStage(
        "spring",
        "spring: springs-dampers, the dampers only when dissipative (forces/spring.py)",
        tables=("forces.spring",),
    ),
    ForceStage(
        "drag",
        "drag: linear and quadratic, translational and rotational (forces/drag.py)",
        tables=("forces.drag",),
        dissipative=True,
    ),
    ForceStage(
        "contact",
        "contact: contact forces, then the static bodies held, their wrench zeroed (physics/contact)",
        tables=("contact", "force_data.contact"),
    ),
)
