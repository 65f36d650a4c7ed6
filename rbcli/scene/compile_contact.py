"""A scene's contact section and bodies' contact keys compiled into a ContactTable, plus its stable step.

Contact spheres per body (physics/contact/tables.py), placed in the principal frame about the centre
of mass like every body point (r = E^T (p_user - centre_user)):
    sphere    one sphere of the shape's radius at the body origin: the exact surface
    lattice   the lattice particles with fewer than 6 lattice neighbours (the surface shell; interior
              particles could only touch anything after a deep, already failed, penetration)
    particles every particle with its own radius
Materials: the body's keys over `contact.material` over the defaults (restitution 0.5, friction 0.5,
stiffness from the body's weight, physics/contact/parameters.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rbcli.physics.contact.parameters import (
    DEFAULT_FRICTION,
    DEFAULT_RESTITUTION,
    IMPACT_DEPTH,
    PENETRATION_AT_REST,
    damping_ratio_for_restitution,
    default_body_stiffness,
    peak_compression,
    plane_stiffness,
    stable_step,
    support_count,
)
from rbcli.physics.contact.tables import ContactTable, contact_table, touching_spheres
from rbcli.physics.forces.tables import ScheduleTable, schedule_values_numpy
from rbcli.physics.kinematic_reference import kinematic_state_numpy
from rbcli.physics.model import Model
from rbcli.physics.rotation import quat_to_matrix
from rbcli.physics.state import State
from rbcli.scene.compile_forces import KinematicRow
from rbcli.scene.contact_speed import ImpactBound, assembly_mass, landing_spheres, speed_bounds
from rbcli.scene.force_specs import (
    ForceAtPoint,
    ForceDrag,
    ForceField,
    ForceImpulse,
    ForceSpring,
    ForceTorque,
    Schedule,
)
from rbcli.scene.joint_spec import WORLD_NAME
from rbcli.scene.spec import BodySpec, MaterialSpec, SceneError, SceneIssue, SceneSpec


@dataclass(frozen=True)
class ContactSummary:
    """What compiling the contacts found, for warnings, sub-steps and `rbsim info`."""

    sphere_count: int
    plane_count: int
    static_count: int
    kinematic_count: int
    stable_step: float  # [s] dt_crit of the stiffest, lightest contact (inf: nothing can collide)
    limiting_body: str  # the body that sets it
    stiffness: float  # [N/m] that body's per-sphere stiffness
    impact: ImpactBound | None = None  # how fast spheres can meet (scene/contact_speed.py), set by compile_model
    boxes: int = 0  # shape bodies that touch planes and walls as their exact box (compile_primitives)
    capsules: int = 0  # ... as their exact capsule
    shape_spheres: int = 0  # the lattice spheres of those shape bodies: their mass only, they touch nothing

    def describe(self, substeps: int | None = None, implicit: bool = False) -> str:
        """One line for `rbsim validate` and the run summary; implicit: the integrator's contact is
        implicit (reduced-implicit), so the explicit stable step does not bound its step."""
        planes = f"{self.plane_count} plane" + "s" * (self.plane_count != 1)
        kinds = (("box", "boxes", self.boxes), ("capsule", "capsules", self.capsules))
        shapes = " and ".join(f"{n} {one if n == 1 else many}" for one, many, n in kinds if n)
        spheres = self.sphere_count - self.shape_spheres  # a shape's lattice spheres are its mass only
        parts = [f"{spheres:,} contact spheres"] if spheres or not shapes else []
        if shapes:  # (docs/contact.md "Primitive contact")
            one = self.boxes + self.capsules == 1
            touch = "it touches" if one else "they touch"
            parts.append(f"{shapes} ({touch} planes, walls and bodies as {'its' if one else 'their'} exact shape"
                         f"{'' if one else 's'})")  # fmt: skip
        text = f"contact: {', '.join(parts)}, {planes}"
        if self.static_count:
            text += f", {self.static_count} static bod" + ("y" if self.static_count == 1 else "ies")
        if self.kinematic_count:
            text += f", {self.kinematic_count} kinematic bod" + ("y" if self.kinematic_count == 1 else "ies")
        if math.isfinite(self.stable_step):
            text += f"; stable step {self.stable_step:.3g} s (body '{self.limiting_body}')"
            text += " of an explicit step (this integrator's contact is implicit: no bound)" if implicit else ""
        if substeps is not None and substeps > 1:
            text += f"; {substeps} sub-steps per step"
        return text


def lattice_surface(points: np.ndarray, spacing: float) -> np.ndarray:
    """Indices of the lattice points that miss at least one of their 6 neighbours at `spacing`."""
    cells = np.rint((points - points.min(axis=0)) / spacing).astype(np.int64)
    span = cells.max(axis=0) + 3  # room for the +-1 neighbours without wrapping
    cells += 1

    def key(c: np.ndarray) -> np.ndarray:
        return (c[:, 2] * span[1] + c[:, 1]) * span[0] + c[:, 0]

    present = np.sort(key(cells))
    surface = np.zeros(len(points), dtype=bool)
    for axis in range(3):
        for step in (-1, 1):
            shifted = cells.copy()
            shifted[:, axis] += step
            k = key(shifted)
            at = np.clip(np.searchsorted(present, k), 0, len(present) - 1)
            surface |= present[at] != k
    return np.flatnonzero(surface)


def spheres_of(
    body: BodySpec, model: Model, b: int, centre: np.ndarray, E: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """(offsets in the principal frame (k, 3), radii (k,)) of body b's contact spheres; E is its
    user-from-principal rotation."""
    if body.contact_spheres is not None:  # a welded body: its parts' own spheres (scene/welds.py)
        centres, radii = body.contact_spheres
        return (centres - centre) @ E, np.asarray(radii, dtype=float)
    if body.contact_geometry == "sphere":
        return ((np.zeros(3) - centre) @ E)[None, :], np.array([body.contact_size])
    start, count = int(model.body_particle_start[b]), int(model.body_particle_count[b])
    offsets = model.particle_offset[start : start + count]
    radii = np.asarray(body.particle_radius, dtype=float)
    if body.contact_geometry == "lattice":
        keep = lattice_surface(np.asarray(body.particle_position, dtype=float), body.contact_size)
        return offsets[keep], radii[keep]
    return offsets, radii


def compile_contact(
    spec: SceneSpec, model: Model, centres_user: np.ndarray, state: State
) -> tuple[ContactTable, ContactSummary]:
    """The ContactTable of a scene with a `contact:` section (spec.contact is not None), from the initial
    `state` too (a primitive's default stiffness follows its speed bound: `compile_primitives`)."""
    contact = spec.contact
    assert contact is not None
    n = model.body_count
    base = contact.material.over(MaterialSpec(None, DEFAULT_RESTITUTION, DEFAULT_FRICTION))
    with np.errstate(over="ignore"):  # an absurd gravity (1e300) overflows to inf: refused below, no warning
        g = float(np.linalg.norm(spec.gravity)) if spec.gravity is not None else 0.0
    sphere_body, offsets, radii = [], [], []
    stiffness = np.zeros(n)
    zeta = np.zeros(n)
    friction = np.zeros(n)
    support = np.ones(n)
    plane_k = np.zeros(n)
    min_radius = np.full(n, np.inf)
    ratio_cache: dict[float, float] = {}
    frames = quat_to_matrix(model.body_frame_q)  # user-from-principal, all bodies in one call
    # (support, rest) per distinct sphere set: a pile of identical bodies counts its layers once
    support_cache: dict[bytes, tuple[int, int]] = {}

    def damping_ratio(e: float) -> float:  # a bisection per distinct restitution, not per body
        if e not in ratio_cache:
            ratio_cache[e] = damping_ratio_for_restitution(e)
        return ratio_cache[e]

    for b, body in enumerate(spec.bodies):
        material = body.material.over(base)
        assert material.restitution is not None and material.friction is not None
        e = material.restitution
        zeta[b] = damping_ratio(e)
        friction[b] = material.friction
        if not body.collide:
            continue
        off, rad = spheres_of(body, model, b, centres_user[b], frames[b])
        sphere_body.append(np.full(len(rad), b))
        offsets.append(off)
        radii.append(rad)
        min_radius[b] = float(rad.min())
        key = off.tobytes() + b"|" + rad.tobytes() + b"|" + frames[b].tobytes()
        if key not in support_cache:
            support_cache[key] = (
                support_count(off, rad, E=frames[b]),
                support_count(off, rad, E=frames[b], tolerance=PENETRATION_AT_REST * min_radius[b]),
            )
        support[b], rest = support_cache[key]
        if material.stiffness is not None:
            stiffness[b] = material.stiffness
        else:
            with np.errstate(all="ignore"):
                stiffness[b] = float(default_body_stiffness(model.body_mass[b : b + 1], min_radius[b : b + 1], g)[0])
            stiffness[b] /= support[b]
            if not 0.0 < stiffness[b] < math.inf:
                # found by fuzzing: gravity 9.8e300 gave k = inf, numpy warnings on the terminal and NaN forces
                message = (
                    f"body '{body.name}': its contact stiffness, from its mass {model.body_mass[b]:.4g} kg, sphere "
                    f"radius {min_radius[b]:.4g} m and gravity {g:.4g} m/s^2, is {stiffness[b]:.4g} N/m, not a "
                    "positive finite number"
                )
                expected = "masses, sizes and gravity in SI units, or a material stiffness"
                raise SceneError([SceneIssue(body.location, message, expected)])
        plane_k[b] = stiffness[b]
        if material.stiffness is None:  # carried at rest by fewer spheres than `support` (parameters.py)
            plane_k[b] = plane_stiffness(stiffness[b], int(support[b]), rest)
    planes = contact.planes
    plane_point = np.array([p.point for p in planes], dtype=float).reshape(-1, 3)
    plane_normal = np.array([p.normal for p in planes], dtype=float).reshape(-1, 3)
    all_body = np.concatenate(sphere_body) if sphere_body else np.zeros(0, dtype=np.int64)
    all_offset = np.concatenate(offsets) if offsets else np.zeros((0, 3))
    primitive = compile_primitives(spec, model, centres_user, frames, np.asarray([len(r) for r in radii]),
                                   [b for b, body in enumerate(spec.bodies) if body.collide], g)  # fmt: skip
    # the landing rule (compile_primitives' docstring): the speed bounds, a shape's fall ending at its size
    carried = assembly_mass(spec, model)
    exact = landing_spheres(carried, model.body_mass, primitive.kind >= 0)
    size = np.where(primitive.kind >= 0, primitive.scale, np.where(exact, min_radius, 0.0))
    speed = speed_bounds(spec, model, state, all_body, all_offset, plane_point, plane_normal, size)[0]
    for b in range(n):
        if spec.bodies[b].material.over(base).stiffness is not None:
            continue
        if primitive.kind[b] >= 0:
            landing = impact_stiffness(carried[b], speed[b], zeta[b], primitive.scale[b])
            primitive.stiffness[b] = max(primitive.stiffness[b], landing)
        elif exact[b]:  # spheres held by joints: the first to touch lands as a primitive's point does
            landing = impact_stiffness(carried[b], speed[b], zeta[b], min_radius[b])
            stiffness[b] = max(stiffness[b], landing)
            plane_k[b] = max(plane_k[b], landing)
    for b in np.flatnonzero(primitive.kind >= 0).tolist():  # planes touch its primitive, its own stiffness
        material = spec.bodies[b].material.over(base)
        plane_k[b] = material.stiffness if material.stiffness is not None else primitive.stiffness[b]
        # and so do other bodies (primitive_search.py): per manifold point, its points sharing 1 / M
        stiffness[b] = plane_k[b]
    colliding = np.isfinite(min_radius)
    stiffness[~colliding] = plane_k[~colliding] = (
        1.0  # never used: such a body has no spheres; keeps the pair formula finite
    )
    # static and kinematic bodies: infinite mass for contact, their wrench held at zero (they keep P and L)
    static = np.array([b.static or b.kinematic for b in spec.bodies], dtype=bool)
    inv_mass = np.where(static, 0.0, np.where(primitive.kind >= 0, 1.0, support) / model.body_mass)
    # what carries it on another body and on a plane: a primitive's manifold points (its lattice spheres
    # touch nothing: the stable step is its own), a cloud's supporting spheres
    pair_support = np.where(primitive.kind >= 0, primitive.points, support)
    plane_support = pair_support
    plane_zeta = [damping_ratio(e)
                  for e in (p.material.over(base).restitution or DEFAULT_RESTITUTION for p in planes)]  # fmt: skip
    movable = colliding & ~static
    with np.errstate(all="ignore"):  # a huge stiffness over a tiny mass: dt_crit 0 (a warning of its own)
        pair_k = stiffness * pair_support
        dt_crit, worst = stable_step(model.body_mass, pair_k, np.where(colliding, zeta, 0.0), movable,
                                     planes=bool(planes), plane_stiffness=plane_k * plane_support)  # fmt: skip
    table = contact_table(
        sphere_body=all_body,
        sphere_offset=all_offset,
        sphere_radius=np.concatenate(radii) if radii else [],
        body_inv_contact_mass=inv_mass,
        body_stiffness=stiffness,
        body_plane_stiffness=plane_k,
        body_damping_ratio=zeta,
        body_friction=friction,
        static_body=np.flatnonzero(static),
        plane_point=plane_point,
        plane_normal=plane_normal,
        plane_damping_ratio=plane_zeta,
        plane_friction=[p.material.over(base).friction for p in planes],
        stable_step=dt_crit,
        body_plane_inv_contact_mass=np.where(static, 0.0, plane_support / model.body_mass),
        primitive_kind=primitive.kind,
        primitive_offset=primitive.offset,
        primitive_rotation=primitive.rotation,
        primitive_size=primitive.size,
        body_steady_accel=steady_accelerations(spec, model),
    )
    summary = ContactSummary(
        sphere_count=int(table.sphere_radius.shape[0]),
        plane_count=len(planes),
        static_count=int(sum(b.static for b in spec.bodies)),
        kinematic_count=int(sum(b.kinematic for b in spec.bodies)),
        stable_step=dt_crit,
        limiting_body=model.body_names[worst] if worst >= 0 else "",
        stiffness=float(stiffness[worst]) if worst >= 0 else math.nan,
        boxes=int(np.count_nonzero(primitive.kind == PRIMITIVE_BOX)),
        capsules=int(np.count_nonzero(primitive.kind == PRIMITIVE_CAPSULE)),
        shape_spheres=int(table.sphere_radius.shape[0]) - touching_spheres(table),
    )
    return table, summary


def _constant(schedule: Schedule | None) -> float | None:
    """The factor of a schedule that is the same at every time (None: none, 1), else None."""
    if schedule is None:
        return 1.0
    if schedule.kind == "constant" and schedule.start == -math.inf and schedule.stop == math.inf:
        return schedule.value
    return None


def steady_accelerations(spec: SceneSpec, model: Model) -> np.ndarray:
    """|a_b| [m/s^2] (body_count,) of each body whose linear acceleration is the same at every time and in
    every state, for the quiet skin's sure windows (contact/quiet.py): gravity, world-frame forces and
    `per: mass` fields of constant strength (no schedule, or a constant one for all time), any torque. 0
    for a static body and a kinematic one that keeps its initial velocity; inf for a body that anything
    else moves: a spring, drag, another field, a force that turns with the body or follows a schedule, an
    impulse, a joint, a prescribed motion, a term of a kind not known here. (Contact forces are the
    quiet's own question: it holds only while none can act.)"""
    n = model.body_count
    index = {name: b for b, name in enumerate(model.body_names)}
    gravity = np.zeros(3) if spec.gravity is None else np.asarray(spec.gravity, dtype=float)
    accel = np.tile(gravity, (n, 1))
    unsteady = np.zeros(n, dtype=bool)

    def bodies(names: tuple[str, ...] | None) -> list[int] | None:  # None: a name not known here
        if names is None:
            return list(range(n))
        found = [index.get(name) for name in names if name != WORLD_NAME]
        return None if None in found else [b for b in found if b is not None]

    for term in spec.forces:
        factor = _constant(getattr(term, "schedule", None))
        if isinstance(term, ForceTorque):
            continue
        if isinstance(term, ForceAtPoint) and term.frame == "world" and factor is not None:
            which = bodies((term.at.body,))
            if which is not None:
                for b in which:
                    accel[b] += factor * np.asarray(term.vector, dtype=float) / model.body_mass[b]
                continue
        elif isinstance(term, ForceField) and term.per == "mass" and term.gradient is None and factor is not None:
            which = bodies(term.bodies)
            if which is not None:
                accel[which] += factor * np.asarray(term.value, dtype=float)
                continue
        else:
            known, touched = _bodies_of(term)
            which = bodies(touched) if known else None
            if which is not None:
                unsteady[which] = True
                continue
        unsteady[:] = True  # a term whose bodies are not known here: no body is sure
    for joint in spec.joints:
        which = bodies(tuple(joint.bodies))
        if which is None:
            unsteady[:] = True
        else:
            unsteady[which] = True
    for b, body in enumerate(spec.bodies):
        if body.static or (body.kinematic and body.kinematic_motion is None):
            accel[b], unsteady[b] = 0.0, False
        elif body.kinematic:
            unsteady[b] = True
    with np.errstate(over="ignore"):
        size = np.linalg.norm(accel, axis=1)
    return np.where(unsteady | ~np.isfinite(size), math.inf, size)


def _bodies_of(term: object) -> tuple[bool, tuple[str, ...] | None]:
    """(whether this kind of force term is known here, the bodies it acts on: None, every body)."""
    if isinstance(term, ForceSpring):
        return True, tuple(end.body for end in (term.end_a, term.end_b) if end is not None)
    if isinstance(term, (ForceDrag, ForceField)):
        return True, term.bodies
    if isinstance(term, (ForceAtPoint, ForceImpulse)):
        return True, (term.at.body,)
    return False, None


@dataclass(frozen=True)
class Primitives:
    """The bodies' primitives for ContactTable (kind -1: none), each one's plane stiffness per manifold
    point by default [N/m] (the rest rule; compile_contact raises it to the landing rule), the points it
    rests on and its size scale [m] (a box's smallest half extent, a capsule's radius) (`compile_primitives`)."""

    kind: np.ndarray
    offset: np.ndarray
    rotation: np.ndarray
    size: np.ndarray
    stiffness: np.ndarray
    points: np.ndarray
    scale: np.ndarray


# primitives.PRIMITIVE_CAPSULE, PRIMITIVE_BOX (not imported: `rbsim validate` imports no numba; tested equal)
PRIMITIVE_CAPSULE, PRIMITIVE_BOX = 1, 2
# a capsule along user axis x, y or z: its frame's columns (its local z is the axis), right-handed
_CAPSULE_FRAMES = (np.eye(3)[:, [1, 2, 0]], np.eye(3)[:, [2, 0, 1]], np.eye(3))


def compile_primitives(spec: SceneSpec, model: Model, centres_user: np.ndarray, frames: np.ndarray,
                       sphere_counts: np.ndarray, colliding: list[int], g: float) -> Primitives:  # fmt: skip
    """Each box and capsule shape body's primitive (docs/contact.md "Primitive contact"), in a scene with
    contact (`contact.primitives`, the default): its centre and axes in the principal frame
    (r = E^T (p_user - centre_user), R = E^T R_user), its size (box: half extents; capsule: radius,
    half-length) and its stiffness from geometry, per manifold point, the larger of two rules (the
    second applied by `compile_contact`, which knows the speed bounds):
    - at rest on its `points` manifold points (a box on a face 4, a lying capsule 2) it sinks
      PENETRATION_AT_REST of its size (box: its smallest half extent; capsule: its radius),
      k = M g / (PENETRATION_AT_REST size) / points, as a sphere sinks that fraction of its radius;
    - landing at its speed bound v with the mass m it carries (its assembly's) on one point, the clamped
      spring-dashpot goes no deeper than IMPACT_DEPTH of its size:
      k = m (peak_compression(zeta) v / (IMPACT_DEPTH size))^2 (physics/contact/parameters.py).
    A body with fewer contact spheres than its features (a box's 8 vertices: each feature keeps its
    tangential spring in the history row of one of the body's spheres) keeps its spheres."""
    n = model.body_count
    out = Primitives(np.full(n, -1, dtype=np.int64), np.zeros((n, 3)), np.tile(np.eye(3), (n, 1, 1)),
                     np.zeros((n, 3)), np.zeros(n), np.ones(n), np.zeros(n))  # fmt: skip
    contact = spec.contact
    if contact is None or not contact.primitives:
        return out
    for row, b in enumerate(colliding):
        body = spec.bodies[b]
        if body.contact_primitive is None or body.contact_spheres is not None:
            continue
        name, size = body.contact_primitive
        if name == "box":
            kind, features, points, scale = PRIMITIVE_BOX, 8, 4, min(size)
            rotation, extent = np.eye(3), np.asarray(size, dtype=float)
        else:
            kind, features, points, scale = PRIMITIVE_CAPSULE, 2, 2, size[0]
            rotation, extent = _CAPSULE_FRAMES[int(size[2])], np.array([size[0], size[1], 0.0])
        if sphere_counts[row] < features:
            continue
        E = frames[b]
        out.kind[b] = kind
        out.offset[b] = (np.zeros(3) - centres_user[b]) @ E
        out.rotation[b] = E.T @ rotation
        out.size[b] = extent
        out.points[b] = points
        out.scale[b] = scale
        with np.errstate(all="ignore"):
            k_body = float(default_body_stiffness(model.body_mass[b : b + 1], np.array([scale]), g)[0])
        out.stiffness[b] = k_body / points
    return out


def impact_stiffness(carried: float, speed: float, zeta: float, size: float) -> float:
    """[N/m] The stiffness of one contact point that stops `carried` [kg] landing on it at `speed` [m/s]
    within IMPACT_DEPTH of `size` [m]: the clamped spring-dashpot's deepest compression is
    peak_compression(zeta) v sqrt(m / k) (physics/contact/parameters.py), so
    k = m (peak_compression(zeta) v / (IMPACT_DEPTH size))^2; 0 for a body that cannot move."""
    with np.errstate(all="ignore"):
        landing = peak_compression(float(zeta)) * float(speed) / (IMPACT_DEPTH * float(size))
        k = float(carried) * landing * landing
    return k if math.isfinite(k) else 0.0


def kinematic_rows(spec: SceneSpec, model: Model, state: State) -> list[KinematicRow]:
    """The prescribed motion of each kinematic body (physics/kinematic.py) from its spec and
    initial state: `kinematic: true` keeps its initial velocity and angular velocity (v0 = P / M,
    w0 = L / I: isotropic) about its centre of mass; `kinematic: {...}` gives v0, w0, a pivot and a schedule."""
    rows = []
    for b, body in enumerate(spec.bodies):
        if not body.kinematic:
            continue
        x0 = state.x[b].copy()
        motion = body.kinematic_motion
        if motion is None:
            v0, w0 = state.P[b] / model.body_mass[b], state.L[b] / model.body_inertia[b, 0]
            pivot, schedule = x0, None
        else:
            v0, w0, schedule = motion.velocity, motion.angular_velocity, motion.schedule
            pivot = x0 if motion.pivot is None else motion.pivot
        rows.append(KinematicRow(b, np.array(v0, dtype=float), np.array(w0, dtype=float), np.array(pivot, dtype=float),
                                 x0, state.q[b].copy(), schedule, body.location))  # fmt: skip
    return rows


def kinematic_initial_state(model: Model, schedule: ScheduleTable, state: State) -> None:
    """Set the kinematic bodies' P and L (the model's kinematic table; its schedules are rows of the
    force terms' `schedule`) to their prescribed motion at t = 0 (s(0) scales it)."""
    table = model.kinematic
    if not table.body.shape[0]:
        return
    rate = schedule_values_numpy(schedule, table.schedule, 0.0)
    body = table.body
    _, _, P, L = kinematic_state_numpy(table, np.zeros(len(body)), rate, model.body_mass[body],
                                       model.body_inertia[body, 0])  # fmt: skip
    state.P[body] = P
    state.L[body] = L
