"""Contact (issue 18): the broad phase against brute force, and the force law against exact results.

Every physical check compares with a closed-form result or a conservation law: momentum, the
configured coefficient of restitution, static friction on a slope (slides iff tan(angle) > mu), rolling
without slipping at (5/7) g sin(angle), a resting body that neither creeps nor gains energy.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import rbcli
from rbcli.physics.contact.broad_phase import build_grid
from rbcli.physics.contact.force import accumulate_contact, hold_static_bodies
from rbcli.physics.contact.parameters import (
    PENETRATION_AT_REST,
    damping_ratio_for_restitution,
    restitution_for_damping_ratio,
    stable_step,
)
from rbcli.physics.contact.reference import contact_wrench_numpy
from rbcli.physics.contact.tables import (
    COUNT_CANDIDATES,
    STAT_CONTACTS,
    STAT_MAX_PENETRATION,
    contact_table,
    make_contact_work,
)
from rbcli.physics.integrators import INTEGRATORS
from rbcli.physics.model import KernelBodies
from rbcli.physics.rotation import quat_to_matrix
from rbcli.scene.load import load_scene_text
from rbcli.scene.spec import SceneError

G = 9.81


def ball(name: str, position, velocity=(0.0, 0.0, 0.0), radius=0.05, mass=0.5, extra="") -> str:  # noqa: ANN001
    """A solid sphere as one particle with a radius (inertia 2/5 m r^2 exactly), one contact sphere."""
    return (
        f"  - {{name: {name}, particles: {{positions: [[0, 0, 0]], masses: [{mass!r}], radius: [{radius!r}]}}, "
        f"position: {list(map(float, position))}, velocity: {list(map(float, velocity))}{extra}}}"
    )


def scene(bodies: list[str], *, dt=1e-3, steps=1000, contact="", gravity=True, integrator="split2") -> rbcli.Simulation:  # noqa: ANN001
    text = (
        f"name: t\nsimulation: {{dt: {dt!r}, steps: {steps}, integrator: {integrator}}}\n"
        + ("gravity: [0, 0, -9.81]\n" if gravity else "")
        + "contact:\n"
        + (contact or "  substeps: 1\n")
        + "bodies:\n"
        + "\n".join(bodies)
        + "\n"
    )
    return rbcli.Simulation(load_scene_text(text))


def kinetic(sim: rbcli.Simulation) -> float:
    s = sim.state
    return float(0.5 * (sim.model.body_mass[:, None] * s.v**2).sum() + 0.5 * (s.omega * s.L).sum())


def mechanical(sim: rbcli.Simulation) -> float:
    """Kinetic + gravitational + the energy stored in the contact springs [J]."""
    s = sim.state
    stored = sim.data.force.contact.stats[2]
    return kinetic(sim) + float(G * (sim.model.body_mass * s.x[:, 2]).sum()) + float(stored)


# ---- broad phase and force law against brute force ----------------------------------------------------


def _random_scene(count: int, seed: int, box: float, outlier: bool = False) -> rbcli.Simulation:
    rng = np.random.default_rng(seed)
    bodies = []
    for i in range(count):
        pos = rng.uniform(-box, box, 3)
        vel = rng.normal(size=3)
        if i % 3 == 0:  # a cloud of 4 spheres: contact points off the centre, torques
            pts = rng.normal(scale=0.03, size=(4, 3)).round(4).tolist()
            rad = rng.uniform(0.01, 0.03, 4).round(4).tolist()
            spin = rng.normal(size=3).tolist()
            particles = f"{{positions: {pts}, masses: [0.1, 0.2, 0.3, 0.1], radius: {rad}}}"
            bodies.append(f"  - {{name: c{i}, particles: {particles}, position: {pos.tolist()}, "
                          f"velocity: {vel.tolist()}, angular_velocity: {spin}}}")  # fmt: skip
        else:
            bodies.append(
                ball(f"s{i}", pos, vel, radius=float(rng.uniform(0.01, 0.04)), mass=float(rng.uniform(0.1, 1)))
            )
    if outlier:
        bodies.append(ball("far", (1e6, -3e5, 2e5)))
    contact = "  planes: [{point: [0, 0, " + repr(-box) + "], normal: [0.1, 0.2, 1], friction: 0.3}]\n"
    contact += "  material: {restitution: 0.4, friction: 0.6}\n"
    return scene(bodies, contact=contact, gravity=False)


def _compiled_and_reference(sim: rbcli.Simulation) -> tuple[np.ndarray, ...]:
    contact = sim.model.contact
    work = make_contact_work(contact, sim.model.body_count)
    s = sim.data.state
    F, tau = np.zeros_like(s.x), np.zeros_like(s.x)
    accumulate_contact(sim.model.kernel_bodies(), contact, work, 0.0, s.x, s.q, s.P, s.L, F, tau)
    hold_static_bodies(contact, F, tau)
    F_ref, tau_ref, found = contact_wrench_numpy(sim.model, contact, s.x, s.q, s.P, s.L)
    return F, tau, F_ref, tau_ref, np.array([work.stats[STAT_CONTACTS], found, work.counters[COUNT_CANDIDATES]])


@pytest.mark.parametrize("outlier", [False, True], ids=["dense grid", "hashed grid"])
def test_contact_forces_equal_brute_force_on_random_clouds(outlier):
    """Every overlapping pair found exactly once: the wrench of the grid search equals the O(n^2) sum.
    One body a million metres away forces the hashed grid (the dense box would need ~10^22 cells)."""
    sim = _random_scene(150, seed=3, box=0.25, outlier=outlier)
    F, tau, F_ref, tau_ref, (found, expected, _) = _compiled_and_reference(sim)
    assert found == expected > 50
    scale = np.abs(F_ref).max()
    np.testing.assert_allclose(F, F_ref, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(tau, tau_ref, rtol=0, atol=1e-12 * scale)


def _candidates_per_sphere(count: int, seed: int = 0) -> float:
    """Distance checks per sphere of one force evaluation on `count` equal spheres (radius 0.01 m),
    uniform in a cube sized for 1,000 spheres per 0.01 m^3 (the same density at every count)."""
    rng = np.random.default_rng(seed)
    side = (count / 1000 * 0.01) ** (1 / 3)
    positions = rng.uniform(0.0, side, (count, 3))
    index = np.zeros(count, np.int64)
    inertia = np.full((count, 3), 0.4e-4)
    model = KernelBodies(np.ones(count), inertia, 1.0 / inertia, np.zeros((0, 3)), np.zeros(0), index, index,
                        np.tile(np.eye(3), (count, 1, 1)))  # fmt: skip
    contact = contact_table(sphere_body=np.arange(count), sphere_offset=np.zeros((count, 3)),
                            sphere_radius=np.full(count, 0.01), body_inv_contact_mass=np.ones(count),
                            body_stiffness=np.ones(count), body_damping_ratio=np.zeros(count),
                            body_friction=np.zeros(count))  # fmt: skip
    work = make_contact_work(contact, count)
    q = np.tile([1.0, 0.0, 0.0, 0.0], (count, 1))
    zeros = np.zeros((count, 3))
    accumulate_contact(model, contact, work, 0.0, positions, q, zeros, zeros, zeros.copy(), zeros.copy())
    return work.counters[COUNT_CANDIDATES] / count


def test_broad_phase_work_grows_linearly():
    """Candidate pairs (distance checks) per sphere stay flat from 2,000 to 128,000 spheres at one density:
    the work is linear in the count (the count of checks, not a time, so the test is not flaky)."""
    rates = [_candidates_per_sphere(n) for n in (2_000, 16_000, 128_000)]
    assert max(rates) < 1.25 * min(rates), rates
    assert max(rates) < 14 * 2, rates  # about half of 27 cells' share, not a scan of everything


def test_grid_buckets_hold_every_sphere_once():
    sim = _random_scene(60, seed=5, box=0.2, outlier=True)
    contact = sim.model.contact
    work = make_contact_work(contact, sim.model.body_count)
    work.sphere_position[:] = np.random.default_rng(0).uniform(-1, 1, work.sphere_position.shape)
    build_grid(contact, work)
    assert sorted(work.sorted_sphere.tolist()) == list(range(contact.sphere_radius.shape[0]))
    start = work.bucket_start
    for b in range(contact.bucket_count):
        members = work.sorted_sphere[start[b] : start[b + 1]]
        assert np.all(work.sphere_bucket[members] == b)


# ---- collisions against exact results -------------------------------------------------------------------


def _head_on(restitution: float, integrator: str = "split2", friction: float = 0.0) -> rbcli.Simulation:
    contact = f"  material: {{restitution: {restitution}, friction: {friction}}}\n"
    sim = scene([ball("a", (0, 0, 0), (1.0, 0.02, 0.0)), ball("b", (0.3, 0, 0), (-1.0, 0.0, 0.0))],
                dt=1e-4, steps=3000, contact=contact, gravity=False, integrator=integrator)  # fmt: skip
    return sim


@pytest.mark.parametrize("restitution", [0.5, 0.9])
def test_head_on_spheres_conserve_momentum_and_rebound_at_the_configured_restitution(restitution):
    sim = _head_on(restitution)
    P0 = sim.state.P.sum(axis=0)
    v0 = sim.state.v.copy()
    sim.step(3000)
    P1 = sim.state.P.sum(axis=0)
    np.testing.assert_allclose(P1, P0, rtol=0, atol=1e-15)
    approach = v0[0, 0] - v0[1, 0]
    separation = sim.state.v[1, 0] - sim.state.v[0, 0]
    assert separation / approach == pytest.approx(restitution, rel=0.05)
    assert np.all(sim.state.omega == 0.0)  # frictionless: no spin


@pytest.mark.parametrize("integrator", list(INTEGRATORS))
def test_every_integrator_runs_contact(integrator):
    """Each fixed-step integrator: momentum conserved and a physical rebound (docs/integrators.md says
    which lose their order with contact)."""
    sim = _head_on(0.5, integrator)
    P0 = sim.state.P.sum(axis=0)
    sim.step(3000)
    np.testing.assert_allclose(sim.state.P.sum(axis=0), P0, rtol=0, atol=1e-12)
    e = (sim.state.v[1, 0] - sim.state.v[0, 0]) / 2.0
    assert 0.4 < e < 0.6, e


def test_restitution_formula_round_trips_and_matches_the_clamped_oscillator():
    """e(zeta) of the clamped spring-dashpot against a direct fine integration of m d'' = -k d - c d'."""
    for e in (0.05, 0.3, 0.5, 0.95):
        zeta = damping_ratio_for_restitution(e)
        assert restitution_for_damping_ratio(zeta) == pytest.approx(e, rel=1e-10)
        d, v, h = 0.0, 1.0, 1e-5  # w = 1; leapfrog, far below its step limit
        while True:
            a = -(d + 2 * zeta * v)
            if d > 0 and a >= 0.0:
                break
            v_half = v + 0.5 * h * a
            d += h * v_half
            v = v_half + 0.5 * h * -(d + 2 * zeta * v_half)
        assert -v == pytest.approx(e, rel=1e-3)


