"""How fast a scene's contact spheres can meet, and what that asks of the sub-steps and the stiffness
(issue 28 item 3: deep impacts). Numpy, once per scene at compile time.

Speed bound of body b's contact spheres at their first touch. Until then a movable body flies free
under gravity: |v|^2 <= |v0|^2 + 2 g h, and torque-free rotation keeps its energy T_rot = w . L / 2 >=
I_min |w|^2 / 2, so a sphere at rho from the centre of mass moves at |v + w x r| <= |v| + |w| rho:

    movable    sqrt(|v0|^2 + 2 g h) + sqrt(2 T_rot / I_min) rho + 2 u_kin
    kinematic  s_max (|v0| + |w0| (rho + |x0 - p0|))            (its prescribed motion, docs/contact.md)
    static     0

- h is the centre of mass's height above the floor (of the planes, the one facing gravity most
  directly: n . g_hat < 0) measured along gravity, h = n . (x - p0) / (-n . g_hat); with no such plane,
  the depth along gravity of the lowest static or kinematic sphere below it (what it can land on); with
  neither, 0: uniform gravity does not change the relative velocity of two falling bodies.
- u_kin, the fastest kinematic sphere: a hit by a kinematic (infinitely heavy) body moving at u returns
  at most 2 u + v (restitution <= 1).
Why it is safe for the impacts it bounds: before its first contact a body's motion is the free flight
above, exactly. Later impacts stay within it as long as contacts only take energy away (the dashpots and
the Coulomb cap dissipate) and bodies do not hand each other energy. What it does not cover: a bounce
that turns fall into spin (a sphere of a tumbling brick can then move up to sqrt(1 + M rho^2 / I_min)
times faster, which a bound from energy alone would have to assume everywhere), a light body struck by a
heavier one (a stack of balls dropped together returns the top one faster than its fall), a body sliding
down a tilted plane with no wall below, and energy put in by springs, applied forces or fields.

The travel rule of `substeps: auto` (parameters.TRAVEL_FRACTION) takes the largest bound. Two spheres
approach at most at the sum of their bodies' bounds (`approach_speed`: the two largest), a sphere and a
plane at its body's.

Depth of an impact at speed v against a plane or a static body: the linear spring-dashpot compresses
to peak_compression(zeta) v / w (parameters.py), w = sqrt(k / m). The estimate takes the first sphere
to touch as carrying the whole body mass M (its effective mass is at most M, and the next spheres of a
lattice take part only once it is deep), so it is an upper bound until then: a tilted brick landing on
a corner sphere. For a body held by joints, M is its assembly's mass (`assembly_mass`: a ragdoll's arm
lands with the torso behind it; `impact_bound`). It is compared with DEPTH_FRACTION of that sphere's
radius, or for a body that touches planes as its primitive (a box or capsule shape), with DEPTH_FRACTION
of the primitive's size, its first manifold point carrying the whole mass at its per-point stiffness.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rbcli.physics.contact.parameters import DEPTH_FRACTION, peak_compression
from rbcli.physics.contact.tables import ContactTable
from rbcli.physics.model import Model
from rbcli.physics.rotation import quat_to_matrix
from rbcli.physics.state import State
from rbcli.scene.force_specs import Schedule
from rbcli.scene.spec import SceneSpec


@dataclass(frozen=True)
class DeepImpact:
    """The body whose impact at its speed bound goes deepest against DEPTH_FRACTION of its radius."""

    body: str
    speed: float  # [m/s] its speed bound
    depth: float  # [1] the estimated deepest compression / its smallest sphere radius
    stiffness: float  # [N/m] its per-sphere stiffness against a plane
    stiffness_needed: float  # [N/m] the per-sphere stiffness that keeps the estimate at DEPTH_FRACTION r
    speed_taken: float  # [m/s] the fastest impact its stiffness keeps at DEPTH_FRACTION r
    count: int  # how many bodies exceed DEPTH_FRACTION r


@dataclass(frozen=True)
class ImpactBound:
    """What `impact_bound` finds: the largest speed bound (the travel rule of `substeps: auto`), the
    fastest approach and the deepest impact."""

    approach_speed: float  # [m/s] the fastest two contact spheres (or a sphere and a plane) can approach
    radius: float  # [m] the smallest contact sphere radius
    body: str  # the body with the largest speed bound
    speed: float  # [m/s] its bound
    fall: float  # [m] the fall height in it
    deep: DeepImpact | None  # None: every body's estimate is within DEPTH_FRACTION r


def schedule_peak(schedule: Schedule | None) -> float:
    """max |s(t)| over all t of a schedule (None: s = 1)."""
    if schedule is None:
        return 1.0
    if schedule.kind == "piecewise_linear":
        return float(max((abs(v) for v in schedule.values), default=0.0))
    if schedule.kind == "sine":
        return abs(schedule.offset) + abs(schedule.amplitude)
    return abs(schedule.value)


def impact_bound(spec: SceneSpec, model: Model, state: State, table: ContactTable) -> ImpactBound | None:
    """The speed bounds of the module docstring for a compiled scene (None: no contact spheres)."""
    sphere_body = table.sphere_body
    if not sphere_body.shape[0]:
        return None
    radius = np.full(model.body_count, np.inf)
    np.minimum.at(radius, sphere_body, table.sphere_radius)
    assembly = assembly_mass(spec, model)
    shaped = _landing_shapes(model, table, assembly)
    carried = np.where(shaped, assembly, model.body_mass)  # behind an impact: the assembly where it lands so
    clearance = np.where(shaped, _depth_scale(table, radius), 0.0)
    speed, fall, colliding, movable = speed_bounds(spec, model, state, sphere_body, table.sphere_offset,
                                                   table.plane_point, table.plane_normal, clearance)  # fmt: skip
    static = np.array([b.static for b in spec.bodies], dtype=bool)
    fastest = int(np.argmax(speed))
    top = np.sort(speed[colliding & ~static])[::-1]
    approach = float(top[0] + top[1]) if top.shape[0] > 1 else float(top[0]) if top.shape[0] else 0.0
    return ImpactBound(
        approach_speed=approach,
        radius=float(table.sphere_radius.min()),
        body=model.body_names[fastest],
        speed=float(speed[fastest]),
        fall=float(fall[fastest]),
        deep=_deepest(model, table, speed, _depth_scale(table, radius), movable, carried),
    )


def speed_bounds(
    spec: SceneSpec,
    model: Model,
    state: State,
    sphere_body: np.ndarray,
    sphere_offset: np.ndarray,
    plane_point: np.ndarray,
    plane_normal: np.ndarray,
    clearance: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per body: (its contact spheres' speed bound [m/s], its fall height [m], whether it has contact
    spheres, whether it is movable) from the module docstring's rules, given the contact spheres (body,
    offset in the principal frame) and planes: what `impact_bound` reports and what a primitive's default
    stiffness is set from (scene/compile_contact.py). `clearance` [m] per body is taken off its fall: a
    primitive's centre stays at least its smallest size (a box's smallest half extent, a capsule's
    radius) above what it lands on, so a box resting on its face has no fall left."""
    n = model.body_count
    mass = model.body_mass
    colliding = np.zeros(n, dtype=bool)
    colliding[sphere_body] = True
    reach = np.zeros(n)
    if sphere_body.shape[0]:
        np.maximum.at(reach, sphere_body, np.linalg.norm(sphere_offset, axis=1))
    static = np.array([b.static for b in spec.bodies], dtype=bool)
    kinematic = np.array([b.kinematic for b in spec.bodies], dtype=bool)
    movable = colliding & ~static & ~kinematic
    with np.errstate(all="ignore"):  # huge initial states are refused elsewhere; here they give inf
        v0 = np.linalg.norm(state.P, axis=1) / mass
        # w0 and T_rot = w0 . L0 / 2 in the principal frame: m = R^T L, w = m / I
        m = np.einsum("kji,kj->ki", quat_to_matrix(state.q), state.L)
        w0 = np.linalg.norm(m / model.body_inertia, axis=1)
        rotation = 0.5 * np.sum(m * m / model.body_inertia, axis=1)
        fall = _fall_height(spec, model, state, sphere_body, sphere_offset, plane_point, plane_normal,
                            static | kinematic)  # fmt: skip
        if clearance is not None:
            fall = np.maximum(0.0, fall - clearance)
        g = float(np.linalg.norm(spec.gravity)) if spec.gravity is not None else 0.0
        speed = np.sqrt(v0 * v0 + 2.0 * g * fall) + np.sqrt(2.0 * rotation / model.body_inertia.min(axis=1)) * reach
    for b, body in enumerate(spec.bodies):  # kinematic bodies only: a handful per scene
        if not body.kinematic:
            continue
        motion = body.kinematic_motion
        if motion is None:  # kinematic: true keeps its initial motion about its centre of mass
            speed[b] = v0[b] + w0[b] * reach[b]
        else:
            arm = 0.0 if motion.pivot is None else float(np.linalg.norm(state.x[b] - motion.pivot))
            peak = schedule_peak(motion.schedule)
            speed[b] = peak * (
                np.linalg.norm(motion.velocity) + np.linalg.norm(motion.angular_velocity) * (reach[b] + arm)
            )
    kinematic_top = float(speed[kinematic & colliding].max()) if (kinematic & colliding).any() else 0.0
    speed[movable] += 2.0 * kinematic_top
    speed[~colliding | static] = 0.0
    return speed, fall, colliding, movable


