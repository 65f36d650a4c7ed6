"""Adaptive runs through the runner: uniform output times, the tolerance reached, step counts reported."""

import numpy as np
import pytest
from conftest import make_body, make_scene

from rbcli.analysis.exact import quat_geodesic_angle, torque_free
from rbcli.api import simulate

# a flat plate with I = diag(1, 2, 3) kg m^2 (principal axes = user axes)
PLATE = dict(
    particle_position=np.array([[1.0, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0]]),
    particle_mass=np.array([1.0, 1.0, 0.5, 0.5]),
)


def test_adaptive_run_lands_on_output_times_and_reaches_the_tolerance():
    omega0 = np.array([1.0, 1.0, 2.0])
    body = make_body("plate", angular_velocity=omega0, angular_velocity_frame="body", **PLATE)
    scene = make_scene([body], dt=0.1, duration=10.0, integrator="dopri5")
    traj = simulate(scene, tolerance=1e-8)
    np.testing.assert_allclose(traj.t, np.arange(101) * 0.1, rtol=0, atol=1e-12)
    exact = torque_free(np.array([1.0, 2.0, 3.0]), np.eye(3), omega0, traj.t, frame="body")
    error = quat_geodesic_angle(traj.q[:, 0], exact.q).max()
    assert error < 1e-7  # well-conditioned motion: the global error is about the tolerance (module docstring)
    assert traj.summary.steps_accepted > 0 and traj.summary.steps_rejected >= 0
    looser = simulate(scene, tolerance=1e-4)
    assert looser.summary.steps_accepted < traj.summary.steps_accepted  # a looser budget takes fewer steps


def test_tolerance_needs_an_adaptive_integrator():
    with pytest.raises(ValueError, match="adaptive integrator"):
        simulate(make_scene([make_body("b")], integrator="split2"), tolerance=1e-6)
