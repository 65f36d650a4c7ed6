"""Force terms against closed-form results: moments of off-centre forces, impulses, drag laws, schedules.

Points and vectors are given as a user writes them (the body's own particle frame, any origin), so
these tests also check the compile-time conversion to principal-frame offsets about the centre of
mass: r_world = R_user (p_user - centre_user).
"""

from dataclasses import replace

import numpy as np
import pytest
from conftest import HANDLE_POSITIONS, make_body, make_scene

from rbcli.api import prepare, simulate
from rbcli.physics.forces.impulse import NO_IMPULSE_STEP, apply_impulses, impulse_step_indices, next_impulse_step
from rbcli.physics.forces.tables import make_force_data
from rbcli.physics.forces.wrench import accumulate_wrench
from rbcli.physics.integrators import get_integrator
from rbcli.physics.model import mass_properties
from rbcli.physics.rotation import quat_to_matrix
from rbcli.scene.force_specs import BodyPoint, ForceAtPoint, ForceDrag, ForceImpulse, ForceTorque, Schedule

G = np.array([0.0, 0.0, -9.81])
Q0 = np.array([0.9, 0.1, -0.3, 0.2]) / np.linalg.norm([0.9, 0.1, -0.3, 0.2])
# six 1 kg particles at +-0.5 m on each axis: M = 6 kg, I = 4 * 1 * 0.25 = 1 kg m^2 about every axis
OCTAHEDRON = np.vstack([np.eye(3) * 0.5, -np.eye(3) * 0.5])


def with_forces(scene, *forces):  # noqa: ANN001, ANN201
    return replace(scene, forces=tuple(forces))


def wrench_at_start(compiled):  # noqa: ANN001, ANN201
    s = compiled.initial_state
    n = compiled.model.body_count
    F, tau = np.zeros((n, 3)), np.zeros((n, 3))
    force_data, km = make_force_data(compiled.model, forces=compiled.forces), compiled.model.kernel()
    accumulate_wrench(km, compiled.forces, km.contact, force_data, 0.0, s.x, s.q, s.P, s.L, F, tau)
    return F, tau


def run_steps(compiled, steps, integrator="euler-matrix"):  # noqa: ANN001, ANN201
    """The runner's contract by hand: impulses of [t, t + dt) on the state at t, then one step."""
    kernel = get_integrator(integrator).load()
    km, forces, dt = compiled.model.kernel(), compiled.forces, compiled.settings.dt
    s = compiled.initial_state.copy()
    n = compiled.model.body_count
    F, tau, scratch = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, kernel.SCRATCH_WIDTH))
    P_history = [s.P.copy()]
    for k in range(steps):
        data = make_force_data(km, forces=forces)
        apply_impulses(km, forces, data, k * dt, (k + 1) * dt, s.x, s.q, s.P, s.L)
        kernel.step(km, forces, km.contact, data, k * dt, dt, s.x, s.q, s.P, s.L, F, tau, scratch)
        P_history.append(s.P.copy())
    return s, np.array(P_history)


def test_off_centre_force_gives_tau_r_cross_F_in_the_users_frame():
    """F = f, tau = r x f with r = R_user (p - centre_user); body-frame f turns: f_world = R_user f_user;
    a particle index names the particle's own position. The handle's frame is not principal, so a
    wrong E or a missing centre shift would show."""
    _, centre, _ = mass_properties(HANDLE_POSITIONS, make_body().particle_mass)
    R = quat_to_matrix(Q0)
    p, f, f_user = np.array([0.3, -0.1, 0.25]), np.array([1.0, -2.0, 0.5]), np.array([0.0, 0.7, -0.4])
    scene = make_scene([make_body("h", position=np.array([0.5, -1.0, 2.0]), orientation_wxyz=Q0)])
    cases = [
        (ForceAtPoint(at=BodyPoint(body="h", point=p), vector=f), R @ (p - centre), f),
        (ForceAtPoint(at=BodyPoint(body="h", point=p), vector=f_user, frame="body"), R @ (p - centre), R @ f_user),
        (ForceAtPoint(at=BodyPoint(body="h", particle=2), vector=f), R @ (HANDLE_POSITIONS[2] - centre), f),
        (ForceAtPoint(at=BodyPoint(body="h"), vector=f), np.zeros(3), f),
    ]
    for spec, r, f_world in cases:
        F, tau = wrench_at_start(prepare(with_forces(scene, spec)))
        np.testing.assert_allclose(F[0], f_world, rtol=0, atol=1e-14)
        np.testing.assert_allclose(tau[0], np.cross(r, f_world), rtol=0, atol=1e-14)


