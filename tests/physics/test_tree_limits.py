"""Limits, cones and motors in joint coordinates (physics/tree/limits.py): measured with the maximal
joints' own coordinate functions (physics/joints/drives.py `limit_row`, computed from the bodies' states,
not from the tree's coordinates), on joints whose link is either end and whose parent is the world, a
static body or another link; a motor's relative spin against momentum conservation; a limit's reaction
against statics. The single-joint cases (a slider onto its limit, a hinge between two, a capped motor, a
box in its cone) are the maximal solver's tests run on every integrator (test_joints_limits.py,
test_joints_drives.py, test_joints_cone.py)."""

from __future__ import annotations

import numpy as np
import pytest

from rbcli.physics.integrators import REDUCED_INTEGRATORS, get_integrator
from rbcli.physics.joints.drives import limit_row
from rbcli.physics.joints.tables import JOINT_BALL
from rbcli.runner.simulation import Simulation
from rbcli.scene import compile_trees
from rbcli.scene.load import load_scene_text
from rbcli.scene.spec import SceneError

# the distinct methods in joint coordinates: reduced-implicit is reduced-euler's step and loop without contact
# (bitwise: test_tree_integrate.py test_reduced_implicit_without_contact_is_reduced_euler), so these run
# the two methods; its contact has its own tests (test_implicit_contact.py)
REDUCED_METHODS = [name for name in REDUCED_INTEGRATORS if not get_integrator(name).implicit_contact]

G = 9.81
BOX = ", ".join(f"[{sx * 0.1}, {sy * 0.05}, {sz * 0.15}]" for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1))
# three links under a static, tilted post: the shoulder (a ball, its link body_a, its parent the static
# post), the elbow (a hinge whose link is its body_b) and the wrist (a ball whose link is its body_b, an
# elliptic cone), all thrown hard enough to reach every bound
CHAIN = f"""
simulation: {{dt: 0.001, steps: 10, integrator: split2}}
gravity: [0, 0, -9.81]
contact: {{}}
bodies:
  - name: post
    static: true
    particles: {{positions: [[0, 0, 0]], masses: 1.0, radius: 0.05}}
    position: [0, 0, 2.0]
    orientation: {{axis_angle: {{axis: [1, 1, 0], angle: 0.6}}}}
  - name: upper
    particles: {{positions: [{BOX}], masses: [0.1, 0.15, 0.1, 0.12, 0.1, 0.1, 0.13, 0.1]}}
    position: [0, 0, 1.8]
    collide: false
    angular_velocity: [3.0, -2.0, 4.0]
    velocity: [1.0, 0.5, 0]
  - name: rod
    particles: {{positions: [[0, 0, 0.15], [0, 0, 0.05], [0, 0, -0.05], [0, 0, -0.15]], masses: 0.1, radius: 0.02}}
    position: [0, 0, 1.45]
    angular_velocity: [0, 6.0, 0]
  - name: lower
    particles: {{positions: [{BOX}], masses: [0.1, 0.1, 0.12, 0.1, 0.14, 0.1, 0.1, 0.11]}}
    position: [0, 0, 1.1]
    collide: false
    angular_velocity: [-5.0, 2.0, 6.0]
joints:
  - {{name: shoulder, type: ball, bodies: [upper, post], anchor: [0, 0, 2.0],
     cone: {{axis: [0, 0, -1], swing: 0.15, twist: [-0.3, 0.3]}}}}
  - {{name: elbow, type: hinge, bodies: [upper, rod], anchor: [0, 0, 1.62], axis: [0, 1, 0], limits: [-0.2, 0.2]}}
  - {{name: wrist, type: ball, bodies: [rod, lower], anchor: [0, 0, 1.28],
     cone: {{axis: [0, 0, -1], swing: [0.5, 0.3], reference: [1, 0, 0], twist: [-0.2, 0.25]}}}}
"""


