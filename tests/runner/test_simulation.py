"""The object API (`rbcli.Simulation`): stepping is the chunk loop, state reads and writes are in the user's
frames and consistent with the internal principal-frame state, and `simulate` is `Simulation.run`."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import make_body, make_scene, random_bodies

import rbcli
from rbcli.record.memory_sink import SinkMemory

G = np.array([0.0, 0.0, -9.81])
ROOT = Path(__file__).resolve().parents[2]


def _bits(sim: rbcli.Simulation) -> bytes:
    s = sim.data.state
    return b"".join(a.tobytes() for a in (s.x, s.q, s.P, s.L))


@pytest.mark.parametrize("integrator", ["split2", "rk4", "euler-matrix", "exact"])
def test_steps_split_anywhere_give_the_same_bits(integrator):
    """step(a) then step(b) equals step(a + b) bitwise: time is index * dt, and nothing but the state is
    carried from one call to the next."""
    scene = make_scene(random_bodies(3, seed=4), dt=0.01, integrator=integrator, gravity=G)
    whole, split = rbcli.Simulation(scene), rbcli.Simulation(scene)
    whole.step(37)
    split.step(5)
    split.step(0)
    split.step(32)
    assert split.step_index == whole.step_index == 37 and split.time == 37 * 0.01
    assert _bits(split) == _bits(whole)


def test_simulate_equals_simulation_run():
    scene = make_scene(random_bodies(2, seed=5), dt=0.01, duration=0.5, every=4, integrator="split2", gravity=G)
    traj = rbcli.simulate(scene)
    memory = SinkMemory()
    summary = rbcli.Simulation(scene).run(sinks=[memory])
    again = memory.trajectory()
    assert summary.status == "completed" and again.step.tolist() == traj.step.tolist()
    for name in ("x", "q", "v", "omega", "P", "L"):
        assert np.array_equal(getattr(traj, name), getattr(again, name)), name


def test_run_continues_from_the_current_state_and_equals_steps():
    """run() after step() records from the current step on; its states are those of plain steps."""
    scene = make_scene(random_bodies(2, seed=6), dt=0.01, duration=1.0, every=5, integrator="rk4", gravity=G)
    sim, ref = rbcli.Simulation(scene), rbcli.Simulation(scene)
    sim.step(10)
    memory = SinkMemory()
    sim.run(0.2, sinks=[memory])
    traj = memory.trajectory()
    assert traj.step.tolist() == [10, 15, 20, 25, 30]
    ref.step(30)
    assert _bits(sim) == _bits(ref)


def test_state_reads_back_what_was_written_in_the_user_frames():
    """set_state in the user's frames, read back: x, v, P exactly; q, omega, L to round-off. A tilted,
    lopsided cloud makes the principal frame differ from the user frame, so a conversion done in the
    wrong frame (or with R transposed) shows."""
    rng = np.random.default_rng(7)
    sim = rbcli.Simulation(make_scene(random_bodies(3, seed=7), integrator="split2"))
    q = rng.normal(size=(3, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1
    x, v, omega = rng.normal(size=(3, 3)), rng.normal(size=(3, 3)), rng.normal(size=(3, 3))
    sim.set_state(x=x, q=q, v=v, omega=omega)
    state = sim.state
    assert np.array_equal(state.x, x)
    np.testing.assert_allclose(state.v, v, rtol=1e-15, atol=1e-15)
    np.testing.assert_allclose(state.q, q, rtol=0, atol=1e-15)
    np.testing.assert_allclose(state.omega, omega, rtol=0, atol=1e-13)
    sim.set_state(P=state.P, L=state.L)
    assert np.array_equal(sim.state.P, state.P) and np.array_equal(sim.state.L, state.L)
    with pytest.raises(ValueError, match="shape"):
        sim.set_state(x=np.zeros((2, 3)))
    with pytest.raises(ValueError, match="finite"):
        sim.set_state(v=np.full((3, 3), np.nan))


def _world_inertia(positions: np.ndarray, masses: np.ndarray, q_user: np.ndarray) -> np.ndarray:
    """I = sum m (|r|^2 1 - r r^T) about the centre of mass, r the world offsets: straight from the
    particles, independent of rbsim's principal-axis decomposition."""
    R = _rotation(q_user)
    centre = masses @ positions / masses.sum()
    r = (positions - centre) @ R.T
    return sum(m * (ri @ ri * np.eye(3) - np.outer(ri, ri)) for m, ri in zip(masses, r, strict=True))