def test_mass_ratio_1_to_100():
    contact = "  material: {restitution: 0.8, friction: 0.3}\n  substeps: auto\n"
    sim = scene([ball("light", (0, 0, 0), (2.0, 0.1, 0.0), radius=0.02, mass=0.01),
                 ball("heavy", (0.2, 0.01, 0), (-0.5, 0, 0), radius=0.1, mass=1.0)],
                dt=1e-3, steps=400, contact=contact, gravity=False)  # fmt: skip
    P0 = sim.state.P.sum(axis=0)
    E0 = kinetic(sim)
    deepest = 0.0
    for _ in range(400):
        sim.step(1)
        deepest = max(deepest, sim.data.force.contact.stats[STAT_MAX_PENETRATION])
        assert mechanical(sim) <= E0 * (1 + 1e-9)
    assert np.all(np.isfinite(sim.state.x))
    np.testing.assert_allclose(sim.state.P.sum(axis=0), P0, rtol=1e-12, atol=1e-14)
    assert 0 < deepest < 0.2 * 0.02


# ---- the world: resting, sliding, rolling ----------------------------------------------------------------


def test_resting_sphere_neither_creeps_nor_gains_energy():
    sim = scene([ball("b", (0, 0, 0.05))], dt=2e-3, steps=5000, contact="  ground: 0\n")
    sim.step(250)  # settle the first sag (it starts touching, at zero overlap)
    x0 = sim.state.x[0].copy()
    E = mechanical(sim)
    for _ in range(19):
        sim.step(250)
        E_now = mechanical(sim)
        assert E_now <= E + 1e-12
        E = E_now
    assert np.linalg.norm(sim.state.x[0] - x0) < 1e-4
    assert sim.step_index == 5000  # 10 s


