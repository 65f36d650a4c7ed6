"""Dampers and drag on jointed bodies keep split2 + RATTLE second order (joints/dissipation.py).

The rod of scenes/joints/pendulum.yaml on its hinge, released at 60 degrees, 0.5 s, with a spring damper
from a point off its axis to a world point, linear drag, or angular drag: split2's end states converge to
reduced-rk4's (joint coordinates, converged to ~1e-12 at dt = 2.5e-4) at order 2. Before the dissipation
flow was taken on the joints' tangent space it was first order (9.5e-4, 4.8e-4, 2.4e-4 for the damper:
docs/integrators.md). Both families converging to one motion also checks the dissipative forces of each.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from joint_scenes import pendulum_text
from test_integrators_accuracy import fitted_slope

from rbcli.api import Simulation
from rbcli.scene.load import load_scene_text

DURATION = 0.5  # [s]
FORCES = {
    "damper": "{type: spring, body: rod, point: [0.05, 0.02, -0.9], anchor: [0.5, 0.3, 0.5], stiffness: 20, "
    "rest_length: 0.1, damping: 0.5}",
    "drag": "{type: drag, bodies: all, linear: 0.5}",
    "angular drag": "{type: drag, bodies: all, angular_linear: 0.05}",
}


def _end_state(dt: float, integrator: str, force: str) -> np.ndarray:
    steps = round(DURATION / dt)
    text = pendulum_text(math.radians(60.0), dt, steps=steps, integrator=integrator) + f"forces:\n  - {force}\n"
    sim = Simulation(load_scene_text(text))
    sim.step(steps)
    state = sim.state
    return np.concatenate([state.x.ravel(), state.v.ravel(), state.omega.ravel()])


@pytest.mark.parametrize("name", list(FORCES))
def test_split2_keeps_second_order_with_dissipation_on_a_jointed_body(name):
    force = FORCES[name]
    reference = _end_state(2.5e-4, "reduced-rk4", force)
    assert np.max(np.abs(_end_state(5e-4, "reduced-rk4", force) - reference)) < 1e-10
    dts = [2e-3, 1e-3, 5e-4]
    gaps = [float(np.max(np.abs(_end_state(dt, "split2", force) - reference))) for dt in dts]
    assert abs(fitted_slope(dts, gaps) - 2.0) < 0.15, gaps
    assert gaps[-1] < 5e-5, gaps
