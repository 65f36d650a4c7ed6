"""A ball joint's swing cone and twist limits (physics/joints/cone.py, drives.py; docs/joints.md, "Cone
and twist limits"): the swing-twist decomposition and the rows' Jacobians against numpy and central
differences, a spinning box on a ball joint held inside a circular and an elliptic cone and its twist range
to round-off, moving bitwise as without limits until it first reaches one and losing energy at every stop,
and each impossible cone refused at its line and column."""

from __future__ import annotations

import numpy as np
import pytest

from rbcli.physics.joints.cone import (
    relative_rotation,
    swing_measure_numpy,
    swing_measure_row,
    swing_twist_numpy,
    swing_vector,
    twist_angle_row,
)
from rbcli.physics.joints.drives import limit_row
from rbcli.physics.joints.tables import CONE_FRAME_A, CONE_FRAME_B, CONE_SWING
from rbcli.physics.rotation import quat_conjugate, quat_from_axis_angle, quat_multiply, quat_normalize
from rbcli.runner.simulation import Simulation
from rbcli.scene.load import analyse_scene_text, load_scene_text

G = 9.81
# a box of eight corner particles (three different moments) hanging 0.5 m below a ball joint at the origin,
# spinning about its long axis and thrown sideways: it swings out to the cone and twists to its range
BOX = """\
simulation: {{dt: 0.001, steps: 10, integrator: split2}}
gravity: [0, 0, -9.81]
bodies:
  - name: box
    particles:
      positions: [{corners}]
      masses: [0.1, 0.15, 0.1, 0.12, 0.1, 0.1, 0.13, 0.1]
    position: [0, 0, -0.5]
    angular_velocity: [4.0, -2.5, 3.0]
    velocity: [1.25, 2.0, 0]
joints:
  - {{name: shoulder, type: ball, bodies: [box, world], anchor: [0, 0, 0]{cone}}}
"""
CORNERS = ", ".join(f"[{sx * 0.12}, {sy * 0.07}, {sz * 0.2}]" for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1))
CIRCLE = ", cone: {axis: [0, 0, -1], swing: 0.5, twist: [-0.4, 0.3]}"
ELLIPSE = ", cone: {axis: [0, 0, -1], swing: [0.6, 0.3], reference: [1, 1, 0], twist: [-0.25, 0.35]}"


def _box(cone: str, integrator: str = "split2") -> Simulation:
    text = BOX.format(corners=CORNERS, cone=cone)
    return Simulation(load_scene_text(text.replace("integrator: split2", f"integrator: {integrator}")))


def _q(rng: np.random.Generator) -> np.ndarray:
    return quat_normalize(rng.normal(size=4))


def _turn(q: np.ndarray, omega: np.ndarray, eps: float) -> np.ndarray:
    """exp(eps omega) q: q turned by eps |omega| about omega (world)."""
    angle = eps * float(np.linalg.norm(omega))
    return quat_multiply(quat_from_axis_angle(omega, angle), q) if angle else q


def test_the_swing_twist_decomposition_matches_quaternion_algebra_and_rebuilds_q():
    """For random relative rotations (and near the identity and near a half-turn swing), the kernel's
    twist angle and swing rotation vector equal numpy's Q = S T by quaternion algebra to 1e-13, S is a turn
    across the axis (r_x = 0), and S T rebuilt from them is Q (or -Q) to 1e-14."""
    rng = np.random.default_rng(7)
    cases = [_q(rng) for _ in range(200)]
    cases += [quat_normalize(np.r_[1.0, 1e-9 * rng.normal(size=3)]), quat_normalize([0.01, 0.2, 0.7, -0.7])]
    for Q in cases:
        Q = Q if Q[0] >= 0 else -Q
        tau, _ = twist_angle_row((Q[0], Q[1], Q[2], Q[3]))
        phi, ry, rz = swing_vector((Q[0], Q[1], Q[2], Q[3]))
        tau_np, r_np = swing_twist_numpy(Q)
        assert abs(tau - tau_np) <= 1e-13 and r_np[0] == pytest.approx(0.0, abs=1e-15)
        np.testing.assert_allclose([ry, rz], r_np[1:], atol=1e-13)
        assert abs(phi - np.linalg.norm(r_np)) <= 1e-13
        S = quat_from_axis_angle(np.array([0.0, ry, rz]), phi) if phi else np.array([1.0, 0, 0, 0])
        T = quat_from_axis_angle(np.array([1.0, 0.0, 0.0]), tau)
        rebuilt = quat_multiply(S, T)
        assert min(np.abs(rebuilt - Q).max(), np.abs(rebuilt + Q).max()) <= 1e-14


