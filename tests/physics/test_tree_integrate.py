"""The integrators in joint coordinates (reduced-euler, reduced-rk4: physics/tree/integrate.py) through the
runner, against exact solutions and against the maximal integrators.

- The compound pendulum, T = 4 K(sin^2(theta0/2)) sqrt(I/(M g d)) its exact period, is at theta = 0 moving
  at -2 Omega sin(theta0/2) (energy) after a quarter period, Omega = sqrt(M g d / I): the phase-space
  error there falls at each integrator's order, at 10 and 170 degrees. (A turning point would not do for
  reduced-euler: semi-implicit Euler on one hinge is conjugate to the leapfrog by a shift proportional to
  the rate, so at rest its error is second order while elsewhere it is first.)
- A free body is a one-link tree on a free joint: the torque-free asymmetric body against the Jacobi
  elliptic solution (analysis/exact.py), slopes 1 and 4.
- A 3-D chain of non-isotropic tumbling bodies (ball, tilted hinge) pulled by a damped spring on its last
  link, with drag: split2 with RATTLE, reduced-euler and reduced-rk4 converge to one motion as dt falls,
  each at its order, from initial velocities that break the hinge (both project them the same way: the
  joints' impulsive reaction), so the forces reach the joints alike (J^T f in joint coordinates).
- What the trees refuse is a located error.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from joint_scenes import angle_and_rate, double_pendulum_3d_text, exact_period, pendulum_text, rod_pivot_inertia
from test_integrators_accuracy import FLIP, GENERIC, fitted_slope, rotation_error

from rbcli.api import Simulation
from rbcli.physics.integrators import REDUCED_INTEGRATORS, get_integrator
from rbcli.scene.load import load_scene_text
from rbcli.scene.spec import SceneError

# the distinct methods in joint coordinates: reduced-implicit is reduced-euler's step and loop without contact
# (bitwise: test_reduced_implicit_without_contact_is_reduced_euler below), so these run
# the two methods; its contact has its own tests (test_implicit_contact.py)
REDUCED_METHODS = [name for name in REDUCED_INTEGRATORS if not get_integrator(name).implicit_contact]

ORDER = {"reduced-euler": 1, "reduced-rk4": 4}
# steps per quarter period where each order is asymptotic and far above round-off (10 and 170 degrees)
QUARTER_STEPS = {"reduced-euler": (100, 200, 400), "reduced-rk4": (25, 50, 100)}


def _phase_error_after_a_quarter_period(integrator: str, theta0: float, steps: int) -> float:
    """|(theta, (omega - omega_exact) / Omega)| after a quarter of the exact period in `steps` steps."""
    quarter = exact_period(theta0) / 4.0
    sim = Simulation(load_scene_text(pendulum_text(theta0, quarter / steps, steps=steps, integrator=integrator)))
    sim.step(steps)
    state = sim.state
    theta, rate = angle_and_rate(state.x[0], state.v[0])
    M, d, inertia = rod_pivot_inertia()
    natural = math.sqrt(M * 9.81 * d / inertia)
    return math.hypot(theta, (rate + 2.0 * natural * math.sin(theta0 / 2.0)) / natural)


@pytest.mark.parametrize("integrator", list(REDUCED_METHODS))
@pytest.mark.parametrize("degrees", [10.0, 170.0])
def test_the_pendulum_reaches_its_exact_quarter_period_state_at_the_integrator_s_order(integrator, degrees):
    theta0 = math.radians(degrees)
    steps = QUARTER_STEPS[integrator]
    errors = [_phase_error_after_a_quarter_period(integrator, theta0, n) for n in steps]
    slope = fitted_slope(1.0 / np.array(steps), errors)
    assert abs(slope - ORDER[integrator]) < 0.25, (errors, slope)
    assert errors[-1] < (1e-2 if integrator == "reduced-euler" else 1e-6), errors


@pytest.mark.parametrize("integrator", list(REDUCED_METHODS))
@pytest.mark.parametrize("case", [GENERIC, FLIP], ids=["generic", "flip"])
def test_a_free_body_is_a_free_root_at_the_integrator_s_order(integrator, case):
    """The torque-free asymmetric body (and near the intermediate-axis separatrix), 20 s, against the
    exact solution: the largest orientation error falls at the method's order."""
    dts = {"reduced-euler": (1e-4, 3e-4, 1e-3), "reduced-rk4": (1e-2, 2e-2, 5e-2)}[integrator]
    errors = [rotation_error(integrator, case, dt, 20.0, every=max(1, round(0.01 / dt)))[0] for dt in dts]
    assert abs(fitted_slope(dts, errors) - ORDER[integrator]) < 0.25, errors


