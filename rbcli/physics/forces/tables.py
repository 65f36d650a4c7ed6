"""Parameter tables of the force terms: one named tuple of flat arrays per force type.

A table has one row per (term, touched body); a scene that does not use a type gets the same table
with 0 rows, so Python code reads every ForceTables alike (`forces.spring.body_a`, `table_rows`).
Compiled kernels take `ForceTables.kernel()` instead (KernelForceTables): every force type's table None
in a scene whose only force is gravity, so no force stage compiles (forces/stages.py), and every table,
empty ones too, in a scene with any other force, so all such scenes share one compiled loop; the numba
types are stable from run to run.

Points are body-fixed offsets about the centre of mass in the PRINCIPAL frame
(`KernelModel.particle_offset`'s frame), converted once at compile time from the user's body frame:
r = E^T (p_user - centre_user). Vectors flagged `body_frame` are in the principal
frame too (v = E^T v_user); the others are world-frame. Every array of the tables is read-only; what
the force pass writes at run time is a `ForceData`, owned by the run's Data (physics/data.py).

Only force terms live here. The contact, joint and kinematic tables are the model's (physics/model.py:
`model.contact`, `model.joint`, `model.kinematic`), as MuJoCo's mjModel holds them; the force pass
reads the contact table beside these (contact is a force stage). The schedules stay here: they are
the force terms' time profiles, and a kinematic body's motion borrows a row of the same table, so one
table serves both (and the adaptive loop's step floor at a window edge: physics/adaptive.py).

This module imports numpy only (no numba), so `scene/compile.py` can build tables cheaply.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from rbcli.physics.contact.tables import ContactTable, ContactWork, contact_present, make_contact_work
from rbcli.physics.table_arrays import frozen_bools, frozen_floats, frozen_ints

if TYPE_CHECKING:
    from rbcli.physics.model import KernelModel, Model

# Row column `schedule` value meaning "no schedule": the force acts at full strength at all times.
NO_SCHEDULE = -1
# Row column `body_b` of a spring meaning "the second end is a world anchor".
WORLD = -1
# Columns of ForceData.damper: a damper row's constants over one dissipation flow (forces/damping.py).
DAMPER_COLUMNS = 19

SCHEDULE_CONSTANT = 0
SCHEDULE_PIECEWISE_LINEAR = 1
SCHEDULE_SINE = 2
SCHEDULE_KINDS = {"constant": SCHEDULE_CONSTANT, "piecewise_linear": SCHEDULE_PIECEWISE_LINEAR, "sine": SCHEDULE_SINE}

# Indices into ForceData.term_evaluations, and the names force_terms_present reports.
TERM_NAMES = ("gravity", "field", "point_force", "torque", "spring", "drag", "impulse", "contact")
TERM_GRAVITY, TERM_FIELD, TERM_POINT_FORCE, TERM_TORQUE, TERM_SPRING, TERM_DRAG, TERM_IMPULSE, TERM_CONTACT = range(8)


class ScheduleTable(NamedTuple):
    """Time profiles s(t) [1] that multiply a row's force or torque; rows refer to them by index.

    s(t) = 0 outside the window start <= t < stop; inside it, by kind:
      constant:          s = offset
      piecewise_linear:  linear interpolation through the knots (knot_time ascending, knot_value),
                         held at the first / last value before / after them
      sine:              s = offset + amplitude sin(2 pi frequency t + phase), t the absolute time.
    Knots of schedule j: knot_time[knot_start[j] : knot_start[j] + knot_count[j]].
    """

    kind: np.ndarray  # int64 (schedule_count,)
    start: np.ndarray  # [s] (schedule_count,)
    stop: np.ndarray  # [s] (schedule_count,)
    amplitude: np.ndarray  # [1] (schedule_count,)
    frequency: np.ndarray  # [Hz] (schedule_count,)
    phase: np.ndarray  # [rad] (schedule_count,)
    offset: np.ndarray  # [1] (schedule_count,)
    knot_start: np.ndarray  # int64 (schedule_count,)
    knot_count: np.ndarray  # int64 (schedule_count,)
    knot_time: np.ndarray  # [s] (knot_count_total,)
    knot_value: np.ndarray  # [1] (knot_count_total,)


class FieldTable(NamedTuple):
    """Per-particle force fields, one row per (field, body): a(x) = value + gradient x at each particle.

    per_mass: F_i = s(t) m_i a(x_i) (an acceleration field [m/s^2], [1/s^2] for the gradient);
    otherwise F_i = s(t) a(x_i) (a force per particle [N], [N/m]). x_i is the particle's world
    position; the body gets F = sum F_i and tau = sum r_i x F_i, r_i = x_i - x the world offset.
    """

    body: np.ndarray  # int64 (row_count,)
    per_mass: np.ndarray  # bool (row_count,)
    value: np.ndarray  # (row_count, 3), world
    gradient: np.ndarray  # (row_count, 3, 3), world: a_j += gradient[j, k] x_k
    schedule: np.ndarray  # int64 (row_count,), NO_SCHEDULE or a ScheduleTable row


class PointForceTable(NamedTuple):
    """Forces at body-fixed points: F += s(t) f, tau += r x s(t) f with r = R point (world offset)."""

    body: np.ndarray  # int64 (row_count,)
    point: np.ndarray  # [m] (row_count, 3), principal frame, about the centre of mass
    vector: np.ndarray  # [N] (row_count, 3), world, or principal frame where body_frame
    body_frame: np.ndarray  # bool (row_count,): vector turns with the body (f = R vector)
    schedule: np.ndarray  # int64 (row_count,)


class TorqueTable(NamedTuple):
    """Pure torques (couples): tau += s(t) vector, world or turning with the body."""

    body: np.ndarray  # int64 (row_count,)
    vector: np.ndarray  # [N m] (row_count, 3), world, or principal frame where body_frame
    body_frame: np.ndarray  # bool (row_count,)
    schedule: np.ndarray  # int64 (row_count,)


class SpringTable(NamedTuple):
    """Springs-dampers between a body point and a world anchor or another body's point.

    With d = p_a - p_b, l = |d|, e = d / l: f = -(k (l - l0) + c dl/dt) e on end a (at p_a) and -f on
    end b; dl/dt = e . (v_a - v_b). Potential V = k (l - l0)^2 / 2.
    """

    body_a: np.ndarray  # int64 (row_count,)
    point_a: np.ndarray  # [m] (row_count, 3), principal frame of body_a, about its centre of mass
    body_b: np.ndarray  # int64 (row_count,), WORLD for an anchored spring
    point_b: np.ndarray  # [m] (row_count, 3), principal frame of body_b; the world anchor if WORLD
    stiffness: np.ndarray  # k [N/m] (row_count,)
    rest_length: np.ndarray  # l0 [m] (row_count,)
    damping: np.ndarray  # c [N s/m] (row_count,)


class DragTable(NamedTuple):
    """Drag at the centre of mass: F = -(b + c |v|) v, tau = -(b_r + c_r |omega|) omega."""

    body: np.ndarray  # int64 (row_count,)
    linear: np.ndarray  # b [N s/m] (row_count,)
    quadratic: np.ndarray  # c [N s^2/m^2] (row_count,)
    angular_linear: np.ndarray  # b_r [N m s] (row_count,)
    angular_quadratic: np.ndarray  # c_r [N m s^2] (row_count,)


class ImpulseTable(NamedTuple):
    """Impulses J at body points, applied between steps (see impulse.py), rows sorted by time."""

    body: np.ndarray  # int64 (row_count,)
    time: np.ndarray  # [s] (row_count,), ascending
    vector: np.ndarray  # J [N s] (row_count, 3), world, or principal frame where body_frame
    point: np.ndarray  # [m] (row_count, 3), principal frame, about the centre of mass
    body_frame: np.ndarray  # bool (row_count,)


# the fields of ForceTables that kernels take as they are (switches, gravity, the shared schedules);
# every other field is a force type's table, None in KernelForceTables when it has no rows
_KERNEL_AS_IS = ("gravity", "has_gravity", "has_torque", "torque_body", "schedule")


class ForceTables(NamedTuple):
    """Every force term of a scene as arrays (numba-friendly).

    gravity: uniform field [m/s^2], (3,), world; acts at the centre of mass, so no torque.
    has_gravity: False when the scene has no gravity (the term is skipped).
    has_torque: False when no term can produce a torque: integrators may skip the torque kick, and
      the wrench leaves tau untouched (all zeros). Equal to torque_body.any().
    torque_body: bool (body_count,): True for a body that some term can give a torque (a field row,
      a point force or spring end off its centre of mass, a pure torque, angular drag, contact with
      friction or spheres off the centre: the model's contact table is a force stage). Integrators
      run their torque path (L += h tau, the body-frame torque in Euler's equations) only for these
      bodies; every other body's tau is exactly zero, so skipping it changes nothing. Impulses act
      on L between steps, not through tau, so they flag nothing.
    """

    gravity: np.ndarray
    has_gravity: bool
    has_torque: bool
    torque_body: np.ndarray
    schedule: ScheduleTable
    field: FieldTable
    point_force: PointForceTable
    torque: TorqueTable
    spring: SpringTable
    drag: DragTable
    impulse: ImpulseTable

    def kernel(self) -> KernelForceTables:
        """The tables as compiled kernels take them: None for every force type's table when the scene has
        no rows of any, else every table as it is, the empty ones too (see KernelForceTables)."""
        forced = any(table_rows(getattr(self, name)) for name in self._fields if name not in _KERNEL_AS_IS)
        fields: list[Any] = [value if name in _KERNEL_AS_IS or forced else None
                             for name, value in zip(self._fields, self, strict=True)]  # fmt: skip
        return KernelForceTables(*fields)


class KernelForceTables(NamedTuple):
    """ForceTables as compiled kernels take them (`ForceTables.kernel()`, like Model.kernel()): the
    same fields in the same order. A scene whose only force is gravity has every force type's table None,
    so numba types them as NoneType and the force stages compile to nothing (forces/stages.py,
    physics/stages.py). A scene with any other force term has every table, those of the types it lacks
    with 0 rows, which each stage skips at run time (one row-count test per force evaluation): every scene
    with forces has the same numba type, so the loop and the stages one such scene compiles serve all of
    them, whatever their mix of force types (issue 44: each combination of six types was a loop of its
    own, ~6 CPU-s each; the stages of all six types together compile in a few seconds, once). Kernels
    also accept a ForceTables (every stage then compiled, skipped at run time for 0 rows), as tests and
    benchmarks that call them directly do."""

    gravity: np.ndarray
    has_gravity: bool
    has_torque: bool
    torque_body: np.ndarray
    schedule: ScheduleTable
    field: FieldTable | None
    point_force: PointForceTable | None
    torque: TorqueTable | None
    spring: SpringTable | None
    drag: DragTable | None
    impulse: ImpulseTable | None


class ForceData(NamedTuple):
    """What the force pass writes besides F and tau: the mutable part beside the read-only tables,
    allocated once per run (`make_force_data`) and owned by the run's Data.

    term_evaluations: int64 (len(TERM_NAMES),), a diagnostic counter (Rapier's stage counters): each
      evaluation of a term adds the rows (field: particles; impulse: impulses applied; contact: contacts
      found) it processed.
    contact: the contact stage's grid, per-evaluation arrays and contact history (contact/tables.py);
      None when the scene has no contact stage (`contact_present`), as KernelModel.contact is. The force
      pass's contact stage writes it; the pipeline's contact stages start, commit and record it.
    damper: float64 (spring rows, forces/damping.py DAMPER_COLUMNS): each damper's constants over one
      dissipation flow D(h) of the splitting integrators (its line, moment arms and weight, computed once
      for the palindrome's two passes); 0 rows in a scene without a damper.
    """

    term_evaluations: np.ndarray
    contact: ContactWork | None
    damper: np.ndarray


def make_force_data(
    model: Model | KernelModel,
    contact_threads: int = 1,
    implicit_contact: bool = False,
    forces: ForceTables | KernelForceTables | None = None,
) -> ForceData:
    """A zeroed ForceData for the model `model` (Model, KernelModel: the same ForceData; what it needs is
    the model's contact table) and its force tables `forces` (either form; what it needs is the spring
    table's size; None: a scene without dampers); contact_threads > 1: the contact pair search runs on
    that many threads (contact/threaded.py); implicit_contact: the contact stage keeps its contacts for
    the linearly implicit correction (contact/implicit_rows.py)."""
    contact: ContactTable | None = model.contact
    spring = forces.spring if forces is not None else None
    dampers = spring.damping.shape[0] if spring is not None and np.any(spring.damping != 0.0) else 0
    return ForceData(
        term_evaluations=np.zeros(len(TERM_NAMES), dtype=np.int64),
        contact=make_contact_work(contact, model.body_mass.shape[0], threads=contact_threads, implicit=implicit_contact)
        if contact is not None and contact_present(contact)
        else None,
        damper=np.zeros((dampers, DAMPER_COLUMNS)),
    )


# ---- constructors: every table has the same dtypes and layouts whether empty or not ----------------


def schedule_table(
    kind=(), start=(), stop=(), amplitude=(), frequency=(), phase=(), offset=(), knots=()
) -> ScheduleTable:  # noqa: ANN001
    """A ScheduleTable from per-schedule sequences; knots: per schedule a (times, values) pair."""
    counts = [len(t) for t, _ in knots]
    starts: Any = np.concatenate([[0], np.cumsum(counts)[:-1]]) if counts else []
    times: Any = np.concatenate([np.asarray(t, dtype=np.float64) for t, _ in knots]) if counts else []
    values: Any = np.concatenate([np.asarray(v, dtype=np.float64) for _, v in knots]) if counts else []
    return ScheduleTable(
        frozen_ints(kind),
        frozen_floats(start),
        frozen_floats(stop),
        frozen_floats(amplitude),
        frozen_floats(frequency),
        frozen_floats(phase),
        frozen_floats(offset),
        frozen_ints(starts),
        frozen_ints(counts),
        frozen_floats(times),
        frozen_floats(values),
    )


def field_table(body=(), per_mass=(), value=(), gradient=(), schedule=()) -> FieldTable:  # noqa: ANN001
    return FieldTable(
        frozen_ints(body),
        frozen_bools(per_mass),
        frozen_floats(value, 3),
        frozen_floats(gradient, 3, 3),
        frozen_ints(schedule),
    )


def point_force_table(body=(), point=(), vector=(), body_frame=(), schedule=()) -> PointForceTable:  # noqa: ANN001
    return PointForceTable(
        frozen_ints(body),
        frozen_floats(point, 3),
        frozen_floats(vector, 3),
        frozen_bools(body_frame),
        frozen_ints(schedule),
    )


def torque_table(body=(), vector=(), body_frame=(), schedule=()) -> TorqueTable:  # noqa: ANN001
    return TorqueTable(frozen_ints(body), frozen_floats(vector, 3), frozen_bools(body_frame), frozen_ints(schedule))


def spring_table(body_a=(), point_a=(), body_b=(), point_b=(), stiffness=(), rest_length=(), damping=()) -> SpringTable:  # noqa: ANN001
    return SpringTable(
        frozen_ints(body_a),
        frozen_floats(point_a, 3),
        frozen_ints(body_b),
        frozen_floats(point_b, 3),
        frozen_floats(stiffness),
        frozen_floats(rest_length),
        frozen_floats(damping),
    )


def drag_table(body=(), linear=(), quadratic=(), angular_linear=(), angular_quadratic=()) -> DragTable:  # noqa: ANN001
    return DragTable(
        frozen_ints(body),
        frozen_floats(linear),
        frozen_floats(quadratic),
        frozen_floats(angular_linear),
        frozen_floats(angular_quadratic),
    )


def impulse_table(body=(), time=(), vector=(), point=(), body_frame=()) -> ImpulseTable:  # noqa: ANN001
    """An ImpulseTable with its rows sorted by time (stable, so equal times keep their given order)."""
    time = np.asarray(time, dtype=np.float64).reshape(-1)
    order = np.argsort(time, kind="stable")
    return ImpulseTable(
        frozen_ints(np.asarray(body, dtype=np.int64).reshape(-1)[order]),
        frozen_floats(time[order]),
        frozen_floats(np.asarray(vector, dtype=np.float64).reshape(-1, 3)[order], 3),
        frozen_floats(np.asarray(point, dtype=np.float64).reshape(-1, 3)[order], 3),
        frozen_bools(np.asarray(body_frame, dtype=np.bool_).reshape(-1)[order]),
    )


def table_rows(table: NamedTuple) -> int:
    """Number of rows of a force table (the length of its first column)."""
    return int(table[0].shape[0])


def schedule_values_numpy(schedule: ScheduleTable, index: np.ndarray, t: float) -> np.ndarray:
    """Plain numpy reference of `forces/schedule.py: schedule_value` (numpy only, so compiling a scene can
    evaluate a schedule) for an array of row indices (NO_SCHEDULE -> 1)."""
    index = np.asarray(index, dtype=np.int64)
    out = np.ones(index.shape)
    for n, j in enumerate(index.tolist()):  # tests only: one schedule at a time is clearest
        if j == NO_SCHEDULE:
            continue
        if not (schedule.start[j] <= t < schedule.stop[j]):
            out[n] = 0.0
        elif schedule.kind[j] == SCHEDULE_CONSTANT:
            out[n] = schedule.offset[j]
        elif schedule.kind[j] == SCHEDULE_SINE:
            out[n] = schedule.offset[j] + schedule.amplitude[j] * np.sin(
                2 * np.pi * schedule.frequency[j] * t + schedule.phase[j]
            )
        elif schedule.kind[j] == SCHEDULE_PIECEWISE_LINEAR:
            knots = slice(schedule.knot_start[j], schedule.knot_start[j] + schedule.knot_count[j])
            times, values = schedule.knot_time[knots], schedule.knot_value[knots]
            k = int(np.searchsorted(times, t, side="right")) - 1  # times[k] <= t < times[k + 1]
            if k < 0 or k == len(times) - 1:
                out[n] = values[max(k, 0)]
            else:
                out[n] = values[k] + (values[k + 1] - values[k]) * (t - times[k]) / (times[k + 1] - times[k])
    return out