def test_the_cone_measure_is_the_normalised_ellipse_and_its_gradient_is_exact():
    """c = sqrt((r_z / a1)^2 + (r_y / a2)^2) equals numpy's from the decomposition (1e-13), is phi / a for
    a circle, and the rate row j of the swing measure and of the twist gives dh/dt = j . w for
    dQ/dt = 1/2 (0, w) Q: against central differences (h = 1e-6) to 1e-8 relative."""
    rng = np.random.default_rng(11)
    for _ in range(100):
        Q = _q(rng)
        Q = Q if Q[0] >= 0 else -Q
        a1, a2 = rng.uniform(0.2, 2.5, size=2)
        c, j = swing_measure_row(tuple(Q), a1, a2)
        assert abs(c - swing_measure_numpy(Q, a1, a2)) <= 1e-13 * max(1.0, c)
        circle = swing_measure_row(tuple(Q), a1, a1)[0]
        assert abs(circle - swing_vector(tuple(Q))[0] / a1) <= 1e-13 * max(1.0, circle)
        w = rng.normal(size=3)
        for value, row in ((lambda P, a1=a1, a2=a2: swing_measure_row(tuple(P), a1, a2)[0], j),
                           (lambda P: twist_angle_row(tuple(P if P[0] >= 0 else -P))[0],
                            twist_angle_row(tuple(Q))[1])):  # fmt: skip
            h = 1e-6
            plus, minus = (quat_multiply(quat_from_axis_angle(w, s * h * np.linalg.norm(w)), Q) for s in (1, -1))
            numeric = (value(plus) - value(minus)) / (2 * h)
            assert abs(numeric - np.dot(row, w)) <= 1e-8 * max(1.0, abs(numeric)), (numeric, np.dot(row, w))


def test_the_limit_rows_are_the_coordinates_jacobians_on_two_bodies():
    """limit_row (the kernel the stages call) on a ball joint between two turned bodies: J_a . (0, omega_a)
    + J_b . (0, omega_b) is the central difference of the swing measure and of the twist when both bodies
    turn (world omegas), to 1e-8; the linear parts are zero; the twist is 0 and the swing 0 at the
    initial poses."""
    text = BOX.format(corners=CORNERS, cone=ELLIPSE).replace("bodies: [box, world]", "bodies: [box, top]")
    text = text.replace("joints:", "  - {name: top, particles: {positions: [[0, 0, 0.1], [0.1, 0, 0.3], "
                        "[0, 0.1, 0.2]], masses: [1, 2, 1.5]}, position: [0.02, 0.03, 0.2]}\njoints:")  # fmt: skip
    sim = Simulation(load_scene_text(text))
    table, s = sim.model.joint, sim.data.state
    assert int(table.body_b[0]) == 1
    x, q0 = s.x.copy(), s.q.copy()
    assert abs(limit_row(table, 0, False, x, q0)[0]) <= 1e-15 and limit_row(table, 0, True, x, q0)[0] <= 1e-14
    rng = np.random.default_rng(3)
    for _ in range(30):
        q = np.array([_q(rng), _q(rng)])
        omega = rng.normal(size=(2, 3))
        for swing in (False, True):
            c, ja, jb = limit_row(table, 0, swing, x, q)
            assert ja[:3] == (0.0, 0.0, 0.0) and jb[:3] == (0.0, 0.0, 0.0)
            h = 1e-6
            values = []
            for sign in (1, -1):
                turned = np.array([_turn(q[k], omega[k], sign * h) for k in range(2)])
                values.append(limit_row(table, 0, swing, x, turned)[0])
            numeric = (values[0] - values[1]) / (2 * h)
            rate = np.dot(ja[3:], omega[0]) + np.dot(jb[3:], omega[1])
            assert abs(numeric - rate) <= 1e-8 * max(1.0, abs(numeric)), (swing, numeric, rate)
            Q = relative_rotation(table, 0, tuple(q[0]), tuple(q[1]))[0]
            pa = quat_multiply(q[0], table.cone[0, CONE_FRAME_A : CONE_FRAME_A + 4])
            pb = quat_multiply(q[1], table.cone[0, CONE_FRAME_B : CONE_FRAME_B + 4])
            expected = quat_multiply(quat_conjugate(pb), pa)
            assert min(np.abs(np.array(Q) - expected).max(), np.abs(np.array(Q) + expected).max()) <= 1e-15


