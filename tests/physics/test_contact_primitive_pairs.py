"""Shape bodies touching each other as their primitives (issue 47 slice 3, docs/contact.md "Primitive
contact"): two bodies whose boxes meet touch through primitives.primitive_pair (both primitives) or each
cloud sphere against the primitive (sphere-X); a primitive body's own lattice spheres touch nothing.

Every check is a closed form: at rest each manifold point carries its share of the weight, k d = M g / n
(k the pair's stiffness, springs in series of the bodies' per-point stiffness), so the heights are the
sinks of the stiffness from geometry and the reaction is the weight; momentum is conserved to round-off in
a head-on impact and the bodies part at the material's restitution (the n manifold points share the
pair's reduced mass: one spring-dashpot of damping ratio zeta); stacks do not creep.
"""

from __future__ import annotations

import numpy as np
import pytest

import rbcli
from rbcli.physics.contact.parameters import PENETRATION_AT_REST
from rbcli.physics.contact.points import contact_points
from rbcli.physics.contact.primitive_search import FEATURE_KEYS, feature_key
from rbcli.physics.contact.primitives import PRIMITIVE_BOX, PRIMITIVE_CAPSULE
from rbcli.physics.contact.tables import STAT_CONTACTS, make_contact_work
from rbcli.physics.rotation import quat_to_matrix
from rbcli.scene.load import load_scene_text

G = 9.81
H = 0.05  # the boxes' half thickness [m]
BOX = "shape: {type: box, size: [0.2, 0.2, 0.1]}, spacing: 0.025, density: 600"
CAPSULE = "shape: {type: capsule, radius: 0.03, height: 0.12, axis: y}, spacing: 0.01, density: 800"


def scene(bodies: str, contact: str = "  ground: 0\n", *, dt: float = 1e-3) -> rbcli.Simulation:
    text = (
        f"name: t\nsimulation: {{dt: {dt!r}, steps: 1, integrator: split2}}\n"
        + "gravity: [0, 0, -9.81]\n"
        + "contact:\n"
        + contact
        + "bodies:\n"
        + bodies
    )
    return rbcli.Simulation(load_scene_text(text), threads=1)  # one compiled loop for every scene here


def stack(n: int, shift: float = 0.0) -> str:
    """n boxes stacked on the ground, touching, each `shift` [m] along x from the one below."""
    return "".join(f"  - {{name: b{i}, {BOX}, position: [{i * shift!r}, 0, {(2 * i + 1) * H!r}]}}\n" for i in range(n))


def points(sim: rbcli.Simulation) -> tuple[np.ndarray, np.ndarray]:
    """The contact points [m] and their normal forces [N] of the current state (the contacts stream)."""
    s = sim.data.state
    work = make_contact_work(sim.model.contact, sim.model.body_count, history=False)
    point, force = np.zeros((256, 3)), np.zeros(256)
    found = contact_points(sim.model.kernel_bodies(), sim.model.contact, work, s.x, s.q, s.P, s.L, point, force)
    return point[:found], force[:found]