def test_a_cloud_ball_resting_on_an_edge_sinks_the_rest_fraction_of_its_sphere_radius():
    """The default stiffness's promise (parameters.py): a body resting on the spheres that carry it sinks
    PENETRATION_AT_REST of their radius. A 13-sphere ball (a 3 cm centre sphere and 12 of 2 cm on an
    icosahedron, the pile benchmark's) lying on an edge rests on 2 spheres, though 4 lie within half a
    radius of the ground (`support`): its plane contacts are twice as stiff as its pair contacts, and
    its stable step is the same as with plane stiffness = pair stiffness."""
    phi = (1 + 5**0.5) / 2
    v = np.array([(0, s1, s2 * phi) for s1 in (-1, 1) for s2 in (-1, 1)], dtype=float)
    v = np.concatenate([v, v[:, [1, 2, 0]], v[:, [2, 0, 1]]])
    points = np.concatenate([np.zeros((1, 3)), 0.03 * v / np.linalg.norm(v[0])])
    radii = [0.03] + [0.02] * 12
    z = float(0.02 - points[:, 2].min())  # the lowest two spheres (an edge along y) touch the ground
    cloud = f"{{positions: {points.tolist()}, masses: {[0.04] * 13}, radius: {radii}}}"
    sim = scene([f"  - {{name: ball, particles: {cloud}, position: [0, 0, {z!r}]}}"], dt=1e-3, steps=1000,
                contact="  ground: 0\n")  # fmt: skip
    table = sim.model.contact
    assert table.body_plane_stiffness[0] == pytest.approx(2 * table.body_stiffness[0], rel=1e-12)
    sim.step(1000)
    assert sim.data.force.contact.stats[STAT_CONTACTS] == 2
    overlap = sim.data.force.contact.stats[STAT_MAX_PENETRATION]
    assert overlap == pytest.approx(PENETRATION_AT_REST * 0.02, rel=1e-3)
    k_body, m = 4 * table.body_stiffness, sim.model.body_mass
    zeta = table.body_damping_ratio
    same = stable_step(m, k_body, zeta, np.ones(1, bool), True, plane_stiffness=4 * table.body_plane_stiffness)
    assert same == stable_step(m, k_body, zeta, np.ones(1, bool), True)


