"""Welds merged at compile time: bodies joined by `fixed` joints become one rigid body (docs/joints.md,
"Welds"), as MuJoCo treats bodies welded without a joint and Bullet and PhysX build compound shapes.

The connected components of the `fixed`-joint graph (union-find, the world a vertex too) are the
simulated bodies. A component of several parts is one BodySpec of all their particles, given in the
world frame at t = 0 (its own frame: orientation 1, its particles where the parts put them, in part
order), so its mass, centre of mass and inertia are those of one body of all those particles, to the bit
of a body written by hand the same way. Its initial state keeps the parts' total momenta:
P = sum P_i and L = sum (L_i + (x_i - x) x P_i) about its centre of mass x; parts whose initial
velocities are not one rigid motion are welded as an inelastic weld would weld them (a warning says how
much kinetic energy that takes). A component welded to the world, or holding a static body, is static;
one holding a kinematic body moves as that body is prescribed to.

Everything that named a part is re-expressed on its simulated body, exactly: joint ends, anchors and
axes, contact spheres, points, vectors and particles of force terms; joints and springs with both ends
on one welded body hold nothing and are left out (a warning). Two things are not exact, each warned:
drag acts at each body's centre of mass with its velocity, so a welded part's drag becomes drag on its
body (its coefficients added: exact for the angular terms and for a translating body, the force that a
rotation gives an offset part and its moment are not represented); and contact materials are per body,
so a welded body takes its first part's material. A field on some parts of a welded body is a point
force on each (exact for a uniform field; a gradient on some parts is refused).

compile.py builds the parts' own model and initial state and calls `merge_welds`; the PartView it
returns maps the simulated bodies back to the parts for every output (scene/parts.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from rbcli.physics.joints.tables import WORLD
from rbcli.physics.model import Model, mass_properties
from rbcli.physics.rotation import quat_conjugate, quat_multiply, quat_to_matrix
from rbcli.physics.state import State
from rbcli.scene.compile_contact import spheres_of
from rbcli.scene.force_specs import (
    BodyPoint,
    ForceAtPoint,
    ForceDrag,
    ForceField,
    ForceImpulse,
    ForceSpring,
    ForceTorque,
)
from rbcli.scene.joint_spec import WORLD_NAME, JointSpec
from rbcli.scene.parts import PartView
from rbcli.scene.spec import BodySpec, ForceSpec, KinematicSpec, SceneError, SceneIssue, SceneSpec

# initial velocities of welded parts that differ from one rigid motion by more than this fraction of
# their speed scale are worth a warning (the weld absorbs the difference): far above round-off
RIGID_TOLERANCE = 1e-9


@dataclass(frozen=True)
class WeldMerge:
    """The simulated scene of a scene with welds, and what maps it back to the parts.

    spec: the scene with every welded component one body (BodySpecs, joints and forces re-expressed).
    components: per simulated body, its parts (scene body indices, ascending).
    roots: per simulated body, the part its spanning tree of welds starts from (WORLD: the world).
    joint_table_index, joint_parts, weld_joint: PartView's.
    warnings: what the merge could not keep exactly, and the welds' inelastic start.
    """

    spec: SceneSpec
    components: tuple[tuple[int, ...], ...]
    roots: tuple[int, ...]
    joint_table_index: np.ndarray
    joint_parts: np.ndarray
    weld_joint: np.ndarray
    warnings: tuple[SceneIssue, ...]


def has_welds(spec: SceneSpec) -> bool:
    return any(joint.kind == "fixed" for joint in spec.joints)


def constraint_joints(spec: SceneSpec) -> bool:
    """True when the scene has joints that stay constraints after welds are merged (not only `fixed`)."""
    return any(joint.kind != "fixed" for joint in spec.joints)


def _components(spec: SceneSpec) -> tuple[list[list[int]], list[bool]]:
    """The welded components (scene body indices, in order of their first part) and whether each holds the
    world: union-find over the `fixed` joints, the world the vertex len(bodies)."""
    n = len(spec.bodies)
    index = {b.name: i for i, b in enumerate(spec.bodies)}
    parent = list(range(n + 1))

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for joint in spec.joints:
        if joint.kind == "fixed":
            a, b = (n if name == WORLD_NAME else index[name] for name in joint.bodies)
            ra, rb = find(a), find(b)
            if ra != rb:
                parent[max(ra, rb)] = min(ra, rb)
    groups: dict[int, list[int]] = {}
    for i in range(n):
        groups.setdefault(find(i), []).append(i)
    world = find(n)
    ordered = sorted(groups.items(), key=lambda item: item[1][0])
    return [members for _, members in ordered], [root == world for root, _ in ordered]


def merge_welds(spec: SceneSpec, parts: Model, centres: np.ndarray, state: State) -> WeldMerge:
    """The simulated scene of `spec` (which has welds): parts: the scene's bodies as bodies of their own
    (compile.py build_model, kinematic bodies isotropic), centres: their centres of mass in their user
    frames, state: their initial state. SceneError for what cannot be merged."""
    components, world = _components(spec)
    merger = _Merger(spec, parts, centres, state, components)
    bodies, roots, issues = [], [], []
    for members, welded_to_world in zip(components, world, strict=True):
        try:
            body, root = merger.body(members, welded_to_world)
        except _Invalid as exc:
            issues.append(SceneIssue(spec.bodies[members[0]].location, str(exc), exc.expected))
            continue
        bodies.append(body)
        roots.append(root)
    joints, table_index, joint_parts = merger.joints()
    forces = merger.forces()
    issues += merger.errors
    if issues:
        raise SceneError(issues)
    merged = replace(spec, bodies=tuple(bodies), joints=tuple(joints), forces=tuple(forces), compiled_model=None,
                     warnings=())  # fmt: skip
    welds = np.array([j for j, joint in enumerate(spec.joints) if joint.kind == "fixed"], dtype=np.int64)
    return WeldMerge(merged, tuple(map(tuple, components)), tuple(roots), table_index, joint_parts, welds,
                     tuple(merger.warnings))  # fmt: skip


class _Invalid(Exception):
    def __init__(self, message: str, expected: str = ""):
        super().__init__(message)
        self.expected = expected


class _Merger:
    """Builds the simulated scene's bodies, joints and forces from the parts (compile time only)."""

    def __init__(self, spec: SceneSpec, parts: Model, centres: np.ndarray, state: State,
                 components: list[list[int]]) -> None:  # fmt: skip
        self.spec, self.parts, self.centres, self.state = spec, parts, centres, state
        self.index = {b.name: i for i, b in enumerate(spec.bodies)}
        self.body_of = np.empty(len(spec.bodies), dtype=np.int64)
        self.names: list[str] = []
        taken = set(self.index)
        for k, members in enumerate(components):
            self.body_of[members] = k
            name = spec.bodies[members[0]].name
            if len(members) > 1:
                name = "+".join(spec.bodies[i].name for i in members)
                while name in taken:  # a scene body already named so: the simulated body's name must differ
                    name += "'"
                taken.add(name)
            self.names.append(name)
        self.components = components
        self.first_particle = np.zeros(len(spec.bodies), dtype=np.int64)  # of each part in its body's list
        for members in components:
            counts = [int(parts.body_particle_count[i]) for i in members]
            self.first_particle[members] = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
        # world-from-user rotation of every part at t = 0 (its written orientation)
        self.R_user = quat_to_matrix(np.array([b.orientation_wxyz for b in spec.bodies], dtype=float).reshape(-1, 4))
        self.R = quat_to_matrix(state.q)  # world-from-principal at t = 0
        self.warnings: list[SceneIssue] = []
        self.errors: list[SceneIssue] = []

    # ---- where things go -----------------------------------------------------------------------------

    def welded(self, part: int) -> bool:
        """True when the part shares its simulated body (its frame is then the world frame at t = 0)."""
        return len(self.components[int(self.body_of[part])]) > 1

    def world_point(self, part: int, user_point: np.ndarray) -> np.ndarray:
        """A point given in a part's own (user) frame, in the world at t = 0: its welded body's frame."""
        return self.state.x[part] + self.R_user[part] @ (np.asarray(user_point, dtype=float) - self.centres[part])

    def world_vector(self, part: int, user_vector: np.ndarray) -> np.ndarray:
        return self.R_user[part] @ np.asarray(user_vector, dtype=float)

    def point(self, at: BodyPoint) -> BodyPoint:
        """The same body point on the simulated body (unchanged for a part alone on its body)."""
        part = self.index.get(at.body)
        if part is None or not self.welded(part):
            return at  # compile_forces reports an unknown name
        name = self.names[int(self.body_of[part])]
        if at.particle is not None and at.point is None:
            count = int(self.parts.body_particle_count[part])
            k = at.particle
            if isinstance(k, bool) or not isinstance(k, int | np.integer) or not 0 <= k < count:
                raise _Invalid(f"particle {k!r} is not a particle of body {at.body!r}", f"an index 0..{count - 1}")
            return BodyPoint(body=name, particle=int(self.first_particle[part] + k))
        if at.point is not None and at.particle is None:
            return BodyPoint(body=name, point=self.world_point(part, at.point))
        if at.point is None:  # the part's centre of mass
            return BodyPoint(body=name, point=self.state.x[part].copy())
        return replace(at, body=name)  # both given: compile_forces refuses it

    def vector(self, part_name: str, vector: np.ndarray, frame: str) -> np.ndarray:
        part = self.index.get(part_name)
        if frame != "body" or part is None or not self.welded(part):
            return vector
        return self.world_vector(part, vector)

    # ---- bodies --------------------------------------------------------------------------------------

    def body(self, members: list[int], welded_to_world: bool) -> tuple[BodySpec, int]:
        """The simulated body of one component, and its spanning tree's root part (WORLD: the world)."""
        bodies = [self.spec.bodies[i] for i in members]
        kinematic = [i for i in members if self.spec.bodies[i].kinematic]
        static = welded_to_world or any(b.static for b in bodies)
        names = ", ".join(repr(b.name) for b in bodies)
        if kinematic and (static or len(kinematic) > 1):
            what = "the world or a static body" if static else "another kinematic body"
            raise _Invalid(f"bodies {names} are welded into one body that is kinematic and also welded to {what}: "
                           "it cannot follow two prescribed motions", "at most one kinematic body in a welded group, "
                           "not welded to the world or a static body")  # fmt: skip
        root = WORLD if static else (kinematic[0] if kinematic else members[0])
        if static:
            self._warn_moving_static(members)
        if len(members) == 1:
            body = bodies[0]
            if static and not body.static:  # welded to the world: static, at rest
                body = replace(body, static=True, velocity=None, momentum=None, angular_velocity=None,
                               angular_momentum=None)  # fmt: skip
            return body, root
        state, parts = self.state, self.parts
        position = np.concatenate([self._world_particles(i) for i in members])
        mass = np.concatenate([np.asarray(parts.particle_mass[parts.particle_slice(i)]) for i in members])
        with_radius = any(b.particle_radius is not None for b in bodies)
        radius = np.concatenate([np.broadcast_to(np.asarray(b.particle_radius if b.particle_radius is not None
                                 else 0.0, dtype=float), (int(parts.body_particle_count[i]),))
                                 for i, b in zip(members, bodies, strict=True)]) if with_radius else None  # fmt: skip
        total, centre, _ = mass_properties(position, mass, radius)
        P = state.P[members].sum(axis=0)
        L = (state.L[members] + np.cross(state.x[members] - centre, state.P[members])).sum(axis=0)
        first = bodies[0]
        body = BodySpec(
            name=self.names[int(self.body_of[members[0]])],
            particle_position=position,
            particle_mass=mass,
            position=centre,
            orientation_wxyz=np.array([1.0, 0.0, 0.0, 0.0]),
            particle_radius=radius,
            momentum=None if static or kinematic else P,
            angular_momentum=None if static or kinematic else L,
            location=first.location,
            material=first.material,
            static=static,
            kinematic=bool(kinematic),
            kinematic_motion=self._kinematic_motion(kinematic[0]) if kinematic else None,
            collide=any(b.collide for b in bodies),
            contact_spheres=self._contact_spheres(members),
        )
        self._warn_materials(bodies)
        if not (static or kinematic):
            self._warn_inelastic(members, total, centre, P, L)
        return body, root

    def _world_particles(self, part: int) -> np.ndarray:
        """The part's particles in the world at t = 0, from its written pose (x_i + R_user (p - c_user))."""
        body = self.spec.bodies[part]
        p = np.asarray(body.particle_position, dtype=float).reshape(-1, 3)
        return self.state.x[part] + (p - self.centres[part]) @ self.R_user[part].T

    def _contact_spheres(self, members: list[int]) -> tuple[np.ndarray, np.ndarray] | None:
        """Every colliding part's own contact spheres in the world at t = 0; None (the body's particles, as
        a body of all of them would have) when every part collides on its particles."""
        if self.spec.contact is None:
            return None
        bodies = [self.spec.bodies[i] for i in members]
        if all(b.collide and b.contact_geometry == "particles" and b.contact_spheres is None for b in bodies):
            return None
        E = quat_to_matrix(self.parts.body_frame_q)
        centres, radii = [], []
        for i, body in zip(members, bodies, strict=True):
            if body.collide:
                offsets, r = spheres_of(body, self.parts, i, self.centres[i], E[i])
                centres.append(self.state.x[i] + offsets @ self.R[i].T)
                radii.append(r)
        if not radii:
            return np.zeros((0, 3)), np.zeros(0)
        return np.concatenate(centres), np.concatenate(radii)

    def _kinematic_motion(self, part: int) -> KinematicSpec:
        """The kinematic part's prescribed motion for its welded body: the same rigid motion of space
        (`kinematic: true`: its initial velocity and angular velocity about its centre of mass)."""
        body = self.spec.bodies[part]
        if body.kinematic_motion is not None:
            motion = body.kinematic_motion
            return replace(motion, pivot=self.state.x[part].copy() if motion.pivot is None else motion.pivot)
        v = self.state.P[part] / self.parts.body_mass[part]
        w = self.state.L[part] / self.parts.body_inertia[part, 0]  # isotropic: compile.py
        return KinematicSpec(velocity=v, angular_velocity=w, pivot=self.state.x[part].copy())

    def _warn(self, part: int, message: str, expected: str = "") -> None:
        self.warnings.append(SceneIssue(self.spec.bodies[part].location, message, expected, severity="warning"))

    def _warn_moving_static(self, members: list[int]) -> None:
        moving = [i for i in members if np.any(self.state.P[i] != 0.0) or np.any(self.state.L[i] != 0.0)]
        if moving and not any(self.spec.bodies[i].kinematic for i in members):
            names = ", ".join(repr(self.spec.bodies[i].name) for i in moving)
            message = f"bodies {names} are welded to the world (or to a static body), so they are static: "
            self._warn(moving[0], message + "their initial velocities are dropped", "no velocity on them")

    def _warn_materials(self, bodies: Sequence[BodySpec]) -> None:
        if self.spec.contact is None or all(b.material == bodies[0].material for b in bodies):
            return
        self.warnings.append(SceneIssue(
            bodies[0].location,
            f"bodies {', '.join(repr(b.name) for b in bodies)} are welded into one body and give different "
            f"contact materials: contact materials are per body, so the welded body takes '{bodies[0].name}''s",
            "one material for welded bodies", severity="warning",
        ))  # fmt: skip

    def _warn_inelastic(self, members: list[int], total: float, centre: np.ndarray, P: np.ndarray,
                        L: np.ndarray) -> None:  # fmt: skip
        """A warning when the parts' initial velocities are not one rigid motion: the weld takes the
        difference as an inelastic weld would (momenta kept); says the kinetic energy it takes."""
        parts, state = self.parts, self.state
        m = parts.body_mass[members]
        v = state.P[members] / m[:, None]
        R = self.R[members]
        omega = np.einsum("bij,bj->bi", R, np.einsum("bji,bj->bi", R, state.L[members]) / parts.body_inertia[members])
        inertia = sum(
            self.R[i] @ np.diag(parts.body_inertia[i]) @ self.R[i].T
            + parts.body_mass[i] * (np.dot(r, r) * np.eye(3) - np.outer(r, r))
            for i, r in zip(members, state.x[members] - centre, strict=True)
        )
        w = np.linalg.solve(inertia, L)
        rigid_v = P / total + np.cross(w, state.x[members] - centre)
        size = float(np.abs(state.x[members] - centre).max())  # omega x size: a speed
        scale = float(np.abs(v).max()) + float(np.abs(omega).max()) * size
        miss = float(np.abs(v - rigid_v).max()) + float(np.abs(omega - w).max()) * size
        if miss <= RIGID_TOLERANCE * scale:
            return
        before = 0.5 * float(np.sum(m * np.sum(v * v, axis=1)) + np.sum(omega * state.L[members]))
        after = 0.5 * (float(P @ P) / total + float(w @ L))
        names = ", ".join(repr(self.spec.bodies[i].name) for i in members)
        message = (
            f"bodies {names} are welded but their initial velocities are not one rigid motion: the weld takes the "
            f"difference as an inelastic weld would (momentum and angular momentum kept, {before - after:.4g} J of "
            "kinetic energy lost)"
        )
        self._warn(members[0], message, "welded bodies given one rigid motion")

    # ---- joints --------------------------------------------------------------------------------------

    def joints(self) -> tuple[list[JointSpec], np.ndarray, np.ndarray]:
        """The joints that stay constraints, on the simulated bodies; per scene joint its table row (-1: a
        weld, or left out) and its reaction rows' parts (row 0 never the world; -1 the world)."""
        out: list[JointSpec] = []
        table_index = np.full(len(self.spec.joints), -1, dtype=np.int64)
        parts = np.full((len(self.spec.joints), 2), WORLD, dtype=np.int64)
        for j, joint in enumerate(self.spec.joints):
            ends = [WORLD if name == WORLD_NAME else self.index[name] for name in joint.bodies]
            parts[j] = ends[::-1] if ends[0] == WORLD else ends
            if joint.kind == "fixed":
                continue
            bodies = [-2 if e == WORLD else int(self.body_of[e]) for e in ends]
            if bodies[0] == bodies[1]:
                message = f"joint '{joint.name}': both its bodies are welded into one body, so it holds nothing"
                self._warn(ends[0], message + " and is left out", "a joint between bodies not welded together")
                continue
            table_index[j] = len(out)
            out.append(self._joint(joint, ends))
        return out, table_index, parts

    def _joint(self, joint: JointSpec, ends: list[int]) -> JointSpec:
        """The joint on the simulated bodies: per-body anchors and axes of a welded part in its body's frame."""
        names = tuple(WORLD_NAME if e == WORLD else self.names[int(self.body_of[e])] for e in ends)
        anchors, axes = joint.anchors, joint.axes
        if anchors is not None:
            anchors = np.array([a if e == WORLD or not self.welded(e) else self.world_point(e, a)
                                for e, a in zip(ends, anchors, strict=True)])  # fmt: skip
        if axes is not None:
            axes = np.array([u if e == WORLD or not self.welded(e) else self.world_vector(e, u)
                             for e, u in zip(ends, axes, strict=True)])  # fmt: skip
        return replace(joint, bodies=(names[0], names[1]), anchors=anchors, axes=axes)

    # ---- forces --------------------------------------------------------------------------------------

    def forces(self) -> list[ForceSpec]:
        out: list[ForceSpec] = []
        for spec in self.spec.forces:
            try:
                out += self._force(spec)
            except _Invalid as exc:
                self.errors.append(SceneIssue(spec.location, f"force {spec.kind!r}: {exc}", exc.expected))
        return out

    def _force(self, spec: ForceSpec) -> list[ForceSpec]:
        if isinstance(spec, ForceSpring):
            a = self.index.get(spec.end_a.body)
            b = None if spec.end_b is None else self.index.get(spec.end_b.body)
            if a is not None and b is not None and a != b and self.body_of[a] == self.body_of[b]:
                names = f"'{spec.end_a.body}' and '{self.spec.bodies[b].name}'"
                message = f"force 'spring': bodies {names} are welded into one body, so the spring holds nothing"
                expected = "a spring between bodies that are not welded together"
                self.warnings.append(SceneIssue(spec.location, message + " and is left out", expected, "warning"))
                return []
            return [replace(spec, end_a=self.point(spec.end_a),
                            end_b=None if spec.end_b is None else self.point(spec.end_b))]  # fmt: skip
        # a body-frame vector of a welded part stays a body-frame vector, of its body, whose frame is the world
        # frame at t = 0: re-expressed there, it turns with the body as it turned with the part
        if isinstance(spec, ForceAtPoint | ForceImpulse):
            return [replace(spec, at=self.point(spec.at), vector=self.vector(spec.at.body, spec.vector, spec.frame))]
        if isinstance(spec, ForceTorque):
            part = self.index.get(spec.body)
            if part is None or not self.welded(part):
                return [spec]
            return [replace(spec, body=self.names[int(self.body_of[part])],
                            vector=self.vector(spec.body, spec.vector, spec.frame))]  # fmt: skip
        if isinstance(spec, ForceDrag):
            return self._drag(spec)
        if isinstance(spec, ForceField):
            return self._field(spec)
        return [spec]

    def _listed(self, names: Sequence[str] | None) -> list[int] | None:
        """The parts a drag or field names (None: unknown names, left for compile_forces to refuse)."""
        if names is None:
            return list(range(len(self.spec.bodies)))
        if isinstance(names, str) or any(n not in self.index for n in names) or len(set(names)) != len(names):
            return None
        return [self.index[n] for n in names]

    def _drag(self, spec: ForceDrag) -> list[ForceSpec]:
        listed = self._listed(spec.bodies)
        if listed is None or not any(self.welded(i) for i in listed):
            return [spec]
        alone = [self.names[int(self.body_of[i])] for i in listed if not self.welded(i)]
        out: list[ForceSpec] = [replace(spec, bodies=tuple(alone))] if alone else []
        welded = [i for i in listed if self.welded(i)]
        for i in welded:  # one row per part: the kernel adds them on the body
            out.append(replace(spec, bodies=(self.names[int(self.body_of[i])],)))
        if spec.linear or spec.quadratic:
            names = ", ".join(repr(self.spec.bodies[i].name) for i in welded)
            self.warnings.append(SceneIssue(
                spec.location, f"force 'drag' on welded bodies {names}: drag acts at each simulated body's centre of "
                "mass with its velocity, so a welded body's parts add their coefficients there (exact while it only "
                "translates; the drag a rotation gives a part away from the centre of mass, and its moment, are left "
                "out)", "drag on bodies that are not welded, or angular drag only", severity="warning",
            ))  # fmt: skip
        return out

    def _field(self, spec: ForceField) -> list[ForceSpec]:
        listed = self._listed(spec.bodies)
        if listed is None or not any(self.welded(i) for i in listed):
            return [spec]
        chosen = set(listed)
        whole: list[tuple[int, list[int]]] = []
        some: list[tuple[int, list[int]]] = []
        for k, members in enumerate(self.components):
            named = [i for i in members if i in chosen]
            if named:
                (whole if len(named) == len(members) else some).append((k, named))
        out: list[ForceSpec] = []
        if whole:
            out.append(replace(spec, bodies=tuple(self.names[k] for k, _ in whole)))
        if some:
            uniform = spec.gradient is None or not np.any(np.asarray(spec.gradient))
            if not uniform:
                names = ", ".join(repr(self.spec.bodies[i].name) for _, named in some for i in named)
                raise _Invalid(f"a field with a gradient on {names}, welded to bodies it does not name: a field acts "
                               "on every particle of a simulated body", "a field on every body of a welded group, "
                               "or a uniform field")  # fmt: skip
            for k, named in some:  # a uniform field on a part: one force at its centre of mass (or particle centroid)
                for i in named:
                    particles = self._world_particles(i)
                    if spec.per == "mass":
                        weight, point = float(self.parts.body_mass[i]), self.state.x[i].copy()
                    else:
                        weight, point = float(len(particles)), particles.mean(axis=0)
                    out.append(ForceAtPoint(at=BodyPoint(body=self.names[k], point=point),
                                            vector=weight * np.asarray(spec.value, dtype=float), frame="world",
                                            schedule=spec.schedule, location=spec.location))  # fmt: skip
        return out