@pytest.mark.parametrize("shift", [0.0, 0.03])
def test_box_on_a_box_rests_on_four_points_carrying_its_weight(shift):
    """Aligned (their edges coincide: box_box takes the outline's points once) and shifted: 4 points on the
    ground and 4 between the boxes, the reaction there the top box's weight, the heights the sinks when
    aligned: 2 M g = 4 k_0 d under the bottom box (k_0 its per-point plane stiffness) and M g = 4 k d
    between them (k = 2 k_0 k_1 / (k_0 + k_1), the two per-point stiffnesses in series; the top box's
    is its landing rule's, stiffer than the rest rule's k = M g / (PENETRATION_AT_REST h) / 4, as it could
    fall to the ground), and no drift."""
    sim = scene(stack(2, shift))
    assert sim.model.contact.primitive_kind.tolist() == [PRIMITIVE_BOX] * 2
    sim.step(1000)
    assert sim.data.force.contact.stats[STAT_CONTACTS] == 8  # not the lattices' sphere pairs
    settled = sim.state.x.copy()
    sim.step(2000)
    assert np.abs(sim.state.x - settled).max() < 1e-6
    assert np.abs(sim.state.v).max() < 1e-5
    if shift == 0.0:  # shifted, the points carry unequal loads (the boxes tilt by a few microradians)
        weight = float(sim.model.body_mass[1]) * G
        assert sim.model.contact.body_plane_stiffness[0] == pytest.approx(weight / (PENETRATION_AT_REST * H) / 4)
        k0, k1 = sim.model.contact.body_stiffness
        ground, between = 2 * weight / (4 * k0), weight / (4 * (2 * k0 * k1 / (k0 + k1)))
        assert sim.state.x[0, 2] == pytest.approx(H - ground, abs=1e-3 * ground)
        assert sim.state.x[1, 2] == pytest.approx(3 * H - ground - between, abs=2e-3 * between)
    point, force = points(sim)
    between = np.abs(point[:, 2] - 2 * H) < 0.1 * H
    weight = float(sim.model.body_mass[1]) * G
    assert between.sum() == 4 and force[between].sum() == pytest.approx(weight, rel=1e-4)
    assert force[~between].sum() == pytest.approx(2 * weight, rel=1e-4)


def test_capsule_lying_on_a_box_rests_on_its_two_end_balls():
    """The capsule's end balls carry it: 2 points, k d = M g / 2 with k the series of the capsule's and the
    box's per-point stiffness; no drift, no roll."""
    r = 0.03
    # at the box's centre: off it, the box tilts on the ground's unequal loads and the capsule rolls
    sim = scene(stack(1) + f"  - {{name: rod, {CAPSULE}, position: [0, 0, {2 * H + r!r}]}}\n")
    assert sim.model.contact.primitive_kind.tolist() == [PRIMITIVE_BOX, PRIMITIVE_CAPSULE]
    sim.step(1000)
    settled = sim.state.x.copy()
    sim.step(2000)
    assert np.abs(sim.state.x - settled).max() < 1e-6
    ka, kb = sim.model.contact.body_stiffness
    k = 2 * ka * kb / (ka + kb)
    sink = float(sim.model.body_mass[1]) * G / (2 * k)
    top = sim.state.x[0, 2] + H
    assert sim.state.x[1, 2] == pytest.approx(top + r - sink, abs=1e-3 * sink)
    point, force = points(sim)
    on_box = point[:, 2] > H
    assert on_box.sum() == 2
    assert force[on_box].sum() == pytest.approx(float(sim.model.body_mass[1]) * G, rel=1e-4)


@pytest.mark.parametrize("e", [0.3, 0.8])
def test_capsules_head_on_keep_momentum_and_part_at_the_restitution(e):
    """No planes: two capsules (masses 1 : 2 by density) along one horizontal axis meet end to end at 1 m/s
    each, falling together (gravity along z changes nothing between them, and the test shares the compiled
    loop of the others): P along the axis is conserved to round-off and they part at e times their
    approach speed (one manifold point carrying the pair's reduced mass: a spring-dashpot of the
    material's zeta)."""
    light = CAPSULE
    heavy = CAPSULE.replace("density: 800", "density: 1600")
    gap = 0.12 + 2 * 0.03 + 0.001  # centres one capsule length and 1 mm apart
    bodies = (f"  - {{name: a, {light}, position: [0, 0, 0], velocity: [0, 1, 0]}}\n"
              f"  - {{name: b, {heavy}, position: [0, {gap!r}, 0], velocity: [0, -1, 0]}}\n")  # fmt: skip
    sim = scene(bodies, f"  material: {{stiffness: 2.0e5, restitution: {e}, friction: 0.3}}\n", dt=1e-5)
    assert sim.model.contact.primitive_kind.tolist() == [PRIMITIVE_CAPSULE] * 2
    P0 = sim.state.P.sum(axis=0).copy()
    approach = sim.state.v[0, 1] - sim.state.v[1, 1]
    touched = False
    for _ in range(400):
        sim.step(10)
        touched = touched or sim.data.force.contact.stats[STAT_CONTACTS] > 0
        if touched and sim.data.force.contact.stats[STAT_CONTACTS] == 0:
            break
    assert touched and sim.data.force.contact.stats[STAT_CONTACTS] == 0
    # momentum across gravity: the pair's forces are equal and opposite (round-off of a few hundred steps)
    P = sim.state.P.sum(axis=0)
    assert np.abs(P[:2] - P0[:2]).max() < 1e-12 * np.abs(sim.state.P).max()
    parting = sim.state.v[1, 1] - sim.state.v[0, 1]
    assert parting == pytest.approx(e * approach, rel=0.01)
    assert sim.state.v[0, 2] == pytest.approx(sim.state.v[1, 2], abs=1e-12)  # falling together
    assert np.abs(sim.state.omega).max() < 1e-9  # along the axes: no torque


