"""Adaptive dopri5 (`rbcli.physics.adaptive`): tolerance reached, uniform output, fewer steps on a transient.

`run_adaptive` below drives the adaptive loop (physics/adaptive_loop.py) the way the runner
does (chunks, frame buffers), on a Data of its own.
"""

import dataclasses

import numpy as np
from conftest import as_runner_passes, make_body, make_scene

from rbcli.analysis.exact import quat_geodesic_angle, torque_free
from rbcli.api import prepare
from rbcli.physics.adaptive import STATUS_STEP_TOO_SMALL
from rbcli.physics.data import make_data
from rbcli.physics.forces import WORLD, build_force_tables, spring_table
from rbcli.physics.frames import user_orientation
from rbcli.physics.integrators import get_integrator
from rbcli.physics.step import STATUS_FULL, STATUS_OK, empty_buffers
from rbcli.record.memory_sink import SinkMemory
from rbcli.runner.simulation import run

FLIP = ((1.0, 2.0, 3.0), (0.01, 5.0, 0.0))
GENERIC = ((1.0, 2.0, 3.0), (1.0, 1.0, 2.0))


def _compiled(case, dt, duration, integrator="dopri5", every=1):
    inertia = case[0]
    # diag(1, 2, 3) as two point-mass pairs on the x and y axes (see test_integrators_accuracy.py)
    assert inertia == (1.0, 2.0, 3.0)
    positions = np.array([[1.0, 0, 0], [-1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0]])
    masses = np.array([1.0, 1.0, 0.5, 0.5])
    body = make_body("body", particle_position=positions, particle_mass=masses, angular_velocity=np.array(case[1]),
                     angular_velocity_frame="body")  # fmt: skip
    return prepare(make_scene([body], dt=dt, duration=duration, integrator=integrator, every=every))


