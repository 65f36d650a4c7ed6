"""Contact parameters (read-only, in ForceTables) and contact work arrays (mutable, in the run's Data).

Geometry: each contact body carries contact spheres, body-fixed, given in the PRINCIPAL frame about
its centre of mass like every other body point (model.py). A sphere-shaped body is one sphere (its
exact surface); a sampled shape, mesh or compound body uses the particles of its lattice surface; an
explicit particle cloud uses every particle with its radius. The world has planes (half-spaces: the
ground, walls, an axis-aligned container), each with an outward unit normal.

Materials are per body (and per plane): stiffness k [N/m], damping ratio zeta [1] (from a coefficient
of restitution, `parameters.damping_ratio_for_restitution`) and Coulomb friction mu [1]. A pair mixes
them as springs in series for k (2 ka kb / (ka + kb), so equal materials keep their k; a plane uses
the body's k), the smaller zeta (the livelier material wins, as Box2D's max-restitution rule) and
sqrt(mu_a mu_b) for friction (Box2D's b2MixFriction).

Like the force tables, a scene without contact gets the same types with 0 rows, so one compiled kernel
serves every scene and the contact stage is skipped at the cost of one comparison. This module imports
numpy only.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

# A plane partner of a contact is stored in the history as -(plane + 1), a sphere partner as its index.
PLANE_PARTNER_BASE = -1

# History slots per contact sphere: the contacts it owns (it is the lower index of the pair, or a plane
# contact). 12 is the kissing number of equal spheres; a sphere owning more contacts keeps the first 12
# histories and counts the others in `ContactWork.counters[COUNT_OVERFLOW]` (their friction then starts
# afresh every step, still Coulomb-limited): recorded as the invariant `contact_history_overflow`, and
# `rbsim run` warns naming the body of the first such sphere.
HISTORY_SLOTS = 12

# ContactWork.stats of the last force evaluation: contacts, the deepest overlap [m], the elastic energy
# stored in the contact springs [J] (normal k d^2 / 2 plus tangential k_t |xi|^2 / 2)
STAT_CONTACTS, STAT_MAX_PENETRATION, STAT_ENERGY = range(3)
STAT_COUNT = 3
# columns of a recorded frame's contact row (physics/step.py FrameBuffers.contact, CONTACT_STATS): the
# STAT_* of the recorded state (contact/state.py), then the run's history overflows so far
STAT_OVERFLOW = 3
FRAME_STAT_COUNT = 4
# ContactWork.counters, cumulative over a run: candidate pairs tested (distance checks), contacts found,
# contacts whose history did not fit, force evaluations
COUNT_CANDIDATES, COUNT_CONTACTS, COUNT_OVERFLOW, COUNT_EVALUATIONS = range(4)
COUNTER_COUNT = 4


class ContactTable(NamedTuple):
    """Contact geometry and materials of a scene (read-only)."""

    sphere_body: np.ndarray  # int64 (sphere_count,), body of each contact sphere, spheres grouped by body
    sphere_offset: np.ndarray  # [m] (sphere_count, 3), principal frame, about the body's centre of mass
    sphere_radius: np.ndarray  # [m] (sphere_count,)
    # [1/kg] (body_count,): support / M, the inverse of the mass one contact sphere carries when the body
    # rests on its `support` spheres (parameters.support_count); 0 for a static body. The dashpot of a
    # contact uses it, so a body resting on n spheres has the damping ratio its material asks for
    # (with the whole mass per sphere, n contacts would damp like sqrt(n) zeta: overdamped, unstable)
    body_inv_contact_mass: np.ndarray
    body_stiffness: np.ndarray  # k [N/m] (body_count,) per contact sphere
    body_plane_stiffness: np.ndarray  # k [N/m] (body_count,) per contact sphere against a plane
    body_damping_ratio: np.ndarray  # zeta [1] (body_count,)
    body_friction: np.ndarray  # mu [1] (body_count,)
    static_body: np.ndarray  # int64 (static_count,): bodies that never move (F = tau = 0, P = L = 0)
    plane_point: np.ndarray  # [m] (plane_count, 3), world
    plane_normal: np.ndarray  # (plane_count, 3), world, unit, pointing out of the solid
    plane_damping_ratio: np.ndarray  # (plane_count,)
    plane_friction: np.ndarray  # (plane_count,)
    body_friction_root: np.ndarray  # sqrt(mu) per body: a pair's sqrt(mu_a mu_b) is one product
    plane_friction_root: np.ndarray  # sqrt(mu) per plane
    cell_size: float  # [m] broad-phase grid cell: the largest sphere diameter
    tangential_ratio: float  # k_t / k_n of every contact
    bucket_count: int  # size of the broad phase's bucket table (see broad_phase.py)
    # [s] the smallest stable step of the contacts the scene can form (parameters.stable_step; inf: none
    # can collide): adaptive stepping never steps longer (physics/adaptive.py)
    stable_step: float = math.inf


class ContactWork(NamedTuple):
    """The contact stage's mutable arrays, allocated once per run (`make_contact_work`).

    clock (3,): start time [s] and length h [s] of the step being taken (set by the pipeline's
    contact_begin stage; a force evaluation at time t is at offset s = t - clock[0] into it), and the
    offset s of the last evaluation.
    History (the tangential spring per contact, state carried between steps): for each sphere the
    contacts it owns, hist_count[i] of them, partner hist_partner[i, k] and spring elongation
    hist_xi[i, k] [m] (world frame). A force evaluation writes the contacts it finds into the trial_*
    arrays; the pipeline's contact_commit stage makes the last evaluation's trial the history once the
    step is complete, advanced to the end of the step (force.commit_contacts), so the stages of a
    multi-stage method and a step that is thrown away never move it.
    """

    clock: np.ndarray
    body_velocity: np.ndarray  # [m/s] (body_count, 3), world, at the current evaluation
    body_omega: np.ndarray  # [rad/s] (body_count, 3), world
    sphere_position: np.ndarray  # [m] (sphere_count, 3), world
    sphere_cell: np.ndarray  # int64 (sphere_count, 3), grid cell of each sphere
    sphere_bucket: np.ndarray  # int64 (sphere_count,)
    bucket_start: np.ndarray  # int64 (bucket_count + 1,)
    sorted_sphere: np.ndarray  # int64 (sphere_count,), spheres ordered by bucket
    sorted_position: np.ndarray  # (sphere_count, 4): x, y, z [m] and radius [m] in that order
    sorted_cell: np.ndarray  # int64 (sphere_count, 3): cells in that order
    hist_count: np.ndarray  # int64 (sphere_count,)
    hist_partner: np.ndarray  # int64 (sphere_count, HISTORY_SLOTS)
    hist_xi: np.ndarray  # [m] (sphere_count, HISTORY_SLOTS, 3)
    trial_count: np.ndarray
    trial_partner: np.ndarray
    trial_xi: np.ndarray  # elongation at the evaluation [m]
    trial_normal: np.ndarray  # (sphere_count, HISTORY_SLOTS, 3), the contact normal at the evaluation
    trial_point: np.ndarray  # [m] (sphere_count, HISTORY_SLOTS, 3), the contact point, world
    trial_limit: np.ndarray  # [m] (sphere_count, HISTORY_SLOTS), the Coulomb limit mu f_n / k_t of |xi|
    stats: np.ndarray  # float64 (STAT_COUNT,)
    counters: np.ndarray  # int64 (COUNTER_COUNT,)
    # int64 (1,): the sphere of the run's first contact whose history did not fit (-1: none), so the
    # runner can name its body; not carried by checkpoints (a resumed run names its own first)
    overflow_sphere: np.ndarray


def _ro(values: object, dtype: type, *shape: int) -> np.ndarray:
    out: np.ndarray = np.ascontiguousarray(np.asarray(values, dtype=dtype).reshape((-1, *shape)))
    out.setflags(write=False)
    return out


def contact_table(
    *,
    sphere_body=(),  # noqa: ANN001
    sphere_offset=(),  # noqa: ANN001
    sphere_radius=(),  # noqa: ANN001
    body_inv_contact_mass=(),  # noqa: ANN001
    body_stiffness=(),  # noqa: ANN001
    body_plane_stiffness=None,  # noqa: ANN001
    body_damping_ratio=(),  # noqa: ANN001
    body_friction=(),  # noqa: ANN001
    static_body=(),  # noqa: ANN001
    plane_point=(),  # noqa: ANN001
    plane_normal=(),  # noqa: ANN001
    plane_damping_ratio=(),  # noqa: ANN001
    plane_friction=(),  # noqa: ANN001
    tangential_ratio: float = 2.0 / 7.0,
    stable_step: float = math.inf,
) -> ContactTable:
    """A ContactTable with consistent dtypes (all empty: a scene without contact)."""
    radius = _ro(sphere_radius, np.float64)
    spheres = radius.shape[0]
    # a power of two >= 4 S: dense grids up to that many cells, hashed (with a mask) otherwise (broad_phase.py)
    buckets = 1 << int(4 * spheres - 1).bit_length() if spheres else 0
    return ContactTable(
        sphere_body=_ro(sphere_body, np.int64),
        sphere_offset=_ro(sphere_offset, np.float64, 3),
        sphere_radius=radius,
        body_inv_contact_mass=_ro(body_inv_contact_mass, np.float64),
        body_stiffness=_ro(body_stiffness, np.float64),
        body_plane_stiffness=_ro(body_stiffness if body_plane_stiffness is None else body_plane_stiffness, np.float64),
        body_damping_ratio=_ro(body_damping_ratio, np.float64),
        body_friction=_ro(body_friction, np.float64),
        static_body=_ro(static_body, np.int64),
        plane_point=_ro(plane_point, np.float64, 3),
        plane_normal=_ro(plane_normal, np.float64, 3),
        plane_damping_ratio=_ro(plane_damping_ratio, np.float64),
        plane_friction=_ro(plane_friction, np.float64),
        body_friction_root=_ro(np.sqrt(np.asarray(body_friction, dtype=np.float64)), np.float64),
        plane_friction_root=_ro(np.sqrt(np.asarray(plane_friction, dtype=np.float64)), np.float64),
        cell_size=float(2.0 * radius.max()) if spheres else 1.0,
        tangential_ratio=float(tangential_ratio),
        bucket_count=int(buckets),
        stable_step=float(stable_step),
    )


def make_contact_work(contact: ContactTable, body_count: int, *, history: bool = True) -> ContactWork:
    """Zeroed work arrays for `contact` (0-sized without contact spheres: nothing is allocated).
    history=False: no history or trial slots (a scratch for the search alone: contact/points.py)."""
    s = contact.sphere_radius.shape[0]
    b = body_count if s else 0
    k = HISTORY_SLOTS if s and history else 0
    return ContactWork(
        clock=np.zeros(3),
        body_velocity=np.zeros((b, 3)),
        body_omega=np.zeros((b, 3)),
        sphere_position=np.zeros((s, 3)),
        sphere_cell=np.zeros((s, 3), dtype=np.int64),
        sphere_bucket=np.zeros(s, dtype=np.int64),
        bucket_start=np.zeros(contact.bucket_count + 1, dtype=np.int64),
        sorted_sphere=np.zeros(s, dtype=np.int64),
        sorted_position=np.zeros((s, 4)),
        sorted_cell=np.zeros((s, 3), dtype=np.int64),
        hist_count=np.zeros(s, dtype=np.int64),
        hist_partner=np.zeros((s, k), dtype=np.int64),
        hist_xi=np.zeros((s, k, 3)),
        trial_count=np.zeros(s, dtype=np.int64),
        trial_partner=np.zeros((s, k), dtype=np.int64),
        trial_xi=np.zeros((s, k, 3)),
        trial_normal=np.zeros((s, k, 3)),
        trial_point=np.zeros((s, k, 3)),
        trial_limit=np.zeros((s, k)),
        stats=np.zeros(STAT_COUNT),
        counters=np.zeros(COUNTER_COUNT, dtype=np.int64),
        overflow_sphere=np.full(1, -1, dtype=np.int64),
    )
