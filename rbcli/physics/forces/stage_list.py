"""The force pass as one list: FORCE_STAGES, the stages of `accumulate_wrench` in order, and the
generator of the compiled pass (forces/wrench_pass.py) from it, as physics/pipeline.py generates the
chunk loops from STEP_STAGES.

The pass sets F [N] and tau [N m] (body_count, 3), world frame, about each centre of mass, to the sum of
the scene's force terms at time t: F = sum over stages, tau likewise. Each stage that has a table is
called through a dispatcher (forces/stages.py `force_stage`, a `numba.extending.overload`) that
compiles to nothing when the table is None in `ForceTables.kernel()` (contact: in `Model.kernel()`), so
a scene compiles only the force types it has; behind the same row test as before, so a plain
ForceTables (tests, benchmarks) still works. Why generated, not a loop over the list: numba can iterate
a tuple of kernels only as first-class function values, which its cache does not serve (every process
compiled the pass anew: measured), and a dispatcher must be named in the code that calls it.

Adding a force type: its module (kernel `accumulate_*`, numpy reference, potential when conservative),
its table in forces/tables.py, one entry here, then `python tests/physics/test_pipeline.py
--regenerate` (forces/__init__.py lists what else names a force type, and why).
This module imports nothing but the standard library: the generator runs without numba.
"""

from __future__ import annotations

import re
from dataclasses import dataclass


@dataclass(frozen=True)
class ForceStage:
    """One stage of the force pass, as code.

    Names the code may use: model (the body arrays, KernelBodies), forces (KernelForceTables or
    ForceTables), contact (the model's contact table, None without contact), force_data (ForceData), t,
    x, q, P, L, F, tau, counts (force_data.term_evaluations: add the rows processed at forces/tables.py's
    TERM_<name>), dissipative. `tables`: "forces.<field>", "force_data.<field>" or "contact", each of
    which must be a table (not None) for the stage to exist; empty: always compiled (gravity, a flag and
    a vector, tested at run time).
    """

    name: str
    why: str  # the one-line comment written above the stage's call
    imports: tuple[str, ...]
    code: str  # lines of the stage, without indentation
    tables: tuple[str, ...] = ()
    dissipative: bool = False  # left out when dissipative=False (the splitting integrators' own damping flow)


FORCE_STAGES: tuple[ForceStage, ...] = (
    ForceStage(
        "gravity",
        "gravity: M g at every centre of mass (forces/gravity.py)",
        (
            "from rbcli.physics.forces.gravity import accumulate_gravity",
            "from rbcli.physics.forces.tables import TERM_GRAVITY",
        ),
        "if forces.has_gravity:\n"
        "    accumulate_gravity(model.body_mass, forces.gravity, F)\n"
        "    counts[TERM_GRAVITY] += F.shape[0]",
    ),
    ForceStage(
        "field",
        "field: per-particle force or acceleration fields (forces/field.py)",
        (
            "from rbcli.physics.forces.field import accumulate_field",
            "from rbcli.physics.forces.tables import TERM_FIELD",
        ),
        "if forces.field.body.shape[0]:\n"
        "    counts[TERM_FIELD] += accumulate_field(model, forces.field, forces.schedule, t, x, q, F, tau)",
        tables=("forces.field",),
    ),
    ForceStage(
        "point_force",
        "point_force: forces at body points (forces/point_force.py)",
        (
            "from rbcli.physics.forces.point_force import accumulate_point_force",
            "from rbcli.physics.forces.tables import TERM_POINT_FORCE",
        ),
        "if forces.point_force.body.shape[0]:\n"
        "    counts[TERM_POINT_FORCE] += accumulate_point_force(forces.point_force, forces.schedule, t, q, F, tau)",
        tables=("forces.point_force",),
    ),
    ForceStage(
        "torque",
        "torque: pure couples (forces/torque.py)",
        (
            "from rbcli.physics.forces.tables import TERM_TORQUE",
            "from rbcli.physics.forces.torque import accumulate_torque",
        ),
        "if forces.torque.body.shape[0]:\n"
        "    counts[TERM_TORQUE] += accumulate_torque(forces.torque, forces.schedule, t, q, tau)",
        tables=("forces.torque",),
    ),
    ForceStage(
        "spring",
        "spring: springs-dampers, the dampers only when dissipative (forces/spring.py)",
        (
            "from rbcli.physics.forces.spring import accumulate_spring",
            "from rbcli.physics.forces.tables import TERM_SPRING",
        ),
        "if forces.spring.body_a.shape[0]:\n"
        "    counts[TERM_SPRING] += accumulate_spring(model, forces.spring, x, q, P, L, F, tau, dissipative)",
        tables=("forces.spring",),
    ),
    ForceStage(
        "drag",
        "drag: linear and quadratic, translational and rotational (forces/drag.py)",
        (
            "from rbcli.physics.forces.drag import accumulate_drag",
            "from rbcli.physics.forces.tables import TERM_DRAG",
        ),
        "if forces.drag.body.shape[0]:\n"
        "    counts[TERM_DRAG] += accumulate_drag(model, forces.drag, q, P, L, F, tau)",
        tables=("forces.drag",),
        dissipative=True,
    ),
    ForceStage(
        "contact",
        "contact: contact forces, then the static bodies held, their wrench zeroed (physics/contact)",
        (
            "from rbcli.physics.contact.force import accumulate_contact, hold_static_bodies",
            "from rbcli.physics.contact.quiet import contact_quiet",
            "from rbcli.physics.forces.tables import TERM_CONTACT",
        ),
        "work = force_data.contact\n"
        "if contact.sphere_body.shape[0] and not contact_quiet(work, x, t):  # else nothing can touch\n"
        "    accumulate_contact(model, contact, work, t, x, q, P, L, F, tau)\n"
        "    counts[TERM_CONTACT] += np.int64(work.stats[0])\n"
        "if contact.static_body.shape[0]:\n"
        "    hold_static_bodies(contact, F, tau)",
        tables=("contact", "force_data.contact"),
    ),
)  # fmt: skip