def _slope_scene(angle_deg: float, mu: float, body: str) -> rbcli.Simulation:
    a = math.radians(angle_deg)
    normal = [-math.sin(a), 0.0, math.cos(a)]
    contact = f"  planes: [{{point: [0, 0, 0], normal: {normal}, friction: {mu}}}]\n  material: {{friction: {mu}}}\n"
    return scene([body], dt=5e-4, steps=2000, contact=contact)


def _along_slope(sim: rbcli.Simulation, angle_deg: float) -> float:
    a = math.radians(angle_deg)
    return float(sim.state.x[0] @ np.array([-math.cos(a), 0.0, -math.sin(a)]))  # downhill


@pytest.mark.parametrize("ratio", [0.8, 1.25])
def test_box_on_a_slope_slides_iff_tan_angle_exceeds_mu(ratio):
    mu = 0.5
    angle = math.degrees(math.atan(ratio * mu))
    a = math.radians(angle)
    n = np.array([-math.sin(a), 0.0, math.cos(a)])
    centre = (0.051 * n).tolist()  # half the box height above the plane, its face on it
    orient = f"orientation: {{axis_angle: {{axis: [0, 1, 0], angle: {-angle}, degrees: true}}}}"
    shape = "shape: {type: box, size: [0.1, 0.1, 0.1]}, spacing: 0.02, density: 500"
    box = f"  - {{name: box, {shape}, position: {centre}, {orient}}}"
    sim = _slope_scene(angle, mu, box)
    sim.step(400)  # settle onto the plane
    downhill = np.array([math.cos(a), 0.0, math.sin(a)]) * -1.0
    s0, u0 = _along_slope(sim, angle), float(sim.state.v[0] @ downhill)
    sim.step(1600)
    travelled = _along_slope(sim, angle) - s0
    t = 1600 * 5e-4
    if ratio < 1:
        assert abs(travelled) < 1e-4
    else:
        accel = G * (math.sin(a) - mu * math.cos(a))
        assert travelled == pytest.approx(u0 * t + 0.5 * accel * t**2, rel=0.05)