def test_torque_in_world_and_body_frame():
    scene = make_scene([make_body("h", orientation_wxyz=Q0)])
    c = np.array([0.2, -0.1, 0.4])
    for frame, expected in (("world", c), ("body", quat_to_matrix(Q0) @ c)):
        F, tau = wrench_at_start(prepare(with_forces(scene, ForceTorque(body="h", vector=c, frame=frame))))
        assert not F.any()
        np.testing.assert_allclose(tau[0], expected, rtol=0, atol=1e-15)


def test_impulse_changes_P_by_J_and_L_by_r_cross_J_exactly():
    """P += J, L += r x J with r = R_user (p - centre_user), on a moving, spinning, rotated body;
    'exactly' = to the rounding of each addition (1 ulp) and of turning r and a body-frame J (a few ulps)."""
    _, centre, _ = mass_properties(HANDLE_POSITIONS, make_body().particle_mass)
    R = quat_to_matrix(Q0)
    p, J, J_user = np.array([0.3, -0.1, 0.25]), np.array([1.5, -0.5, 2.0]), np.array([0.0, 1.0, 1.0])
    body = make_body("h", orientation_wxyz=Q0, velocity=np.array([0.3, 0.1, -0.2]),
                     angular_momentum=np.array([0.01, -0.02, 0.03]))  # fmt: skip
    for frame, J_world in (("world", J), ("body", R @ J_user)):
        spec = ForceImpulse(at=BodyPoint(body="h", point=p), time=0.0, vector=J if frame == "world" else J_user,
                            frame=frame)  # fmt: skip
        compiled = prepare(with_forces(make_scene([body]), spec))
        s = compiled.initial_state.copy()
        P0, L0 = s.P.copy(), s.L.copy()
        force_data = make_force_data(compiled.model, forces=compiled.forces)
        assert apply_impulses(compiled.model.kernel(), compiled.forces, force_data, 0.0, 0.01, s.x, s.q, s.P, s.L) == 1
        np.testing.assert_allclose(s.P[0] - P0[0], J_world, rtol=0, atol=1e-15)
        np.testing.assert_allclose(s.L[0] - L0[0], np.cross(R @ (p - centre), J_world), rtol=0, atol=1e-15)


@pytest.mark.parametrize("integrator", ["euler-matrix", "split2", "rk4"])
def test_impulse_lands_in_the_step_containing_its_time_for_any_integrator(integrator):
    """Free body, J at T = 0.3 s with dt = 0.1 s (3 * 0.1 = 0.30000000000000004 > 0.3: the round-off
    rule must still pick the step from t = 0.3): P = P0 before, P0 + J from the frame at 0.4 s on,
    whatever the method, since no force acts; then x(0.5) = x0 + 0.5 v0 + (0.5 - 0.3) J / M exactly."""
    body = make_body("h", velocity=np.array([1.0, 0.0, 0.5]))
    J = np.array([0.0, 2.0, 0.0])
    scene = with_forces(make_scene([body], dt=0.1, duration=0.5, integrator=integrator),
                        ForceImpulse(at=BodyPoint(body="h"), time=0.3, vector=J))  # fmt: skip
    compiled = prepare(scene)
    s, P = run_steps(compiled, 5, integrator)
    M = compiled.model.body_mass[0]
    P0 = M * body.velocity
    np.testing.assert_array_equal(P[:4, 0], np.broadcast_to(P0, (4, 3)))
    np.testing.assert_allclose(P[4:, 0], np.broadcast_to(P0 + J, (2, 3)), rtol=0, atol=1e-15)
    np.testing.assert_allclose(s.x[0], 0.5 * body.velocity + 0.2 * J / M, rtol=0, atol=1e-14)


