"""The body level of the two-level broad phase (issue 28 item 2) against brute force.

On random scenes of many bodies (clouds of spheres, rotated; far apart, touching, nested: small bodies
inside a large body's box, static bodies among them) the grid over bodies (and its large-body list)
finds exactly the pairs an O(n^2) comparison of the same boxes finds; every box holds all its spheres;
every pair of bodies with two overlapping spheres (an O(S^2) sphere search) is a body pair, and every
body with a sphere overlapping a plane is flagged for that plane. The work (box tests) per body stays
flat from 4,000 to 64,000 bodies at one density: linear.
"""

from __future__ import annotations

import numpy as np
import pytest

from rbcli.physics.contact.body_phase import body_pairs_numpy, body_phase
from rbcli.physics.contact.tables import (
    ACTIVE_PAIR,
    FAT_AGE,
    FAT_PAIRS,
    FAT_WAIT,
    SWEEP_CHECKS,
    contact_table,
    make_contact_work,
)
from rbcli.physics.rotation import quat_to_matrix


def _random_rotations(rng: np.random.Generator, n: int) -> np.ndarray:
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def _scene(rng: np.random.Generator, bodies: int, box: float, nested: bool = False, static_share: float = 0.1):
    """(table, x, q): bodies of 1-6 spheres (offsets within 3 cm per axis, radii 0.5-3 cm) in a cube of side `box`;
    nested: the first body is a large hollow shell of spheres (radius 1 m) with the others inside its box."""
    sphere_body, offset, radius = [], [], []
    for b in range(bodies):
        if nested and b == 0:
            d = rng.normal(size=(200, 3))
            offset.append(d / np.linalg.norm(d, axis=1, keepdims=True))
            radius.append(np.full(200, 0.05))
            sphere_body.append(np.zeros(200, dtype=np.int64))
            continue
        k = int(rng.integers(1, 7))
        offset.append(rng.uniform(-0.03, 0.03, size=(k, 3)) if k > 1 else np.zeros((1, 3)))
        radius.append(rng.uniform(0.005, 0.03, k))
        sphere_body.append(np.full(k, b))
    inv_mass = np.where(rng.uniform(size=bodies) < static_share, 0.0, 1.0)
    table = contact_table(
        sphere_body=np.concatenate(sphere_body), sphere_offset=np.concatenate(offset),
        sphere_radius=np.concatenate(radius), body_inv_contact_mass=inv_mass, body_stiffness=np.ones(bodies),
        body_damping_ratio=np.zeros(bodies), body_friction=np.zeros(bodies),
        plane_point=[[0.0, 0.0, -0.5 * box], [0.0, 0.3 * box, 0.0]],
        plane_normal=[[0.0, 0.0, 1.0], [0.0, -0.6, 0.8]],
        plane_damping_ratio=[0.0, 0.0], plane_friction=[0.0, 0.0],
    )  # fmt: skip
    x = rng.uniform(-0.5 * box, 0.5 * box, (bodies, 3))
    if nested:
        x[0] = 0.0
        x[1:] = rng.uniform(-0.6, 0.6, (bodies - 1, 3))
    return table, x, _random_rotations(rng, bodies)


def _sphere_world(table, x: np.ndarray, q: np.ndarray) -> np.ndarray:  # noqa: ANN001
    b = table.sphere_body
    return x[b] + np.einsum("kij,kj->ki", quat_to_matrix(q[b]), table.sphere_offset)


def _run(table, x: np.ndarray, q: np.ndarray):  # noqa: ANN001, ANN202
    work = make_contact_work(table, x.shape[0])
    pairs = np.zeros((x.shape[0] * 64, 2), dtype=np.int64)
    count = body_phase(table, work, x, q, pairs)
    assert count <= pairs.shape[0]
    return work, {(int(a), int(b)) for a, b in pairs[:count]}, count


CASES = {
    "far apart": dict(bodies=300, box=40.0),
    "touching": dict(bodies=300, box=0.6),
    "nested": dict(bodies=150, box=1.0, nested=True),
}