def _energy(sim: Simulation) -> float:
    s, mass = sim.state, sim.model.body_mass
    return float(np.sum(s.P * s.v) / 2 + np.sum(s.L * s.omega) / 2 + G * np.sum(mass * s.x[:, 2]))


def _measures(table, q: np.ndarray) -> tuple[float, float]:  # noqa: ANN001
    """(c, tau) of joint 0 (body 0 on the world) by numpy: the cone measure and the twist."""
    pa = quat_multiply(q[0], table.cone[0, CONE_FRAME_A : CONE_FRAME_A + 4])
    Q = quat_multiply(quat_conjugate(table.cone[0, CONE_FRAME_B : CONE_FRAME_B + 4]), pa)
    a1, a2 = table.cone[0, CONE_SWING : CONE_SWING + 2]
    return swing_measure_numpy(Q, a1, a2), swing_twist_numpy(Q)[0]


@pytest.mark.parametrize("integrator", ["split2", "reduced-euler", "reduced-rk4"])
@pytest.mark.parametrize("cone", [CIRCLE, ELLIPSE], ids=["circle", "ellipse"])
def test_a_spinning_box_stays_in_its_cone_and_twist_range_and_each_stop_loses_energy(cone, integrator):
    """The box thrown at (4, -2.5, 3) rad/s would swing to ~1 rad and twist past both bounds: at every
    step the swing measure stays <= 1 + 1e-12 and the twist within its range to 1e-12, both reach a bound
    (within 1e-9; the twist stays stopped at its lower bound); until the first step that reaches a limit
    the run is bitwise the run without the cone (so its energy is that run's); the first stop takes
    > 0.1 % of the energy, and the steps where a limit acts (stops, and sliding along the cone) never gain
    more than twice the unlimited run's largest step-to-step wobble (7e-8 J against a first stop's
    -0.1 J), or 1e-9 of the energy where the method's wobble is below that (reduced-rk4's, ~1e-13 J);
    by 2 s the stops have taken > 5 % of the energy above rest; the ball joint holds to 1e-12. In maximal
    coordinates and in joint coordinates (physics/tree/limits.py: there the cone is a row on the ball's
    rates, and the joint holds by construction)."""
    limited, free = _box(cone, integrator), _box("", integrator)
    table = limited.model.joint
    lower, upper = float(table.limit_lower[0]), float(table.limit_upper[0])
    rest = G * float(limited.model.body_mass.sum()) * -0.5  # the energy hanging at rest
    e0 = _energy(limited) - rest
    apart = None
    wobble = 0.0
    swing_max, twist_lo, twist_hi = 0.0, 0.0, 0.0
    gained = []
    for n in range(2000):
        before, before_free = _energy(limited), _energy(free)
        limited.step(1)
        free.step(1)
        after = _energy(limited)
        wobble = max(wobble, abs(_energy(free) - before_free))
        c, tau = _measures(table, limited.data.state.q)
        swing_max, twist_lo, twist_hi = max(swing_max, c), min(twist_lo, tau), max(twist_hi, tau)
        assert c <= 1.0 + 1e-12 and lower - 1e-12 <= tau <= upper + 1e-12, (n, c - 1.0, tau)
        pushed = limited.data.joint.limit_hit[0] if limited.data.tree is None else limited.data.tree.limits.impulse
        acted = bool(np.any(pushed != 0.0)) or c >= 1.0 - 1e-9
        acted = acted or tau <= lower + 1e-9 or tau >= upper - 1e-9
        if apart is None:
            same = all(np.array_equal(getattr(limited.data.state, k), getattr(free.data.state, k)) for k in "xqPL")
            if not same:
                apart = n
                assert acted, n  # the runs part where a limit first acts, not before
        if acted:
            gained.append(after - before)
        assert np.linalg.norm(limited.data.state.x[0] + _rotated(limited, table)) <= 1e-12
    assert apart is not None and apart > 20, apart
    assert swing_max >= 1.0 - 1e-9 and (twist_lo <= lower + 1e-9 or twist_hi >= upper - 1e-9)
    assert gained[0] < -1e-3 * e0 and max(gained) <= max(2.0 * wobble, 1e-9 * e0), (gained[0] / e0, max(gained), wobble)
    assert _energy(limited) - rest < 0.95 * e0, (_energy(limited) - rest) / e0