def test_impulse_step_indices_follow_apply_impulses_rule():
    """The steps a runner stops at are exactly those in which apply_impulses applies something, for
    impulse times on the grid (with n * dt round-off), just off it, and between grid points; and
    next_impulse_step (where the adaptive loop lands) finds them from any grid index."""
    times = [0.0, 0.1, 0.3, 0.7, 0.3 - 1e-12, 0.3 + 1e-12, 0.35, 1.0, 2.05, -0.1]
    specs = [ForceImpulse(at=BodyPoint(body="h"), time=T, vector=np.ones(3)) for T in times]
    compiled = prepare(with_forces(make_scene([make_body("h")]), *specs))
    km, forces, dt = compiled.model.kernel(), compiled.forces, 0.1
    s = compiled.initial_state.copy()
    force_data = make_force_data(km, forces=forces)
    applied = {n: apply_impulses(km, forces, force_data, n * dt, (n + 1) * dt, s.x, s.q, s.P, s.L) for n in range(30)}
    assert impulse_step_indices(forces, dt).tolist() == [n for n, count in applied.items() if count]
    assert sum(applied.values()) == len(times) - 1  # all but the one before t = 0
    assert applied[3] == 4 and applied[2] == 0  # 0.3, 0.3 +- 1e-12 and 0.35 land in the step from 3 * 0.1
    # the compiled search the adaptive loop lands by gives, from every grid index, the next of these steps
    steps = impulse_step_indices(forces, dt).tolist()
    found = [next_impulse_step(forces, dt, index) for index in range(-1, 30)]
    assert found == [min([n for n in steps if n > index], default=NO_IMPULSE_STEP) for index in range(-1, 30)]
    assert NO_IMPULSE_STEP in found and found[0] == 0  # after the last impulse; the one at t = 0


def test_adaptive_loop_lands_on_impulse_steps_and_applies_them_there():
    """The adaptive loop applies impulses itself (its step-start stage, landing on each step that holds
    one): a free body (no forces, so dopri5 leaves P as it is, exactly) keeps P0 until grid step 30 and
    has P0 + J after the step-30 impulse, P0 + 2J after step 33's, exactly; and one call over 50 steps
    gives the bits of calls split at 30 and 33, where the runner used to split its chunks to apply
    them from Python (a landing and a restart there is the same computation)."""
    from rbcli.runner.simulation import Simulation

    J = np.array([0.0, 2.0, 0.0])
    body = make_body("h", velocity=np.array([1.0, 0.0, 0.5]), angular_momentum=np.array([0.01, 0.0, 0.02]))
    specs = [
        ForceImpulse(at=BodyPoint(body="h", point=np.array([0.1, 0.0, 0.0])), time=T, vector=J) for T in (0.3, 0.33)
    ]
    scene = with_forces(make_scene([body], dt=0.01, duration=0.5, integrator="dopri5"), *specs)
    whole, split = Simulation(scene, tolerance=1e-8), Simulation(scene, tolerance=1e-8)
    P0 = whole.data.state.P.copy()
    whole.step(50)
    for n, P in ((30, P0), (3, P0 + J), (17, P0 + J + J)):  # the state at steps 30, 33, 50
        split.step(n)
        assert np.array_equal(split.data.state.P, P)
    for name in "xqPL":
        assert np.array_equal(getattr(whole.data.state, name), getattr(split.data.state, name)), name
    assert whole.data.adaptive_counters.tolist() == split.data.adaptive_counters.tolist()


