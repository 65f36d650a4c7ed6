"""The model: constant per-body and per-particle arrays, built once from a scene.

Per the tutorial's precomputation: M = sum m_i, x_cm = sum m_i x_i / M, r0_i = x0_i - x_cm,
I0 = sum m_i (r0_i . r0_i 1 - r0_i r0_i^T). rbsim then diagonalises I0: internally the body frame is
the principal frame (I0 = diag(I1, I2, I3)), which makes omega = I^-1 L three multiplications and
is what the splitting and exact integrators need. `body_frame_q` keeps the fixed rotation from the
principal frame to the user's particle frame so every output is reported in the user's frame.

The model also holds the scene's other constant tables, as MuJoCo's mjModel holds every table: `contact`
(contact spheres, materials, planes, static bodies: physics/contact/tables.py), `joint` (the joints:
physics/joints/tables.py) and `kinematic` (the kinematic bodies' prescribed motions: kinematic_table.py).
The force terms are the force tables' (physics/forces/tables.py). `build_model` builds the bodies;
scene/compile.py adds the tables.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np

from rbcli.physics.contact.tables import ContactTable, contact_present, contact_table
from rbcli.physics.joints.tables import JointTable
from rbcli.physics.kinematic_table import KinematicTable, kinematic_table
from rbcli.physics.rotation import matrix_to_quat, quat_to_matrix
from rbcli.physics.tree.table import TreeTable

# A principal moment below this fraction of the largest makes I0 singular (collinear or single-point
# particle clouds); 1e-12 is far above round-off (~1e-16) and far below any real body's anisotropy.
INERTIA_DEGENERACY_RATIO = 1e-12


def mass_properties(
    positions: np.ndarray, masses: np.ndarray, radii: np.ndarray | None = None
) -> tuple[float, np.ndarray, np.ndarray]:
    """Total mass M [kg], centre of mass x_cm [m] (3,), inertia I0 [kg m^2] (3, 3) about x_cm.

    The tutorial's precomputation, in the frame the positions are given in. A particle with a radius r
    is a small solid sphere and adds its own 2/5 m r^2 about every axis (parallel-axis theorem): this
    is what gives a rod of particles on one line a non-zero inertia about its axis, and it makes
    sampled shapes' inertia converge faster (box error M s^2/15 instead of M s^2/6 at spacing s).
    """
    positions = np.asarray(positions, dtype=np.float64)
    masses = np.asarray(masses, dtype=np.float64)
    total = float(masses.sum())
    centre = (masses[:, None] * positions).sum(axis=0) / total
    r0 = positions - centre
    r0_sq = np.einsum("ij,ij->i", r0, r0)
    inertia = np.einsum("i,jk->jk", masses * r0_sq, np.eye(3)) - np.einsum("i,ij,ik->jk", masses, r0, r0)
    if radii is not None:
        inertia += 0.4 * float(np.sum(masses * np.asarray(radii, dtype=np.float64) ** 2)) * np.eye(3)
    return total, centre, inertia


def principal_axes(inertia: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal moments (..., 3) ascending and right-handed rotations E (..., 3, 3), I0 = E diag E^T.

    Columns of E are the principal axes expressed in the user's frame; any leading axes are batched.
    """
    moments, axes = np.linalg.eigh(0.5 * (inertia + np.swapaxes(inertia, -1, -2)))
    # eigh may return a reflection; flip the third axis to make it a rotation
    axes[..., :, 2] *= np.where(np.linalg.det(axes) < 0.0, -1.0, 1.0)[..., None]
    return moments, axes


def inertia_is_degenerate(moments: np.ndarray) -> bool:
    """True when the smallest principal moment is negligible: I0 cannot be inverted."""
    return bool(moments.min() <= INERTIA_DEGENERACY_RATIO * max(moments.max(), np.finfo(float).tiny))


