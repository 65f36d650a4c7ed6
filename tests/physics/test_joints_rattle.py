"""The joint step is symmetric and symplectic for any bodies (issue 46; joints/rattle.py): a tumbling
chain of unequal-moment bodies on tilted hinges and ball joints retraces its path when its momenta are
negated, the 170-degree pendulum on a tilted hinge keeps its period swing after swing, the 3-D double
pendulum's energy error has no trend, and the tilted pendulum's period converges at second order.

Each of the first three fails on the step before RATTLE (the impulse at the kick along G at an
estimated midpoint, then the velocity projection: docs/joints.md has the numbers); the longer runs are
benchmarks/bench_joint_energy.py."""

from __future__ import annotations

import math

import numpy as np
import pytest
from joint_scenes import (
    BOX_CORNERS,
    CLOUD_MASSES,
    CLOUD_POSITIONS,
    G,
    hanging_double_pendulum_3d_text,
    tilted_hinge_angle,
    tilted_hinge_period,
    tilted_hinge_text,
)

from rbcli.physics.joints.tables import STAT_ITERATIONS, STAT_RESTARTS
from rbcli.physics.rotation import quat_rotate_inverse
from rbcli.runner.simulation import Simulation
from rbcli.scene.load import load_scene_text

CHAIN = f"""
name: tumbling-chain
simulation: {{dt: 0.001, steps: 10, integrator: split2}}
gravity: [0, 0, {-G!r}]
bodies:
  - name: box
    particles: {{positions: {BOX_CORNERS!r}, masses: 0.125, radius: 0.01}}
    position: [0.1, 0.05, 0.8]
    orientation: {{axis_angle: {{axis: [0.3, -0.5, 0.8], angle: 0.7}}}}
    angular_velocity: [3.0, -2.0, 5.0]
  - name: cloud
    particles: {{positions: {CLOUD_POSITIONS!r}, masses: {CLOUD_MASSES!r}, radius: 0.02}}
    position: [0.35, 0.2, 0.55]
    orientation: {{axis_angle: {{axis: [-0.6, 0.2, 0.5], angle: 1.1}}}}
    angular_velocity: [-4.0, 6.0, 2.0]
  - name: slab
    particles: {{positions: [[0.15, 0, 0], [-0.15, 0, 0], [0, 0.06, 0], [0, -0.06, 0], [0, 0, 0.02]],
                 masses: [0.2, 0.3, 0.15, 0.25, 0.1], radius: 0.01}}
    position: [0.55, 0.1, 0.3]
    angular_velocity: [1.0, 2.0, -3.0]
joints:
  - {{name: top, type: hinge, bodies: [box, world], anchor: [0.0, 0.0, 1.0], axis: [1, 1, 0]}}
  - {{name: middle, type: ball, bodies: [cloud, box], anchor: [0.25, 0.12, 0.68]}}
  - {{name: bottom, type: hinge, bodies: [slab, cloud], anchor: [0.45, 0.15, 0.42], axis: [0.2, -0.5, 0.84]}}
"""


def test_a_tumbling_chain_retraces_its_path_when_its_momenta_are_negated():
    """Symmetry and reversibility: with rho(x, q, P, L) = (x, q, -P, -L), a symmetric reversible step
    has Phi_h rho Phi_h = rho, so 1,000 steps, the momenta negated, 1,000 steps and negated again give
    back the start to round-off: 1e-12 of the motion's scale (the largest displacement, |P|, |L| of the
    run; measured 6e-15 at most). The midpoint step before RATTLE came back to 1.4e-7 only: the next
    step's half drift from the projected momenta does not retrace the kick's midpoint (docs/joints.md)."""
    sim = Simulation(load_scene_text(CHAIN))
    sim.step(1)  # the first step's joint_begin makes the given velocities consistent with the joints
    s = sim.data.state
    start = [a.copy() for a in (s.x, s.q, s.P, s.L)]
    moved, momentum, spin = 0.0, 0.0, 0.0
    for _ in range(10):
        sim.step(100)
        moved = max(moved, float(np.abs(s.x - start[0]).max()))
        momentum, spin = max(momentum, float(np.abs(s.P).max())), max(spin, float(np.abs(s.L).max()))
    assert sim.data.joint.stats[1] <= 1e-12  # the joints held
    s.P[:] *= -1.0
    s.L[:] *= -1.0
    sim.step(1000)
    s.P[:] *= -1.0
    s.L[:] *= -1.0
    errors = [
        float(np.abs(s.x - start[0]).max()) / moved,
        float(np.abs(s.q - start[1]).max()),
        float(np.abs(s.P - start[2]).max()) / momentum,
        float(np.abs(s.L - start[3]).max()) / spin,
    ]
    assert moved > 0.1 and max(errors) <= 1e-12, errors