def _landing_shapes(model: Model, table: ContactTable, assembly: np.ndarray) -> np.ndarray:
    """bool per body: the bodies whose default stiffness follows their landing (scene/compile_contact.py):
    primitives, and bodies that touch through spheres held by joints (`landing_spheres`; `assembly`: the
    masses of `assembly_mass`). Their fall ends at their size."""
    kind = table.primitive_kind
    primitive = kind >= 0 if kind.shape[0] else np.zeros(model.body_count, dtype=bool)
    return primitive | landing_spheres(assembly, model.body_mass, primitive)


def landing_spheres(carried: np.ndarray, mass: np.ndarray, primitive: np.ndarray) -> np.ndarray:
    """bool per body: a body that touches through contact spheres (not a `primitive`: a `sphere` shape's
    one exact sphere, a particle cloud's spheres, a mesh's or a shape's lattice with `primitives: false`)
    held by joints to other movable bodies. It takes the landing rule as a primitive does, its smallest
    sphere's radius as its size: it lands with its assembly behind it (with the rest rule the capsule
    ragdoll's head sank 0.16 of its radius, the particle ragdoll's arms 0.74 of theirs, unwarned). A body
    not held so keeps the rest rule: the piles' balls and clouds are stepped as they were."""
    return ~np.asarray(primitive, dtype=bool) & (np.asarray(carried) > np.asarray(mass))


