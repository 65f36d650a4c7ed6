"""Joint limits, one-sided and held to round-off (physics/joints/drives.py): a block on a vertical slider
falls onto its lower limit at the free-fall time and rests there exactly; a pendulum swinging between a
hinge's two limits never passes either and is stopped at each (an inelastic stop loses energy). Each in
maximal coordinates (split2) and in joint coordinates (physics/tree/limits.py)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from rbcli.runner.simulation import Simulation
from rbcli.scene.load import load_scene_text

G = 9.81

SLIDER = """
simulation: {dt: 0.001, steps: 10, integrator: split2}
gravity: [0, 0, -9.81]
bodies:
  - name: block
    particles: {positions: [[0.1, 0, 0], [-0.1, 0, 0], [0, 0.1, 0], [0, -0.1, 0]], masses: 0.25}
    position: [0, 0, 1]
joints:
  - {type: slider, bodies: [block, world], anchor: [0, 0, 1], axis: [0, 0, 1], limits: [-0.3, 0.2]}
"""

HINGE = """
simulation: {dt: 0.001, steps: 10, integrator: split2}
gravity: [0, 0, -9.81]
bodies:
  - name: rod
    particles:
      positions: [[0, 0, -0.2], [0, 0, -0.4], [0, 0, -0.6], [0, 0, -0.8], [0, 0, -1.0]]
      masses: 0.2
      radius: 0.02
    position: [0, 0, 0.4]
    angular_velocity: [0, 4.0, 0]
    velocity: [-2.4, 0, 0]
joints:
  - {type: hinge, bodies: [rod, world], anchor: [0, 0, 1], axis: [0, 1, 0], limits: [-0.3, 0.5]}
"""


INTEGRATORS = ["split2", "reduced-euler", "reduced-rk4"]  # maximal coordinates and both joint-coordinate ones


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_slider_falls_onto_its_lower_limit_and_rests_there_exactly(integrator):
    """Free fall over the 0.3 m of travel takes sqrt(2 0.3 / g) = 0.2473 s; the block then stays at
    z = 1 - 0.3 to round-off with zero velocity (the limit stops it: inelastic), never below."""
    sim = Simulation(load_scene_text(SLIDER.replace("split2", integrator)))
    z, vz = np.empty(1000), np.empty(1000)
    for n in range(1000):
        sim.step(1)
        z[n], vz[n] = sim.data.state.x[0, 2], sim.data.state.P[0, 2]
    assert z.min() >= 0.7 - 1e-12, z.min() - 0.7
    landed = int(np.argmax(z <= 0.7 + 1e-12))  # the step index n is the state at t = (n + 1) dt
    assert abs((landed + 1) * 1e-3 - math.sqrt(2 * 0.3 / G)) <= 1e-3, landed
    assert np.abs(z[landed:] - 0.7).max() <= 1e-12 and np.abs(vz[landed:]).max() <= 1e-12


@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_a_hinge_swings_between_its_limits_and_never_passes_them(integrator):
    """The rod is thrown at 4 rad/s from hanging straight down, enough to reach both limits (its swing
    would reach ~1.1 rad); the angle of its centre of mass about the pivot stays in [-0.3, 0.5] to
    1e-12, each limit is reached (within 1e-9, where the stop acts), and each stop takes energy away."""
    sim = Simulation(load_scene_text(HINGE.replace("split2", integrator)))
    mass = float(sim.model.body_mass[0])

    def energy() -> float:
        s = sim.state
        return float(s.P[0] @ s.v[0] / 2 + s.L[0] @ s.omega[0] / 2 + mass * G * s.x[0, 2])

    sim.step(1)  # the first step's projection makes the thrown velocities consistent with the hinge
    start = energy()
    angle = np.empty(3000)
    for n in range(3000):
        sim.step(1)
        x = sim.data.state.x[0]
        angle[n] = math.atan2(-x[0], 1.0 - x[2])
        assert abs(np.linalg.norm(x - [0, 0, 1]) - 0.6) <= 1e-12  # the hinge still holds
    assert angle.max() <= 0.5 + 1e-12 and angle.min() >= -0.3 - 1e-12, (angle.max() - 0.5, angle.min() + 0.3)
    assert angle.max() >= 0.5 - 1e-9 and angle.min() <= -0.3 + 1e-9
    assert energy() < 0.9 * start