CHAIN_TIME = 0.5  # [s]


def _chain_text(dt: float, integrator: str) -> str:
    """double_pendulum_3d_text with the elbow a hinge about a tilted axis (the box's and the cloud's
    initial spins break it: the first step, or the reduced state's start, projects them), a damped
    spring from a point of the cloud to a world point and drag on both: forces that reach the joints through
    ABA's backward pass (J^T f) in joint coordinates and through the multipliers in maximal ones."""
    text = double_pendulum_3d_text(dt).replace("integrator: split2", f"integrator: {integrator}")
    text = text.replace("steps: 10", f"duration: {CHAIN_TIME!r}")
    text = text.replace("name: elbow, type: ball,", "name: elbow, type: hinge, axis: [0.48, -0.64, 0.6],")
    return (
        text
        + """forces:
  - {type: spring, body: cloud, point: [0.1, 0.0, 0.0], anchor: [0.5, 0.3, 1.5], stiffness: 40, rest_length: 0.2,
     damping: 0.3}
  - {type: drag, bodies: all, linear: 0.05, angular_linear: 0.001}
"""
    )


def _chain_end(dt: float, integrator: str) -> np.ndarray:
    sim = Simulation(load_scene_text(_chain_text(dt, integrator)))
    sim.step(round(CHAIN_TIME / dt))
    state = sim.state
    return np.concatenate([state.x.ravel(), state.v.ravel(), state.omega.ravel()])


def test_maximal_and_reduced_coordinates_converge_to_one_3d_chain_motion():
    reference = _chain_end(2.5e-4, "reduced-rk4")
    assert np.max(np.abs(_chain_end(5e-4, "reduced-rk4") - reference)) < 1e-9  # reduced-rk4 is converged
    dts = [4e-3, 2e-3, 1e-3]
    for integrator, order in (("split2", 2), ("reduced-euler", 1)):
        gaps = [float(np.max(np.abs(_chain_end(dt, integrator) - reference))) for dt in dts]
        assert abs(fitted_slope(dts, gaps) - order) < 0.3, (integrator, gaps)
        assert gaps[-1] < (1e-3 if order == 2 else 0.2), (integrator, gaps)


def test_the_links_obey_the_joints_to_round_off_and_the_state_is_forward_kinematics():
    """reduced-rk4 on the tumbling chain: the anchors coincide to round-off, the hinge's axis stays common,
    and a checkpoint restored continues bitwise."""
    sim = Simulation(load_scene_text(_chain_text(1e-3, "reduced-rk4")))
    table = sim.model.joint
    sim.step(300)
    saved = sim.checkpoint()
    sim.step(200)
    after = sim.checkpoint().arrays
    s = sim.data.state
    from rbcli.physics.rotation import quat_rotate

    for j in range(2):
        a, b = int(table.body_a[j]), int(table.body_b[j])
        p_a = s.x[a] + quat_rotate(s.q[a][None], table.anchor_a[j][None])[0]
        p_b = table.anchor_b[j] if b < 0 else s.x[b] + quat_rotate(s.q[b][None], table.anchor_b[j][None])[0]
        assert np.linalg.norm(p_a - p_b) < 1e-13
    axis_a = quat_rotate(s.q[1][None], table.axis_a[1][None])[0]
    normals = quat_rotate(np.repeat(s.q[0][None], 2, axis=0), table.normal_b[1])
    assert np.max(np.abs(normals @ axis_a)) < 1e-13
    sim.restore(saved)
    sim.step(200)
    for name, array in sim.checkpoint().arrays.items():
        assert np.array_equal(array, after[name], equal_nan=True), name