def test_chunk_loop_applies_impulses_whatever_the_chunking():
    """The impulse stage of the compiled chunk loop (physics/pipeline.py): chunks of 7 steps that start,
    end and run across the impulse steps give, to the last bit, the reference that applies impulses
    before every step (run_steps)."""
    J = np.array([0.0, 2.0, 0.0])
    body = make_body("h", velocity=np.array([1.0, 0.0, 0.5]), angular_momentum=np.array([0.01, 0.0, 0.02]))
    specs = [
        ForceImpulse(at=BodyPoint(body="h", point=np.array([0.1, 0.0, 0.0])), time=T, vector=J) for T in (0.3, 0.33)
    ]
    compiled = prepare(with_forces(make_scene([body], dt=0.01, duration=0.5, gravity=G), *specs))
    from rbcli.runner.simulation import Simulation

    sim = Simulation(compiled)
    assert impulse_step_indices(compiled.forces, compiled.settings.dt).tolist() == [30, 33]
    total = 50
    while sim.step_index < total:
        sim.step(min(7, total - sim.step_index))  # steps 28..34 in one chunk holds both impulses
    s = sim.data.state
    reference, _ = run_steps(compiled, total)
    for name in "xqPL":
        np.testing.assert_array_equal(getattr(s, name), getattr(reference, name))


def test_simulate_applies_impulses_once_at_their_step():
    """The runner applies J at the start of the step containing T: P is 0 before and J from then on."""
    J = np.array([0.0, 2.0, 0.0])
    scene = with_forces(make_scene([make_body("h")], dt=0.1, duration=0.5),
                        ForceImpulse(at=BodyPoint(body="h"), time=0.3, vector=J))  # fmt: skip
    traj = simulate(scene)
    np.testing.assert_array_equal(traj.step, [0, 1, 2, 3, 4, 5])
    np.testing.assert_allclose(traj.P[:4, 0], 0.0, atol=0)  # frames up to t = 0.3 (recorded before the kick)
    np.testing.assert_allclose(traj.P[4:, 0], [J, J], atol=1e-15)


def test_linear_drag_decays_exponentially():
    """M dv/dt = -b v: v = v0 exp(-b t / M). Explicit Euler gives exactly v0 (1 - b dt / M)^n, whose
    relative error against the exponential is n (b dt / M)^2 / 2 + O(dt^2) = t b^2 dt / (2 M^2)."""
    v0, b, dt = np.array([3.0, -1.0, 2.0]), 0.9, 1e-3
    scene = with_forces(make_scene([make_body("h", velocity=v0)], dt=dt, duration=2.0, every=100),
                        ForceDrag(linear=b))  # fmt: skip
    traj = simulate(scene)
    M = prepare(scene).model.body_mass[0]
    t = traj.t[:, None]
    np.testing.assert_allclose(traj.v[:, 0], v0 * (1 - b * dt / M) ** traj.step[:, None], rtol=1e-12)
    exact = v0 * np.exp(-b * t / M)
    bound = t * b**2 * dt / (2 * M**2) * 1.01  # the leading term, +1% for the O(dt^2) rest
    assert np.all(np.abs(traj.v[:, 0] - exact) <= bound * np.abs(exact) + 1e-15)


def test_rotational_linear_drag_on_an_isotropic_body():
    """I dw/dt = -b_r w for I = 1 kg m^2 on every axis (w = L / I whatever the orientation):
    L = L0 exp(-b_r t / I); Euler gives L0 (1 - b_r dt / I)^n exactly."""
    L0, b_r, dt = np.array([0.3, -0.2, 0.5]), 0.4, 1e-3
    body = make_body("o", particle_position=OCTAHEDRON, particle_mass=np.ones(6), angular_momentum=L0,
                     orientation_wxyz=Q0)  # fmt: skip
    traj = simulate(with_forces(make_scene([body], dt=dt, duration=2.0, every=100), ForceDrag(angular_linear=b_r)))
    np.testing.assert_allclose(traj.L[:, 0], L0 * (1 - b_r * dt) ** traj.step[:, None], rtol=1e-12)
    np.testing.assert_allclose(traj.L[:, 0], L0 * np.exp(-b_r * traj.t[:, None]), rtol=traj.t[-1] * b_r**2 * dt)


