"""Shape bodies touching planes as their exact primitive (issue 47 slice 2, docs/contact.md "Primitive contact"):
a box or capsule shape body in a scene with planes gets its primitive in the contact table, and each of its
manifold points against a plane is a contact of the force law, with its own tangential spring.

Every check is a closed form: a box sliding down a slope at g (sin a - mu cos a) and held below tan a = mu;
a capsule rolling about its axis at g sin a / (1 + I / (m r^2)); the rebound of a box and of a lying
capsule dropped flat (e, the material's restitution, since the manifold points share the body's mass);
the sink at rest (PENETRATION_AT_REST of the primitive's size: the stiffness from geometry) and the
springs' energy there (M g d / 2); a box at rest that does not drift; a box landing on an edge that
settles flat on a face; and the count (4 points for a box on its face, not the lattice's 128 spheres).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import rbcli
from rbcli.physics.contact.manifold import MANIFOLD_ROWS
from rbcli.physics.contact.parameters import PENETRATION_AT_REST
from rbcli.physics.contact.primitives import PRIMITIVE_BOX, PRIMITIVE_CAPSULE
from rbcli.physics.contact.tables import STAT_CONTACTS, STAT_ENERGY, STAT_MAX_PENETRATION
from rbcli.physics.rotation import quat_to_matrix
from rbcli.scene.load import load_scene_text

G = 9.81
BOX = "shape: {type: box, size: [0.2, 0.1, 0.05]}, spacing: 0.0125, density: 600"
CAPSULE = "shape: {type: capsule, radius: 0.03, height: 0.12, axis: y}, spacing: 0.01, density: 800"


def scene(body: str, contact: str, *, dt: float = 5e-4, gravity: bool = True) -> rbcli.Simulation:
    text = (
        f"name: t\nsimulation: {{dt: {dt!r}, steps: 1, integrator: split2}}\n"
        + ("gravity: [0, 0, -9.81]\n" if gravity else "")
        + "contact:\n"
        + contact
        + "bodies:\n"
        + body
        + "\n"
    )
    return rbcli.Simulation(load_scene_text(text))


def stats(sim: rbcli.Simulation) -> np.ndarray:
    return sim.data.force.contact.stats


def slope(angle_deg: float, mu: float) -> tuple[str, np.ndarray, np.ndarray]:
    """A plane through the origin tilted by `angle` about y (contact: lines), its normal and downhill."""
    a = math.radians(angle_deg)
    normal = np.array([-math.sin(a), 0.0, math.cos(a)])
    downhill = np.array([math.cos(a), 0.0, math.sin(a)]) * -1.0
    plane = f"  planes: [{{point: [0, 0, 0], normal: {normal.tolist()}, friction: {mu}}}]\n"
    return plane + f"  material: {{friction: {mu}}}\n", normal, downhill


def tilted(angle_deg: float) -> str:
    return f"orientation: {{axis_angle: {{axis: [0, 1, 0], angle: {-angle_deg}, degrees: true}}}}"


@pytest.mark.parametrize("ratio", [0.8, 1.25])
def test_box_on_a_slope_slides_at_g_sin_minus_mu_cos_iff_tan_exceeds_mu(ratio):
    mu = 0.5
    angle = math.degrees(math.atan(ratio * mu))
    a = math.radians(angle)
    contact, normal, downhill = slope(angle, mu)
    centre = (0.025 * normal).tolist()  # its 0.2 x 0.1 face on the plane
    sim = scene(f"  - {{name: box, {BOX}, position: {centre}, {tilted(angle)}}}", contact)
    assert sim.model.contact.primitive_kind.tolist() == [PRIMITIVE_BOX]
    sim.step(200)  # settle onto the plane
    assert stats(sim)[STAT_CONTACTS] == 4  # the face's 4 corners, not its lattice spheres
    s0, u0 = float(sim.state.x[0] @ downhill), float(sim.state.v[0] @ downhill)
    steps = 1600
    sim.step(steps)
    travelled = float(sim.state.x[0] @ downhill) - s0
    t = steps * 5e-4
    if ratio < 1:
        assert abs(travelled) < 1e-4  # held by the 4 corners' tangential springs: no creep
    else:
        accel = G * (math.sin(a) - mu * math.cos(a))
        assert travelled == pytest.approx(u0 * t + 0.5 * accel * t * t, rel=0.01)
        assert stats(sim)[STAT_CONTACTS] == 4


def test_capsule_rolls_down_a_slope_at_g_sin_over_1_plus_i_over_m_r2():
    """A capsule lying across the slope (axis y) rolls on its two end balls, the contact points at rest."""
    angle, mu, r = 10.0, 0.8, 0.03
    a = math.radians(angle)
    contact, normal, downhill = slope(angle, mu)
    sim = scene(f"  - {{name: rod, {CAPSULE}, position: {(r * normal).tolist()}}}", contact)
    assert sim.model.contact.primitive_kind.tolist() == [PRIMITIVE_CAPSULE]
    m = float(sim.model.body_mass[0])
    # its moment about its own axis, of the sampled lattice: the smallest principal moment of this capsule
    # (the two across it are equal)
    moments = np.sort(sim.model.body_inertia[0])
    assert moments[1] == pytest.approx(moments[2], rel=1e-9) and moments[0] < 0.5 * moments[1]
    i_axis = float(moments[0])
    sim.step(100)
    assert stats(sim)[STAT_CONTACTS] == 2
    s0, u0 = float(sim.state.x[0] @ downhill), float(sim.state.v[0] @ downhill)
    steps = 1000
    sim.step(steps)
    t = steps * 5e-4
    accel = G * math.sin(a) / (1.0 + i_axis / (m * r * r))
    travelled = float(sim.state.x[0] @ downhill) - s0
    assert travelled == pytest.approx(u0 * t + 0.5 * accel * t * t, rel=0.01)
    slip = sim.state.v[0] + np.cross(sim.state.omega[0], -r * normal)  # the lowest line's velocity
    assert np.linalg.norm(slip) < 0.01 * np.linalg.norm(sim.state.v[0])
    assert stats(sim)[STAT_CONTACTS] == 2


@pytest.mark.parametrize("body", [BOX, CAPSULE])
def test_dropped_flat_rebounds_at_the_restitution(body):
    """No gravity, 1 m/s straight at the ground, flat: the points share the body's mass, so the body is one
    spring-dashpot of the material's damping ratio and rebounds at e (1 % within its resolved contact)."""
    e = 0.5
    height = 0.025 if body is BOX else 0.03
    sim = scene(f"  - {{name: b, {body}, position: [0, 0, {height + 0.002}], velocity: [0, 0, -1]}}",
                f"  ground: 0\n  material: {{restitution: {e}, friction: 0.5}}\n", dt=1e-5, gravity=False)  # fmt: skip
    touched = False
    for _ in range(400):
        sim.step(10)
        touched = touched or stats(sim)[STAT_CONTACTS] > 0
        if touched and stats(sim)[STAT_CONTACTS] == 0:
            break
    assert touched and stats(sim)[STAT_CONTACTS] == 0
    assert sim.state.v[0, 2] == pytest.approx(e * 1.0, rel=0.01)
    assert np.abs(sim.state.v[0, :2]).max() < 1e-9 and np.abs(sim.state.omega[0]).max() < 1e-6