def assembly_mass(spec: SceneSpec, model: Model) -> np.ndarray:
    """[kg] per body, the mass an impact of it may carry: its own, or for a body held by joints to other
    movable bodies, the whole assembly's (the bodies its joints connect it to, through any chain of them;
    static and kinematic bodies and the world end a chain). A ragdoll's arm lands with the torso behind
    it: measured on a capsule ragdoll dropped 1 m, stiffness set from the arm's own 2.5 kg let it sink
    0.96 of its radius."""
    n = model.body_count
    parent = list(range(n))

    def root(b: int) -> int:
        while parent[b] != b:
            parent[b] = parent[parent[b]]
            b = parent[b]
        return b

    index = {name: i for i, name in enumerate(model.body_names)}
    held = {i for i, body in enumerate(spec.bodies) if body.static or body.kinematic}
    for joint in spec.joints:
        ends = [index.get(name, -1) for name in joint.bodies]
        if len(ends) == 2 and all(e >= 0 and e not in held for e in ends):
            parent[root(ends[0])] = root(ends[1])
    roots = np.array([root(b) for b in range(n)])
    total = np.zeros(n)
    np.add.at(total, roots, model.body_mass)
    return total[roots]


def _fall_height(spec: SceneSpec, model: Model, state: State, sphere_body: np.ndarray, sphere_offset: np.ndarray,
                 point: np.ndarray, normal: np.ndarray, held: np.ndarray) -> np.ndarray:  # fmt: skip
    """h per body [m] (module docstring): the height above the floor along gravity, or the depth of the
    lowest held (static or kinematic) sphere below it; 0 without gravity or anything to land on."""
    n = model.body_count
    if spec.gravity is None or not np.linalg.norm(spec.gravity) > 0.0:
        return np.zeros(n)
    down = np.asarray(spec.gravity, dtype=float) / np.linalg.norm(spec.gravity)
    if normal.shape[0]:
        up = -(normal @ down)
        p = int(np.argmax(up))
        if up[p] > 1e-9:
            return np.maximum(0.0, (state.x - point[p]) @ normal[p]) / up[p]
    spheres = np.flatnonzero(held[sphere_body])
    if not spheres.shape[0]:
        return np.zeros(n)
    body = sphere_body[spheres]
    world = state.x[body] + np.einsum("kij,kj->ki", quat_to_matrix(state.q[body]), sphere_offset[spheres])
    lowest = float((world @ down).max())  # the deepest held sphere along gravity
    return np.maximum(0.0, lowest - state.x @ down)