@pytest.mark.parametrize("case", CASES, ids=list(CASES))
def test_body_pairs_equal_brute_force(case):
    rng = np.random.default_rng(len(case))
    table, x, q = _scene(rng, **CASES[case])
    work, found, count = _run(table, x, q)
    assert count == len(found)  # each pair once
    assert found == body_pairs_numpy(work.body_lo, work.body_hi, table.body_inv_contact_mass)
    # the boxes hold their spheres
    world = _sphere_world(table, x, q)
    r = table.sphere_radius[:, None]
    assert np.all(world - r >= work.body_lo[table.sphere_body]) and np.all(world + r <= work.body_hi[table.sphere_body])
    # every touching sphere pair of different bodies, not both of infinite mass, is in a body pair
    d = np.linalg.norm(world[:, None] - world[None], axis=-1)
    touching = d < table.sphere_radius[:, None] + table.sphere_radius[None]
    sb = table.sphere_body
    inv = table.body_inv_contact_mass
    touching &= (sb[:, None] != sb[None]) & ~((inv[sb][:, None] == 0) & (inv[sb][None] == 0))
    i, j = np.nonzero(np.triu(touching, k=1))
    needed = {(int(min(a, b)), int(max(a, b))) for a, b in zip(sb[i], sb[j], strict=True)}
    assert needed <= found
    for a, b in needed:
        assert work.body_active[a] & ACTIVE_PAIR and work.body_active[b] & ACTIVE_PAIR
    # every sphere overlapping a plane flags its (movable) body for that plane
    for p in range(table.plane_point.shape[0]):
        dist = (world - table.plane_point[p]) @ table.plane_normal[p]
        bodies = set(sb[(dist < table.sphere_radius) & (inv[sb] > 0)].tolist())
        assert all(work.body_plane[b, p] for b in bodies)
    if case == "far apart":
        assert count < 5 and not needed  # nothing to grid
    elif case == "touching":
        assert len(needed) > 20
    else:  # the shell's box holds every other body: a pair with each, though few spheres touch
        assert {(0, b) for b in range(1, x.shape[0])} <= found


def test_body_pairs_follow_the_bodies_as_they_move():
    """One work reused as the bodies move (a little, then a shuffle, then squeezed into a column): the
    pairs still equal brute force each time."""
    rng = np.random.default_rng(7)
    table, x, q = _scene(rng, bodies=400, box=0.8)
    work = make_contact_work(table, x.shape[0])
    pairs = np.zeros((20000, 2), dtype=np.int64)
    for move in ("small", "shuffle", "column"):
        if move == "small":
            x = x + rng.normal(scale=0.01, size=x.shape)
        elif move == "shuffle":
            x = x[rng.permutation(x.shape[0])]
        else:
            x = x[:, [2, 0, 1]] * np.array([0.1, 0.1, 10.0])
        count = body_phase(table, work, x, q, pairs)
        found = {(int(a), int(b)) for a, b in pairs[:count]}
        assert count == len(found) > 50, move
        assert found == body_pairs_numpy(work.body_lo, work.body_hi, table.body_inv_contact_mass), move


def test_a_large_body_among_small_ones_is_tested_against_all_of_them():
    """A 2 m shell among 1-6 cm bodies stays out of the body grid (its cell would hold everything) and
    is paired with each body inside its box."""
    rng = np.random.default_rng(3)
    table, x, q = _scene(rng, bodies=150, box=1.0, nested=True)
    assert table.body_large.tolist() == [True] + [False] * 149
    assert table.body_cell_size == pytest.approx(2 * table.body_bound_radius[1:].max())


def test_body_phase_work_grows_linearly():
    """Box tests per body stay flat from 4,000 to 64,000 bodies at one density, in a cube (a count, not a
    time: not flaky). Sort-and-sweep along one axis would grow as n^(2/3) here."""
    rates = []
    for bodies in (4_000, 16_000, 64_000):
        rng = np.random.default_rng(bodies)
        side = (bodies / 1000.0) ** (1 / 3) * 1.2  # 1,000 bodies per 1.73 m^3 at every count
        table, x, q = _scene(rng, bodies=bodies, box=side, static_share=0.0)
        work = make_contact_work(table, bodies)
        body_phase(table, work, x, q, np.zeros((0, 2), dtype=np.int64))
        rates.append(work.body_sweep[SWEEP_CHECKS] / bodies)
    assert max(rates) < 1.25 * min(rates), rates
    assert max(rates) < 60.0, rates  # the neighbours within a cell or two, not a scan of thousands