@pytest.mark.parametrize(("body", "size", "points"), [(BOX, 0.025, 4), (CAPSULE, 0.03, 2)])
def test_resting_sinks_the_fraction_of_its_size_and_stays_put(body, size, points):
    """Set down on the ground sliding at 5 cm/s, a box (4 corners) and a lying capsule (2 end balls; slid
    along its axis, so it cannot roll) stop after v^2 / (2 mu g), less at most the tangential springs'
    stretch at the Coulomb limit as they relax (mu M g / k_t, k_t = 2/7 k_body of all its points), then
    drift < 1 um over 2 s; at rest they sink PENETRATION_AT_REST of their size (the stiffness from
    geometry); set down still, their springs store M g d / 2."""
    mu, v = 0.5, 0.05
    sim = scene(f"  - {{name: b, {body}, position: [0, 0, {size}], velocity: [0, {v}, 0]}}",
                f"  ground: 0\n  material: {{friction: {mu}}}\n", dt=1e-3)  # fmt: skip
    sim.step(1000)
    stopped = sim.state.x[0].copy()
    slide = v * v / (2.0 * mu * G)
    recoil = mu * G / (2.0 / 7.0 * G / (PENETRATION_AT_REST * size))  # mu M g / k_t, k_body = M g / (0.0025 size)
    assert slide - recoil - 1e-6 <= stopped[1] <= slide * 1.01
    assert abs(stopped[0]) < 1e-9
    sim.step(2000)
    assert np.abs(sim.state.x[0, :2] - stopped[:2]).max() < 1e-6
    sink = PENETRATION_AT_REST * size
    assert stats(sim)[STAT_CONTACTS] == points
    assert stats(sim)[STAT_MAX_PENETRATION] == pytest.approx(sink, rel=1e-3)
    assert sim.state.x[0, 2] == pytest.approx(size - sink, rel=1e-6)
    # set down at rest (no tangential spring stretched): the springs hold the normal M g d / 2 alone
    still = scene(f"  - {{name: b, {body}, position: [0, 0, {size}]}}", "  ground: 0\n", dt=1e-3)
    still.step(1000)
    weight = float(still.model.body_mass[0]) * G
    assert stats(still)[STAT_ENERGY] == pytest.approx(0.5 * weight * sink, rel=1e-3)