@pytest.mark.parametrize("factor", [0.5, 1.6])
def test_sphere_rolls_without_slipping_iff_tan_angle_at_most_3_5_mu(factor):
    """Below tan(angle) = 3.5 mu a solid sphere rolls at (5/7) g sin(angle), its contact point at rest;
    above it, it slides at g (sin - mu cos) while friction spins it up at 5 mu g cos / (2 r)."""
    mu = 0.3
    angle = math.degrees(math.atan(factor * 3.5 * mu))
    a = math.radians(angle)
    n = np.array([-math.sin(a), 0.0, math.cos(a)])
    sim = _slope_scene(angle, mu, ball("ball", (0.05 * n).tolist()))
    sim.step(200)
    s0, v0 = _along_slope(sim, angle), sim.state.v[0].copy()
    sim.step(1000)
    t = 1000 * 5e-4
    downhill = -np.array([math.cos(a), 0.0, math.sin(a)])
    travelled = _along_slope(sim, angle) - s0
    u0 = float(v0 @ downhill)
    r = -0.05 * n
    slip = sim.state.v[0] + np.cross(sim.state.omega[0], r)
    if factor <= 1.0:
        accel = (5.0 / 7.0) * G * math.sin(a)
        assert np.linalg.norm(slip) < 0.01 * np.linalg.norm(sim.state.v[0])  # rolling: contact point at rest
    else:
        accel = G * (math.sin(a) - mu * math.cos(a))
        assert np.linalg.norm(slip) > 0.2 * np.linalg.norm(sim.state.v[0])  # sliding
    assert travelled == pytest.approx(u0 * t + 0.5 * accel * t**2, rel=0.02)


def test_fast_impact_does_not_tunnel_with_auto_substeps():
    """20 m/s into the ground at dt = 2 ms: sub-steps engage and the sphere never passes below z = -r."""
    contact = "  ground: 0\n  substeps: auto\n  material: {restitution: 0.5}\n"
    sim = scene([ball("b", (0, 0, 0.2), (0, 0, -20.0))], dt=2e-3, steps=100, contact=contact)
    assert sim.settings.substeps > 1
    lowest = np.inf
    for _ in range(100):
        sim.step(1)
        lowest = min(lowest, sim.state.x[0, 2])
    assert lowest > 0.0  # the centre stays above the ground: the sphere bounced back
    assert sim.state.v[0, 2] > 0.0 or sim.state.x[0, 2] > 0.05


def test_box_dropped_with_spin_settles_flat():
    box = ("  - {name: box, shape: {type: box, size: [0.2, 0.1, 0.05]}, spacing: 0.025, density: 600, "
           "position: [0, 0, 0.3], orientation: {axis_angle: {axis: [1, 1, 0], angle: 40, degrees: true}}, "
           "angular_velocity: [2, -3, 5]}")  # fmt: skip
    contact = "  ground: 0\n  material: {restitution: 0.3, friction: 0.6}\n  substeps: auto\n"
    sim = scene([box], dt=1e-3, steps=4000, contact=contact)
    sim.step(4000)
    R = quat_to_matrix(sim.state.q[0])
    up = np.abs(R[2])  # |z| of each body axis in the world
    assert up.max() > math.cos(math.radians(2.0))  # one axis vertical: lying on a face
    assert kinetic(sim) < 1e-4
    half = [0.1, 0.05, 0.025][int(np.argmax(up))]
    assert sim.state.x[0, 2] == pytest.approx(half, abs=0.004)


# ---- scene keys ------------------------------------------------------------------------------------------


