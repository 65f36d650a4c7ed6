"""Springs and dampers: small-oscillation periods, Newton's third law, energy conservation and decay.

Runs use `euler-matrix` (the only method guaranteed here) with a dt small enough that its errors are
far below each tolerance: its oscillation frequency is off by (w dt)^2 / 3 relative and its energy
grows ~ w^2 dt per unit time, both stated where a tolerance depends on them.
"""

from dataclasses import replace

import numpy as np
import pytest
from conftest import make_body, make_scene

from rbcli.api import prepare, simulate
from rbcli.physics.model import mass_properties
from rbcli.scene.force_specs import BodyPoint, ForceDrag, ForceSpring

G = np.array([0.0, 0.0, -9.81])
# a box of 8 x 0.25 kg corners at (+-0.1, +-0.15, +-0.05) m: M = 2 kg, principal axes = user axes,
# centre of mass at the origin; I_yy = sum m (x^2 + z^2) = 2 (0.01 + 0.0025) = 0.025 kg m^2
BOX = np.array([[sx * 0.1, sy * 0.15, sz * 0.05] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
BOX_MASS = np.full(8, 0.25)
ANCHOR = np.array([0.0, 0.0, 3.0])


def crossing_period(t: np.ndarray, y: np.ndarray) -> float:
    """Period of y(t) oscillating about 0: linearly interpolated zero crossings, and the least-squares
    slope of crossing time against crossing number (= half a period)."""
    i = np.flatnonzero(np.signbit(y[:-1]) != np.signbit(y[1:]))
    crossings = t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])
    assert crossings.size >= 5, "fewer than two and a half periods recorded"
    return 2.0 * np.polyfit(np.arange(crossings.size), crossings, 1)[0]


def test_vertical_mode_of_a_hanging_body_has_period_2pi_sqrt_m_over_k():
    """Spring at the centre of mass from a world anchor: along the line M z'' = -k (z - z_eq) exactly
    (no torque, no swing when released straight down), T = 2 pi sqrt(M / k) = 0.444 s. Euler's
    frequency error (w dt)^2 / 3 = 3e-7 at w = 14 rad/s, dt = 1e-4; tolerance 1e-5."""
    k, l0, M = 400.0, 1.0, 2.0
    z_eq = ANCHOR[2] - l0 - M * 9.81 / k
    body = make_body("box", particle_position=BOX, particle_mass=BOX_MASS, position=np.array([0.0, 0.0, z_eq - 0.05]))
    spring = ForceSpring(end_a=BodyPoint(body="box"), anchor=ANCHOR, stiffness=k, rest_length=l0)
    traj = simulate(replace(make_scene([body], dt=1e-4, duration=2.0, gravity=G, every=5), forces=(spring,)))
    assert np.abs(traj.x[:, 0, :2]).max() == 0.0 and np.abs(traj.L).max() == 0.0
    period = crossing_period(traj.t, traj.x[:, 0, 2] - z_eq)
    assert period == pytest.approx(2 * np.pi * np.sqrt(M / k), rel=1e-5)


def swing_modes(M: float, I: float, d: float, k: float) -> tuple[np.ndarray, np.ndarray]:
    """Small swings of a body whose point d above its centre of mass hangs on a zero-length spring k
    (an isotropic linear spring: f = -k (p - anchor)). Coordinates: centre-of-mass x offset X and swing
    angle phi, with the pivot's x = X - d phi. Linearised about equilibrium (spring stretched by
    M g / k) the potential is k (X - d phi)^2 / 2 + M g d phi^2 / 2, so K = [[k, -k d], [-k d,
    k d^2 + M g d]], mass matrix diag(M, I). Returns (w^2 ascending, mode shapes as columns)."""
    K = np.array([[k, -k * d], [-k * d, k * d * d + M * 9.81 * d]])
    Minv_sqrt = np.diag([M**-0.5, I**-0.5])
    w2, modes = np.linalg.eigh(Minv_sqrt @ K @ Minv_sqrt)
    return w2, Minv_sqrt @ modes