@pytest.mark.parametrize("frame", ["world", "body"])
def test_angular_velocity_of_a_tilted_lopsided_body_compiles_to_L_equal_I_world_omega(frame):
    """L = R I_user R^T omega_world (omega given in the body frame: omega_world = R omega_body). With the
    identity orientation or axis-aligned clouds R and R^T agree, so this body is tilted and lopsided."""
    positions = np.array([[0.3, 0.1, 0.0], [-0.2, 0.4, 0.1], [0.0, -0.3, 0.5], [0.1, 0.0, -0.4], [0.5, 0.2, 0.3]])
    masses = np.array([1.0, 2.0, 0.5, 1.5, 0.7])
    q_user = np.array([0.8, 0.3, -0.4, 0.34])
    q_user /= np.linalg.norm(q_user)
    omega = np.array([0.7, -1.3, 2.1])
    body = make_body("tilted", particle_position=positions, particle_mass=masses, orientation_wxyz=q_user,
                     angular_velocity=omega, angular_velocity_frame=frame)  # fmt: skip
    sim = rbcli.Simulation(make_scene([body], integrator="split2"))
    I_world = _world_inertia(positions, masses, q_user)
    R = _rotation(q_user)
    omega_world = omega if frame == "world" else R @ omega
    np.testing.assert_allclose(sim.state.L[0], I_world @ omega_world, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(sim.state.omega[0], omega_world, rtol=1e-13, atol=1e-13)


def _rotation(q: np.ndarray) -> np.ndarray:
    w, a, b, c = q
    return np.array([[1 - 2 * (b * b + c * c), 2 * (a * b - w * c), 2 * (a * c + w * b)],
                     [2 * (a * b + w * c), 1 - 2 * (a * a + c * c), 2 * (b * c - w * a)],
                     [2 * (a * c - w * b), 2 * (b * c + w * a), 1 - 2 * (a * a + b * b)]])  # fmt: skip


def test_a_changed_state_takes_effect_and_reset_restores_the_scene():
    """Free flight from a state set between steps: x = x0 + v t exactly for split2 without forces
    (the drift is exact), then reset() gives back the scene's initial bits."""
    scene = make_scene([make_body("b")], dt=0.125, integrator="split2")
    sim = rbcli.Simulation(scene)
    initial = _bits(sim)
    sim.step(3)
    sim.set_state(x=np.zeros((1, 3)), v=np.array([[1.0, -2.0, 0.5]]))
    sim.step(8)
    np.testing.assert_allclose(sim.state.x, [[1.0, -2.0, 0.5]], rtol=0, atol=1e-15)  # 8 x 0.125 s = 1 s
    sim.reset()
    assert sim.step_index == 0 and _bits(sim) == initial


def test_step_reports_divergence():
    sim = rbcli.Simulation(make_scene([make_body("rock")], dt=1.0, gravity=np.array([0.0, 0.0, -1e98])))
    with pytest.raises(rbcli.SimulationDiverged, match="diverged"):
        sim.step(100)
    assert sim.step_index == 100  # checked at the end of the call


def test_adaptive_simulation_steps_and_lands_on_the_grid():
    scene = make_scene(random_bodies(2, seed=8), dt=0.05, integrator="dopri5", gravity=G)
    sim = rbcli.Simulation(scene, tolerance=1e-8)
    sim.step(10)
    assert sim.step_index == 10 and sim.data.adaptive_counters[0] > 0


def test_spring_stability_warning_uses_the_dt_that_runs():
    """The spring pendulum's limit is 0.163 s: --dt 0.5 must warn although the scene's own dt does not."""
    scene = rbcli.load_scene(ROOT / "scenes/forces/spring_pendulum.yaml")
    assert not any("stability limit" in str(w) for w in rbcli.prepare(scene).warnings)
    warned = [str(w) for w in rbcli.prepare(scene, dt=0.5).warnings]
    assert any("stability limit" in w and "dt = 0.5 s" in w for w in warned), warned
    out = subprocess.run(
        [sys.executable, "-m", "rbcli.cli.app", "validate", str(ROOT / "scenes/forces/spring_pendulum.yaml")],
        capture_output=True, text=True, env={**os.environ, "COLUMNS": "200"},
    )  # fmt: skip
    assert "stability limit" not in out.stdout + out.stderr


def test_load_compiles_once():
    """prepare() with overrides reuses the model compiled while loading (compile_model is not called)."""
    import rbcli.scene.compile as compile_module

    scene = rbcli.load_scene(ROOT / "scenes/forces/spring_pendulum.yaml")
    calls = []
    original = compile_module.compile_model
    compile_module.compile_model = lambda spec: calls.append(spec) or original(spec)
    try:
        a = rbcli.prepare(scene, dt=0.002, integrator="rk4")
        b = rbcli.prepare(scene)
    finally:
        compile_module.compile_model = original
    assert calls == [] and a.model is b.model
    sa, sb = rbcli.Simulation(a), rbcli.Simulation(b)
    assert sa.data.force.term_evaluations is not sb.data.force.term_evaluations  # each run counts its own


def test_chunk_loops_do_not_allocate_per_step():
    """numba's allocation counters (NRT statistics, on in a fresh process) grow by the same amount for a
    10-step and a 10,000-step call: nothing in the loop allocates."""
    code = (
        "import numpy as np, rbcli\n"
        "from numba.core.runtime import rtsys\n"
        "import sys; sys.path.insert(0, 'tests')\n"
        "from conftest import make_scene, random_bodies\n"
        "from rbcli.physics.integrators import INTEGRATORS\n"
        "for name, tol in [*((n, None) for n in INTEGRATORS), ('dopri5', 1e-6)]:\n"
        "    scene = make_scene(random_bodies(3), dt=1e-3, integrator=name, gravity=np.array([0, 0, -9.8]))\n"
        "    sim = rbcli.Simulation(scene, tolerance=tol)\n"
        "    sim.step(1)\n"
        "    counts = []\n"
        "    for n in (10, 10_000):\n"
        "        before = rtsys.get_allocation_stats().alloc\n"
        "        sim.step(n)\n"
        "        counts.append(rtsys.get_allocation_stats().alloc - before)\n"
        "    print(name + ('-adaptive' if tol else ''), counts[0], counts[1])\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                         env={**os.environ, "NUMBA_NRT_STATS": "1"}, check=True)  # fmt: skip
    rows = [line.split() for line in out.stdout.splitlines()]
    assert len(rows) == 11
    for name, short, long in rows:
        assert int(short) == int(long), (name, short, long)