def test_contact_errors_are_located():
    text = """name: bad
simulation: {dt: 0.001, steps: 10}
contact:
  planes: [{normal: [0, 0, 0]}]
  container: {min: [0, 0, 0], max: [1, -1, 1]}
  material: {restitution: 0.001}
bodies:
  - {name: wall, shape: {type: box, size: [1, 1, 1]}, spacing: 0.5, density: 1, static: true, velocity: [1, 0, 0]}
  - {name: dots, particles: {positions: [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], masses: [1, 1, 1, 1]}}
"""
    with pytest.raises(SceneError) as info:
        load_scene_text(text, file="bad.yaml")
    found = {(i.location.line, i.message.split(":")[0]) for i in info.value.issues if i.location}
    lines = sorted(line for line, _ in found)
    assert lines == [4, 5, 6, 8, 9], [str(i) for i in info.value.issues]


def test_stability_and_integrator_warnings():
    text = """name: w
simulation: {dt: 0.01, steps: 10, integrator: euler-matrix}
gravity: [0, 0, -9.81]
contact: {ground: 0}
bodies:
  - {name: b, particles: {positions: [[0, 0, 0]], masses: [0.5], radius: [0.05]}, position: [0, 0, 0.1]}
"""
    spec = load_scene_text(text, file="w.yaml")
    warnings = [str(w) for w in rbcli.prepare(spec).warnings]
    assert any("stable step" in w for w in warnings) and any("euler-matrix" in w for w in warnings)
    auto = rbcli.prepare(spec, integrator="split2")
    assert not [w for w in auto.warnings if "euler-matrix" in str(w)]


def test_default_integrator_with_contact_is_split2():
    spec = load_scene_text("""name: d
simulation: {dt: 0.001, steps: 10}
contact: {ground: 0}
bodies:
  - {name: b, particles: {positions: [[0, 0, 0]], masses: [0.5], radius: [0.05]}, position: [0, 0, 0.1]}
""")
    assert spec.simulation.integrator == "split2"


def test_contact_history_is_state_step_splits_and_reset():
    """step(a) then step(b) equals step(a + b) bitwise with contacts carrying history; reset clears it."""
    bodies = [ball("a", (0, 0, 0.05), (0.5, 0, 0)), ball("b", (0.3, 0.02, 0.05), (-0.5, 0, 0))]
    whole = scene(bodies, dt=1e-3, steps=600, contact="  ground: 0\n")
    split = scene(bodies, dt=1e-3, steps=600, contact="  ground: 0\n")
    whole.step(600)
    split.step(250)
    assert split.data.force.contact.hist_count.sum() > 0
    split.step(350)
    for name in ("x", "q", "P", "L"):
        assert np.array_equal(getattr(whole.data.state, name), getattr(split.data.state, name))
    split.reset()
    assert split.data.force.contact.hist_count.sum() == 0
    split.step(600)
    assert np.array_equal(whole.data.state.x, split.data.state.x)


def test_kinematic_paddle_turns_uniformly_whatever_it_hits():
    """A kinematic body keeps its velocity and angular velocity exactly (infinite mass for contact, no
    force acts on it, an isotropic inertia so its torque-free turn is uniform) and pushes what it meets."""
    paddle = ("  - {name: paddle, shape: {type: box, size: [0.6, 0.05, 0.1]}, spacing: 0.025, density: 500, "
              "kinematic: true, position: [0, 0, 0.06], angular_velocity: [0, 0, 3], "
              "velocity: [0.05, 0, 0]}")  # fmt: skip
    sim = scene([paddle, ball("ball", (0.2, 0.2, 0.04), radius=0.04, mass=0.2)], dt=1e-3, steps=2000,
                contact="  ground: 0\n  material: {restitution: 0.3, friction: 0.5}\n")  # fmt: skip
    sim.step(2000)
    np.testing.assert_allclose(sim.state.omega[0], [0, 0, 3], atol=1e-12)
    np.testing.assert_allclose(sim.state.v[0], [0.05, 0, 0], atol=1e-15)
    np.testing.assert_allclose(sim.state.x[0], [0.1, 0, 0.06], atol=1e-12)
    assert np.linalg.norm(sim.state.v[1]) > 0.3  # the ball was hit


def test_static_and_kinematic_bodies_need_contact():
    text = """name: k
simulation: {dt: 0.001, steps: 10}
bodies:
  - {name: post, particles: {positions: [[0, 0, 0]], masses: [1], radius: [0.1]}, static: true}
"""
    with pytest.raises(SceneError, match="static bodies need contact"):
        load_scene_text(text)