class KernelBodies(NamedTuple):
    """The model's body and particle arrays as compiled kernels take them (a numba-friendly named tuple):
    what every kernel below the chunk loops takes as `model`. One numba type for every scene, so a stage
    kernel compiled for one kind of scene serves every other (physics/kernel_link.py); the chunk loops
    take the whole KernelModel and pass its tables by name (physics/chunk_loop.py)."""

    body_mass: np.ndarray  # [kg], (body_count,)
    body_inertia: np.ndarray  # principal moments [kg m^2], (body_count, 3)
    body_inertia_inv: np.ndarray  # 1 / principal moments [1/(kg m^2)], (body_count, 3)
    particle_offset: np.ndarray  # [m], (particle_count, 3), principal body frame, about the centre of mass
    particle_mass: np.ndarray  # [kg], (particle_count,)
    body_particle_start: np.ndarray  # int64 (body_count,): first particle of each body
    body_particle_count: np.ndarray  # int64 (body_count,)
    body_frame: np.ndarray  # E, user-from-principal rotation, (body_count, 3, 3)


class KernelModel(NamedTuple):
    """The whole model as the compiled chunk loops take them (`Model.kernel()`): KernelBodies' arrays,
    then the tables, each None where the scene lacks it, so numba types it as NoneType and the stages
    that use it compile to nothing (physics/stages.py, joints/stages.py); a scene always gets the same
    combination, so its loop's numba type is the same from run to run."""

    body_mass: np.ndarray
    body_inertia: np.ndarray
    body_inertia_inv: np.ndarray
    particle_offset: np.ndarray
    particle_mass: np.ndarray
    body_particle_start: np.ndarray
    body_particle_count: np.ndarray
    body_frame: np.ndarray
    contact: ContactTable | None  # None without contact spheres and static bodies (`contact_present`)
    joint: JointTable | None  # None without joints
    kinematic: KinematicTable | None  # None without kinematic bodies
    tree: TreeTable | None = None  # None in maximal coordinates (the reduced integrators: physics/tree/)


@dataclass(frozen=True)
class Model:
    """Constant description of the bodies; read-only after compilation.

    body_frame_q: (body_count, 4) wxyz, rotation user-frame-from-principal-frame (the E above).
    particle_offset_user: (particle_count, 3) [m], user frame, about the centre of mass (for output).
    contact: contact spheres, materials, planes and static bodies (0 spheres and no static body: no
      contact stages). joint: the joints, None without joints. kinematic: the kinematic bodies' motions
      (0 rows: no kinematic stages). tree: the links of the articulated trees (physics/tree/table.py)
      when a reduced integrator runs the scene (scene/compile_trees.py), else None. Python code reads
      every Model alike (`model.contact.sphere_body`);
      kernels take `kernel()`, in which absent tables are None.
    """

    body_names: tuple[str, ...]
    body_mass: np.ndarray
    body_inertia: np.ndarray
    body_frame_q: np.ndarray
    particle_offset: np.ndarray
    particle_offset_user: np.ndarray
    particle_mass: np.ndarray
    particle_radius: np.ndarray
    body_particle_start: np.ndarray
    body_particle_count: np.ndarray
    contact: ContactTable = field(default_factory=contact_table)
    joint: JointTable | None = None
    kinematic: KinematicTable = field(default_factory=kinematic_table)
    tree: TreeTable | None = None

    @property
    def body_count(self) -> int:
        return len(self.body_names)

    @property
    def particle_count(self) -> int:
        return int(self.particle_mass.shape[0])

    def kernel(self) -> KernelModel:
        """The model as the chunk loops take it: the body arrays and each table, None where the scene
        lacks it (see KernelModel)."""
        return KernelModel(
            *self.kernel_bodies(),
            contact=self.contact if contact_present(self.contact) else None,
            joint=self.joint,  # None without joints (a table of welds alone has 0 rows: its stages skip)
            kinematic=self.kinematic if self.kinematic.body.shape[0] else None,
            tree=self.tree,
        )

    def kernel_bodies(self) -> KernelBodies:
        """The body and particle arrays as kernels below the chunk loops take them (see KernelBodies):
        what Python passes a stage kernel it calls itself (the recording thread's joint violations)."""
        return KernelBodies(
            self.body_mass,
            self.body_inertia,
            1.0 / self.body_inertia,
            self.particle_offset,
            self.particle_mass,
            self.body_particle_start,
            self.body_particle_count,
            quat_to_matrix(self.body_frame_q),
        )

    def particle_slice(self, body: int) -> slice:
        start = int(self.body_particle_start[body])
        return slice(start, start + int(self.body_particle_count[body]))