def test_the_reduced_integrators_are_listed_with_their_order():
    for name, order in ORDER.items():
        info = get_integrator(name)
        assert info.reduced and info.order == order


def test_what_the_trees_do_not_hold_is_a_located_error():
    text = double_pendulum_3d_text(1e-3).replace("integrator: split2", "integrator: reduced-rk4")
    loop = text + "  - {name: loop, type: ball, bodies: [cloud, world], anchor: [0.0, 0.0, 2.0]}\n"
    with pytest.raises(SceneError) as raised:
        Simulation(load_scene_text(loop.replace("anchor: [0.0, 0.0, 2.0]", "anchor: " + _cloud_point(text))))
    message = str(raised.value)
    assert message.startswith("<string>:19:") and "joint 'loop': it closes a loop" in message
    tethered = text + "  - {name: tether, type: distance, bodies: [cloud, box], anchors: [[0, 0, 0], [0, 0, 0]]}\n"
    with pytest.raises(SceneError, match="joint 'tether': a distance joint is a constraint between two links"):
        Simulation(load_scene_text(tethered))
    # a kinematic body joined to a tree (a moving root) is not modelled in joint coordinates: named, refused
    # at the joint; named nothing, the scene runs split2 (tests/scene/test_joints_format.py)
    crank = (
        PADDLE.replace("DT", "0.001")
        .replace("INTEGRATOR", "reduced-rk4")
        .replace("bodies: [bob, world]", "bodies: [bob, paddle]")
    )
    with pytest.raises(SceneError, match="joint 'pivot': a kinematic body in a tree is not modelled yet"):
        Simulation(load_scene_text(crank))


def _cloud_point(text: str) -> str:
    """The cloud's initial centre of mass as the scene gives it (a point on the cloud: a valid anchor)."""
    line = text.split("name: cloud", 1)[1].split("position: ", 1)[1].splitlines()[0]
    return line.strip()