def _rotated(sim: Simulation, table) -> np.ndarray:  # noqa: ANN001
    """R(q_a) r_a: the anchor's offset from the box's centre of mass (the anchor is at the origin)."""
    q = sim.data.state.q[0]
    return quat_multiply(quat_multiply(q, np.r_[0.0, table.anchor_a[0]]), quat_conjugate(q))[1:]


SCENE = """\
simulation: {dt: 0.001, duration: 0.01}
bodies:
  - name: arm
    particles: {positions: [[0, 0, 0], [0, 0, -1]], masses: 0.5, radius: 0.05}
    position: [0, 0, 0.5]
joints:
"""
LINE = SCENE.count("\n") + 1


@pytest.mark.parametrize(
    ("cone", "fragment", "at", "message"),
    [
        ("{axis: [0, 0, 0], swing: 0.5}", "[0, 0, 0]", "cone.axis", "a zero axis (0) has no direction"),
        ("{axis: [0, 0, -1], swing: 3.2}", "3.2", "cone.swing", "swing half-angle 3.2 rad is not in (0, pi)"),
        ("{axis: [0, 0, -1], swing: [0.5, 0]}", "0]", "cone.swing[1]", "swing half-angle 0 rad is not in (0, pi)"),
        ("{axis: [0, 0, -1], swing: -0.1}", "-0.1", "cone.swing", "swing half-angle -0.1 rad is not in (0, pi)"),
        (
            "{axis: [0, 0, -1], twist: [0.3, -0.2]}",
            "[0.3, -0.2]",
            "cone.twist",
            "lower twist limit 0.3 is above upper twist limit -0.2",
        ),
        ("{axis: [0, 0, -1], twist: [-3.2, 0.2]}", "-3.2", "cone.twist[0]", "twist limit -3.2 rad is not in (-pi, pi)"),
        (
            "{axis: [0, 0, -1], twist: [-0.2, 3.15]}",
            "3.15",
            "cone.twist[1]",
            "twist limit 3.15 rad is not in (-pi, pi)",
        ),
        (
            "{axis: [0, 0, -1], swing: 1, reference: [0, 0, 2]}",
            "[0, 0, 2]",
            "cone.reference",
            "the reference has no direction across the axis",
        ),
        ("{axis: [0, 0, -1]}", "{axis", "cone", "the cone gives neither `swing` nor `twist`: it limits nothing"),
        ("{axis: [0, 0, -1], swing: 1, spin: 2}", "spin", "cone.spin", "unknown key 'spin'"),
    ],  # fmt: skip
)
def test_each_impossible_cone_is_refused_at_its_key(cone, fragment, at, message):
    line = f"  - {{type: ball, bodies: [arm, world], anchor: [0, 0, 1], cone: {cone}}}\n"
    spec, issues = analyse_scene_text(SCENE + line, "s.yaml")
    errors = [str(i) for i in issues if i.severity == "error"]
    assert spec is None and len(errors) == 1, errors
    column = line.index(fragment, line.index("cone:") + 5) + 1
    assert errors[0].startswith(f"s.yaml:{LINE}:{column}: error: joints[0].{at}: {message}"), errors[0]
    assert " expected " in errors[0]


