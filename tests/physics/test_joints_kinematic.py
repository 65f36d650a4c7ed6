"""A kinematic body carrying a joint (issue 27 item 3, a driven crank): the joint rows read the crank's
prescribed pose (kinematic_end runs before joint_position, so the Newton solve meets its end-of-step
pose) and its velocity enters G V, with W = 0 for it (nothing applied to it)."""

from __future__ import annotations

import math

import numpy as np

import rbcli
from rbcli.physics.joints.reference import joint_rows_numpy
from rbcli.scene.load import load_scene_text

R, ROD, OMEGA = 0.1, 0.3, 5.0


def _slider_crank() -> str:
    """A crank (kinematic, spinning about y at OMEGA about its centre at the origin) whose pin at (R, 0,
    0) is tied by a rod (distance joint, length ROD) to a slider guided along x (slider joint to the
    world); gravity on. Contact on, the crank and slider colliding: the joint's pair is excluded."""
    return f"""
simulation: {{dt: 0.001, steps: 10, integrator: split2}}
gravity: [0, 0, -9.81]
contact: {{}}
bodies:
  - {{name: crank, particles: {{positions: [[0, 0, 0], [{R}, 0, 0], [{-R}, 0, 0]], masses: 1.0, radius: 0.01}},
     position: [0, 0, 0], kinematic: {{angular_velocity: [0, {OMEGA}, 0]}}}}
  - {{name: slider, particles: {{positions: [[0, 0, 0]], masses: [0.5], radius: [0.02]}}, position: [{R + ROD}, 0, 0]}}
joints:
  - {{name: rod, type: distance, bodies: [crank, slider], anchors: [[{R}, 0, 0], [0, 0, 0]]}}
  - {{name: guide, type: slider, bodies: [slider, world], anchor: [{R + ROD}, 0, 0], axis: [1, 0, 0]}}
"""


def test_a_kinematic_crank_drives_a_slider_on_the_exact_slider_crank_kinematics():
    """Over one second (0.8 turns) the joints hold to round-off and the slider's x equals
    x(t) = R cos(w t) + sqrt(l^2 - R^2 sin^2(w t)) (the pin at R (cos w t, 0, -sin w t)) to round-off:
    the slider has no freedom left, so any lag of the crank's pose in the rows would show at O(w R h)."""
    sim = rbcli.Simulation(load_scene_text(_slider_crank()))
    worst_row = worst_x = 0.0
    for _ in range(100):
        sim.step(10)
        s = sim.data.state
        worst_row = max(worst_row, float(np.abs(joint_rows_numpy(sim.model.joint, s.x, s.q)[0]).max()))
        wt = OMEGA * sim.time
        exact = R * math.cos(wt) + math.sqrt(ROD**2 - (R * math.sin(wt)) ** 2)
        worst_x = max(worst_x, abs(float(s.x[1, 0]) - exact))
    assert sim.time > 0.99
    assert worst_row <= 1e-12, worst_row
    assert worst_x <= 1e-12, worst_x
    # the crank kept its prescribed spin: the joint applied nothing to it (W = 0)
    np.testing.assert_allclose(sim.state.omega[0], [0.0, OMEGA, 0.0], rtol=0, atol=1e-12)