def test_joint_coordinates_are_read_and_written_by_joint_name():
    """The pendulum in joint coordinates: the hinge's angle is 0 at the initial pose; set to 0.3 rad moving
    at 1.5 rad/s, the rod's centre of mass is at theta0 + 0.3 about the pivot moving at 1.5 rad/s (read off
    the bodies' state, which forward kinematics rewrote); a ball joint's quaternion and rate, in the
    child's own frame, read back as written; a maximal run has no joint coordinates."""
    theta0 = math.radians(10.0)
    sim = Simulation(load_scene_text(pendulum_text(theta0, 1e-3, integrator="reduced-euler")))
    pivot = sim.joint_state()["pivot"]
    assert (pivot.kind, pivot.child, pivot.parent) == ("hinge", "rod", "world")
    assert abs(pivot.position[0]) < 1e-15 and abs(pivot.rate[0]) < 1e-15
    sim.set_joint_state("pivot", position=[0.3], rate=[1.5])
    theta, rate = angle_and_rate(sim.state.x[0], sim.state.v[0])
    assert abs(theta - (theta0 + 0.3)) < 1e-13 and abs(rate - 1.5) < 1e-12
    assert sim.joint_state()["pivot"].position[0] == 0.3
    sim.step(10)
    assert sim.joint_state()["pivot"].rate[0] < 1.5  # rising away from the bottom: slower
    chain = Simulation(load_scene_text(double_pendulum_3d_text(1e-3).replace("integrator: split2",
                                                                               "integrator: reduced-rk4")))  # fmt: skip
    u = np.array([0.9, 0.1, -0.3, 0.2])
    u /= np.linalg.norm(u)
    chain.set_joint_state("elbow", position=u, rate=[0.5, -1.0, 2.0])
    elbow = chain.joint_state()["elbow"]
    assert (elbow.kind, elbow.child, elbow.parent) == ("ball", "cloud", "box")
    np.testing.assert_allclose(elbow.position, u, atol=1e-15)
    np.testing.assert_allclose(elbow.rate, [0.5, -1.0, 2.0], atol=1e-14)
    with pytest.raises(ValueError, match="no joint 'knee'"):
        chain.set_joint_state("knee", rate=[1.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="rate must be 3 finite"):
        chain.set_joint_state("elbow", rate=[1.0])
    with pytest.raises(ValueError, match="maximal coordinates"):
        Simulation(load_scene_text(pendulum_text(theta0, 1e-3))).joint_state()


def test_a_scene_says_it_runs_in_joint_coordinates():
    """`simulation: {coordinates: reduced}` without an integrator runs reduced-rk4; with a maximal integrator
    it is a located error, and so is an override to one; a tree that names no integrator runs reduced-rk4,
    one that says `coordinates: maximal` split2."""
    theta0 = math.radians(10.0)
    text = pendulum_text(theta0, 1e-3)  # names split2
    reduced = text.replace("integrator: split2}", "coordinates: reduced}")
    sim = Simulation(load_scene_text(reduced))
    assert sim.settings.integrator == "reduced-rk4" and sim.model.tree is not None
    sim.step(5)
    assert set(sim.joint_state()) == {"pivot"}
    with pytest.raises(SceneError) as raised:
        load_scene_text(text.replace("integrator: split2}", "integrator: split2, coordinates: reduced}"))
    message = str(raised.value)
    assert message.startswith("<string>:3:") and "integrator 'split2' runs in maximal coordinates" in message
    with pytest.raises(ValueError, match="integrator='split2': the scene runs in joint coordinates"):
        Simulation(load_scene_text(reduced), integrator="split2")
    named_none = text.replace("integrator: split2}", "}")  # a tree: reduced-rk4 unless the scene says maximal
    assert Simulation(load_scene_text(named_none)).settings.integrator == "reduced-rk4"
    maximal = text.replace("integrator: split2}", "coordinates: maximal}")
    assert Simulation(load_scene_text(maximal)).settings.integrator == "split2"


def _limitless_ragdoll(substeps: int) -> str:
    """scenes/joints/capsule_ragdoll.yaml without its cones, limits and joint dampers (what the trees do
    not hold yet), 1 s, with `substeps` contact sub-steps per 1 ms step."""
    import re
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "scenes" / "joints" / "capsule_ragdoll.yaml").read_text()
    text = re.sub(r", (cone: \{[^}]*\}|damping: [0-9.]+|limits: \[[^\]]*\])", "", text)
    return text.replace("duration: 3.0", "duration: 1.0").replace("substeps: auto", f"substeps: {substeps}")


def _ragdoll_path(integrator: str, substeps: int) -> np.ndarray:
    """Every part's centre of mass every 0.1 s, (10, 8, 3)."""
    sim = Simulation(load_scene_text(_limitless_ragdoll(substeps)), integrator=integrator)
    path = []
    for _ in range(10):
        sim.step(100)
        path.append(sim.state.x.copy())
    return np.array(path)


def test_a_ragdoll_with_contact_moves_alike_in_both_families():
    """Eight capsules and a sphere on ball joints and hinges (a tree), dropped 1 m onto a tilted plane:
    split2 + RATTLE and reduced-rk4 fall together to 1e-12 m until the first touch-down (~0.45 s: a rigid
    assembly in free fall, which both integrate exactly to round-off). Contact is not smooth and the pile
    of impacts amplifies any difference, so after it the tolerance is the discretisation's own: their gap
    at 1 s with 22 sub-steps a step (measured 5.9e-2 m) is within 1.5 times what halving the sub-step
    changes either method (4.4e-2, 4.7e-2), and it shrinks as the sub-step halves (3.8e-2 at 44)."""
    maximal = {s: _ragdoll_path("split2", s) for s in (22, 44)}
    reduced = {s: _ragdoll_path("reduced-rk4", s) for s in (22, 44)}
    gap = {s: np.max(np.abs(maximal[s] - reduced[s]), axis=(1, 2)) for s in (22, 44)}
    assert np.all(gap[22][:4] < 1e-12), gap[22]  # 0.1 .. 0.4 s: before the touch-down
    own = max(np.max(np.abs(maximal[22][-1] - maximal[44][-1])), np.max(np.abs(reduced[22][-1] - reduced[44][-1])))
    assert gap[22][-1] <= 1.5 * own, (gap[22][-1], own)
    assert gap[44][-1] < gap[22][-1], (gap[44][-1], gap[22][-1])