def test_a_cone_on_a_hinge_is_an_unknown_key_and_a_good_cone_reaches_the_table():
    hinge = "  - {type: hinge, bodies: [arm, world], anchor: [0, 0, 1], axis: [0, 1, 0], cone: {axis: [0, 0, 1]}}\n"
    spec, issues = analyse_scene_text(SCENE + hinge, "s.yaml")
    assert spec is None and [i.location.column for i in issues] == [hinge.index("cone") + 1]
    assert "unknown key 'cone'" in issues[0].message
    good = "  - {type: ball, bodies: [world, arm], anchor: [0, 0, 1], cone: {axis: [0, 0, -2], swing: [0.5, 0.25], "
    table = load_scene_text(SCENE + good + "reference: [0, 3, 1], twist: [-0.1, 0.2]}}\n").compiled_model.model.joint
    assert table.cone[:, CONE_SWING:].tolist() == [[0.5, 0.25]]
    assert table.limit_lower.tolist() == [-0.1] and table.limit_upper.tolist() == [0.2]
    # the joint frame in the world at the initial poses: x the axis, y the reference's part across it
    frame = table.cone[0, CONE_FRAME_B : CONE_FRAME_B + 4]  # the world end carries the cone
    x_axis = quat_multiply(quat_multiply(frame, [0, 1.0, 0, 0]), quat_conjugate(frame))[1:]
    y_axis = quat_multiply(quat_multiply(frame, [0, 0, 1.0, 0]), quat_conjugate(frame))[1:]
    np.testing.assert_allclose(x_axis, [0, 0, -1], atol=1e-15)
    np.testing.assert_allclose(y_axis, [0, 1, 0], atol=1e-15)


DAMPED = """\
simulation: {{dt: 0.001, steps: 10, integrator: split2}}
bodies:
  - name: star
    particles: {{positions: [{points}], masses: {masses}}}
    angular_velocity: [3.0, -2.0, 1.0]
joints:
  - {{type: ball, bodies: [star, world], anchor: [0, 0, 0], damping: 0.02}}
"""


def test_a_damped_ball_joint_slows_an_isotropic_body_exactly_and_a_tumbling_one_always():
    """A ball joint's damper (the hinge's exact damper about the world's x, y, z in turn) on a body jointed
    at its centre of mass, no gravity: an isotropic star (I = 0.04 kg m^2 about every axis) slows as
    omega0 exp(-c t / I) to 1e-12 over 1,000 steps; a tumbling box's kinetic energy falls every step."""
    star = "[0.2, 0, 0], [-0.2, 0, 0], [0, 0.2, 0], [0, -0.2, 0], [0, 0, 0.2], [0, 0, -0.2]"
    sim = Simulation(load_scene_text(DAMPED.format(points=star, masses=0.5)))
    inertia = 4 * 0.5 * 0.2**2
    sim.step(1000)
    expected = np.array([3.0, -2.0, 1.0]) * np.exp(-0.02 * 1.0 / inertia)
    np.testing.assert_allclose(sim.state.omega[0], expected, rtol=1e-12, atol=1e-12)
    masses = "[0.1, 0.15, 0.1, 0.12, 0.1, 0.1, 0.13, 0.1]"
    box = Simulation(load_scene_text(DAMPED.format(points=CORNERS, masses=masses)))
    energy = []
    for _ in range(500):
        box.step(1)
        energy.append(float(box.state.L[0] @ box.state.omega[0]) / 2)
    assert np.all(np.diff(energy) < 0.0) and energy[-1] < 0.9 * energy[0]
