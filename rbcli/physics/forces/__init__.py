"""Force terms: each accumulates a wrench (F, tau) per body for a given state and time.

Force types are data: `ForceTables` holds one parameter table per type (`tables.py`), with 0 rows
when the scene does not use it, so the compiled step does no work for terms a scene does not have,
and a table lists only the bodies its terms touch. The compiled force pass `accumulate_wrench`
(`wrench_pass.py`) calls the stages of one list, `stage_list.py: FORCE_STAGES`, in its order (each
stage's dispatcher comes from `stages.py: force_stage`).

Adding a force type, in physics/ (what each place is for):
  1. its module here: the compiled `accumulate_<name>` kernel, a numpy reference, a potential energy
     when conservative;
  2. `tables.py`: its table (NamedTuple + constructor), a field in ForceTables and KernelForceTables
     (numba needs a typed field per table: a dict of tables would not compile), and its TERM_<NAME>
     counter in TERM_NAMES (`force_terms_present` and `ForceTables.kernel()` then cover it);
  3. one entry in `stage_list.py: FORCE_STAGES` and its stage in `wrench_pass.py` (a `_<name>`
     function, its `<name>_stage = force_stage(...)` dispatcher and the call in accumulate_wrench, where
     the list puts it: tests/physics/test_pipeline.py checks the two agree);
  4. the Python side that is not compiled: a line each in `wrench.py: wrench_numpy` and, when
     conservative, `potential_energy` (each reference has its own arguments), a keyword of
     `build_force_tables`, and its torque rule in `terms_with_torque` / `bodies_with_torque` when it can
     produce a torque (`conservation.py` when it changes which invariants are kept).
The scene side (schemas/scene.schema.json, scene/force_specs.py, scene/compile_forces.py) parses and
compiles its YAML into the table; docs/forces.md documents it.

Modules: gravity (uniform, at the centre of mass), field (per-particle force or acceleration field),
point_force (force at a body point), torque (pure couple), spring (spring-damper to a world anchor or
between bodies), drag (linear and quadratic, translational and rotational), impulse (instantaneous
changes of P and L, applied between steps), schedule (time profiles that scale a term).
This package's `__init__` and `tables.py` import numpy only; the kernel modules import numba.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from rbcli.physics.contact.tables import ContactTable, check_contact_table
from rbcli.physics.forces.tables import (
    NO_SCHEDULE,
    TERM_NAMES,
    WORLD,
    DragTable,
    FieldTable,
    ForceData,
    ForceTables,
    ImpulseTable,
    PointForceTable,
    ScheduleTable,
    SpringTable,
    TorqueTable,
    drag_table,
    field_table,
    impulse_table,
    make_force_data,
    point_force_table,
    schedule_table,
    spring_table,
    table_rows,
    torque_table,
)

__all__ = [
    "NO_SCHEDULE",
    "TERM_NAMES",
    "WORLD",
    "DragTable",
    "FieldTable",
    "ForceData",
    "ForceTables",
    "ImpulseTable",
    "PointForceTable",
    "ScheduleTable",
    "SpringTable",
    "TorqueTable",
    "bodies_with_torque",
    "build_force_tables",
    "force_terms_present",
    "make_force_data",
    "terms_with_torque",
]


def build_force_tables(
    gravity: np.ndarray | None,
    *,
    body_count: int,
    schedule: ScheduleTable | None = None,
    field: FieldTable | None = None,
    point_force: PointForceTable | None = None,
    torque: TorqueTable | None = None,
    spring: SpringTable | None = None,
    drag: DragTable | None = None,
    impulse: ImpulseTable | None = None,
    contact: ContactTable | None = None,
) -> ForceTables:
    """Tables for a scene of body_count bodies from plain tables (a missing table = 0 rows); contact:
    the model's contact table (None: no contact), which only decides the bodies contact can give a
    torque (`bodies_with_torque`): the table itself is the model's (physics/model.py).

    `rbcli.scene.compile_forces` builds the tables from a scene's force specs; this function only
    assembles them, checks that every row names a body in range, and derives the switches
    has_gravity, has_torque and the per-body torque_body (`bodies_with_torque`).
    """
    g = np.zeros(3) if gravity is None else np.asarray(gravity, dtype=np.float64).copy()
    g.setflags(write=False)
    tables: dict[str, Any] = dict(
        schedule=schedule if schedule is not None else schedule_table(),
        field=field if field is not None else field_table(),
        point_force=point_force if point_force is not None else point_force_table(),
        torque=torque if torque is not None else torque_table(),
        spring=spring if spring is not None else spring_table(),
        drag=drag if drag is not None else drag_table(),
        impulse=impulse if impulse is not None else impulse_table(),
    )
    _check_bodies(body_count, **tables)
    if contact is not None:
        check_contact_table(contact, body_count)
    torque_body = bodies_with_torque(body_count, **tables, contact=contact)
    return ForceTables(
        gravity=g,
        has_gravity=gravity is not None and bool(np.any(g != 0.0)),
        has_torque=bool(torque_body.any()),
        torque_body=torque_body,
        **tables,
    )


def terms_with_torque(
    *,
    field: FieldTable,
    point_force: PointForceTable,
    torque: TorqueTable,
    spring: SpringTable,
    drag: DragTable,
    contact: ContactTable | None = None,
    **_: object,
) -> tuple[str, ...]:
    """Names of the terms whose rows can produce a torque about a centre of mass.

    A force applied at the centre of mass (point = 0) gives tau = 0 x f = 0 exactly, so point forces
    and springs attached at centres of mass, and drag without angular coefficients, leave a scene
    torque-free. Impulses change L directly (between steps), not through tau.
    """
    names = []
    if table_rows(field):  # sum r_i x F_i: zero only for a uniform per-mass field, keep it general
        names.append("field")
    if np.any(point_force.point != 0.0):
        names.append("point_force")
    if table_rows(torque):
        names.append("torque")
    if np.any(spring.point_a != 0.0) or np.any((spring.point_b != 0.0) & (spring.body_b >= 0)[:, None]):
        names.append("spring")
    if np.any(drag.angular_linear != 0.0) or np.any(drag.angular_quadratic != 0.0):
        names.append("drag")
    if contact is not None and contact.sphere_body.size:
        if np.any(contact.sphere_offset != 0.0) or np.any(contact.body_friction[contact.sphere_body] > 0.0):
            names.append("contact")
    return tuple(names)


def bodies_with_torque(
    body_count: int,
    *,
    field: FieldTable,
    point_force: PointForceTable,
    torque: TorqueTable,
    spring: SpringTable,
    drag: DragTable,
    contact: ContactTable | None = None,
    **_: object,
) -> np.ndarray:
    """bool (body_count,), read-only: True for each body that some row can give a torque; the
    per-body form of `terms_with_torque` (same rules), so has_torque == torque_body.any().

    Conservative: a row flags its body whatever its schedule, strength or the state (a scheduled
    torque that is off for now, a zero vector, a field that happens to be uniform). A field row always
    flags (tau = sum r_i x F_i; even a uniform per-mass field gives round-off torques); a point force
    or spring end flags only when its point is off the centre of mass (r = 0 gives tau = 0 x f = 0
    exactly); drag only with an angular coefficient; a contact body when it has friction or a sphere
    off its centre (a frictionless sphere at the centre is pushed along the normal through it). A body
    that no row flags gets tau = 0 exactly, so an integrator may skip its torque path with bitwise the
    same result. Impulses flag nothing: they change L between steps, never through tau.
    """
    flag = np.zeros(body_count, dtype=np.bool_)
    flag[field.body] = True
    flag[point_force.body[np.any(point_force.point != 0.0, axis=1)]] = True
    flag[torque.body] = True
    flag[spring.body_a[np.any(spring.point_a != 0.0, axis=1)]] = True
    flag[spring.body_b[(spring.body_b >= 0) & np.any(spring.point_b != 0.0, axis=1)]] = True
    flag[drag.body[(drag.angular_linear != 0.0) | (drag.angular_quadratic != 0.0)]] = True
    if contact is not None and contact.sphere_body.size:
        off_centre = np.any(contact.sphere_offset != 0.0, axis=1)
        flag[contact.sphere_body[off_centre]] = True
        with_spheres = np.zeros(body_count, dtype=np.bool_)
        with_spheres[contact.sphere_body] = True
        flag |= with_spheres & (contact.body_friction > 0.0)
    flag.setflags(write=False)
    return flag


def _check_bodies(body_count: int, **tables: Any) -> None:
    """ValueError unless every row's body index is in [0, body_count) (a spring's body_b may be WORLD):
    the kernels index per-body arrays with them unchecked."""
    columns = {name: table.body for name, table in tables.items() if hasattr(table, "body")}
    columns["spring body_a"] = tables["spring"].body_a
    columns["spring body_b"] = tables["spring"].body_b[tables["spring"].body_b != WORLD]
    for name, body in columns.items():
        if body.size and (body.min() < 0 or body.max() >= body_count):
            raise ValueError(f"{name} table names body {body.min()}..{body.max()}, outside 0..{body_count - 1}")


def force_terms_present(forces: ForceTables, contact: ContactTable | None) -> tuple[str, ...]:
    """Names of the terms the compiled wrench (and `apply_impulses`) will evaluate, in TERM_NAMES order;
    contact: the model's contact table (`model.contact`; None: no contact)."""
    spheres = 0 if contact is None else int(contact.sphere_body.shape[0])
    special = {"gravity": 1 if forces.has_gravity else 0, "contact": spheres}
    rows = {name: special[name] if name in special else table_rows(getattr(forces, name)) for name in TERM_NAMES}
    return tuple(name for name in TERM_NAMES if rows[name])