def test_swing_mode_matches_the_compound_pendulum_with_the_inertia_about_the_pivot():
    """A stiff spring at a point d above the centre of mass acts as a pivot: T -> 2 pi sqrt(I_p / (M g d))
    with I_p = I_yy + M d^2 (parallel axes) as k -> oo. At finite k the exact linear two-mode result
    (swing_modes) is the reference (tolerance 2e-4: amplitude 0.01 rad shifts the period by phi^2 / 16
    ~ 1e-5, Euler by (w dt)^2 / 3 ~ 1e-9); the compound-pendulum formula is within ~ M g / (k d) of it."""
    d, k = 0.4, 2.0e4
    M, _, I0 = mass_properties(BOX, BOX_MASS)
    I = I0[1, 1]
    w2, modes = swing_modes(M, I, d, k)
    X0, phi0 = modes[:, 0] / modes[1, 0] * 0.01  # the slow mode, scaled to 0.01 rad
    # the pivot p = com + d (-sin phi, 0, cos phi) is a turn of (0, 0, d) about +y by -phi
    orientation = np.array([np.cos(-phi0 / 2), 0.0, np.sin(-phi0 / 2), 0.0])
    z0 = ANCHOR[2] - M * 9.81 / k - d * np.cos(phi0)
    body = make_body("box", particle_position=BOX, particle_mass=BOX_MASS, position=np.array([X0, 0.0, z0]),
                     orientation_wxyz=orientation)  # fmt: skip
    spring = ForceSpring(end_a=BodyPoint(body="box", point=np.array([0.0, 0.0, d])), anchor=ANCHOR, stiffness=k)
    traj = simulate(replace(make_scene([body], dt=2e-5, duration=4.0, gravity=G, every=20), forces=(spring,)))
    period = crossing_period(traj.t, traj.x[:, 0, 0])
    assert period == pytest.approx(2 * np.pi / np.sqrt(w2[0]), rel=2e-4)
    compound = 2 * np.pi * np.sqrt((I + M * d * d) / (M * 9.81 * d))
    assert period == pytest.approx(compound, rel=2 * M * 9.81 / (k * d))


def chain_scene(dt: float, duration: float, damping: float = 0.0, integrator: str = "euler-matrix"):  # noqa: ANN201
    """Two boxes: the first hangs from an anchor by an off-centre spring, the second from the first;
    released off equilibrium with a little spin so all six degrees of freedom of each move."""
    a = make_body("a", particle_position=BOX, particle_mass=BOX_MASS, position=np.array([0.2, 0.0, 2.2]),
                  angular_momentum=np.array([0.0, 0.002, 0.001]))  # fmt: skip
    b = make_body("b", particle_position=BOX, particle_mass=BOX_MASS, position=np.array([0.3, 0.1, 1.3]),
                  orientation_wxyz=np.array([np.cos(0.2), np.sin(0.2), 0.0, 0.0]))  # fmt: skip
    springs = (
        ForceSpring(
            end_a=BodyPoint(body="a", point=np.array([0.1, 0.15, 0.05])),
            anchor=ANCHOR,
            stiffness=200.0,
            rest_length=0.5,
            damping=damping,
        ),  # fmt: skip
        ForceSpring(
            end_a=BodyPoint(body="b", particle=7),
            end_b=BodyPoint(body="a", point=np.array([0.0, 0.0, -0.05])),
            stiffness=150.0,
            rest_length=0.6,
            damping=damping,
        ),  # fmt: skip
    )
    scene = make_scene([a, b], dt=dt, duration=duration, gravity=G, integrator=integrator, every=round(0.01 / dt))
    return replace(scene, forces=springs)


def energy_error(dt: float, integrator: str = "euler-matrix") -> float:
    traj = simulate(chain_scene(dt, 1.0, integrator=integrator))
    energy = traj.invariants["energy_total"]
    return float(np.abs(energy - energy[0]).max())