@pytest.mark.parametrize("integrator", ["split2", *REDUCED_METHODS])
def test_every_limit_of_a_tree_holds_to_round_off_whichever_end_its_link_is(integrator):
    """2 s of the thrown chain: every step, each joint's coordinate as the maximal joints measure it from
    the bodies' poses (hinge angle, ball twist, swing measure c <= 1) is within its bounds to 1e-12 (the
    coupled limits are solved together: a stop at the wrist moves the elbow), and the stops act (each
    reached to 1e-9): both ends of each twist, both cones, and one of the elbow's stops (the motion is
    chaotic: which one depends on everything before)."""
    sim = Simulation(load_scene_text(CHAIN.replace("integrator: split2", f"integrator: {integrator}")))
    table = sim.model.joint
    if integrator != "split2":  # maximal coordinates: the same limits solved together (joints/limit_solve.py)
        assert sim.model.tree is not None and sim.model.tree.joint_side.tolist() == [1, -1, -1]
    low, high, worst = np.full((3, 2), np.inf), np.full((3, 2), -np.inf), 0.0
    for _ in range(2000):
        sim.step(1)
        s = sim.data.state
        for j in range(3):
            c = limit_row(table, j, False, s.x, s.q)[0]  # the hinge's angle or the ball's twist
            low[j, 0], high[j, 0] = min(low[j, 0], c), max(high[j, 0], c)
            worst = max(worst, float(table.limit_lower[j]) - c, c - float(table.limit_upper[j]))
            if table.kind[j] == JOINT_BALL:
                swing = limit_row(table, j, True, s.x, s.q)[0]
                high[j, 1] = max(high[j, 1], swing)
                worst = max(worst, swing - 1.0)
    assert worst <= 1e-12, worst
    np.testing.assert_allclose(low[[0, 2], 0], table.limit_lower[[0, 2]], atol=1e-9)  # both twists, both ends
    np.testing.assert_allclose(high[[0, 2], 0], table.limit_upper[[0, 2]], atol=1e-9)
    np.testing.assert_allclose(high[[0, 2], 1], 1.0, atol=1e-9)  # both cones
    assert min(low[1, 0] - table.limit_lower[1], table.limit_upper[1] - high[1, 0]) <= 1e-9  # the elbow's stop


# a turntable on a vertical axle (free to turn) carrying a wheel on a second vertical axle: the wheel's
# hinge lists the turntable first, so the wheel (the child link) is its body_b; no gravity
TURNTABLE = """
simulation: {dt: 0.001, steps: 10, integrator: split2}
bodies:
  - name: table
    particles: {positions: [[0.3, 0, 0], [-0.3, 0, 0], [0, 0.3, 0], [0, -0.3, 0]], masses: 0.5}
    position: [0, 0, 0]
  - name: wheel
    particles: {positions: [[0.6, 0, 0.1], [0.4, 0, 0.1], [0.5, 0.1, 0.1], [0.5, -0.1, 0.1]], masses: 0.25}
    position: [0.5, 0, 0.1]
joints:
  - {name: axle, type: hinge, bodies: [table, world], anchor: [0, 0, 0], axis: [0, 0, 1]}
  - {name: spindle, type: hinge, bodies: [table, wheel], anchor: [0.5, 0, 0.1], axis: [0, 0, 1],
     motor: {speed: 3.0, max_torque: 0.05}}
"""


@pytest.mark.parametrize("integrator", ["split2", *REDUCED_METHODS])
def test_a_motor_turns_its_joint_the_way_it_is_written_whichever_end_its_link_is(integrator):
    """The spindle's motor drives r = (omega_table - omega_wheel) . z, the joint's rate as the maximal
    joints define it (body_a relative to body_b), to 3 rad/s. Its torque acts between the two bodies, so
    the angular momentum about the axle stays 0 (to 1e-15), r rises at one constant rate (to 1e-9
    relative), reaches 3 rad/s in the step the rigid-body equations give (`_motor_steps`) and holds it
    to 1e-12."""
    sim = Simulation(load_scene_text(TURNTABLE.replace("integrator: split2", f"integrator: {integrator}")))
    rates, momenta = [], []
    for _ in range(1500):
        sim.step(1)
        s = sim.state
        rates.append(s.omega[0, 2] - s.omega[1, 2])
        # about the axle (the origin): both bodies' spin and orbital angular momentum
        momenta.append(sum(s.L[b, 2] + np.cross(s.x[b], s.P[b])[2] for b in range(2)))
    rates = np.array(rates)
    assert np.abs(momenta).max() <= 1e-15, np.abs(momenta).max()
    reached = int(np.argmax(rates >= 3.0 - 1e-12))
    assert 100 < reached < 1400, reached
    slope = np.diff(rates[: reached - 1])
    np.testing.assert_allclose(slope, slope[0], rtol=1e-9)
    assert np.abs(rates[reached:] - 3.0).max() <= 1e-12
    assert abs(reached - _motor_steps()) <= 1, (reached, _motor_steps())  # the closed form's step


