"""The sphere pairs of the body pairs (physics/contact/narrow.py): in scenes of bodies of many spheres
the contacts are found from the body level's pairs and put in the walk's order, so everything the search
hands on (which contacts, in which order, with which numbers) is what the sphere grid's walk hands on,
bit for bit, with far fewer distance checks; and where its buffers or its budget do not fit, or the
grid is hashed, the walk is taken.

Each comparison runs the same state through the search twice, once as configured and once with the
pair path switched off (a work without its buffers), and compares every output exactly: a contact
dropped, added, found twice or handed on out of order changes a sum's last bits; and the order the
force stage hands them on is compared with the recorded contact points' (that stream walks).
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

import rbcli
import rbcli.runner.threads as threads_module
from rbcli.physics.contact.force import accumulate_contact
from rbcli.physics.contact.points import contact_points
from rbcli.physics.contact.tables import COUNT_CANDIDATES, COUNT_CONTACTS, make_contact_work
from rbcli.physics.rotation import quat_to_matrix
from rbcli.scene.load import load_scene_text


def _clouds(side: int, seed: int, *, outlier: bool = False, spacing: float = 0.1, threads: int = 1) -> rbcli.Simulation:
    """side^3 bodies of 4-9 overlapping spheres each (random sizes, offsets, orientations and spins) on
    a jittered lattice whose neighbours touch at their fringes, as in a pile of pebbles, the lowest layer
    into a tilted plane."""
    rng = np.random.default_rng(seed)
    bodies = []
    for i in range(side**3):
        n = int(rng.integers(4, 10))
        pts = rng.normal(scale=0.022, size=(n, 3)).round(4).tolist()
        rad = rng.uniform(0.012, 0.026, n).round(4).tolist()
        masses = rng.uniform(0.05, 0.3, n).round(3).tolist()
        q = rng.normal(size=4)
        q = (q / np.linalg.norm(q)).tolist()
        where = (np.array([i % side, i // side % side, i // side**2]) * spacing + rng.uniform(-0.01, 0.01, 3)).tolist()
        bodies.append(
            f"  - {{name: c{i}, particles: {{positions: {pts}, masses: {masses}, radius: {rad}}}, "
            f"position: {where}, orientation: {{wxyz: {q}}}, "
            f"velocity: {rng.normal(size=3).tolist()}, angular_velocity: {rng.normal(size=3).tolist()}}}"
        )
    if outlier:  # one body a million metres away: the sphere grid is hashed
        bodies.append("  - {name: far, particles: {positions: [[0, 0, 0], [0.05, 0, 0]], masses: [1, 1], "
                      "radius: [0.03, 0.03]}, position: [1000000.0, -300000.0, 200000.0]}")  # fmt: skip
    text = (
        "name: clouds\nsimulation: {dt: 0.001, steps: 10, integrator: split2}\ncontact:\n"
        "  planes: [{point: [0, 0, 0.02], normal: [0.1, 0.2, 1], friction: 0.3}]\n"
        "  material: {restitution: 0.4, friction: 0.6}\nbodies:\n" + "\n".join(bodies) + "\n"
    )
    return rbcli.Simulation(load_scene_text(text), threads=threads)


def _without_pairs(work):  # noqa: ANN001, ANN202
    return work._replace(pair_found=np.zeros((0, 2), dtype=np.int64))


def _search(sim: rbcli.Simulation, work) -> tuple[np.ndarray, ...]:  # noqa: ANN001
    """One force evaluation of sim's state with `work`: its forces, trial springs and statistics."""
    s = sim.data.state
    F, tau = np.zeros_like(s.x), np.zeros_like(s.x)
    accumulate_contact(sim.model.kernel_bodies(), sim.model.contact, work, 0.0, s.x, s.q, s.P, s.L, F, tau)
    trial = [getattr(work, name).copy() for name in ("trial_count", "trial_partner", "trial_xi", "trial_normal",
                                                     "trial_point", "trial_limit")]  # fmt: skip
    return F, tau, *trial, work.stats.copy(), work.counters[COUNT_CONTACTS]


def _points(sim: rbcli.Simulation, work) -> np.ndarray:  # noqa: ANN001
    """The contact points [m] in the order the search hands them on (the contact-points stream)."""
    s = sim.data.state
    point, force = np.zeros((4096, 3)), np.zeros(4096)
    found = contact_points(sim.model.kernel_bodies(), sim.model.contact, work, s.x, s.q, s.P, s.L, point, force)
    assert found < 4096
    return point[:found]


def _sphere_positions(sim: rbcli.Simulation) -> np.ndarray:
    """p = x_b + R_b r0 of every contact sphere [m] (numpy)."""
    contact, s = sim.model.contact, sim.data.state
    body = contact.sphere_body
    return s.x[body] + np.einsum("nij,nj->ni", quat_to_matrix(s.q[body]), contact.sphere_offset)