def _flywheel_text(joint: str, damping: float, dt: float, integrator: str) -> str:
    """A cube of eight 0.5 kg particles at (+-0.1, +-0.1, +-0.1) m (radius 0.01 m: isotropic inertia I) on
    a damped hinge about z, or a damped ball joint, at its centre, spinning at 5 rad/s about z; no gravity."""
    corners = ", ".join(f"[{x}, {y}, {z}]" for x in (-0.1, 0.1) for y in (-0.1, 0.1) for z in (-0.1, 0.1))
    axis = ", axis: [0, 0, 1]" if joint == "hinge" else ""
    return f"""
name: flywheel
simulation: {{dt: {dt!r}, duration: 1.0, integrator: {integrator}}}
bodies:
  - name: wheel
    particles: {{positions: [{corners}], masses: 0.5, radius: 0.01}}
    position: [0, 0, 0]
    angular_velocity: [0, 0, 5.0]
joints:
  - {{name: axle, type: {joint}, bodies: [wheel, world], anchor: [0, 0, 0]{axis}, damping: {damping!r}}}
"""


FLYWHEEL_INERTIA = 8 * 0.5 * (2 * 0.1**2) + 8 * 0.4 * 0.5 * 0.01**2  # [kg m^2] about any axis (a cube)


@pytest.mark.parametrize("joint", ["hinge", "ball"])
def test_a_joint_damper_is_implicit_in_reduced_euler_and_fourth_order_in_reduced_rk4(joint):
    """omega(t) = 5 exp(-c t / I). reduced-euler's damper is backward Euler, so after n steps omega is
    exactly 5 (1 + c h / I)^-n, at any c h (here up to 50 I: a stiff damper stays stable and monotone);
    reduced-rk4's error falls at order 4."""
    for c in (0.05, 50.0 * FLYWHEEL_INERTIA / 1e-2):
        sim = Simulation(load_scene_text(_flywheel_text(joint, c, 1e-2, "reduced-euler")))
        sim.step(10)
        expected = 5.0 * (1.0 + c * 1e-2 / FLYWHEEL_INERTIA) ** -10
        np.testing.assert_allclose(sim.state.omega[0], [0.0, 0.0, expected], rtol=1e-12, atol=1e-14 * 5.0)
    errors = []
    for dt in (0.1, 0.05, 0.025):
        sim = Simulation(load_scene_text(_flywheel_text(joint, 0.05, dt, "reduced-rk4")))
        sim.step(round(1.0 / dt))
        errors.append(abs(sim.state.omega[0, 2] - 5.0 * math.exp(-0.05 / FLYWHEEL_INERTIA)))
    assert abs(fitted_slope([0.1, 0.05, 0.025], errors) - 4.0) < 0.25, errors