def build_model(
    names: list[str],
    particle_positions: list[np.ndarray],
    particle_masses: list[np.ndarray],
    particle_radii: list[np.ndarray | None] | None = None,
) -> tuple[Model, np.ndarray]:
    """Precompute every body's mass properties; returns the model and each body's centre of mass in
    its user frame, shape (body_count, 3) (needed to place bodies and to report particles).

    Raises ValueError naming the body when its inertia is singular (collinear or single-point cloud) or
    too small to invert in float64.
    """
    count = len(names)
    body_mass = np.empty(count)
    centres = np.empty((count, 3))
    inertias = np.empty((count, 3, 3))
    offsets_user, masses, radii = [], [], []
    # bodies from one template (a grid, a pile) share their clouds: their mass properties are computed
    # once per distinct cloud, with the same bits as computing each
    known: dict[bytes, tuple[float, np.ndarray, np.ndarray]] = {}
    for b in range(count):  # once per body at compile time, not in a step; the 3x3 work is batched below
        pos = np.asarray(particle_positions[b], dtype=np.float64).reshape(-1, 3)
        mass = np.broadcast_to(np.asarray(particle_masses[b], dtype=np.float64), (pos.shape[0],))
        rad = None if particle_radii is None or particle_radii[b] is None else particle_radii[b]
        rad = None if rad is None else np.broadcast_to(np.asarray(rad, dtype=np.float64), (pos.shape[0],)).copy()
        key = (
            pos.tobytes()
            + b"|"
            + np.ascontiguousarray(mass).tobytes()
            + b"|"
            + (b"-" if rad is None else rad.tobytes())
        )
        if key not in known:
            known[key] = mass_properties(pos, mass, rad)
        body_mass[b], centres[b], inertias[b] = known[key]
        offsets_user.append(pos - centres[b])
        masses.append(np.array(mass))
        radii.append(np.zeros(pos.shape[0]) if rad is None else rad)
    body_inertia, axes = principal_axes(inertias)
    smallest, largest = (body_inertia.min(axis=1), body_inertia.max(axis=1)) if count else (np.zeros(0), np.zeros(0))
    degenerate = smallest <= INERTIA_DEGENERACY_RATIO * np.maximum(largest, np.finfo(float).tiny)
    for refused in np.flatnonzero(degenerate | (smallest < 1.0 / np.finfo(float).max)):  # only bodies refused
        b = int(refused)
        if inertia_is_degenerate(body_inertia[b]):
            raise ValueError(
                f"body {names[b]!r}: its inertia I0 is singular (principal moments {body_inertia[b].tolist()}); "
                "its particles are collinear or a single point, so it has no inertia about some axis"
            )
        if body_inertia[b].min() < 1.0 / np.finfo(float).max:  # omega = L / I: 1 / I must be a finite float
            raise ValueError(
                f"body {names[b]!r}: its principal moments {body_inertia[b].tolist()} kg m^2 are so small that "
                "1 / I overflows float64 (masses or sizes far too small: masses in kg, positions in m)"
            )
    body_frame_q = matrix_to_quat(axes) if count else np.zeros((0, 4))
    # particle offsets along the principal axes: E^T r0 for each particle's body
    body_of = np.repeat(np.arange(count), [len(m) for m in masses])
    offset_user = np.concatenate(offsets_user) if count else np.zeros((0, 3))
    offset_principal = np.einsum("pi,pij->pj", offset_user, axes[body_of]) if count else np.zeros((0, 3))
    counts = np.array([m.shape[0] for m in masses], dtype=np.int64)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    model = Model(
        body_names=tuple(names),
        body_mass=body_mass,
        body_inertia=body_inertia,
        body_frame_q=body_frame_q,
        particle_offset=offset_principal,
        particle_offset_user=offset_user,
        particle_mass=np.concatenate(masses) if count else np.zeros(0),
        particle_radius=np.concatenate(radii) if count else np.zeros(0),
        body_particle_start=starts,
        body_particle_count=counts,
    )
    for arr in (model.body_mass, model.body_inertia, model.body_frame_q, model.particle_offset):
        arr.setflags(write=False)
    return model, centres
