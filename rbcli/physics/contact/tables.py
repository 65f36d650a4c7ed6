"""Contact parameters (read-only, the model's `contact`) and contact work arrays (mutable, in the run's Data).

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

# ContactWork.body_active flags (body_phase.py)
ACTIVE_PAIR = 1  # in a body pair: its spheres join the sphere grid
ACTIVE_PLANE = 2  # near a plane: its spheres are tested against the flagged planes

# ContactWork.body_sweep slots (body_phase.py)
SWEEP_PAIRS, SWEEP_CHECKS, SWEEP_SPHERES = range(3)
SWEEP_COUNT = 3
# ContactWork.row_counts: the rows listed in trial_rows and in history_rows (-1: history rows not known)
ROWS_TRIAL, ROWS_HISTORY = range(2)
# ContactWork.fat_state (body_phase.kept_box_pairs): the pairs kept (-1: none), evaluations to wait before
# keeping pairs again, evaluations since they were found
FAT_PAIRS, FAT_WAIT, FAT_AGE = range(3)
# a body whose rho_max is above this many times the median is kept out of the body grid (body_phase.py)
LARGE_BODY = 4.0

# The threaded contact search (threaded.py): walkers per block of records, and the rows a block holds
# per walker. A walker finds ~2 contacts in a settled pile of equal balls (at most 6: half of the
# kissing number), ~0.2 per sphere of a cloud; a block that finds more than its rows is searched again
# serially.
RECORD_BLOCK = 64
RECORDS_PER_WALKER = 4
# a record's int64 columns: owner and partner (search.py), their bodies (-1: a plane)
RECORD_INT_OWNER, RECORD_INT_PARTNER, RECORD_INT_BODY_A, RECORD_INT_BODY_B = range(4)
RECORD_INT_COUNT = 4
# its float64 columns: the normal n, the overlap d, the point c, friction (1.0 or 0.0), then what
# law.contact_values computed: f, u, the Coulomb limit and the energy
RECORD_NORMAL, RECORD_OVERLAP, RECORD_POINT, RECORD_FRICTION = 0, 3, 4, 7
RECORD_FORCE, RECORD_ELONGATION, RECORD_LIMIT, RECORD_ENERGY = 8, 11, 14, 15
RECORD_COUNT = 16

# ContactWork.quiet_state slots (quiet.py): 1 while no contact is possible within the skins; the commits
# left to wait before the next try after a failed one; 1 once a window has been set; 1 while the window is
# sure (every body's steady acceleration keeps it within its skin: no evaluation tests the paths)
QUIET_ON, QUIET_WAIT, QUIET_ARMED, QUIET_SURE = range(4)


class ContactTable(NamedTuple):
    """Contact geometry and materials of a scene (read-only)."""

    sphere_body: np.ndarray  # int64 (sphere_count,), body of each contact sphere, spheres grouped by body
    sphere_offset: np.ndarray  # [m] (sphere_count, 3), principal frame, about the body's centre of mass
    sphere_radius: np.ndarray  # [m] (sphere_count,)
    # [1/kg] (body_count,): support / M, the inverse of the mass one contact sphere carries when the body
    # rests on its `support` spheres (parameters.support_count); 0 for a static body. The dashpot of a
    # contact uses it, so a body resting on n spheres has the damping ratio its material asks for
    # (with the whole mass per sphere, n contacts would damp like sqrt(n) zeta: overdamped, unstable). A
    # body touching as its primitive: 1 / M (primitive_search.py shares it among a manifold's points)
    body_inv_contact_mass: np.ndarray
    body_stiffness: np.ndarray  # k [N/m] (body_count,) per contact sphere (a primitive: per manifold point)
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
    # the body level of the broad phase (body_phase.py): spheres of body b are body_sphere_start[b] :
    # body_sphere_start[b + 1] (int64, body_count + 1); the box of its spheres (radii included) in the
    # principal frame, centre [m] and half extents [m] (body_count, 3; -inf: no spheres); rho_max [m]
    # (body_count,), the farthest sphere surface from the centre of mass (-inf: no spheres)
    body_sphere_start: np.ndarray
    body_box_centre: np.ndarray
    body_box_half: np.ndarray
    body_bound_radius: np.ndarray
    body_large: np.ndarray  # bool (body_count,): rho_max > LARGE_BODY x the median, outside the body grid
    body_cell_size: float  # [m] the body grid's cell: the largest 2 rho_max of the other bodies
    body_level_off: bool  # spheres <= 2 colliding bodies: the body level is skipped (body_phase.py)
    cell_size: float  # [m] broad-phase grid cell: the largest sphere diameter
    sphere_radius_min: float  # [m] the smallest sphere radius (body_phase.whole_grid_hashed)
    tangential_ratio: float  # k_t / k_n of every contact
    bucket_count: int  # size of the broad phase's bucket table (see broad_phase.py)
    # [s] the smallest stable step of the contacts the scene can form (parameters.stable_step; inf: none
    # can collide): adaptive stepping never steps longer (physics/adaptive.py)
    stable_step: float = math.inf
    # int64 sorted keys a * body_count + b (a < b) of the body pairs that never collide: the two bodies
    # of a joint without `collide: true` (docs/joints.md); empty for a scene without joints, where the
    # pair search pays one length test per overlapping pair
    excluded_pair: np.ndarray = np.zeros(0, dtype=np.int64)
    # [1/kg] (body_count,): the inverse contact mass of a body's plane contacts, body_inv_contact_mass but
    # for a body that touches planes as its primitive: points / M, its manifold points sharing its mass
    # (docs/contact.md "Primitive contact")
    body_plane_inv_contact_mass: np.ndarray = np.zeros(0)
    # a shape body's primitive (docs/contact.md "Primitive contact"), against planes and bodies in place of
    # its contact spheres (its mass only): kind (int64 (body_count,): primitives.PRIMITIVE_*, -1 none),
    # centre [m] (body_count, 3) and rotation (body_count, 3, 3; columns: its axes) in the principal frame,
    # size [m] (body_count, 3)
    primitive_kind: np.ndarray = np.zeros(0, dtype=np.int64)
    primitive_offset: np.ndarray = np.zeros((0, 3))
    primitive_rotation: np.ndarray = np.zeros((0, 3, 3))
    primitive_size: np.ndarray = np.zeros((0, 3))
    # [m/s^2] (body_count,): |a| of a body whose linear acceleration is the same at every time and state
    # (gravity, constant world forces; scene/compile_contact.py steady_accelerations), inf for any other;
    # the quiet skin's sure windows (quiet.py). Empty: none known (every quiet evaluation tests the paths)
    body_steady_accel: np.ndarray = np.zeros(0)


# contacts a step reduced-implicit treats implicitly (implicit_rows.py; the rows of its dense solve are at
# most 3 a contact: its normal and, with friction, its two tangent directions)
IMPLICIT_CAPACITY = 128
IMPLICIT_COLUMNS = 24  # implicit_rows.py's IMP_* columns of a kept contact
IMPLICIT_ROW_COLUMNS = 13  # tree/implicit_contact.py's ROW_* columns of a solve's row


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
    # the body level of the broad phase (body_phase.py), per evaluation
    body_lo: np.ndarray  # [m] (body_count, 3), world box of each body's spheres
    body_hi: np.ndarray  # [m] (body_count, 3)
    body_cell: np.ndarray  # int64 (body_count, 3), body grid cell of each box centre
    body_bucket: np.ndarray  # int64 (body_count,), its hashed bucket (-1: not in the grid)
    body_bucket_start: np.ndarray  # int64 (buckets + 1,), buckets a power of two >= 2 body_count
    body_sorted: np.ndarray  # int64 (body_count,), gridded bodies ordered by bucket
    body_active: np.ndarray  # uint8 (body_count,), body_phase.ACTIVE_PAIR | ACTIVE_PLANE
    body_plane: np.ndarray  # uint8 (body_count, plane_count), 1: the body's box meets the plane
    body_sweep: np.ndarray  # int64 (SWEEP_COUNT,): body pairs, box tests, spheres gridded
    active_sphere: np.ndarray  # int64 (sphere_count,), the spheres of bodies in body pairs, ascending
    # the rows (spheres) holding trial contacts of this evaluation, in the order they got their first
    # (law.apply_contact), and the rows holding history after the last commit (force.commit_contacts):
    # int64 (sphere_count,) each; ROWS_TRIAL, ROWS_HISTORY their counts (ROWS_HISTORY -1: not known, as
    # after a restore: the commit then visits every row)
    trial_rows: np.ndarray
    history_rows: np.ndarray
    row_counts: np.ndarray
    body_pair_none: np.ndarray  # int64 (0, 2): quiet.py takes box_pairs' answer, not its pair list
    # the body pairs (a < b) body_phase found (narrow.py; 0 rows where the body level is off)
    body_pair: np.ndarray  # int64 (capacity, 2)
    # the body pairs kept between evaluations (body_phase.kept_box_pairs): each body's padded box when
    # they were found [m] (body_count, 3); the pairs of padded boxes that meet, (a, b) ascending, int64
    # (capacity, 2), and the walk's unsorted list of them; per body the start of its pairs (body_count + 1,);
    # a scratch of flags (body_count,); int64 (3,) FAT_PAIRS (-1: none kept), FAT_WAIT, FAT_AGE
    fat_lo: np.ndarray
    fat_hi: np.ndarray
    fat_pair: np.ndarray
    fat_found: np.ndarray
    fat_start: np.ndarray
    fat_active: np.ndarray
    fat_state: np.ndarray
    # the quiet skin (quiet.py): int64 (4,) QUIET_ON, QUIET_WAIT, QUIET_ARMED, QUIET_SURE; each body's
    # position [m] and velocity [m/s] (body_count, 3) when it was set, how far [m] (body_count,) it may
    # stray (max norm) from that straight path, its acceleration [m/s^2] (body_count,) over the last
    # window, and the window [t0, t_end] [s] with the (sub-)step h [s] it was set for (3,)
    quiet_state: np.ndarray
    quiet_reference: np.ndarray
    quiet_velocity: np.ndarray
    quiet_skin: np.ndarray
    quiet_accel: np.ndarray
    quiet_window: np.ndarray
    # the threaded contact search (threaded.py), per block of RECORD_BLOCK walkers: its rows
    # (RECORD_BLOCK * RECORDS_PER_WALKER each, block after block: RECORD_INT_* int64 and RECORD_* float64
    # columns), how many contacts it found (int64 (blocks,); more than its rows: the block is searched
    # again serially) and its candidate pairs (int64 (blocks,)). None in a serial run: numba compiles no
    # threaded code for it. (Arrays of their own, not a tuple in this one: numba's parallel loops
    # cannot take a tuple nested in a tuple.)
    # the sphere pairs of the body pairs (narrow.py; None where the body level is off: numba then compiles
    # none of it, ~8 s of a cold first run): the spheres of each side of one pair that meet the other's
    # box and the other side's positions and radii, one run per thread, each run's found, tests and
    # cost, the contacts found (walker, partner) and their sort keys, the sort's permutations and
    # histogram, the tests made
    pair_side: np.ndarray | None = None  # int64 (runs, 2, largest body's spheres)
    pair_near: np.ndarray | None = None  # (runs, largest body's spheres, 4): x, y, z [m] and r [m]
    pair_tally: np.ndarray | None = None  # int64 (runs, 8)
    pair_found: np.ndarray | None = None  # int64 (capacity, 2)
    pair_key: np.ndarray | None = None  # int64 (capacity, 2)
    pair_order: np.ndarray | None = None  # int64 (2, capacity)
    pair_radix: np.ndarray | None = None  # int64 (2^11 + 1,)
    pair_tests: np.ndarray | None = None  # int64 (1,)
    record_int: np.ndarray | None = None
    record_float: np.ndarray | None = None
    record_count: np.ndarray | None = None
    record_candidates: np.ndarray | None = None
    # the primitives' contacts (search.py, primitive_search.py; None in a scene without primitives: numba
    # then compiles none of it): each primitive's world centre [m] (body_count, 3) and rotation
    # (body_count, 3, 3) of the evaluation, and a manifold's rows (manifold.py: point, normal, depth, feature)
    primitive_centre: np.ndarray | None = None
    primitive_frame: np.ndarray | None = None
    manifold_point: np.ndarray | None = None
    manifold_normal: np.ndarray | None = None
    manifold_depth: np.ndarray | None = None
    manifold_feature: np.ndarray | None = None
    # [m] (body_count + 1, 3): ContactTable.primitive_size, writable (primitive_search.py passes each pair's
    # sizes from one array type, so primitive_pair compiles once), and a last row for a cloud sphere's (r, 0, 0)
    primitive_shape: np.ndarray | None = None
    # the contacts of the last force evaluation for linearly implicit contact (implicit_rows.py; None
    # unless the integrator has `implicit_contact`: numba then compiles none of it): their bodies, their
    # values (implicit_rows.IMP_* columns), how many (and how many past the capacity), and the tree
    # stage's scratch (tree/implicit_contact.py)
    implicit_int: np.ndarray | None = None
    implicit_float: np.ndarray | None = None
    implicit_count: np.ndarray | None = None
    implicit_matrix: np.ndarray | None = None
    implicit_row: np.ndarray | None = None
    implicit_force: np.ndarray | None = None
    implicit_torque: np.ndarray | None = None
    implicit_link: np.ndarray | None = None


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
    excluded_pair=(),  # noqa: ANN001
    body_plane_inv_contact_mass=None,  # noqa: ANN001
    primitive_kind=None,  # noqa: ANN001
    primitive_offset=None,  # noqa: ANN001
    primitive_rotation=None,  # noqa: ANN001
    primitive_size=None,  # noqa: ANN001
    body_steady_accel=(),  # noqa: ANN001
) -> ContactTable:
    """A ContactTable with consistent dtypes (all empty: a scene without contact). Without primitives
    every body's kind is -1 and its plane contacts take body_inv_contact_mass."""
    radius = _ro(sphere_radius, np.float64)
    spheres = radius.shape[0]
    bodies = len(np.asarray(body_inv_contact_mass))
    start, centre, half, rho = body_boxes_numpy(
        np.asarray(sphere_body, dtype=np.int64).reshape(-1), np.asarray(sphere_offset, dtype=float).reshape(-1, 3),
        radius, bodies,
    )  # fmt: skip
    kind = np.full(bodies, -1, dtype=np.int64) if primitive_kind is None else np.asarray(primitive_kind, np.int64)
    prim_offset = np.zeros((bodies, 3)) if primitive_offset is None else np.asarray(primitive_offset, float)
    prim_rotation = np.tile(np.eye(3), (bodies, 1, 1))
    if primitive_rotation is not None:
        prim_rotation = np.asarray(primitive_rotation, float)
    prim_size = np.zeros((bodies, 3)) if primitive_size is None else np.asarray(primitive_size, float)
    if (kind >= 0).any():  # the body boxes hold the primitives too (the body phase flags their planes)
        centre, half, rho = primitive_boxes_numpy(centre, half, rho, kind, prim_offset, prim_rotation, prim_size)
    finite = rho >= 0.0
    large = finite & (rho > LARGE_BODY * (np.median(rho[finite]) if finite.any() else 0.0))
    regular = finite & ~large
    body_cell = float(2.0 * rho[regular].max()) if regular.any() else 1.0
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
        body_sphere_start=_ro(start, np.int64),
        body_box_centre=_ro(centre, np.float64, 3),
        body_box_half=_ro(half, np.float64, 3),
        body_bound_radius=_ro(rho, np.float64),
        body_large=_ro(large, np.bool_),
        body_cell_size=body_cell,
        # a primitive's pairs come from the body pairs (primitive_search.py): never off with primitives
        body_level_off=bool(spheres <= 2 * int(finite.sum())) and not bool((kind >= 0).any()),
        cell_size=float(2.0 * radius.max()) if spheres else 1.0,
        sphere_radius_min=float(radius.min()) if spheres else 0.0,
        tangential_ratio=float(tangential_ratio),
        bucket_count=int(buckets),
        stable_step=float(stable_step),
        excluded_pair=excluded_pair_keys(excluded_pair, bodies),
        body_plane_inv_contact_mass=_ro(
            body_inv_contact_mass if body_plane_inv_contact_mass is None else body_plane_inv_contact_mass, np.float64
        ),
        primitive_kind=_ro(kind, np.int64),
        primitive_offset=_ro(prim_offset, np.float64, 3),
        primitive_rotation=_ro(prim_rotation, np.float64, 3, 3),
        primitive_size=_ro(prim_size, np.float64, 3),
        body_steady_accel=_ro(body_steady_accel, np.float64),
    )


