"""Turn raw recorded states (internal principal frame) into FrameBlocks for the sinks.

The raw states are the simulated bodies'; a scene with welds records its own bodies (the parts,
scene/parts.py) and its welds' reactions (runner/weld_reactions.py), its invariants from the simulated ones."""

from __future__ import annotations

import numpy as np

from rbcli.physics.energy import CONTACT_INVARIANT_NAMES, JOINT_INVARIANT_NAMES, invariants_from_totals
from rbcli.physics.frames import particle_world
from rbcli.physics.model import Model
from rbcli.physics.outputs import TOTALS_WIDTH, derive_outputs
from rbcli.record.frame import FrameBlock
from rbcli.scene.compile import CompiledScene
from rbcli.scene.parts import part_states


def make_block(
    compiled: CompiledScene,
    step: np.ndarray,
    x: np.ndarray,
    q: np.ndarray,
    P: np.ndarray,
    L: np.ndarray,
    contact: np.ndarray | None = None,
    joint: np.ndarray | None = None,
    previous: np.ndarray | None = None,
) -> FrameBlock:
    """A FrameBlock of K frames from raw (K, N, ...) arrays; copies, so buffers can be reused. contact:
    (K, 4) the contact statistics of each frame (FrameBuffers.contact), for scenes with contact; joint:
    (K, J, 12) the joints' reactions (FrameBuffers.joint), kept with the joint_forces stream. previous:
    scenes with welds, (K, N, 13) the state one step before each frame (x, q, P, L; NaN: unknown), from
    which the welds' reactions are read."""
    model, settings = compiled.model, compiled.settings
    q_user, v, omega = np.empty_like(q), np.empty_like(P), np.empty_like(L)
    totals = np.empty((q.shape[0], TOTALS_WIDTH))
    derive_outputs(model.body_mass, 1.0 / model.body_inertia, model.body_frame_q, x, q, P, L, q_user, v, omega, totals)
    recorded = (x.copy(), q, P.copy(), L.copy())
    parts = compiled.parts
    if parts is not None:  # the scene's bodies, welded ones on their simulated body
        recorded = part_states(parts, model, x, q, P, L)
        body = parts.model
        q_user, v, omega = np.empty_like(recorded[1]), np.empty_like(recorded[2]), np.empty_like(recorded[3])
        derive_outputs(body.body_mass, 1.0 / body.body_inertia, body.body_frame_q, *recorded, q_user, v, omega,
                       np.empty_like(totals))  # fmt: skip
    block = FrameBlock(
        step=step.astype(np.int64, copy=True),
        t=step * settings.dt,
        x=recorded[0],
        q=q_user,
        v=v,
        omega=omega,
        P=recorded[2],
        L=recorded[3],
    )
    if "invariants" in settings.streams:
        block.invariants = invariants_from_totals(model, compiled.forces, x, q, totals)
        if compiled.contact is not None:
            stats = np.zeros((q.shape[0], len(CONTACT_INVARIANT_NAMES))) if contact is None else contact
            for k, name in enumerate(CONTACT_INVARIANT_NAMES):
                block.invariants[name] = np.ascontiguousarray(stats[:, k], dtype=np.float64)
            for name in ("energy_potential", "energy_total"):  # the contact springs' energy is potential
                block.invariants[name] = block.invariants[name] + block.invariants["contact_energy"]
        if compiled.model.joint is not None:
            for name, column in zip(JOINT_INVARIANT_NAMES, joint_invariants(compiled, x, q, P, L).T, strict=True):
                block.invariants[name] = np.ascontiguousarray(column)
    if "particles" in settings.streams:
        block.particle_position, _ = particle_world(recorded_model(compiled), *recorded)
    if "contacts" in settings.streams and compiled.contact is not None:
        block.contact_point, block.contact_force = frame_contacts(compiled, x, q, P, L)
    count = recorded_joint_count(compiled)
    table = np.full((q.shape[0], count, 12), np.nan) if joint is None else joint.copy()
    if parts is not None and recorded_joint_names(compiled):
        from rbcli.runner.weld_reactions import joint_reactions

        block.joint_force = joint_reactions(parts, model, settings.dt, step, previous, (x, q, P, L), table)
    elif count:
        block.joint_force = table
    return block


def recorded_model(compiled: CompiledScene) -> Model:
    """The bodies a recording shows: the scene's own (with welds, the parts: scene/parts.py)."""
    return compiled.parts.model if compiled.parts is not None else compiled.model


def recorded_joint_names(compiled: CompiledScene) -> tuple[str, ...]:
    """The joints whose reactions the recording holds (the joint_forces stream): the scene's, welds too."""
    if "joint_forces" not in compiled.settings.streams:
        return ()
    if compiled.parts is not None:
        return tuple(joint.name for joint in compiled.spec.joints)
    return tuple(joint.name for joint in compiled.spec.joints) if compiled.model.joint is not None else ()


def recorded_joint_count(compiled: CompiledScene) -> int:
    """The joint table's joints whose reactions the chunks record (FrameBuffers.joint): all of them with
    the joint_forces stream, else 0 (a scene with welds records its welds' beside them: make_block)."""
    table = compiled.model.joint
    if table is None or "joint_forces" not in compiled.settings.streams:
        return 0
    return int(table.body_a.shape[0])


# in joint coordinates (whose loop compiles none of the maximal joints' rows) a scene of at most this
# many joints evaluates its joint invariants in numpy: compiling joint_violations costs ~3.5 s of its first
# run, the numpy twin ~50 us a joint a recorded frame (the recording thread's, beside the steps)
NUMPY_INVARIANT_JOINTS = 64


def joint_invariants(compiled: CompiledScene, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray) -> np.ndarray:
    """(K, 2): each raw state's largest joint violation in position and velocity (physics/joints/violation.py;
    its numpy twin in small scenes in joint coordinates: NUMPY_INVARIANT_JOINTS)."""
    from rbcli.physics.joints.tables import make_joint_work

    table = compiled.model.joint
    assert table is not None
    if compiled.model.tree is not None and table.kind.shape[0] <= NUMPY_INVARIANT_JOINTS:
        from rbcli.physics.joints.reference import joint_violations_numpy

        return joint_violations_numpy(compiled.model, table, x, q, P, L)
    from rbcli.physics.joints.violation import joint_violations

    out = np.zeros((x.shape[0], 2))
    joint_violations(compiled.model.kernel_bodies(), table, make_joint_work(table), x, q, P, L, out)
    return out


def frame_contacts(
    compiled: CompiledScene, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray
) -> tuple[list[np.ndarray], list[np.ndarray]]:
    """The contact points [m] and normal force magnitudes [N] of each of K raw states (K, N, ...),
    internal principal frame (physics/contact/points.py): only recorded frames pay for them."""
    from rbcli.physics.contact.points import contact_points
    from rbcli.physics.contact.tables import make_contact_work

    table = compiled.model.contact
    work = make_contact_work(table, compiled.model.body_count, history=False)
    model = compiled.model.kernel_bodies()
    capacity = max(16, table.sphere_radius.shape[0])
    point, force = np.empty((capacity, 3)), np.empty(capacity)
    points, forces = [], []
    for k in range(q.shape[0]):
        count = contact_points(model, table, work, x[k], q[k], P[k], L[k], point, force)
        if count > capacity:  # more contacts than spheres (a dense pack): once more with room for all
            capacity = 2 * count
            point, force = np.empty((capacity, 3)), np.empty(capacity)
            count = contact_points(model, table, work, x[k], q[k], P[k], L[k], point, force)
        points.append(point[:count].copy())
        forces.append(force[:count].copy())
    return points, forces