def swing_periods(dt: float, steps: int) -> np.ndarray:
    """The tilted-hinge pendulum from 170 degrees: the times between every other crossing of the bottom
    (each a full period), each crossing from the cubic Hermite interpolant of (theta, theta')."""
    from joint_scenes import crossings

    sim = Simulation(load_scene_text(tilted_hinge_text(math.radians(170), dt)))
    s, mass = sim.data.state, float(sim.model.body_mass[0])
    theta, rate = np.empty(steps + 1), np.empty(steps + 1)
    theta[0], rate[0] = tilted_hinge_angle(s.x[0], s.P[0] / mass)
    for k in range(steps):
        sim.step(1)
        theta[k + 1], rate[k + 1] = tilted_hinge_angle(s.x[0], s.P[0] / mass)
    found = crossings(np.arange(steps + 1) * dt, theta, rate)
    return found[2:] - found[:-2]


def test_the_tilted_hinge_keeps_its_period_swing_after_swing():
    """The box on a hinge about (1, 1, 0)/sqrt 2, its pivot off every principal axis, released at 170
    degrees: over 1e5 steps (33 swings) its first and last periods agree to 1e-9 (measured 1.2e-10, the
    crossings' interpolation: a symmetric step's orbit of a one-degree-of-freedom system closes). The
    midpoint step lost energy every swing, its period shortening by 1.0e-5 of itself per swing (3.3e-4
    from the first swing to the last)."""
    periods = swing_periods(1e-3, 100_000)
    assert len(periods) >= 60, len(periods)
    drift = abs(periods[-1] - periods[0]) / periods[0], abs(periods[-2] - periods[1]) / periods[1]
    assert max(drift) <= 1e-9, drift


def test_the_tilted_hinge_period_converges_at_second_order():
    """Against its exact period 4 K(sin^2(theta0/2)) sqrt(l_eff / g) (joint_scenes.tilted_hinge_period):
    halving dt divides the error by 4 (measured slopes 2.00; 2.7e-6 relative at dt = 1e-3). The midpoint
    step's slopes were 3.1-3.5: its per-step loss, O(dt^3), offset the leading O(dt^2) term."""
    exact = tilted_hinge_period(math.radians(170))
    dts = np.array([4e-3, 2e-3, 1e-3])
    errors = np.array([abs(swing_periods(float(dt), int(1.3 * exact / dt))[0] - exact) / exact for dt in dts])
    slopes = np.diff(np.log(errors)) / np.diff(np.log(dts))
    assert np.all((slopes > 1.9) & (slopes < 2.1)), (errors, slopes)
    assert errors[-1] < 1e-5, errors