def test_quadratic_drag_terminal_velocity():
    """M dv/dt = M g - c |v| v: v_t = sqrt(M g / c), v(t) = -v_t tanh(g t / v_t) from rest. Explicit
    Euler's fixed point is the exact v_t (Mg = c v^2 is where P stops changing); near it the error
    decays like exp(-2 g t / v_t), to 1e-16 after 20 s; on the way Euler's error is O(dt), < 5e-3 v_t."""
    c, dt = 0.2, 1e-3
    scene = with_forces(make_scene([make_body("h")], dt=dt, duration=20.0, every=50, gravity=G),
                        ForceDrag(quadratic=c))  # fmt: skip
    traj = simulate(scene)
    M = prepare(scene).model.body_mass[0]
    v_t = np.sqrt(M * 9.81 / c)
    np.testing.assert_allclose(traj.v[-1, 0], [0.0, 0.0, -v_t], rtol=0, atol=1e-12 * v_t)
    exact = -v_t * np.tanh(9.81 * traj.t / v_t)
    assert np.abs(traj.v[:, 0, 2] - exact).max() < 5e-3 * v_t


def test_quadratic_angular_drag_terminal_spin_under_a_torque():
    """I dw/dt = tau0 - c_r |w| w on an isotropic body: w_t = sqrt(tau0 / c_r), reached to round-off
    (the error decays like exp(-2 c_r w_t t / I) = exp(-4 t))."""
    tau0, c_r = np.array([0.0, 0.0, 8.0]), 0.5
    body = make_body("o", particle_position=OCTAHEDRON, particle_mass=np.ones(6))
    scene = with_forces(make_scene([body], dt=1e-3, duration=12.0, every=1000),
                        ForceTorque(body="o", vector=tau0), ForceDrag(angular_quadratic=c_r))  # fmt: skip
    traj = simulate(scene)
    np.testing.assert_allclose(traj.omega[-1, 0], [0.0, 0.0, np.sqrt(8.0 / c_r)], rtol=0, atol=1e-12)


def test_scheduled_force_acts_in_its_window_and_ramps():
    """Euler integrates P += dt F(t_k): a window [0.25, 0.75) of value 3 on f adds 3 f dt per step
    whose start time lies in the window (50 steps at dt = 0.01); a ramp 0 -> 2 over [0, 1] s then
    held adds the integral 1 + 2 (T - 1) to within the left Riemann sum's error slope * T * dt / 2."""
    f = np.array([1.0, 0.0, -2.0])
    window = ForceAtPoint(at=BodyPoint(body="h"), vector=f, schedule=Schedule(start=0.25, stop=0.75, value=3.0))
    traj = simulate(with_forces(make_scene([make_body("h")], dt=0.01, duration=1.0), window))
    inside = [k for k in range(100) if 0.25 <= k * 0.01 < 0.75]
    assert len(inside) == 50
    np.testing.assert_allclose(traj.P[-1, 0], 3 * f * 0.01 * len(inside), rtol=1e-13)
    before = traj.P[traj.t < 0.25 + 1e-9, 0]
    assert not before.any()

    ramp = ForceAtPoint(at=BodyPoint(body="h"), vector=f,
                        schedule=Schedule(kind="piecewise_linear", times=(0.0, 1.0), values=(0.0, 2.0)))  # fmt: skip
    traj = simulate(with_forces(make_scene([make_body("h")], dt=1e-3, duration=3.0), ramp))
    np.testing.assert_allclose(traj.P[-1, 0], f * (1.0 + 2.0 * 2.0), atol=np.abs(f).max() * 2.0 * 1e-3)
