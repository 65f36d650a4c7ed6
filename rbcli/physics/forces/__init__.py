"""Force terms: each accumulates a wrench (F, tau) per body for a given state and time.

Force types are data: `ForceTables` holds one parameter table per type (`tables.py`), with 0 rows
when the scene does not use it, so the compiled step does no work for terms a scene does not have,
and a table lists only the bodies its terms touch. Adding a force type = one module here with a
compiled `accumulate_*` kernel (+ numpy reference and, when conservative, a potential energy), one
table in `tables.py`, and one line each in `accumulate_wrench`, `wrench_numpy`, `potential_energy`.

Modules: gravity (uniform, at the centre of mass), field (per-particle force or acceleration field),
point_force (force at a body point), torque (pure couple), spring (spring-damper to a world anchor or
between bodies), drag (linear and quadratic, translational and rotational), impulse (instantaneous
changes of P and L, applied between steps), schedule (time profiles that scale a term).
This package's `__init__` and `tables.py` import numpy only; the kernel modules import numba.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.forces.tables import (
    NO_SCHEDULE,
    TERM_NAMES,
    WORLD,
    DragTable,
    FieldTable,
    ForceTables,
    ImpulseTable,
    PointForceTable,
    ScheduleTable,
    SpringTable,
    TorqueTable,
    drag_table,
    field_table,
    impulse_table,
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
    "ForceTables",
    "ImpulseTable",
    "PointForceTable",
    "ScheduleTable",
    "SpringTable",
    "TorqueTable",
    "build_force_tables",
    "force_terms_present",
    "terms_with_torque",
]


def build_force_tables(
    gravity: np.ndarray | None,
    *,
    schedule: ScheduleTable | None = None,
    field: FieldTable | None = None,
    point_force: PointForceTable | None = None,
    torque: TorqueTable | None = None,
    spring: SpringTable | None = None,
    drag: DragTable | None = None,
    impulse: ImpulseTable | None = None,
) -> ForceTables:
    """Tables for a scene's force terms from plain tables (a missing table = 0 rows).

    `rbcli.scene.compile_forces` builds the tables from a scene's force specs; this function only
    assembles them and derives the switches has_gravity and has_torque.
    """
    g = np.zeros(3) if gravity is None else np.asarray(gravity, dtype=np.float64).copy()
    g.setflags(write=False)
    tables = dict(
        schedule=schedule if schedule is not None else schedule_table(),
        field=field if field is not None else field_table(),
        point_force=point_force if point_force is not None else point_force_table(),
        torque=torque if torque is not None else torque_table(),
        spring=spring if spring is not None else spring_table(),
        drag=drag if drag is not None else drag_table(),
        impulse=impulse if impulse is not None else impulse_table(),
    )
    return ForceTables(
        gravity=g,
        has_gravity=gravity is not None and bool(np.any(g != 0.0)),
        has_torque=bool(terms_with_torque(**tables)),
        term_evaluations=np.zeros(len(TERM_NAMES), dtype=np.int64),
        **tables,
    )


def terms_with_torque(
    *,
    field: FieldTable,
    point_force: PointForceTable,
    torque: TorqueTable,
    spring: SpringTable,
    drag: DragTable,
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
    return tuple(names)


def force_terms_present(forces: ForceTables) -> tuple[str, ...]:
    """Names of the terms the compiled wrench (and `apply_impulses`) will evaluate, in TERM_NAMES order."""
    rows = {
        "gravity": 1 if forces.has_gravity else 0,
        "field": table_rows(forces.field),
        "point_force": table_rows(forces.point_force),
        "torque": table_rows(forces.torque),
        "spring": table_rows(forces.spring),
        "drag": table_rows(forces.drag),
        "impulse": table_rows(forces.impulse),
    }
    return tuple(name for name in TERM_NAMES if rows[name])