def run_adaptive(compiled, tolerance, chunk_steps=None):
    """All frames of an adaptive run (output grid = the scene's dt and record_every), as the runner would.

    Returns (t, q_user (K, N, 4), x (K, N, 3), counters [accepted, rejected], final status).
    """
    model, settings = compiled.model, compiled.settings
    n, total, dt, every = model.body_count, settings.steps, settings.dt, settings.record_every
    data = make_data(compiled.initial_state, compiled.model, 0, adaptive=True, tolerance=tolerance, duration=total * dt)
    state, run_chunk = data.state, get_integrator("dopri5").adaptive_chunk().run_chunk
    frames = empty_buffers(total // every + 2, n)
    frames.step[0], frames.x[0], frames.q[0] = 0, state.x, state.q
    filled, index, status = 1, 0, STATUS_OK
    while index < total and status in (STATUS_OK, STATUS_FULL):
        todo = total - index if chunk_steps is None else min(chunk_steps, total - index)
        handles = as_runner_passes(model.kernel(), compiled.forces.kernel(), data.kernel(), frames)
        done, filled, status = run_chunk(*handles[:3], dt, index, todo, every, handles[3], filled)
        index += done
    k = filled
    return frames.step[:k] * dt, user_orientation(model, frames.q[:k]), frames.x[:k], data.adaptive_counters, status


def _flip_error(t, q):
    exact = torque_free(np.array(FLIP[0]), np.eye(3), np.array(FLIP[1]), t, frame="body")
    return float(quat_geodesic_angle(q[:, 0], exact.q).max())


def test_reaches_the_tolerance_on_the_flip_case_and_reports_its_steps():
    """The flip, recorded every 0.5 s for 20 s: with tolerance = the run's error budget, the max angle
    error stays within 10x the tolerance (measured 1.3x at 1e-6; the separatrix amplifies errors)."""
    for tolerance in (1e-4, 1e-6):
        t, q, _, counters, status = run_adaptive(_compiled(FLIP, 0.5, 20.0), tolerance)
        assert status in (STATUS_OK, STATUS_FULL)
        assert np.allclose(t, 0.5 * np.arange(41), rtol=0, atol=0)  # landed exactly on every output time
        assert _flip_error(t, q) <= 10 * tolerance
        assert counters[0] > 40 and counters[1] >= 0
    loose = run_adaptive(_compiled(FLIP, 0.5, 20.0), 1e-4)[3]
    tight = run_adaptive(_compiled(FLIP, 0.5, 20.0), 1e-8)[3]
    assert tight[0] > 3 * loose[0]  # a tighter tolerance takes more steps (about tol^(-1/4))


def test_chunk_boundaries_on_output_times_do_not_change_the_result():
    """The controller state (next h, last rejection) persists across chunks, so chunks ending on output
    times give bitwise the same run as one chunk."""
    compiled = _compiled(FLIP, 0.1, 5.0, every=2)
    whole = run_adaptive(compiled, 1e-6)
    chopped = run_adaptive(compiled, 1e-6, chunk_steps=6)
    assert np.array_equal(whole[0], chopped[0]) and np.array_equal(whole[1], chopped[1])
    assert np.array_equal(whole[3], chopped[3])
    np.testing.assert_allclose(whole[0], 0.2 * np.arange(26), rtol=0, atol=1e-12)


def test_an_impossible_tolerance_stops_with_step_too_small():
    t, _, _, counters, status = run_adaptive(_compiled(GENERIC, 0.5, 2.0), 1e-300)
    assert status == STATUS_STEP_TOO_SMALL and counters[0] == 0 and counters[1] > 5 and len(t) == 1


def _transient(dt, duration=10.0):
    """A fast transient: the tumbling body on a stiff damped spring at its centre of mass, released
    0.5 m out (30 rad/s, damping ratio 0.15: it rings down in ~1 s, then only the slow tumble is left)."""
    compiled = _compiled(GENERIC, dt, duration)
    mass, omega_n, zeta = compiled.model.body_mass[0], 30.0, 0.15
    k, c = mass * omega_n**2, 2.0 * zeta * mass * omega_n
    spring = spring_table(body_a=[0], point_a=[[0.0, 0.0, 0.0]], body_b=[WORLD], point_b=[[0.0, 0.0, 0.0]],
                          stiffness=[k], rest_length=[0.0], damping=[c])  # fmt: skip
    compiled.initial_state.x[0] = [0.5, 0.0, 0.0]
    forces = build_force_tables(None, body_count=compiled.model.body_count, spring=spring)
    return dataclasses.replace(compiled, forces=forces), omega_n, zeta


def _transient_error(t, q, x, omega_n, zeta):
    """max(|x - x_exact| / 0.5 m, rotation angle): the damped oscillator along x, and the free tumble."""
    wd = omega_n * np.sqrt(1.0 - zeta**2)
    x_exact = 0.5 * np.exp(-zeta * omega_n * t) * (np.cos(wd * t) + zeta * omega_n / wd * np.sin(wd * t))
    rotation = torque_free(np.array(GENERIC[0]), np.eye(3), np.array(GENERIC[1]), t, frame="body")
    return max(np.abs(x[:, 0, 0] - x_exact).max() / 0.5, quat_geodesic_angle(q[:, 0], rotation.q).max())


def test_fewer_steps_than_fixed_step_at_equal_error_on_a_fast_transient():
    """Same method (dopri5), same outputs (every 0.1 s): the fixed step must resolve the 30 rad/s ringing
    for the whole 10 s; the adaptive one only while it lasts. Fixed-step errors at dt and dt/2 give the
    dt that matches the adaptive error (error ~ dt^5); the adaptive run must need fewer steps."""
    compiled, omega_n, zeta = _transient(0.1)
    t, q, x, counters, _ = run_adaptive(compiled, 1e-6)
    adaptive_error = _transient_error(t, q, x, omega_n, zeta)
    fixed = {}
    for dt in (0.005, 0.0025):
        compiled, *_ = _transient(dt)
        settings = dataclasses.replace(compiled.settings, record_every=round(0.1 / dt))
        compiled = dataclasses.replace(compiled, settings=settings)
        memory = SinkMemory()
        run(compiled, [memory])
        traj = memory.trajectory()
        fixed[dt] = _transient_error(traj.t, traj.q, traj.x, omega_n, zeta)
    order = np.log(fixed[0.005] / fixed[0.0025]) / np.log(2.0)
    dt_equal = 0.0025 * (adaptive_error / fixed[0.0025]) ** (1.0 / order)
    attempts = counters[0] + counters[1]
    assert 4.5 < order < 5.5
    assert attempts < 0.7 * (10.0 / dt_equal), (attempts, 10.0 / dt_equal, adaptive_error)


def test_a_torque_window_opening_and_closing_keeps_the_tolerance():
    """A scheduled torque switched on at 0.1 s and off at 0.45 s is a jump of dL/dt: the error of a step
    across it is ~ h |tau| (err per unit step independent of h), which stopped dopri5 at 1e-8 with
    "step below 1e-12 t" before the schedule step floor (physics/adaptive.py). The world-frame torque
    gives the exact L(t) = L0 + tau (stop - start) after the window, whatever the rotation."""
    from rbcli.api import simulate
    from rbcli.scene.load import load_scene_text

    L0, tau = np.array([0.01, 0.02, 0.05]), np.array([0.01, 0.0, 0.02])
    spec = load_scene_text(f"""name: torque-window
simulation: {{dt: 0.001, duration: 0.6, integrator: dopri5, record: {{every: 20}}}}
bodies:
  - name: box
    particles: {{positions: [[-0.2, 0, 0], [0.2, 0, 0], [0, 0.05, 0], [0, -0.05, 0], [0, 0, 0.03]],
                masses: [0.3, 0.3, 0.15, 0.15, 0.1]}}
    angular_momentum: {L0.tolist()}
forces:
  - {{type: torque, body: box, vector: {tau.tolist()}, frame: world, schedule: {{start: 0.1, stop: 0.45}}}}
""")
    for tolerance in (1e-6, 1e-8, 1e-10):
        traj = simulate(spec, integrator="dopri5", duration=0.6, record_every=20, tolerance=tolerance,
                        on_diverge="return")  # fmt: skip
        assert traj.summary.status == "completed", (tolerance, traj.summary.message)
        assert np.abs(traj.L[-1, 0] - (L0 + 0.35 * tau)).max() <= tolerance