def _plane_contacts(sim: rbcli.Simulation) -> int:
    """Spheres overlapping the scene's plane (numpy)."""
    contact = sim.model.contact
    p = _sphere_positions(sim)
    normal = contact.plane_normal[0]
    return int(((p - contact.plane_point[0]) @ normal < contact.sphere_radius).sum())


def _pair_points(sim: rbcli.Simulation, pairs: np.ndarray) -> np.ndarray:
    """The contact point of each pair of spheres (search.py's formula, numpy): halfway through the
    overlap, from the lower index's partner."""
    contact = sim.model.contact
    p = _sphere_positions(sim)
    i, j = pairs.min(axis=1), pairs.max(axis=1)
    d = p[i] - p[j]
    dist = np.linalg.norm(d, axis=1)
    overlap = contact.sphere_radius[i] + contact.sphere_radius[j] - dist
    return p[j] + (contact.sphere_radius[j] - 0.5 * overlap)[:, None] * d / dist[:, None]


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_the_pairs_of_the_body_pairs_are_the_walks_contacts_in_its_order(seed):
    sim = _clouds(5, seed)
    contact, bodies = sim.model.contact, sim.model.body_count
    assert not contact.body_level_off  # bodies of many spheres: the body level and the pair path run
    paired, walked = make_contact_work(contact, bodies), _without_pairs(make_contact_work(contact, bodies))
    mine, theirs = _search(sim, paired), _search(sim, walked)
    assert theirs[-1] > 100  # many contacts
    for a, b in zip(mine, theirs, strict=True):
        assert np.array_equal(a, b)
    assert 0 < paired.pair_tests[0] == paired.counters[COUNT_CANDIDATES]  # the pair path was taken
    # the order the force stage handed them on (pair_found, sorted) is the walk's: the recorded contact
    # points (that stream walks) are, after the plane contacts, the points of these pairs in this order
    pairs = paired.pair_found[: int(paired.stats[0]) - _plane_contacts(sim)]
    walked_points = _points(sim, make_contact_work(contact, bodies, history=False))
    np.testing.assert_allclose(walked_points[-len(pairs) :], _pair_points(sim, pairs), rtol=0, atol=1e-12)


def test_the_walk_is_taken_where_the_pairs_do_not_fit_or_the_grid_is_hashed():
    sim = _clouds(4, 5)
    contact, bodies = sim.model.contact, sim.model.body_count
    walked = _search(sim, _without_pairs(make_contact_work(contact, bodies)))
    narrow = make_contact_work(contact, bodies)._replace(  # room for 3 contacts
        pair_found=np.zeros((3, 2), dtype=np.int64), pair_key=np.zeros((3, 2), dtype=np.int64),
        pair_order=np.zeros((2, 3), dtype=np.int64),
    )  # fmt: skip
    few_pairs = make_contact_work(contact, bodies)._replace(body_pair=np.zeros((2, 2), dtype=np.int64))
    for work in (narrow, few_pairs):
        for a, b in zip(_search(sim, work), walked, strict=True):
            assert np.array_equal(a, b)
        assert work.pair_tests[0] == 0  # the pair path gave up before handing anything on
    hashed = _clouds(4, 5, outlier=True)
    work = make_contact_work(hashed.model.contact, hashed.model.body_count)
    theirs = _search(hashed, _without_pairs(make_contact_work(hashed.model.contact, hashed.model.body_count)))
    for a, b in zip(_search(hashed, work), theirs, strict=True):
        assert np.array_equal(a, b)
    assert work.pair_tests[0] == 0


@pytest.mark.parametrize("threads", [1, 2])
def test_a_run_with_the_pair_path_carries_the_bits_of_a_walked_run(threads, monkeypatch):
    """Through steps where the clouds collide and their springs carry history from step to step; on two
    threads the pairs are searched in two runs (narrow.pair_candidates_threaded), gathered and sorted."""
    if threads > numba.config.NUMBA_NUM_THREADS:
        pytest.skip("numba has one thread on this machine")
    monkeypatch.setattr(threads_module, "CONTACT_PARALLEL_MIN_SPHERES", 1)
    monkeypatch.delenv(threads_module.ENV, raising=False)
    sim, walked = _clouds(4, 7, threads=threads), _clouds(4, 7)
    assert sim.contact_threads == threads
    walked.data.force = walked.data.force._replace(contact=_without_pairs(walked.data.force.contact))
    walked._kdata = walked.data.kernel()
    sim.step(60)
    walked.step(60)
    mine, theirs = sim.data.carried(), walked.data.carried()
    for name, value in mine.items():
        if name != "contact.counters":  # its candidate count is the checks made: fewer here
            assert np.array_equal(value, theirs[name]), name
    assert np.array_equal(mine["contact.counters"][1:], theirs["contact.counters"][1:])
    assert sim.data.force.contact.pair_tests[0] > 0  # the last evaluation took the pair path
