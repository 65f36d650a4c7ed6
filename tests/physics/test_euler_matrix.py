"""The tutorial's integrator (`euler-matrix`) against its own formulas and exact free-flight results."""

import numpy as np
import pytest
from conftest import make_body, make_scene, random_bodies

from rbcli.api import prepare, simulate
from rbcli.physics.forces import make_force_data
from rbcli.physics.forces.wrench import wrench_numpy
from rbcli.physics.frames import particle_world
from rbcli.physics.integrators import euler_matrix
from rbcli.physics.model import mass_properties
from rbcli.physics.rotation import gram_schmidt, quat_to_matrix, skew

G = np.array([0.0, 0.0, -9.81])


def test_one_step_equals_the_tutorials_formulas_by_hand():
    """x += dt v; v += dt F/M; R += dt w* R (then Gram-Schmidt); L += dt tau; w = R I0^-1 R^T L,
    all in the user's body frame with the full (non-diagonal) I0 of the particles."""
    q0 = np.array([0.9, 0.1, -0.3, 0.2])
    q0 /= np.linalg.norm(q0)
    body = make_body("h", position=np.array([0.5, -1.0, 2.0]), orientation_wxyz=q0,
                     velocity=np.array([0.3, 0.2, -0.1]), angular_momentum=np.array([0.02, -0.05, 0.04]))  # fmt: skip
    dt = 0.01
    traj = simulate(make_scene([body], dt=dt, duration=dt, gravity=G))

    M, _, I0 = mass_properties(body.particle_position, body.particle_mass)
    R, x, v, L = quat_to_matrix(q0), body.position, body.velocity, body.angular_momentum
    I_inv = R @ np.linalg.inv(I0) @ R.T
    w = I_inv @ L
    x1, v1 = x + dt * v, v + dt * (M * G) / M
    R1 = gram_schmidt(R + dt * skew(w) @ R)
    L1 = L + dt * np.zeros(3)  # gravity acts at the centre of mass: no torque

    assert traj.t.tolist() == [0.0, dt]
    np.testing.assert_allclose(traj.x[1, 0], x1, rtol=0, atol=1e-15)
    np.testing.assert_allclose(traj.v[1, 0], v1, rtol=0, atol=1e-15)
    np.testing.assert_allclose(traj.L[1, 0], L1, rtol=0, atol=0)
    np.testing.assert_allclose(quat_to_matrix(traj.q[1, 0]), R1, rtol=0, atol=1e-14)
    # reported omega is I^-1 L at the new state
    np.testing.assert_allclose(traj.omega[1, 0], R1 @ np.linalg.inv(I0) @ R1.T @ L1, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(traj.omega[0, 0], w, rtol=1e-12, atol=1e-15)


def test_particle_update_matches_the_tutorial():
    """r_i = R r0_i, x_i = x + r_i, v_i = v + w x r_i."""
    body = make_body("h", position=np.array([1.0, 2.0, 3.0]), velocity=np.array([0.1, 0.0, 0.0]),
                     orientation_wxyz=np.array([np.cos(0.4), 0.0, np.sin(0.4), 0.0]),
                     angular_momentum=np.array([0.01, 0.02, -0.03]))  # fmt: skip
    compiled = prepare(make_scene([body]))
    s = compiled.initial_state
    xi, vi = particle_world(compiled.model, s.x, s.q, s.P, s.L)
    M, centre, I0 = mass_properties(body.particle_position, body.particle_mass)
    R = quat_to_matrix(body.orientation_wxyz)
    r = (body.particle_position - centre) @ R.T
    w = R @ np.linalg.inv(I0) @ R.T @ body.angular_momentum
    np.testing.assert_allclose(xi, body.position + r, atol=1e-14)
    np.testing.assert_allclose(vi, body.velocity + np.cross(w, r), atol=1e-14)


@pytest.mark.parametrize("dt", [0.01, 0.005])
def test_free_flight_error_is_explicit_eulers_known_first_order_term(dt):
    """Euler gives x_n = x0 + v0 t + g t^2/2 - g t dt/2 exactly: the error is O(dt) and halves with dt."""
    body = make_body("p", position=np.array([0.0, 0.0, 10.0]), velocity=np.array([1.0, 2.0, 3.0]))
    traj = simulate(make_scene([body], dt=dt, duration=1.0, gravity=G))
    t = traj.t[:, None]
    exact = body.position + body.velocity * t + 0.5 * G * t**2
    error = traj.x[:, 0] - exact
    np.testing.assert_allclose(error, -0.5 * G * t * dt, atol=1e-12)


def test_free_flight_error_halves_when_dt_halves():
    body = make_body("p", velocity=np.array([1.0, 0.0, 5.0]))
    errors = []
    for dt in (0.02, 0.01, 0.005):
        traj = simulate(make_scene([body], dt=dt, duration=2.0, gravity=G))
        exact = body.velocity * 2.0 + 0.5 * G * 4.0
        errors.append(np.linalg.norm(traj.x[-1, 0] - exact))
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    np.testing.assert_allclose(ratios, 2.0, rtol=1e-6)


def test_torque_free_body_keeps_L_exactly_and_R_orthonormal():
    body = make_body("spin", angular_momentum=np.array([0.3, -0.2, 0.5]))
    traj = simulate(make_scene([body], dt=1e-3, duration=10.0, every=100))
    assert traj.step[-1] == 10_000
    assert np.array_equal(traj.L, np.broadcast_to(body.angular_momentum, traj.L.shape))
    R = quat_to_matrix(traj.q[:, 0])
    defect = np.abs(R @ np.swapaxes(R, -1, -2) - np.eye(3)).max()
    assert defect < 1e-12


def test_compiled_step_matches_numpy_reference():
    compiled = prepare(make_scene(random_bodies(7), gravity=G))
    km, forces = compiled.model.kernel(), compiled.forces
    a, b = compiled.initial_state.copy(), compiled.initial_state.copy()
    F, tau, force_data = np.zeros((7, 3)), np.zeros((7, 3)), make_force_data(km)
    for k in range(50):
        euler_matrix.step(
            km,
            forces,
            km.contact,
            force_data,
            k * 0.01,
            0.01,
            a.x,
            a.q,
            a.P,
            a.L,
            F,
            tau,
            np.zeros((7, euler_matrix.SCRATCH_WIDTH)),
        )
        euler_matrix.step_numpy(km, forces, k * 0.01, 0.01, b.x, b.q, b.P, b.L)
    for name in "xqPL":
        np.testing.assert_allclose(getattr(a, name), getattr(b, name), rtol=0, atol=1e-12)


def test_gravity_wrench_acts_at_centre_of_mass():
    compiled = prepare(make_scene(random_bodies(3), gravity=G))
    s = compiled.initial_state
    F, tau = wrench_numpy(compiled.model, compiled.forces, 0.0, s.x, s.q, s.P, s.L)
    np.testing.assert_allclose(F, compiled.model.body_mass[:, None] * G)
    assert not tau.any()