def test_springs_conserve_energy_to_first_order_with_euler_matrix():
    """No damping: E = T + M g z terms + k (l - l0)^2 / 2 is conserved by the motion; explicit Euler's
    error is O(dt), so halving dt halves it (ratios 2 +- 10%: higher-order terms at these dt). Its
    size, ~ w^2 dt E per unit time with w^2 ~ k r^2 / I ~ 300 s^-2 for the tilting modes, is 0.2 J of
    82 J after 1 s at dt = 1e-4 s."""
    errors = [energy_error(dt) for dt in (4e-4, 2e-4, 1e-4)]
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert errors[-1] > 1e-6  # far above round-off, so the ratios measure the method
    np.testing.assert_allclose(ratios, 2.0, rtol=0.1)


def test_springs_conserve_energy_to_second_order_with_split2():
    """With the symmetric splitting `split2` the energy error is O(dt^2): ratios 4."""
    errors = [energy_error(dt, "split2") for dt in (4e-3, 2e-3, 1e-3)]
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    np.testing.assert_allclose(ratios, 4.0, rtol=0.15)


def test_damped_springs_lose_energy_monotonically():
    """With dampers and drag dE/dt = -sum c (dl/dt)^2 - sum (b v^2 + b_r w^2) <= 0. A line damper alone
    leaves the swing modes undamped (their spring length barely changes), and explicit Euler adds
    ~ dt (m a^2 + k v^2) / 2 per step, which wins at turning points; with light drag on every body
    every mode loses more than Euler adds over 10 ms windows (dt = 1e-4 s), so E sampled every 10 ms
    strictly decreases."""
    scene = chain_scene(1e-4, 3.0, damping=4.0)
    scene = replace(scene, forces=(*scene.forces, ForceDrag(linear=1.0, angular_linear=0.005)))
    traj = simulate(scene)
    energy = traj.invariants["energy_total"]
    assert np.all(np.diff(energy) < 0.0)
    assert energy[0] - energy[-1] > 10.0  # [J]: most of the initial stretch and swing energy is gone


def test_body_to_body_spring_conserves_total_momentum():
    """Newton's third law: the two ends get f and -f, so without gravity or anchors sum P is constant
    (to round-off, 1e-15 relative per step over 1000 steps)."""
    a = make_body("a", particle_position=BOX, particle_mass=BOX_MASS, velocity=np.array([0.3, 0.0, 0.1]))
    b = make_body("b", particle_position=BOX, particle_mass=BOX_MASS, position=np.array([1.0, 0.2, 0.0]),
                  angular_momentum=np.array([0.01, 0.0, 0.02]))  # fmt: skip
    spring = ForceSpring(end_a=BodyPoint(body="a", particle=0), end_b=BodyPoint(body="b", particle=5),
                         stiffness=50.0, rest_length=0.5, damping=0.3)  # fmt: skip
    traj = simulate(replace(make_scene([a, b], dt=1e-3, duration=1.0, every=10), forces=(spring,)))
    total = traj.P.sum(axis=1)
    np.testing.assert_allclose(total, np.broadcast_to(total[0], total.shape), rtol=0, atol=1e-13)
    assert np.abs(traj.P[-1, 0] - traj.P[0, 0]).max() > 0.01  # the spring did act


def test_compiled_scene_keeps_anchor_in_world_frame():
    """A world anchor is not shifted or rotated by the body's frame conversion."""
    body = make_body("h", orientation_wxyz=np.array([np.cos(0.3), 0.0, 0.0, np.sin(0.3)]))
    spring = ForceSpring(end_a=BodyPoint(body="h"), anchor=np.array([1.0, 2.0, 3.0]), stiffness=1.0)
    tables = prepare(replace(make_scene([body]), forces=(spring,))).forces
    assert tables.spring.body_b.tolist() == [-1]
    np.testing.assert_array_equal(tables.spring.point_b[0], [1.0, 2.0, 3.0])
    assert not tables.has_torque  # attached at the centre of mass: tau = 0 x f