@pytest.mark.parametrize("outlier", [False, True], ids=["dense grid", "hashed grid"])
def test_the_force_stage_through_the_body_level_equals_brute_force(outlier):
    """Clouds of 3-5 spheres (the body level on: more than 2 spheres per body), some far apart, some
    touching, a static one and a tilted plane: the force stage's wrench equals the O(n^2) sum over every
    sphere pair and plane (contact_wrench_numpy), and it found the same number of contacts. A body a
    million metres away makes the grid over every sphere hashed, so the subset's grid is hashed too."""
    import rbcli
    from rbcli.physics.contact.force import accumulate_contact, hold_static_bodies
    from rbcli.physics.contact.reference import contact_wrench_numpy
    from rbcli.physics.contact.tables import STAT_CONTACTS
    from rbcli.scene.load import load_scene_text

    rng = np.random.default_rng(11)
    bodies = []
    for i in range(90):
        k = int(rng.integers(3, 6))
        pts = rng.uniform(-0.03, 0.03, (k, 3)).round(4).tolist()
        rad = rng.uniform(0.01, 0.03, k).round(4).tolist()
        pos = (rng.uniform(-0.3, 0.3, 3) + (np.array([5.0, 0.0, 0.0]) if i % 5 == 0 else 0.0)).tolist()
        motion = f", velocity: {rng.normal(size=3).tolist()}, angular_velocity: {rng.normal(size=3).tolist()}"
        motion = ", static: true" if i == 1 else motion
        bodies.append(f"  - {{name: c{i}, particles: {{positions: {pts}, masses: {[0.1] * k}, radius: {rad}}}, "
                      f"position: {pos}{motion}}}")  # fmt: skip
    if outlier:
        bodies.append("  - {name: far, particles: {positions: [[0, 0, 0], [0.01, 0, 0], [0, 0.01, 0]], "
                      "masses: [1, 1, 1], radius: [0.02, 0.02, 0.02]}, position: [1e6, -3e5, 2e5]}")  # fmt: skip
    text = ("simulation: {dt: 0.001, steps: 10, integrator: split2}\ncontact:\n"
            "  planes: [{point: [0, 0, -0.25], normal: [0.1, 0.2, 1], friction: 0.3}]\n"
            "  material: {restitution: 0.4, friction: 0.6}\nbodies:\n" + "\n".join(bodies) + "\n")  # fmt: skip
    sim = rbcli.Simulation(load_scene_text(text))
    contact = sim.model.contact
    assert not contact.body_level_off
    work = make_contact_work(contact, sim.model.body_count)
    s = sim.data.state
    F, tau = np.zeros_like(s.x), np.zeros_like(s.x)
    accumulate_contact(sim.model.kernel_bodies(), contact, work, 0.0, s.x, s.q, s.P, s.L, F, tau)
    hold_static_bodies(contact, F, tau)
    F_ref, tau_ref, found = contact_wrench_numpy(sim.model, contact, s.x, s.q, s.P, s.L)
    assert work.stats[STAT_CONTACTS] == found > 30
    assert work.body_sweep[2] < contact.sphere_radius.shape[0]  # some spheres were left out of the grid
    scale = np.abs(F_ref).max()
    np.testing.assert_allclose(F, F_ref, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(tau, tau_ref, rtol=0, atol=1e-12 * scale)


def test_kept_pairs_follow_small_moves_and_are_found_again_after_large_ones():
    """More than a few bodies keep their pairs between evaluations (body_phase.kept_box_pairs): after
    small moves the kept pairs are tested instead of walking the grid (fewer box tests than the first
    evaluation's walk), and after moves past the pads they are found again; every time the pairs equal
    brute force, in ascending (a, b) order."""
    rng = np.random.default_rng(11)
    table, x, q = _scene(rng, bodies=400, box=0.8)
    work = make_contact_work(table, x.shape[0])
    pairs = np.zeros((20000, 2), dtype=np.int64)
    cell = table.body_cell_size
    walked = None
    for move in ("none", "small", "small", "small", "far", "small", "small", "small"):
        if move == "small":  # well inside the pads (a tenth of a cell)
            x = x + rng.uniform(-0.01 * cell, 0.01 * cell, size=x.shape)
        elif move == "far":
            x = x + rng.uniform(-0.5 * cell, 0.5 * cell, size=x.shape)
        count = body_phase(table, work, x, q, pairs)
        found = [(int(a), int(b)) for a, b in pairs[:count]]
        assert found == sorted(found), move  # the bodies' order, whatever the grid's
        assert set(found) == body_pairs_numpy(work.body_lo, work.body_hi, table.body_inv_contact_mass), move
        assert count > 50
        checks = int(work.body_sweep[SWEEP_CHECKS])
        if move in ("none", "far"):
            walked = checks  # the padded boxes walked
            assert work.fat_state[FAT_AGE] == 1
        else:
            assert checks < walked, move  # the kept pairs tested, no walk
            assert work.fat_state[FAT_AGE] > 1


def test_bodies_faster_than_their_pads_walk_the_grid():
    """Bodies that leave their padded boxes within a few evaluations stop the keeping for a while: the
    tight boxes are walked, and the pairs still equal brute force in ascending order."""
    rng = np.random.default_rng(12)
    table, x, q = _scene(rng, bodies=300, box=0.6)
    work = make_contact_work(table, x.shape[0])
    pairs = np.zeros((20000, 2), dtype=np.int64)
    for _ in range(4):
        x = x + rng.uniform(-0.5, 0.5, size=x.shape) * table.body_cell_size
        count = body_phase(table, work, x, q, pairs)
        found = [(int(a), int(b)) for a, b in pairs[:count]]
        assert found == sorted(found)
        assert set(found) == body_pairs_numpy(work.body_lo, work.body_hi, table.body_inv_contact_mass)
    assert work.fat_state[FAT_WAIT] > 0 and work.fat_state[FAT_PAIRS] < 0  # walking, not keeping