def test_box_landing_on_an_edge_settles_flat():
    box = f"  - {{name: box, {BOX}, position: [0, 0, 0.15], orientation: {{axis_angle: {{axis: [1, 0, 0], angle: 40, degrees: true}}}}}}"  # noqa: E501
    sim = scene(box, "  ground: 0\n  material: {restitution: 0.3, friction: 0.6}\n  substeps: auto\n", dt=1e-3)
    sim.step(3000)
    R = quat_to_matrix(sim.state.q[0])
    up = np.abs(R[2])  # |z| of each body axis in the world
    assert up.max() > math.cos(math.radians(1.0))  # one axis vertical: on a face
    half = [0.1, 0.05, 0.025][int(np.argmax(up))]
    # on any face its 4 corners carry it, k d = M g / 4 (one stiffness per body: its landing rule's, it fell)
    k = float(sim.model.contact.body_plane_stiffness[0])
    assert k > float(sim.model.body_mass[0]) * 9.81 / (PENETRATION_AT_REST * 0.025) / 4
    sink = float(sim.model.body_mass[0]) * 9.81 / (4 * k)
    assert sim.state.x[0, 2] == pytest.approx(half - sink, abs=2e-6)
    assert np.linalg.norm(sim.state.v[0]) < 1e-3
    assert stats(sim)[STAT_CONTACTS] == 4


def test_numba_free_copies_of_the_primitive_kinds_agree():
    from rbcli.physics.contact import primitives, tables
    from rbcli.scene import compile_contact

    assert (compile_contact.PRIMITIVE_CAPSULE, compile_contact.PRIMITIVE_BOX) == (PRIMITIVE_CAPSULE, PRIMITIVE_BOX)
    assert tables.primitive_extent(primitives.PRIMITIVE_SPHERE, np.eye(3), np.ones(3))[1] == 1.0
    assert tables.primitive_work(tables.contact_table(), 0) == {}
    boxed = tables.contact_table(
        body_inv_contact_mass=[1.0], primitive_kind=[PRIMITIVE_BOX], primitive_size=[[1, 2, 3.0]]
    )
    assert tables.primitive_work(boxed, 1)["manifold_depth"].shape == (MANIFOLD_ROWS,)
    np.testing.assert_array_equal(boxed.body_box_half[0], [1, 2, 3])  # the body box holds the primitive


def test_primitives_false_keeps_the_sphere_carpet():
    """The same box with `primitives: false` rests on its face's lattice spheres (16 x 8 at this spacing)."""
    sim = scene(f"  - {{name: box, {BOX}, position: [0, 0, 0.025]}}", "  ground: 0\n  primitives: false\n", dt=1e-3)
    assert sim.model.contact.primitive_kind.tolist() == [-1]
    sim.step(200)
    assert stats(sim)[STAT_CONTACTS] == 16 * 8