def _depth_scale(table: ContactTable, radius: np.ndarray) -> np.ndarray:
    """[m] per body, what an impact's depth is compared with: its smallest contact sphere radius, or for a body
    that touches planes as its primitive the primitive's size (a box's smallest half extent, a capsule's
    radius: the size its default stiffness is set from, scene/compile_contact.py)."""
    kind = table.primitive_kind
    if not kind.shape[0] or not (kind >= 0).any():
        return radius
    size = table.primitive_size
    scale = np.where(kind == 2, size.min(axis=1), size[:, 0])
    return np.where(kind >= 0, scale, radius)


def _deepest(model: Model, table: ContactTable, speed: np.ndarray, radius: np.ndarray,
             movable: np.ndarray, carried: np.ndarray) -> DeepImpact | None:  # fmt: skip
    """The estimated impact depth per movable body against a plane or a static body (module docstring),
    the body carrying `carried` [kg] (its assembly's mass: `assembly_mass`)."""
    bodies = np.flatnonzero(movable & (speed > 0.0))
    if not bodies.shape[0]:
        return None
    k = table.body_plane_stiffness[bodies]
    if not table.plane_point.shape[0]:
        k = table.body_stiffness[bodies]
    shape = np.array([peak_compression(float(z)) for z in table.body_damping_ratio[bodies]])
    mass = carried[bodies]
    with np.errstate(all="ignore"):
        depth = shape * speed[bodies] * np.sqrt(mass / k) / radius[bodies]
    deep = depth > DEPTH_FRACTION
    if not deep.any():
        return None
    worst = int(np.argmax(np.where(deep, depth, -np.inf)))
    b = int(bodies[worst])
    with np.errstate(all="ignore"):
        needed = float(mass[worst] * (shape[worst] * speed[b] / (DEPTH_FRACTION * radius[b])) ** 2)
        taken = float(DEPTH_FRACTION * radius[b] * math.sqrt(k[worst] / mass[worst]) / shape[worst])
    return DeepImpact(
        body=model.body_names[b],
        speed=float(speed[b]),
        depth=float(depth[worst]),
        stiffness=float(k[worst]),
        stiffness_needed=needed,
        speed_taken=taken,
        count=int(deep.sum()),
    )