ARGUMENTS = "model, forces, contact, force_data, t, x, q, P, L, F, tau, counts, dissipative"

_HEADER = '''"""The force pass `accumulate_wrench`, generated by forces/stage_list.py from FORCE_STAGES: do not edit.

Regenerate with `python tests/physics/test_pipeline.py --regenerate` after changing the list.
"""

import numba
import numpy as np

{imports}

__all__ = ["accumulate_wrench"]
'''

_PASS = '''

@numba.njit(**STEP_ENTRY)
def accumulate_wrench(model, forces, contact, force_data, t, x, q, P, L, F, tau, dissipative=True) -> None:\
  # noqa: ANN001
    """Set F [N] and tau [N m] (body_count, 3), world frame, about each centre of mass, to the sum of the
    scene's force terms at time t [s]: the stages of FORCE_STAGES in order. tau is left untouched (zero)
    when forces.has_torque is False; otherwise it is exactly zero for every body that forces.torque_body
    does not flag. model: the body arrays (KernelBodies); forces: KernelForceTables (or ForceTables);
    contact: the model's contact table (None without contact); force_data (ForceData) holds what the
    pass writes besides F and tau: the stage counters and the contact work. dissipative=False leaves out
    the spring dampers and drag, which the splitting integrators integrate as their own flow
    (forces/damping.py); contact's dashpots stay in (contact is not smooth, so no integrator keeps its
    order through it anyway)."""
    # zeroed by loops: numba's F[:, :] = 0.0 (a slice assignment) cost ~20-30 ns per evaluation at 2
    # bodies, a fifth of a small scene's step (docs/performance.md, "Idle contact")
    for b in range(F.shape[0]):
        F[b, 0] = F[b, 1] = F[b, 2] = 0.0
    if forces.has_torque:
        for b in range(tau.shape[0]):
            tau[b, 0] = tau[b, 1] = tau[b, 2] = 0.0
    counts = force_data.term_evaluations
{calls}'''


def _indent(code: str, depth: int) -> str:
    return "".join(" " * depth + line + "\n" for line in code.splitlines())


def wrench_source(stages: tuple[ForceStage, ...] = FORCE_STAGES) -> str:
    """The Python source of forces/wrench_pass.py: a dispatcher per stage with tables, and the pass."""
    names: dict[str, set[str]] = {
        "rbcli.physics.forces.stages": set(),
        "rbcli.physics.step": {"STEP_ENTRY"},
    }
    for line in (line for stage in stages for line in stage.imports):
        source, _, imported = line.removeprefix("from ").partition(" import ")
        names.setdefault(source, set()).update(name.strip() for name in imported.split(","))
    dispatchers, calls = [], []
    for stage in stages:
        if not re.fullmatch(r"[a-z_]+", stage.name):
            raise ValueError(f"force stage name {stage.name!r}: lowercase letters and underscores only")
        call = stage.code
        if stage.tables:
            names["rbcli.physics.forces.stages"].add("force_stage")
            tables = ", ".join(f'"{table}"' for table in stage.tables)
            dispatchers.append(
                f"\n\ndef _{stage.name}({ARGUMENTS}) -> None:  # noqa: ANN001\n"
                f'    """The {stage.name} stage of FORCE_STAGES; `{stage.name}_stage` dispatches to it."""\n'
                + _indent(stage.code, 4)
                + f"\n\n{stage.name}_stage = force_stage(_{stage.name}, {tables})  # nothing when a table is None\n"
            )
            call = f"{stage.name}_stage({ARGUMENTS})"
        if stage.dissipative:
            call = "if dissipative:\n" + _indent(call, 4)
        calls.append(_indent(f"# {stage.why}", 4) + _indent(call, 4))
    lines = []
    for source, found in sorted(names.items()):
        if not found:
            continue
        line = f"from {source} import {', '.join(sorted(found))}"
        if len(line) > 120:  # ruff's line length: one name per line in parentheses, as ruff's isort writes it
            line = f"from {source} import (\n" + "".join(f"    {name},\n" for name in sorted(found)) + ")"
        lines.append(line)
    return _HEADER.format(imports="\n".join(lines)) + "".join(dispatchers) + _PASS.format(calls="".join(calls))