def part_view(merge: WeldMerge, parts: Model, model: Model, state: State, parts_state: State) -> PartView:
    """The PartView of a merged scene: model and state the simulated bodies' (compiled from merge.spec),
    parts and parts_state the scene's bodies as bodies of their own."""
    n = len(parts.body_names)
    body = np.empty(n, dtype=np.int64)
    alone = np.zeros(n, dtype=bool)
    for k, members in enumerate(merge.components):
        body[list(members)] = k
        alone[list(members)] = len(members) == 1
    R = quat_to_matrix(state.q[body])
    offset = np.einsum("pji,pj->pi", R, parts_state.x - state.x[body])
    offset[alone] = 0.0
    rotation = quat_multiply(quat_conjugate(state.q[body]), parts_state.q)
    rotation = np.where(rotation[:, :1] < 0.0, -rotation, rotation)
    rotation[alone] = [1.0, 0.0, 0.0, 0.0]
    parent, parent_part, order = _weld_trees(merge, len(parts.body_names))
    return PartView(
        model=parts, part_body=body, part_offset=offset, part_rotation=rotation, alone=alone,
        joint_table_index=merge.joint_table_index, joint_parts=merge.joint_parts, weld_parent=parent,
        weld_order=order, weld_parent_part=parent_part,
        weld_joint=merge.weld_joint,
    )  # fmt: skip


