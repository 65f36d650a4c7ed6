"""A sine-scheduled force and torque through every integrator, against the closed-form motion.

A body of principal inertia diag(1, 2, 3) [kg m^2] spins about its principal z axis (omega0 = 2 rad/s)
and is pushed, without gravity, by
  F(t) = F0 s(t) (world, at the centre of mass: no torque),  tau(t) = tau0 s(t) e_z (body frame),
  s(t) = c + sin(w t + phi),  w = 2 pi f.
tau stays along the spin axis, so the body keeps turning about e_z (omega, L and tau parallel: no
gyroscopic term) and everything is a quadrature:
  v(t) = v0 + F0 S1(t) / M,               x(t) = x0 + v0 t + F0 S2(t) / M,
  L_z(t) = I_3 omega0 + tau0 S1(t),       theta(t) = omega0 t + tau0 S2(t) / I_3,
  S1(t) = int_0^t s = c t - (cos(w t + phi) - cos phi) / w,
  S2(t) = int_0^t S1 = c t^2 / 2 - (sin(w t + phi) - sin phi) / w^2 + t cos(phi) / w.
A method that evaluates the force at a wrong stage time (rk4's third stage at t + h instead of
t + h/2) is first order on this scene whatever its order on autonomous ones: checked by hand when this
test was written (rk4 with its third stage moved fitted a slope of ~1 and failed); every method's fitted
slope must be its registered order within 0.3.
"""

import dataclasses

import numpy as np
import pytest
from conftest import make_body, make_scene

from rbcli.analysis.exact import quat_geodesic_angle
from rbcli.api import prepare
from rbcli.physics.forces import build_force_tables
from rbcli.physics.forces.tables import SCHEDULE_SINE, point_force_table, schedule_table, torque_table
from rbcli.physics.integrators import INTEGRATORS
from rbcli.record.memory_sink import SinkMemory
from rbcli.runner.simulation import run

INERTIA = (1.0, 2.0, 3.0)
OMEGA0 = 2.0  # [rad/s] about the principal z axis
F0 = np.array([1.0, -0.5, 0.25])  # [N], world
TAU0 = 0.7  # [N m] about body z
OFFSET, FREQUENCY, PHASE = 0.3, 0.7, 0.4  # s(t) = 0.3 + sin(2 pi 0.7 t + 0.4)
DURATION = 2.0  # [s]: 1.4 periods of s, so no error cancels at a whole period
V0 = np.array([0.2, 0.0, -0.1])

# per order, three dts where every method's error is asymptotic and far above round-off
DTS = {1: (0.01, 0.005, 0.0025), 2: (0.04, 0.02, 0.01), 4: (0.1, 0.05, 0.025), 5: (0.2, 0.1, 0.05)}


def principal_cloud(inertia):
    """Point masses at +-e_k with inertia exactly diag(inertia) (as in test_integrators_accuracy)."""
    i1, i2, i3 = inertia
    s = 0.5 * np.array([i2 + i3 - i1, i1 + i3 - i2, i1 + i2 - i3])
    positions = [sign * np.eye(3)[k] for k in range(3) if s[k] > 0 for sign in (1.0, -1.0)]
    masses = [0.5 * s[k] for k in range(3) if s[k] > 0 for _ in range(2)]
    return np.array(positions), np.array(masses)


def _integrals(t):
    w = 2.0 * np.pi * FREQUENCY
    s1 = OFFSET * t - (np.cos(w * t + PHASE) - np.cos(PHASE)) / w
    s2 = OFFSET * t * t / 2.0 - (np.sin(w * t + PHASE) - np.sin(PHASE)) / w**2 + t * np.cos(PHASE) / w
    return s1, s2


