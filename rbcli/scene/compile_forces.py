"""Compile a scene's force specs into `ForceTables` (plain arrays), once, with located errors; and the
kinematic bodies' motions into the model's KinematicTable, whose schedules join the force terms'.

Body names become indices; body points given in the user's body frame become principal-frame
offsets about the centre of mass, r = E^T (p_user - centre_user); body-frame vectors become
principal-frame vectors, E^T v_user (E = user-from-principal, `Model.body_frame_q`). A table gets one
row per (term, body it touches), so untouched bodies cost nothing.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rbcli.physics.contact.tables import ContactTable
from rbcli.physics.forces import NO_SCHEDULE, WORLD, ForceTables, build_force_tables
from rbcli.physics.forces.tables import (
    SCHEDULE_KINDS,
    drag_table,
    field_table,
    impulse_table,
    point_force_table,
    schedule_table,
    spring_table,
    torque_table,
)
from rbcli.physics.kinematic_table import KinematicTable, kinematic_table
from rbcli.physics.model import Model
from rbcli.physics.rotation import quat_to_matrix
from rbcli.scene.force_specs import (
    FIELD_PER,
    FRAMES,
    BodyPoint,
    ForceAtPoint,
    ForceDrag,
    ForceField,
    ForceImpulse,
    ForceSpring,
    ForceTorque,
    Schedule,
)
from rbcli.scene.spec import ForceSpec, SceneError, SceneIssue, SourceLocation


class _Invalid(Exception):
    """One problem with one force spec (turned into a located SceneIssue)."""

    def __init__(self, message: str, expected: str = ""):
        super().__init__(message)
        self.expected = expected


def compile_force_tables(
    gravity: np.ndarray | None,
    force_specs: Sequence[ForceSpec],
    model: Model,
    body_index: Mapping[str, int],
    body_centres_user: np.ndarray,
    contact: ContactTable | None = None,
    kinematic: Sequence[KinematicRow] = (),
) -> tuple[ForceTables, KinematicTable]:
    """ForceTables of a scene: uniform gravity [m/s^2] (3,) or None, its force specs, the compiled
    model, body name -> index, and each body's centre of mass in its user frame [m] (body_count, 3);
    with contact, its table (the model's: it decides which bodies contact can give a torque); and the
    model's KinematicTable of the kinematic bodies' motions, whose schedules join the force terms' table
    (ForceTables.schedule: one table of time profiles, forces/tables.py).

    Raises SceneError listing every invalid spec with its location.
    """
    builder = _TableBuilder(model, body_index, np.asarray(body_centres_user, dtype=np.float64))
    issues = []
    for spec in force_specs:
        try:
            builder.add(spec)
        except _Invalid as exc:
            issues.append(SceneIssue(spec.location, f"force {spec.kind!r}: {exc}", exc.expected))
    for row in kinematic:
        try:
            builder.add_kinematic(row)
        except _Invalid as exc:
            issues.append(SceneIssue(row.location, f"kinematic body: {exc}", exc.expected))
    if issues:
        raise SceneError(issues)
    return builder.tables(gravity, contact)


@dataclass(frozen=True)
class KinematicRow:
    """One kinematic body's motion as compile_contact resolves it: v0, w0 [world], the pivot and the
    centre of mass at t = 0 [m, world], q0 (world-from-principal) and the schedule (None: s = 1)."""

    body: int
    velocity: np.ndarray
    angular_velocity: np.ndarray
    pivot: np.ndarray
    position: np.ndarray
    orientation: np.ndarray
    schedule: Schedule | None
    location: SourceLocation | None = None


def _vector(value: object, name: str, shape: tuple[int, ...] = (3,)) -> np.ndarray:
    try:
        out = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise _Invalid(f"{name} is not numeric", f"{shape[0]} numbers") from None
    if out.shape != shape or not np.isfinite(out).all():
        size = "3" if shape == (3,) else "3x3"
        raise _Invalid(f"{name} must be {size} finite numbers, got {value!r}", f"{size} finite numbers")
    return out


def _scalar(value: object, name: str, *, minimum: float | None = 0.0) -> float:
    try:
        out = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise _Invalid(f"{name} is not a number: {value!r}", "a number") from None
    if not math.isfinite(out) or (minimum is not None and out < minimum):
        raise _Invalid(f"{name} must be a finite number >= {minimum}, got {out}", f"a number >= {minimum}")
    return out


def _frame(frame: str) -> bool:
    """True for a body-frame vector."""
    if frame not in FRAMES:
        raise _Invalid(f"frame must be one of {FRAMES}, got {frame!r}", " or ".join(FRAMES))
    return frame == "body"


class _TableBuilder:
    """Rows of every table, appended spec by spec (compile time only, never in a step)."""

    def __init__(self, model: Model, body_index: Mapping[str, int], centres: np.ndarray):
        self.model, self.body_index, self.centres = model, body_index, centres
        self.E = quat_to_matrix(model.body_frame_q)  # user-from-principal, (body_count, 3, 3)
        self.schedule: dict[str, list] = {k: [] for k in ("kind", "start", "stop", "amplitude", "frequency",
                                                           "phase", "offset", "knots")}  # fmt: skip
        self.field: dict[str, list] = {k: [] for k in ("body", "per_mass", "value", "gradient", "schedule")}
        self.point_force: dict[str, list] = {k: [] for k in ("body", "point", "vector", "body_frame", "schedule")}
        self.torque: dict[str, list] = {k: [] for k in ("body", "vector", "body_frame", "schedule")}
        self.spring: dict[str, list] = {k: [] for k in ("body_a", "point_a", "body_b", "point_b", "stiffness",
                                                         "rest_length", "damping")}  # fmt: skip
        self.drag: dict[str, list] = {k: [] for k in ("body", "linear", "quadratic", "angular_linear",
                                                       "angular_quadratic")}  # fmt: skip
        self.impulse: dict[str, list] = {k: [] for k in ("body", "time", "vector", "point", "body_frame")}
        self.kinematic: dict[str, list] = {k: [] for k in ("body", "schedule", "velocity", "angular_velocity",
                                                           "pivot", "position", "orientation")}  # fmt: skip

    # ---- resolution of names, points, vectors, schedules ------------------------------------------

    def body(self, name: str) -> int:
        if name not in self.body_index:
            raise _Invalid(f"no body named {name!r}", "one of " + ", ".join(map(repr, self.body_index)))
        return self.body_index[name]

    def bodies(self, names: Sequence[str] | None) -> list[int]:
        if names is None:
            return list(range(self.model.body_count))
        if isinstance(names, str):
            raise _Invalid(f"bodies must be a list of body names, got the string {names!r}", "a list of names")
        indices = [self.body(n) for n in names]
        if len(set(indices)) != len(indices):
            raise _Invalid(f"a body is listed twice in {list(names)}", "distinct body names")
        return indices

    def point(self, at: BodyPoint) -> tuple[int, np.ndarray]:
        """(body index, principal-frame offset about the centre of mass [m])."""
        b = self.body(at.body)
        if at.point is not None and at.particle is not None:
            raise _Invalid("give either a point or a particle, not both", "point: [x, y, z] or particle: index")
        if at.particle is not None:
            count = int(self.model.body_particle_count[b])
            if (
                isinstance(at.particle, bool)
                or not isinstance(at.particle, int | np.integer)
                or not (0 <= at.particle < count)
            ):
                raise _Invalid(f"particle {at.particle!r} is not a particle of body {at.body!r}",
                               f"an index 0..{count - 1}")  # fmt: skip
            return b, np.array(self.model.particle_offset[self.model.body_particle_start[b] + int(at.particle)])
        if at.point is None:
            return b, np.zeros(3)
        return b, self.E[b].T @ (_vector(at.point, "point") - self.centres[b])

    def oriented(self, b: int, vector: object, name: str, frame: str) -> tuple[np.ndarray, bool]:
        """(vector in world or principal axes, body_frame flag)."""
        v = _vector(vector, name)
        body_frame = _frame(frame)
        return (self.E[b].T @ v if body_frame else v), body_frame

    def add_schedule(self, schedule: Schedule | None) -> int:
        if schedule is None:
            return NO_SCHEDULE
        if schedule.kind not in SCHEDULE_KINDS:
            raise _Invalid(f"schedule kind {schedule.kind!r} is unknown", " or ".join(SCHEDULE_KINDS))
        start, stop = float(schedule.start), float(schedule.stop)
        if math.isnan(start) or math.isnan(stop) or not start < stop:
            raise _Invalid(f"schedule window needs start < stop, got start={start}, stop={stop}", "start < stop")
        times: tuple[float, ...] = ()
        values: tuple[float, ...] = ()
        if schedule.kind == "piecewise_linear":
            times = tuple(_scalar(t, "schedule time", minimum=None) for t in schedule.times)
            values = tuple(_scalar(v, "schedule value", minimum=None) for v in schedule.values)
            if not times or len(times) != len(values):
                raise _Invalid("a piecewise_linear schedule needs as many values as times (at least one)",
                               "times: [...] and values: [...] of equal length")  # fmt: skip
            if any(b < a for a, b in zip(times[:-1], times[1:], strict=True)):
                raise _Invalid(f"schedule times must not decrease, got {list(times)}", "ascending times")
        s = self.schedule
        s["kind"].append(SCHEDULE_KINDS[schedule.kind])
        s["start"].append(start)
        s["stop"].append(stop)
        s["amplitude"].append(_scalar(schedule.amplitude, "schedule amplitude", minimum=None))
        s["frequency"].append(_scalar(schedule.frequency, "schedule frequency", minimum=None))
        s["phase"].append(_scalar(schedule.phase, "schedule phase", minimum=None))
        constant = schedule.kind == "constant"
        s["offset"].append(_scalar(schedule.value if constant else schedule.offset, "schedule value", minimum=None))
        s["knots"].append((times, values))
        return len(s["kind"]) - 1

    def add_kinematic(self, row: KinematicRow) -> None:
        k = self.kinematic
        k["schedule"].append(self.add_schedule(row.schedule))
        k["body"].append(row.body)
        for name in ("velocity", "angular_velocity", "pivot", "position", "orientation"):
            k[name].append(np.asarray(getattr(row, name), dtype=np.float64))

    # ---- one method per spec type --------------------------------------------------------------------

    def add(self, spec: ForceSpec) -> None:
        adders: dict[type, Callable[[Any], None]] = {
            ForceSpring: self.add_spring,
            ForceAtPoint: self.add_point_force,
            ForceTorque: self.add_torque,
            ForceDrag: self.add_drag,
            ForceImpulse: self.add_impulse,
            ForceField: self.add_field,
        }
        adder = adders.get(type(spec))
        if adder is None:
            raise _Invalid(f"unknown force type {spec.kind!r}", "spring, force, torque, drag, impulse or field")
        adder(spec)

    def add_spring(self, spec: ForceSpring) -> None:
        a, ra = self.point(spec.end_a)
        if (spec.end_b is None) == (spec.anchor is None):
            raise _Invalid("a spring needs exactly one of a second body end or a world anchor",
                           "anchor: [x, y, z] or bodies: [a, b]")  # fmt: skip
        if spec.end_b is not None:
            b, rb = self.point(spec.end_b)
            if b == a:
                message = f"both ends are on body {spec.end_a.body!r}; a spring inside one rigid body does nothing"
                raise _Invalid(message, "two different bodies")
        else:
            b, rb = WORLD, _vector(spec.anchor, "anchor")
        row = self.spring
        row["body_a"].append(a)
        row["point_a"].append(ra)
        row["body_b"].append(b)
        row["point_b"].append(rb)
        row["stiffness"].append(_scalar(spec.stiffness, "stiffness"))
        row["rest_length"].append(_scalar(spec.rest_length, "rest_length"))
        row["damping"].append(_scalar(spec.damping, "damping"))

    def add_point_force(self, spec: ForceAtPoint) -> None:
        b, r = self.point(spec.at)
        vector, body_frame = self.oriented(b, spec.vector, "vector", spec.frame)
        row = self.point_force
        row["body"].append(b)
        row["point"].append(r)
        row["vector"].append(vector)
        row["body_frame"].append(body_frame)
        row["schedule"].append(self.add_schedule(spec.schedule))

    def add_torque(self, spec: ForceTorque) -> None:
        b = self.body(spec.body)
        vector, body_frame = self.oriented(b, spec.vector, "vector", spec.frame)
        row = self.torque
        row["body"].append(b)
        row["vector"].append(vector)
        row["body_frame"].append(body_frame)
        row["schedule"].append(self.add_schedule(spec.schedule))

    def add_drag(self, spec: ForceDrag) -> None:
        coefficients = [_scalar(getattr(spec, k), k) for k in ("linear", "quadratic", "angular_linear",
                                                               "angular_quadratic")]  # fmt: skip
        bodies = self.bodies(spec.bodies)
        if not any(coefficients):
            return  # a drag of zero touches nothing: no rows
        for b in bodies:
            self.drag["body"].append(b)
            for key, value in zip(("linear", "quadratic", "angular_linear", "angular_quadratic"), coefficients,
                                  strict=True):  # fmt: skip
                self.drag[key].append(value)

    def add_impulse(self, spec: ForceImpulse) -> None:
        b, r = self.point(spec.at)
        vector, body_frame = self.oriented(b, spec.vector, "vector", spec.frame)
        row = self.impulse
        row["body"].append(b)
        row["time"].append(_scalar(spec.time, "time", minimum=None))
        row["vector"].append(vector)
        row["point"].append(r)
        row["body_frame"].append(body_frame)

    def add_field(self, spec: ForceField) -> None:
        if spec.per not in FIELD_PER:
            raise _Invalid(f"per must be one of {FIELD_PER}, got {spec.per!r}", " or ".join(FIELD_PER))
        value = _vector(spec.value, "value")
        gradient = np.zeros((3, 3)) if spec.gradient is None else _vector(spec.gradient, "gradient", (3, 3))
        if spec.origin is not None:  # a(x) = value + G (x - origin) = (value - G origin) + G x
            value = value - gradient @ _vector(spec.origin, "origin")
        schedule = self.add_schedule(spec.schedule)
        for b in self.bodies(spec.bodies):
            row = self.field
            row["body"].append(b)
            row["per_mass"].append(spec.per == "mass")
            row["value"].append(value)
            row["gradient"].append(gradient)
            row["schedule"].append(schedule)

    def tables(
        self, gravity: np.ndarray | None, contact: ContactTable | None = None
    ) -> tuple[ForceTables, KinematicTable]:
        forces = build_force_tables(
            gravity,
            body_count=self.model.body_count,
            schedule=schedule_table(**self.schedule),
            field=field_table(**self.field),
            point_force=point_force_table(**self.point_force),
            torque=torque_table(**self.torque),
            spring=spring_table(**self.spring),
            drag=drag_table(**self.drag),
            impulse=impulse_table(**self.impulse),
            contact=contact,
        )
        return forces, kinematic_table(**self.kinematic)