def _weld_trees(merge: WeldMerge, part_count: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each welded body's spanning tree of welds, breadth first from its root (the world, a kinematic part or
    its first part): per part the weld to its parent and that parent (-1), and the parts leaves first. As
    the joint solver closes loops, a weld whose ends the earlier welds (in file order) already join closes
    a loop and is in no tree (a loop of welds is statically indeterminate: it reports no reaction)."""
    ends = merge.joint_parts
    group = list(range(part_count + 1))  # union-find; the world is the last vertex

    def find(i: int) -> int:
        while group[i] != i:
            group[i] = group[group[i]]
            i = group[i]
        return i

    tree: dict[int, list[tuple[int, int]]] = {}  # vertex -> (weld, other end)
    for j in merge.weld_joint:
        a, b = (part_count if e == WORLD else int(e) for e in ends[j])
        ra, rb = find(a), find(b)
        if ra == rb:
            continue  # closes a loop
        group[ra] = rb
        tree.setdefault(a, []).append((int(j), b))
        tree.setdefault(b, []).append((int(j), a))
    parent = np.full(part_count, -1, dtype=np.int64)
    parent_part = np.full(part_count, WORLD, dtype=np.int64)
    order: list[int] = []
    for root in merge.roots:
        frontier, seen = [part_count if root == WORLD else root], set()
        seen.update(frontier)
        while frontier:
            node = frontier.pop(0)
            for j, other in tree.get(node, []):
                if other in seen:
                    continue
                seen.add(other)
                parent[other], parent_part[other] = j, WORLD if node == part_count else node
                order.append(other)
                frontier.append(other)
    return parent, parent_part, np.array(order[::-1], dtype=np.int64)