def _motor_steps() -> int:
    """The step in which r reaches 3 rad/s by the rigid-body equations. The motor's torque is -T on the
    wheel (about its centre, where the spindle is: the spindle's force has no moment there) and +T on the
    table, T = 0.05 N m while it is capped: I_w d(omega_w)/dt = -T, and the angular momentum about the
    axle, (I_t + m d^2) omega_t + I_w omega_w, stays 0, so r = omega_t - omega_w grows at
    T (1 / I_w + 1 / (I_t + m d^2)). I_t = 4 (0.5 kg) (0.3 m)^2 and I_w = 4 (0.25 kg) (0.1 m)^2 (point
    particles), the wheel's mass m = 1 kg at d = 0.5 m from the axle."""
    I_t, I_w, m, d = 4 * 0.5 * 0.3**2, 4 * 0.25 * 0.1**2, 1.0, 0.5
    rate = 0.05 * (1.0 / I_w + 1.0 / (I_t + m * d * d))  # [rad/s^2]
    return int(np.ceil(3.0 / (rate * 1e-3) - 1e-9)) - 1  # the state after step n + 1 is rates[n]


ROD_ON_STOP = """
simulation: {dt: 0.001, steps: 1, integrator: split2, record: {streams: [joint_forces]}}
gravity: [0, 0, -9.81]
bodies:
  - name: rod
    particles: {positions: [[0.1, 0, 0], [0.3, 0, 0], [0.5, 0, 0]], masses: 0.2, radius: 0.02}
    position: [0.3, 0, 1.0]
joints:
  - {name: pivot, type: hinge, bodies: [rod, world], anchor: [0, 0, 1.0], axis: [0, 1, 0], limits: [-1.0, 0.0]}
"""


@pytest.mark.parametrize("integrator", list(REDUCED_METHODS))
def test_a_rod_resting_on_its_stop_feels_its_weight_through_the_joint(integrator):
    """A horizontal rod on a hinge whose limit holds it up (gravity turns it about +y: the angle grows,
    the upper bound 0 stops it): it stays at rest to round-off, and the joint's reaction on it (the
    pivot's force and the stop's torque together) is its weight's opposite, (0, 0, m g) with no torque
    about its centre of mass, to 1e-9: the limit's impulse is in the reaction."""
    sim = Simulation(load_scene_text(ROD_ON_STOP.replace("integrator: split2", f"integrator: {integrator}")))
    weight = float(sim.model.body_mass[0]) * G
    for _ in range(50):
        sim.step(1)
    assert np.abs(sim.state.v).max() <= 1e-12 and np.abs(sim.state.omega).max() <= 1e-12
    reaction = sim.joint_reactions["pivot"][0]
    np.testing.assert_allclose(reaction, [0.0, 0.0, weight, 0.0, 0.0, 0.0], rtol=0, atol=1e-9)


def test_more_limits_than_the_trees_hold_are_a_located_error(monkeypatch):
    """The limits' coupling matrix is dense (m x m): beyond MAX_LIMIT_ROWS the scene is refused at the
    first joint past the bound (here the bound lowered to 1 to keep the case small)."""
    monkeypatch.setattr(compile_trees, "MAX_LIMIT_ROWS", 1)
    with pytest.raises(SceneError) as raised:
        Simulation(load_scene_text(CHAIN.replace("integrator: split2", "integrator: reduced-euler")))
    message = str(raised.value)
    assert "joint 'shoulder': more than 1 limits and motors" in message, message