def primitive_extent(kind: int, rotation: np.ndarray, size: np.ndarray) -> tuple[np.ndarray, float]:
    """(half extents [m] of the box about its centre that holds a primitive (kind PRIMITIVE_*: 0 sphere, 1
    capsule, 2 box) of `rotation` (columns: its axes) and `size`, its bound radius [m] about its centre)."""
    if kind == 0:
        return np.full(3, size[0]), float(size[0])
    if kind == 1:
        return np.abs(rotation[:, 2]) * size[1] + size[0], float(size[0] + size[1])
    return np.abs(rotation) @ size[:3], float(np.linalg.norm(size[:3]))


def primitive_boxes_numpy(
    centre: np.ndarray, half: np.ndarray, rho: np.ndarray, kind: np.ndarray, offset: np.ndarray,
    rotation: np.ndarray, size: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """The body boxes (centre, half extents, rho_max; body_boxes_numpy) grown to hold each body's primitive."""
    centre, half, rho = centre.copy(), half.copy(), rho.copy()
    for b in np.flatnonzero(kind >= 0):
        extent, bound = primitive_extent(int(kind[b]), rotation[b], size[b])
        lo, hi = offset[b] - extent, offset[b] + extent
        if np.isfinite(rho[b]):
            lo, hi = np.minimum(lo, centre[b] - half[b]), np.maximum(hi, centre[b] + half[b])
        centre[b], half[b] = 0.5 * (lo + hi), 0.5 * (hi - lo)
        rho[b] = max(rho[b], float(np.linalg.norm(offset[b])) + bound)
    return centre, half, rho


def touching_spheres(contact: ContactTable) -> int:
    """The contact spheres that touch anything: those of bodies that do not touch as their primitive shape
    (a shape body's lattice spheres are its mass only: primitive_search.py)."""
    body = np.asarray(contact.sphere_body)
    if body.shape[0] == 0:
        return 0
    return int(np.count_nonzero(np.asarray(contact.primitive_kind)[body] < 0))


def contact_present(contact: ContactTable | None) -> bool:
    """True when the scene has a contact stage: contact spheres or static bodies."""
    return contact is not None and bool(contact.sphere_body.shape[0] or contact.static_body.shape[0])


def check_contact_table(contact: ContactTable, body_count: int) -> None:
    """ValueError unless the contact table's per-body arrays have body_count rows and its spheres and
    static bodies name bodies in range (the kernels index with them unchecked)."""
    if not contact.sphere_body.size:
        return
    for name in (
        "body_inv_contact_mass",
        "body_stiffness",
        "body_plane_stiffness",
        "body_damping_ratio",
        "body_friction",
    ):
        if getattr(contact, name).shape != (body_count,):
            raise ValueError(f"contact {name} has shape {getattr(contact, name).shape}, expected ({body_count},)")
    for name in ("sphere_body", "static_body"):
        body = getattr(contact, name)
        if body.size and (body.min() < 0 or body.max() >= body_count):
            raise ValueError(f"contact {name} names body {body.min()}..{body.max()}, outside 0..{body_count - 1}")


def excluded_pair_keys(pairs: object, body_count: int) -> np.ndarray:
    """The sorted, unique keys min * body_count + max of body pairs (k, 2) (ContactTable.excluded_pair)."""
    p = np.asarray(pairs, dtype=np.int64).reshape(-1, 2)
    keys = np.unique(np.minimum(p[:, 0], p[:, 1]) * body_count + np.maximum(p[:, 0], p[:, 1]))
    return _ro(keys, np.int64)


def body_boxes_numpy(
    sphere_body: np.ndarray, sphere_offset: np.ndarray, sphere_radius: np.ndarray, body_count: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(body_sphere_start (body_count + 1,), box centre c (body_count, 3) and half extents e (body_count,
    3) [m] in the principal frame, bound radius rho_max (body_count,) [m]) of each body's contact spheres
    (spheres grouped by body, ascending); a body without spheres gets an empty box (e = -inf)."""
    start = np.zeros(body_count + 1, dtype=np.int64)
    np.add.at(start, sphere_body + 1, 1)
    start = np.cumsum(start)
    lo = np.full((body_count, 3), np.inf)
    hi = np.full((body_count, 3), -np.inf)
    r = sphere_radius[:, None]
    np.minimum.at(lo, sphere_body, sphere_offset - r)
    np.maximum.at(hi, sphere_body, sphere_offset + r)
    rho = np.full(body_count, -np.inf)
    np.maximum.at(rho, sphere_body, np.linalg.norm(sphere_offset, axis=1) + sphere_radius)
    empty = ~np.isfinite(rho)
    filled_lo, filled_hi = np.where(empty[:, None], 0.0, lo), np.where(empty[:, None], 0.0, hi)  # inf - inf: no
    centre = 0.5 * (filled_lo + filled_hi)
    half = np.where(empty[:, None], -np.inf, 0.5 * (filled_hi - filled_lo))
    return start, centre, half, rho


def pair_capacities(body_count: int, sphere_count: int, level_off: bool, largest_body: int) -> tuple[int, int, int]:
    """The buffers of the sphere pairs of the body pairs (narrow.py): body pairs, contacts found, spheres
    of one body; all 0 where the body level is off (bodies of about one sphere: the walk is the body
    grid). Too small for a state, they send that evaluation to the walk."""
    if level_off or sphere_count == 0:
        return 0, 0, 0
    return 16 * body_count + 64, 4 * sphere_count + 64, largest_body


def make_contact_work(
    contact: ContactTable, body_count: int, *, history: bool = True, threads: int = 1, implicit: bool = False
) -> ContactWork:
    """Zeroed work arrays for `contact` (0-sized without contact spheres: nothing is allocated).
    history=False: no history or trial slots (a scratch for the search alone: contact/points.py);
    threads > 1: the pair search runs on that many threads (threaded.py), with its record blocks;
    implicit: the force stage keeps its contacts for linearly implicit contact (implicit_rows.py; the
    Simulation asks for a serial search then: threads 1, as its report says)."""
    s = contact.sphere_radius.shape[0]
    b = body_count if s else 0
    threaded = threads > 1 and history and s > 0
    blocks = -(-s // RECORD_BLOCK)
    rows = blocks * RECORD_BLOCK * RECORDS_PER_WALKER
    k = HISTORY_SLOTS if s and history else 0
    largest = int(np.diff(contact.body_sphere_start).max()) if b else 0
    pair_cap, found_cap, side_cap = pair_capacities(b, s, bool(contact.body_level_off), largest)
    runs = max(1, threads) if history else 1
    paired = found_cap > 0
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
        body_lo=np.zeros((b, 3)),
        body_hi=np.zeros((b, 3)),
        body_cell=np.zeros((b, 3), dtype=np.int64),
        body_bucket=np.zeros(b, dtype=np.int64),
        body_bucket_start=np.zeros(((1 << max(1, 2 * b - 1).bit_length()) + 1) if b else 1, dtype=np.int64),
        body_sorted=np.zeros(b, dtype=np.int64),
        body_active=np.zeros(b, dtype=np.uint8),
        body_plane=np.zeros((b, contact.plane_point.shape[0] if s else 0), dtype=np.uint8),
        body_sweep=np.zeros(SWEEP_COUNT, dtype=np.int64),
        active_sphere=np.zeros(s, dtype=np.int64),
        trial_rows=np.zeros(s, dtype=np.int64),
        history_rows=np.zeros(s, dtype=np.int64),
        row_counts=np.zeros(2, dtype=np.int64),
        body_pair_none=np.zeros((0, 2), dtype=np.int64),
        body_pair=np.zeros((pair_cap, 2), dtype=np.int64),
        fat_lo=np.full((b, 3), np.inf),
        fat_hi=np.full((b, 3), -np.inf),
        fat_pair=np.zeros((pair_cap, 2), dtype=np.int64),
        fat_found=np.zeros((pair_cap, 2), dtype=np.int64),
        fat_start=np.zeros(b + 1, dtype=np.int64),
        fat_active=np.zeros(b, dtype=np.uint8),
        fat_state=np.array([-1, 0, 0], dtype=np.int64),
        quiet_state=np.zeros(4, dtype=np.int64),
        quiet_reference=np.zeros((b, 3)),
        quiet_velocity=np.zeros((b, 3)),
        quiet_skin=np.zeros(b),
        quiet_accel=np.zeros(b),
        quiet_window=np.zeros(3),
        pair_side=np.zeros((runs, 2, side_cap), dtype=np.int64) if paired else None,
        pair_near=np.zeros((runs, side_cap, 4)) if paired else None,
        pair_tally=np.zeros((runs, 8), dtype=np.int64) if paired else None,
        pair_found=np.zeros((found_cap, 2), dtype=np.int64) if paired else None,
        pair_key=np.zeros((found_cap, 2), dtype=np.int64) if paired else None,
        pair_order=np.zeros((2, found_cap), dtype=np.int64) if paired else None,
        pair_radix=np.zeros((1 << 11) + 1, dtype=np.int64) if paired else None,
        pair_tests=np.zeros(1, dtype=np.int64) if paired else None,
        record_int=np.zeros((rows, RECORD_INT_COUNT), dtype=np.int64) if threaded else None,
        record_float=np.zeros((rows, RECORD_COUNT)) if threaded else None,
        record_count=np.zeros(blocks, dtype=np.int64) if threaded else None,
        record_candidates=np.zeros(blocks, dtype=np.int64) if threaded else None,
        **primitive_work(contact, b),
        **(_implicit_work(b) if implicit and history and s else {}),
    )


def _implicit_work(body_count: int) -> dict[str, np.ndarray]:
    """ContactWork's implicit_* arrays (make_contact_work with implicit=True; implicit_rows.py fills them)."""
    rows = 3 * IMPLICIT_CAPACITY
    return dict(
        implicit_int=np.zeros((IMPLICIT_CAPACITY, 2), dtype=np.int64),  # body_a, body_b (-1: a plane)
        implicit_float=np.zeros((IMPLICIT_CAPACITY, IMPLICIT_COLUMNS)),  # implicit_rows.IMP_* columns
        implicit_count=np.zeros(2, dtype=np.int64),  # contacts kept, contacts past the capacity (all evaluations)
        implicit_matrix=np.zeros((2, rows, rows)),  # the rows' h A = h J M^-1 J^T, and a factor's scratch
        implicit_row=np.zeros((rows, IMPLICIT_ROW_COLUMNS)),  # tree/implicit_contact.py's per-row scratch
        implicit_force=np.zeros((body_count, 3)),  # a wrench on the bodies (force [N], torque [N m] about x)
        implicit_torque=np.zeros((body_count, 3)),
        implicit_link=np.zeros(body_count, dtype=np.int64),  # each body's link (-1: not a link)
    )


def primitive_work(contact: ContactTable, body_count: int) -> dict[str, np.ndarray | None]:
    """ContactWork's primitive arrays: None where no body has a primitive (make_contact_work)."""
    if not body_count or not (contact.primitive_kind >= 0).any():
        return {}
    rows = 8  # manifold.MANIFOLD_ROWS (this module imports numpy only; tested equal)
    return dict(
        primitive_centre=np.zeros((body_count, 3)),
        primitive_frame=np.zeros((body_count, 3, 3)),
        manifold_point=np.zeros((rows, 3)),
        manifold_normal=np.zeros((rows, 3)),
        manifold_depth=np.zeros(rows),
        manifold_feature=np.zeros(rows, dtype=np.int64),
        primitive_shape=np.concatenate([contact.primitive_size, np.zeros((1, 3))]),
    )