def test_box_stack_of_three_stands():
    sim = scene(stack(3))
    sim.step(500)
    settled = sim.state.x.copy()
    sim.step(2000)
    assert np.abs(sim.state.x - settled).max() < 1e-3
    assert np.abs(sim.state.x[:, :2]).max() < 1e-6  # no creep sideways at all
    assert sim.data.force.contact.stats[STAT_CONTACTS] == 12


def test_cloud_dropped_on_a_box_rests_on_it():
    """A cloud of 8 spheres (a cube's corners, 2 cm from its centre along each axis, radius 1.5 cm) falls
    5 cm onto a box body: its spheres meet the box as sphere-box contacts (the box's own spheres touch
    nothing) and it comes to rest on the box's top face on its 4 lowest spheres, sunk by a small fraction
    of their radius."""
    r, a = 0.015, 0.02
    offsets = [[sx * a, sy * a, sz * a] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    cloud = (f"  - {{name: cloud, particles: {{positions: {offsets}, masses: {[0.05] * 8}, radius: {[r] * 8}}}, "
             f"position: [0.01, 0.02, {2 * H + a + r + 0.05!r}]}}\n")  # fmt: skip
    sim = scene(stack(1) + cloud, "  ground: 0\n  material: {restitution: 0.3, friction: 0.5}\n")
    assert sim.model.contact.primitive_kind.tolist() == [PRIMITIVE_BOX, -1]
    sim.step(1500)
    top = sim.state.x[0, 2] + H
    spheres = sim.state.x[1] + np.asarray(offsets, dtype=float) @ quat_to_matrix(sim.state.q[1]).T
    lowest = np.sort(spheres[:, 2])[:4] - r  # its 4 lowest spheres' bottoms
    assert np.all((top - 0.05 * r < lowest) & (lowest < top))
    assert np.linalg.norm(sim.state.v[1]) < 1e-3
    assert sim.data.force.contact.stats[STAT_CONTACTS] == 8  # 4 box corners on the ground, 4 cloud spheres


def test_primitives_false_keeps_the_carpet_between_bodies():
    """`primitives: false`: no body has a primitive, so every body keeps the sphere search it had (the
    carpet's own tests; not stepped here: that loop is another compile)."""
    sim = scene(stack(2), "  ground: 0\n  primitives: false\n")
    assert sim.model.contact.primitive_kind.tolist() == [-1, -1]
    assert sim.data.force.contact.primitive_centre is None


def test_feature_keys_are_one_to_one_below_feature_keys():
    """A pair of bodies always runs one kernel, so its features need distinct keys within that kernel's:
    box-box's (64 face + code < 32, 1024 + 12 edge_a + edge_b) packed one to one below FEATURE_KEYS, the
    other kernels' (< 64) kept."""
    box_box = [64 * f + c for f in range(12) for c in range(32)] + [1024 + e for e in range(144)]
    keys = [feature_key(f) for f in box_box]
    assert len(set(keys)) == len(box_box) and max(keys) < FEATURE_KEYS
    assert [feature_key(f) for f in range(5)] == list(range(5))