def _compiled(integrator, dt, tolerance=None):
    positions, masses = principal_cloud(INERTIA)
    body = make_body("body", particle_position=positions, particle_mass=masses, velocity=V0,
                     angular_velocity=np.array([0.0, 0.0, OMEGA0]), angular_velocity_frame="body")  # fmt: skip
    spec = make_scene([body], dt=dt, duration=DURATION, integrator=integrator, every=max(1, round(0.05 / dt)))
    if tolerance is not None:
        spec = dataclasses.replace(spec, simulation=dataclasses.replace(spec.simulation, tolerance=tolerance))
    compiled = prepare(spec)
    sine = schedule_table(kind=[SCHEDULE_SINE], start=[-np.inf], stop=[np.inf], amplitude=[1.0],
                          frequency=[FREQUENCY], phase=[PHASE], offset=[OFFSET])  # fmt: skip
    forces = build_force_tables(
        None, body_count=1, schedule=sine,
        point_force=point_force_table(body=[0], point=[[0.0, 0.0, 0.0]], vector=[F0], body_frame=[False], schedule=[0]),
        torque=torque_table(body=[0], vector=[[0.0, 0.0, TAU0]], body_frame=[True], schedule=[0]),
    )  # fmt: skip
    return dataclasses.replace(compiled, forces=forces)


def motion_error(integrator, dt, tolerance=None):
    """Largest error over the recorded frames: |x - x_exact| [m] + the geodesic angle to the exact
    attitude [rad] + |L - L_exact| [kg m^2/s] (all O(1) here, so one sum weighs them alike)."""
    compiled = _compiled(integrator, dt, tolerance)
    np.testing.assert_allclose(compiled.model.body_inertia[0], INERTIA, rtol=1e-14)
    memory = SinkMemory()
    run(compiled, [memory])
    traj = memory.trajectory()
    assert traj.status == "completed"
    t = traj.t
    s1, s2 = _integrals(t)
    mass = compiled.model.body_mass[0]
    x_exact = V0 * t[:, None] + F0 * s2[:, None] / mass
    theta = OMEGA0 * t + TAU0 * s2 / INERTIA[2]
    q_exact = np.stack([np.cos(theta / 2), 0 * t, 0 * t, np.sin(theta / 2)], axis=1)
    L_exact = INERTIA[2] * OMEGA0 + TAU0 * s1
    error = (np.linalg.norm(traj.x[:, 0] - x_exact, axis=1) + quat_geodesic_angle(traj.q[:, 0], q_exact)
             + np.linalg.norm(traj.L[:, 0] - L_exact[:, None] * np.array([0.0, 0.0, 1.0]), axis=1))  # fmt: skip
    return float(error.max())


def fitted_slope(dts, errors):
    return float(np.polyfit(np.log(dts), np.log(errors), 1)[0])


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_sine_scheduled_force_and_torque_at_the_registered_order(name):
    """log(error) against log(dt) over three halvings has the registry's order as slope (+-0.3)."""
    order = INTEGRATORS[name].order
    dts = DTS[order]
    errors = [motion_error(name, dt) for dt in dts]
    assert all(e > 1e-13 for e in errors), errors  # above round-off, so the slope means something
    assert abs(fitted_slope(dts, errors) - order) < 0.3, errors


def test_adaptive_dopri5_follows_the_tolerance():
    """With `tolerance` the error-controlled dopri5 chooses its steps between output times 0.5 s apart;
    on this time-dependent scene its error stays within 10x of the tolerance and falls at least 10x per
    100x of tolerance (measured: 1.3e-5, 2.4e-8, 5.9e-11 for 1e-4, 1e-6, 1e-8). A wrong stage time makes
    both embedded solutions first order with the same leading error, invisible to their difference, so
    the error would then stay far above the tolerance."""
    tolerances = (1e-4, 1e-6, 1e-8)
    errors = [motion_error("dopri5", 0.5, tolerance=tol) for tol in tolerances]
    assert all(e <= 10 * tol for e, tol in zip(errors, tolerances, strict=True)), errors
    assert errors[1] < 0.1 * errors[0] and errors[2] < 0.1 * errors[1], errors