KICKED = """
simulation: {dt: 0.001, steps: 1, integrator: split2}
bodies:
  - name: rod
    particles: {positions: [[0.1, 0, 0], [0.3, 0, 0], [0.5, 0, 0]], masses: [0.2, 0.3, 0.1], radius: 0.02}
    position: [0.3, 0, 0]
joints:
  - {name: pivot, type: hinge, bodies: [rod, world], anchor: [0, 0, 0], axis: [0, 0.6, 0.8]}
forces:
  - {type: impulse, body: rod, time: 0.0, point: [0.2, 0.05, 0], vector: [0.3, 1.0, -0.4], frame: world}
"""


@pytest.mark.parametrize("integrator", ["split2", *REDUCED_METHODS])
def test_an_impulse_on_a_link_is_the_joint_s_exact_impulsive_reaction(integrator):
    """A rod at rest on a tilted hinge, no gravity, kicked at t = 0 by J at a point p off its axis: it
    turns at omega = ((p - o) x J) . a / I_a about the axis a (o the pivot, I_a its moment about the axis),
    whatever part of J the hinge takes. With no force after the kick the rate stays, so after the first
    step the rod's angular velocity is omega a to round-off in every integrator."""
    sim = Simulation(load_scene_text(KICKED.replace("integrator: split2", f"integrator: {integrator}")))
    x0 = sim.state.x[0].copy()
    sim.step(1)
    a = np.array([0.0, 0.6, 0.8])
    masses, points = np.array([0.2, 0.3, 0.1]), np.array([[0.1, 0, 0], [0.3, 0, 0], [0.5, 0, 0]], dtype=float)
    centre = (points * masses[:, None]).sum(axis=0) / masses.sum()  # body points are in the particles' frame
    offsets = points - centre + x0  # the particles at t = 0 (the pivot: the origin)
    across = offsets - np.outer(offsets @ a, a)
    I_a = float(np.sum(masses * np.sum(across**2, axis=1)) + 0.4 * masses.sum() * 0.02**2)  # + the spheres'
    point = x0 + np.array([0.2, 0.05, 0.0]) - centre
    omega = np.cross(point, [0.3, 1.0, -0.4]) @ a / I_a
    np.testing.assert_allclose(sim.state.omega[0], omega * a, rtol=0, atol=1e-12 * abs(omega))


def test_the_numpy_joint_invariants_are_the_kernel_s():
    """Small scenes in joint coordinates record their joint invariants with the numpy twin
    (runner/blocks.py NUMPY_INVARIANT_JOINTS): on states that break every joint (the chain's bodies moved
    and turned at random, random momenta) it gives violation.joint_violations' max |g| and max |G V| to
    1e-12 relative."""
    from rbcli.physics.joints.reference import joint_violations_numpy
    from rbcli.physics.joints.tables import make_joint_work
    from rbcli.physics.joints.violation import joint_violations
    from rbcli.physics.rotation import quat_normalize

    sim = Simulation(load_scene_text(CHAIN.replace("integrator: split2", "integrator: reduced-euler")))
    rng = np.random.default_rng(7)
    s, K = sim.data.state, 5
    x = s.x[None] + 0.01 * rng.normal(size=(K, *s.x.shape))
    q = np.array([[quat_normalize(row + 0.05 * rng.normal(size=4)) for row in s.q] for _ in range(K)])
    P, L = rng.normal(size=(K, *s.P.shape)), rng.normal(size=(K, *s.L.shape))
    table = sim.model.joint
    kernel = np.zeros((K, 2))
    joint_violations(sim.model.kernel_bodies(), table, make_joint_work(table), x, q, P, L, kernel)
    np.testing.assert_allclose(joint_violations_numpy(sim.model, table, x, q, P, L), kernel, rtol=1e-12, atol=0)
    assert kernel.min() > 1e-4  # the states do break the joints