@pytest.mark.parametrize("integrator", list(REDUCED_METHODS))
def test_the_pivot_s_reaction_at_release_is_the_compound_pendulum_s(integrator):
    """Released from rest at 60 degrees, the rod's centre of mass accelerates along its circle at
    d theta'' (theta'' = -M g d sin(theta0) / I_pivot, no centripetal part at rest): the pivot pushes it with
    M (a - g), whose moment about the centre of mass is r x F (r from the centre to the pivot). Over the
    first step the mean reaction is that to O(dt) (reduced-euler's is the start's exactly; reduced-rk4's
    mean moves with the swing): recorded in the joint_forces stream and read by joint_reactions, on the
    rod (the joint's first body) and nothing on the world."""
    from rbcli.record.memory_sink import SinkMemory

    theta0, dt = math.radians(60.0), 1e-5
    text = pendulum_text(theta0, dt, steps=1, integrator=integrator).replace(
        "steps: 1,", "steps: 1, record: {streams: [bodies, joint_forces]},"
    )
    sim = Simulation(load_scene_text(text))
    memory = SinkMemory()
    sim.run(sinks=[memory])
    recorded = memory.trajectory().joint_reactions["pivot"]
    M, d, inertia = rod_pivot_inertia()
    acceleration = -M * 9.81 * d * math.sin(theta0) / inertia
    a = acceleration * d * np.array([-math.cos(theta0), 0.0, math.sin(theta0)])
    force = M * (a - np.array([0.0, 0.0, -9.81]))
    torque = np.cross(np.array([0.0, 0.0, 1.0]) - sim.compiled.initial_state.x[0], force)
    expected = np.concatenate([force, torque])
    rtol = 1e-12 if integrator == "reduced-euler" else 1e-4  # rk4: the mean over the step's swing
    reaction = sim.joint_reactions["pivot"]
    np.testing.assert_allclose(reaction[0], expected, rtol=0, atol=rtol * np.max(np.abs(expected)))
    assert np.all(reaction[1] == 0.0)
    np.testing.assert_array_equal(recorded[-1], reaction)  # the stream's last frame: the same numbers
    assert np.all(np.isnan(recorded[0]))  # no step led to the first frame


def test_the_reported_reactions_balance_each_body_s_momentum_change():
    """The tumbling 3-D double pendulum under reduced-rk4, dt 1 ms: over a step each body's momentum changes
    by dt (m g + the reactions of its joints on it) to 1e-9 of that change (measured 5e-11: RK4's
    weighted mean of the stages' wrenches is the step's mean to O(dt^5)). reduced-euler's balance holds to
    O(dt^2) only (its rates change by dt qdd, its bodies' velocities by forward kinematics of them)."""
    text = double_pendulum_3d_text(1e-3).replace("integrator: split2", "integrator: reduced-rk4")
    sim = Simulation(load_scene_text(text.replace("steps: 10,", "steps: 10, record: {streams: [joint_forces]},")))
    sim.step(5)
    before = sim.state.P.copy()
    sim.step(1)
    reactions, mass, gravity = sim.joint_reactions, sim.model.body_mass, np.array([0.0, 0.0, -9.81])
    box = mass[0] * gravity + reactions["shoulder"][0, :3] + reactions["elbow"][1, :3]
    cloud = mass[1] * gravity + reactions["elbow"][0, :3]
    change = sim.state.P - before
    scale = 1e-3 * max(np.abs(box).max(), np.abs(cloud).max())
    assert np.abs(change[0] - 1e-3 * box).max() < 1e-9 * scale
    assert np.abs(change[1] - 1e-3 * cloud).max() < 1e-9 * scale


def test_set_state_in_joint_coordinates_keeps_what_the_joints_allow():
    """A spin and a velocity the hinge does not allow, set on the pendulum's rod, become the motion the
    hinge allows that is closest in kinetic energy: a turn about the hinge's axis (y) through the pivot,
    its rate (I_pivot omega = the angular momentum about the pivot's axis), and the state stays on it."""
    sim = Simulation(load_scene_text(pendulum_text(math.radians(30.0), 1e-3, integrator="reduced-rk4")))
    pivot = np.array([0.0, 0.0, 1.0])
    x = sim.state.x[0]
    M, d, inertia = rod_pivot_inertia()
    omega, v = np.array([1.0, 2.0, 3.0]), np.array([0.5, -0.2, 0.1])
    sim.set_state(omega=omega[None], v=v[None])
    # the angular momentum about the pivot's y axis: (L + (x - pivot) x P) . y, with L = I omega
    state = sim.state
    I_com = sim.model.body_inertia[0]  # principal; the rod's frame: L = R diag(I) R^T omega
    from rbcli.physics.rotation import quat_rotate, quat_rotate_inverse

    q = sim.data.state.q
    L = quat_rotate(q, I_com * quat_rotate_inverse(q, omega[None]))[0]
    about_y = (L + np.cross(x - pivot, M * v))[1]
    np.testing.assert_allclose(state.omega[0], [0.0, about_y / inertia, 0.0], atol=1e-12)
    np.testing.assert_allclose(state.v[0], np.cross(state.omega[0], x - pivot), atol=1e-12)
    assert abs(sim.joint_state()["pivot"].rate[0] - about_y / inertia) < 1e-12