def energy_errors(text: str, steps: int, every: int) -> np.ndarray:
    """E(t) - E(0) of a scene of free-falling jointed bodies every `every` steps: |P|^2 / 2M + m . m / 2I
    + M g z summed over the bodies (m = R^T L, principal frame); E(0) after the first step."""
    sim = Simulation(load_scene_text(text))
    sim.step(1)  # the given velocities made consistent with the joints
    mass, inertia = sim.model.body_mass, sim.model.body_inertia

    def energy() -> float:
        s = sim.data.state
        m = quat_rotate_inverse(s.q, s.L)
        return float(np.sum(s.P**2 / (2 * mass[:, None])) + 0.5 * np.sum(m * m / inertia) + G * mass @ s.x[:, 2])

    start = energy()
    out = np.empty(steps // every)
    for k in range(out.shape[0]):
        sim.step(every)
        out[k] = energy() - start
    return out


def trend_over_amplitude(errors: np.ndarray) -> float:
    """The least-squares line's rise over the run, over the largest minus the smallest error."""
    t = np.arange(errors.shape[0], dtype=float)
    slope = np.polyfit(t, errors, 1)[0]
    return float(slope * (t[-1] - t[0]) / (errors.max() - errors.min()))


def test_the_3d_double_pendulums_energy_error_has_no_trend():
    """The box and the cloud on two ball joints, swinging and turning about axes off their principal
    axes (joint_scenes.hanging_double_pendulum_3d_text: a regular motion): over 1e5 steps the fitted line
    of E(t) - E(0) rises by less than 1e-2 of the error's range (measured 2.2e-3; 6.5e-4 over 1e6 steps,
    benchmarks/bench_joint_energy.py). The midpoint step's fell by 3.9e-2 of it, and steadily."""
    errors = energy_errors(hanging_double_pendulum_3d_text(1e-3), 100_000, 10)
    assert abs(trend_over_amplitude(errors)) < 1e-2, trend_over_amplitude(errors)


def test_the_extrapolated_first_iterate_saves_iterations_and_reaches_the_same_step():
    """The Newton's first iterate is the line through the last two steps' multipliers (joints/rattle.py).
    It is a starting point only: the tumbling chain run with it, and run with it forgotten before every
    step (the Newton then starts from the free drift), reaches the same states to round-off (1e-12 of
    the motion's scale over 400 steps, where chaos has not yet amplified the round-off), without a
    restart, in fewer iterations (measured 3.1 against 4.2 a step)."""
    runs = []
    for forget in (False, True):
        sim = Simulation(load_scene_text(CHAIN))
        sim.step(1)
        start = sim.data.state.x.copy()
        work, iterations = sim.data.joint, 0.0
        for _ in range(400):
            if forget:
                work.guess_count[:] = 0.0
            sim.step(1)
            iterations += work.stats[STAT_ITERATIONS]
        assert work.stats[STAT_RESTARTS] == 0.0
        s = sim.data.state
        runs.append((s.x.copy(), s.q.copy(), s.L.copy(), iterations / 400, float(np.abs(s.x - start).max())))
    (x, q, L, guessed, moved), (x_cold, q_cold, L_cold, cold, _) = runs
    assert np.abs(x - x_cold).max() <= 1e-12 * moved
    assert np.abs(q - q_cold).max() <= 1e-12
    assert np.abs(L - L_cold).max() <= 1e-12 * np.abs(L_cold).max()
    assert guessed < cold - 0.5, (guessed, cold)


def test_a_checkpoint_from_before_the_chosen_degree_resumes_cold():
    """A log written when RATTLE kept two steps' multipliers (guess (2, R), guess_count (1,)) still
    resumes: the history of another length is dropped and the next step starts from the free drift (a
    step's map does not depend on its first iterate, so the run goes on at the same root)."""
    sim = Simulation(load_scene_text(CHAIN))
    sim.step(20)
    carried = sim.data.carried()
    old = dict(carried)
    rows = carried["joint.guess"].shape[1]
    old["joint.guess"], old["joint.guess_count"] = np.ones((2, rows)), np.array([2.0])
    sim.data.restore_carried(old)
    assert sim.data.joint.guess_count.tolist() == [0.0, 0.0] and not sim.data.joint.guess.any()
    with pytest.raises(ValueError, match="unexpected"):  # the other arrays must still fit
        sim.data.restore_carried({**old, "joint.extra": np.zeros(1)})
