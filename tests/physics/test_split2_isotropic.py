"""split2 (and split4) turn an isotropic body by its exact free rotation: a ball's torque-free spin is
exact to round-off at any dt, where the axis-by-axis pieces T_a T_b T_c of an anisotropic body are
only second order (they do not commute)."""

from __future__ import annotations

import numpy as np
import pytest

import rbcli
from rbcli.physics.rotation import quat_multiply
from rbcli.scene.load import load_scene_text

BALL = """name: ball
simulation: {{dt: {dt}, steps: {steps}, integrator: {integrator}}}
bodies:
  - name: ball
    particles: {{positions: [[0, 0, 0]], masses: [0.5], radius: [0.05]}}
    orientation: {{axis_angle: {{axis: [1, 2, 3], angle: 0.7}}}}
    angular_velocity: [3.0, -7.0, 11.0]
"""


@pytest.mark.parametrize("integrator", ["split2", "split4"])
@pytest.mark.parametrize("dt", [1e-3, 0.05])
def test_ball_spin_is_exact_at_any_dt(integrator, dt):
    steps = 2000
    sim = rbcli.Simulation(load_scene_text(BALL.format(dt=dt, steps=steps, integrator=integrator)))
    q0, omega = sim.state.q[0].copy(), sim.state.omega[0].copy()
    sim.step(steps)
    t = steps * dt
    angle = np.linalg.norm(omega) * t
    axis = omega / np.linalg.norm(omega)
    expected = quat_multiply(np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * axis]), q0)
    got = sim.state.q[0]
    error = 2 * np.arccos(min(1.0, abs(float(got @ expected))))
    assert error < 1e-10 * max(1.0, angle), error  # round-off only (angle up to ~1000 rad)
    np.testing.assert_allclose(sim.state.omega[0], omega, rtol=1e-12)