PADDLE = """
simulation: {dt: DT, duration: 0.6, integrator: INTEGRATOR}
gravity: [0, 0, -9.81]
contact: {material: {restitution: 0.5, friction: 0.0}}
bodies:
  - name: bob
    particles: {positions: [[0, 0, 0]], masses: 1.0, radius: 0.1}
    position: [0, 0, 0]
  - name: paddle
    particles: {positions: [[0, 0, 0]], masses: 1.0, radius: 0.1}
    position: [-0.5, 0, 0]
    kinematic: {velocity: [1.0, 0, 0]}
joints:
  - {name: pivot, type: hinge, bodies: [bob, world], anchor: [0, 0, 1], axis: [0, 1, 0]}
"""


def _bob_at_the_end(integrator: str, dt: float) -> np.ndarray:
    sim = Simulation(load_scene_text(PADDLE.replace("DT", repr(dt)).replace("INTEGRATOR", integrator)))
    sim.step(round(0.2 / dt))
    assert np.abs(sim.state.x[0]).max() <= 1e-14  # at rest until the paddle arrives (~0.3 s)
    sim.step(round(0.4 / dt))
    return sim.state.x[0].copy()


def test_a_kinematic_paddle_pushes_a_link_through_contact_alike_in_both_families():
    """A kinematic sphere moving at 1 m/s meets a bob hanging on a hinge and pushes it (contact forces
    enter ABA as the links' external forces, the paddle as moving ground). The bob is pushed ~0.38 m. The
    contact's penalty spring makes the motion sensitive to the step (the bob's end point moves 3e-3 m
    when dt halves in either family), so the test is the families' agreement relative to that: their gap
    at 0.6 s (measured 3.8e-4 m at dt 1 ms) is below a quarter of split2's own change and shrinks with dt
    (2.3e-4 m at 0.5 ms)."""
    ends = {(name, dt): _bob_at_the_end(name, dt) for name in ("split2", "reduced-rk4") for dt in (1e-3, 5e-4)}
    assert ends[("split2", 1e-3)][0] > 0.3  # pushed
    gap = {dt: np.abs(ends[("split2", dt)] - ends[("reduced-rk4", dt)]).max() for dt in (1e-3, 5e-4)}
    own = np.abs(ends[("split2", 1e-3)] - ends[("split2", 5e-4)]).max()
    assert gap[1e-3] < 0.25 * own and gap[5e-4] < gap[1e-3], (gap, own)


def test_reduced_implicit_without_contact_is_reduced_euler():
    """reduced-implicit differs from reduced-euler only in its contact forces (tree/implicit_contact.py):
    without contact the two run the same compiled loop (the quarter-period pendulum's) and agree bitwise,
    so the tests here that run reduced-euler hold for it."""
    runs = {}
    for name in ("reduced-euler", "reduced-implicit"):
        sim = Simulation(load_scene_text(pendulum_text(math.radians(170.0), 1e-3, steps=500, integrator=name)))
        sim.step(500)
        runs[name] = np.concatenate([sim.state.x, sim.state.q, sim.state.P, sim.state.L], axis=1)
    assert np.array_equal(runs["reduced-euler"], runs["reduced-implicit"])