def test_body_pairs_beyond_the_pair_buffer_still_touch(monkeypatch):
    """A heap of boxes, capsules, spheres and a particle cloud whose body level finds more pairs than a
    (deliberately tiny) pair buffer holds: the primitive search tests every pair of boxes instead
    (primitive_search.py), so the run is the run with the full buffer, bitwise (both take the pairs in the
    bodies' order: body_phase.kept_box_pairs), and no contact is lost."""
    import rbcli.physics.contact.tables as tables

    cloud = "particles: {positions: [[0, 0, 0], [0.03, 0, 0], [0, 0.03, 0], [0, 0, 0.03]], masses: 0.05, radius: 0.02}"
    shapes = [BOX, CAPSULE, "shape: {type: sphere, radius: 0.035}, spacing: 0.01, density: 700", cloud]
    bodies = []
    for i in range(12):
        x, y, z = 0.09 * (i % 3), 0.09 * ((i // 3) % 2), 0.06 + 0.07 * (i // 6)
        bodies.append(f"  - {{name: b{i}, {shapes[i % 4]}, position: [{x}, {y}, {z}], angular_velocity: [0, 0, {i}]}}")
    text = "\n".join(bodies)

    def run(capacity: int | None) -> tuple[np.ndarray, int]:
        if capacity is not None:
            full = tables.pair_capacities
            monkeypatch.setattr(tables, "pair_capacities", lambda *args: (capacity, *full(*args)[1:]))
        sim = scene(text, "  ground: 0\n", dt=5e-4)
        most = 0
        for _ in range(120):
            sim.step(1)
            most = max(most, int(sim.data.force.contact.body_sweep[tables.SWEEP_PAIRS]))
        assert sim.data.force.contact.body_pair.shape[0] == (capacity if capacity is not None else 16 * 12 + 64)
        s = sim.state
        return np.concatenate([s.x.ravel(), s.q.ravel(), s.P.ravel(), s.L.ravel()]), most

    full_run, pairs = run(None)
    small_run, _ = run(2)
    assert pairs > 2  # the heap does overflow the small buffer
    np.testing.assert_array_equal(small_run, full_run)


def test_kept_body_pairs_do_not_change_a_step():
    """A heap of 18 shapes (more than the few bodies tested pair by pair) steps bitwise alike whether its
    body pairs were kept from earlier evaluations, found again from nothing (as in a resumed run, whose
    kept pairs are not carried) or walked on the grid (bodies faster than their pads): every path hands
    the pairs on in the bodies' order (body_phase.kept_box_pairs)."""
    from rbcli.physics.contact.tables import FAT_PAIRS, FAT_WAIT, SWEEP_PAIRS

    shapes = [BOX, CAPSULE, "shape: {type: sphere, radius: 0.035}, spacing: 0.01, density: 700"]
    bodies = []
    for i in range(18):  # three layers of six, the middle one across the gaps of the others
        layer = i // 6
        x, y, z = 0.25 * (i % 3) + 0.125 * (layer == 1), 0.2 * ((i // 3) % 2) + 0.1 * (layer == 1), 0.04 + 0.08 * layer
        bodies.append(f"  - {{name: b{i}, {shapes[i % 3]}, position: [{x}, {y}, {z}], angular_velocity: [0, 0, {i}]}}")
    text = "\n".join(bodies)

    def run(interrupt: str) -> np.ndarray:
        sim = scene(text, "  ground: 0\n  substeps: auto\n", dt=5e-4)
        work = sim.data.force.contact
        kept, most = 0, 0
        for _ in range(500):
            sim.step(1)
            kept += work.fat_state[FAT_PAIRS] >= 0
            most = max(most, work.body_sweep[SWEEP_PAIRS])
            if interrupt == "forget":  # the kept pairs dropped: found again at the next evaluation
                work.fat_state[FAT_PAIRS] = -1
            elif interrupt == "walk":  # the grid walked at every evaluation
                work.fat_state[FAT_PAIRS], work.fat_state[FAT_WAIT] = -1, 1000
        if interrupt == "none":
            assert kept > 350, kept  # the heap mostly keeps its pairs
            assert most >= 3, most  # and has pairs to keep
        s = sim.state
        return np.concatenate([s.x.ravel(), s.q.ravel(), s.P.ravel(), s.L.ravel()])

    kept = run("none")
    np.testing.assert_array_equal(run("forget"), kept)
    np.testing.assert_array_equal(run("walk"), kept)
