"""Integrator kernels: compiled step against its numpy reference, registry contract, shared kinematics."""

import subprocess
import sys

import numpy as np
import pytest
from conftest import as_runner_passes, make_scene, random_bodies

from rbcli.api import prepare
from rbcli.physics.forces import WORLD, build_force_tables, drag_table, spring_table
from rbcli.physics.forces.tables import make_force_data
from rbcli.physics.integrators import INTEGRATORS, get_integrator, integrator_names
from rbcli.physics.integrators.kinematics import axis_order, rotate, rotate_inverse, turn, turn_numpy
from rbcli.physics.rotation import quat_multiply, quat_to_matrix
from rbcli.physics.step import empty_buffers

G = np.array([0.0, 0.0, -9.81])
BODY_COUNT = 5


def _forces(kind: str):
    """ "torque-free": gravity alone; "springs-drag": gravity + springs at off-centre points (one
    body-to-body) + linear and angular drag, forces that depend on x, q, P and L, with torques on every
    body; "mixed": gravity + one off-centre spring on body 0, a centred spring on body 1 and linear drag
    on body 3, so only body 0 takes the torque path (the numpy twin applies tau to every body)."""
    if kind == "torque-free":
        return build_force_tables(G, body_count=BODY_COUNT)
    if kind == "mixed":
        spring = spring_table(
            body_a=[0, 1], point_a=[[0.3, -0.2, 0.1], [0.0, 0.0, 0.0]], body_b=[WORLD, WORLD],
            point_b=[[0.0, 0.0, 2.0], [1.0, 0.0, 0.0]], stiffness=[30.0, 20.0], rest_length=[0.5, 0.2],
            damping=[0.5, 0.1],
        )  # fmt: skip
        drag = drag_table(body=[3], linear=[0.3], quadratic=[0.05], angular_linear=[0.0], angular_quadratic=[0.0])
        return build_force_tables(G, body_count=BODY_COUNT, spring=spring, drag=drag)
    spring = spring_table(
        body_a=[0, 1, 3], point_a=[[0.3, -0.2, 0.1], [0.0, 0.4, 0.0], [0.1, 0.1, -0.2]],
        body_b=[WORLD, 2, WORLD], point_b=[[0.0, 0.0, 2.0], [0.2, 0.0, 0.1], [1.0, 1.0, 0.0]],
        stiffness=[30.0, 20.0, 50.0], rest_length=[0.5, 0.3, 0.0], damping=[0.5, 0.2, 0.0],
    )  # fmt: skip
    drag = drag_table(body=[2, 4], linear=[0.3, 0.1], quadratic=[0.05, 0.0], angular_linear=[0.02, 0.1],
                      angular_quadratic=[0.0, 0.01])  # fmt: skip
    return build_force_tables(G, body_count=BODY_COUNT, spring=spring, drag=drag)


TORQUE_BODIES = {"torque-free": [], "springs-drag": [0, 1, 2, 3, 4], "mixed": [0]}


@pytest.mark.parametrize("kind", list(TORQUE_BODIES))
@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_compiled_step_matches_numpy_reference(name, kind):
    """30 steps of 5 random bodies: the compiled kernel and the vectorised numpy reference agree to
    1e-12 (the same arithmetic in a different order; the state is O(1)). The compiled kernels take the
    torque path only for the bodies torque_body flags, the references for all: a body wrongly left
    unflagged would lose its torque here. The scratch is zeroed before each kernel step: what rk4 and
    split2/split4 carry from one step to the next (the body momentum m and the compensations of the
    sums, docs/accuracy.md) the stateless numpy twins do not have; with it carried, the kernel differs
    from them by an error within the method's own (O(h^5) per step in |m|; checked below to 1e-8,
    against a local error ~(omega h)^5 = 2e-6 of the stiffest spring here)."""
    kernel = get_integrator(name).load()
    compiled = prepare(make_scene(random_bodies(BODY_COUNT, seed=3)))
    forces = _forces(kind)
    assert np.flatnonzero(forces.torque_body).tolist() == TORQUE_BODIES[kind]
    assert forces.has_torque == bool(TORQUE_BODIES[kind])
    kmodel = compiled.model.kernel()
    a, b = compiled.initial_state.copy(), compiled.initial_state.copy()
    F, tau = np.zeros((BODY_COUNT, 3)), np.zeros((BODY_COUNT, 3))
    scratch = np.zeros((BODY_COUNT, kernel.SCRATCH_WIDTH))
    carried, carried_scratch = compiled.initial_state.copy(), np.zeros_like(scratch)
    dt = 0.01
    contact, force_data = kmodel.contact, make_force_data(kmodel, forces=forces)  # no contact stage
    for k in range(30):
        scratch[:] = 0.0
        kernel.step(kmodel, forces, contact, force_data, k * dt, dt, a.x, a.q, a.P, a.L, F, tau, scratch)
        kernel.step_numpy(kmodel, forces, k * dt, dt, b.x, b.q, b.P, b.L)
        c = carried
        kernel.step(kmodel, forces, contact, force_data, k * dt, dt, c.x, c.q, c.P, c.L, F, tau, carried_scratch)
    for field in "xqPL":
        np.testing.assert_allclose(getattr(a, field), getattr(b, field), rtol=0, atol=1e-12, err_msg=field)
        np.testing.assert_allclose(getattr(carried, field), getattr(b, field), rtol=0, atol=1e-8, err_msg=field)
    np.testing.assert_allclose(np.linalg.norm(a.q, axis=1), 1.0, rtol=0, atol=4e-16)


@pytest.mark.parametrize("name", list(INTEGRATORS))
def test_chunk_loop_equals_repeated_steps(name):
    """`run_chunk` (what the runner calls) is exactly the step repeated, with frames recorded on cadence."""
    from rbcli.physics.data import make_data

    kernel = get_integrator(name).load()
    chunk = get_integrator(name).chunk()
    compiled = prepare(make_scene(random_bodies(3, seed=1)))
    # the kernel form of the tables, as Simulation passes them (a plain ForceTables compiles every stage:
    # test_compile_only_what_is_used covers that form once, instead of once per integrator here)
    kmodel, forces = compiled.model.kernel(), _forces("torque-free").kernel()
    data = make_data(compiled.initial_state, compiled.model, chunk.SCRATCH_WIDTH, forces=forces)
    a, b = data.state, compiled.initial_state.copy()
    F, tau, scratch = np.zeros((3, 3)), np.zeros((3, 3)), np.zeros((3, kernel.SCRATCH_WIDTH))
    frames = empty_buffers(4, 3)
    handles = as_runner_passes(kmodel, forces, data.kernel(), frames)  # the runner's form: its loop
    done, filled, status = chunk.run_chunk(*handles[:3], 0.01, 0, 10, 3, handles[3], 0)
    assert (done, filled, status) == (10, 3, 0)
    assert frames.step[:3].tolist() == [3, 6, 9]
    contact, force_data = kmodel.contact, make_force_data(kmodel, forces=forces)
    for k in range(10):
        kernel.step(kmodel, forces, contact, force_data, k * 0.01, 0.01, b.x, b.q, b.P, b.L, F, tau, scratch)
        if k == 8:
            assert np.array_equal(frames.q[2], b.q)
    assert np.array_equal(a.q, b.q) and np.array_equal(a.x, b.x)


def test_registry_entries_are_complete_and_cheap_to_import():
    """Every entry names a module with step / step_numpy / SCRATCH_WIDTH and a generated chunk loop; importing the
    registry itself loads no numba (the CLI's --help and `rbsim integrators --no-measure` stay fast)."""
    for name in integrator_names():
        info = get_integrator(name)
        assert info.order >= 1 and info.force_evals >= 1 and info.conserves and info.summary
        module = info.load()
        # the reduced integrators' reference is the maximal ones they converge with (test_tree_integrate.py)
        for attribute in ("step",) if info.reduced else ("step", "step_numpy"):
            assert callable(getattr(module, attribute)), (name, attribute)
        assert callable(info.chunk().run_chunk) and info.chunk().SCRATCH_WIDTH == module.SCRATCH_WIDTH
        assert isinstance(module.SCRATCH_WIDTH, int) and module.SCRATCH_WIDTH >= 0
    assert [n for n, i in INTEGRATORS.items() if i.adaptive] == ["dopri5"]
    assert [n for n, i in INTEGRATORS.items() if i.demonstration] == ["semi-implicit-gyro"]
    code = "import sys, rbcli.physics.integrators; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    with pytest.raises(KeyError, match="known: euler-matrix"):
        get_integrator("verlet")


def test_axis_turn_is_the_exact_flow_of_one_kinetic_energy_term():
    """turn(k, theta): q <- q (cos theta/2, sin theta/2 e_k), m <- Rot_k(-theta) m. So the world L = R m is
    unchanged, m_k is unchanged, and d/dtheta of m at 0 is m x e_k (the flow of T_k = m_k^2 / 2 I_k
    with dt = theta I_k / m_k: dm/dt = m x omega_k e_k)."""
    rng = np.random.default_rng(7)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    m = rng.normal(size=3)
    L = quat_to_matrix(q) @ m
    for k in range(3):
        theta = 0.7
        out = np.array(turn(k, np.cos(theta / 2), np.sin(theta / 2), *m, *q))
        np.testing.assert_allclose(quat_to_matrix(out[3:]) @ out[:3], L, rtol=0, atol=1e-15)
        assert out[k] == m[k]
        r = np.zeros(4)
        r[0], r[1 + k] = np.cos(theta / 2), np.sin(theta / 2)
        np.testing.assert_allclose(out[3:], quat_multiply(q, r), rtol=0, atol=1e-15)
        eps = 1e-7
        small = np.array(turn(k, np.cos(eps / 2), np.sin(eps / 2), *m, *q))
        np.testing.assert_allclose((small[:3] - m) / eps, np.cross(m, np.eye(3)[k]), atol=1e-7)
        m_np, q_np = turn_numpy(np.array([k]), theta / m[k], m[None], q[None], np.ones((1, 3)))
        np.testing.assert_allclose(np.concatenate([m_np[0], q_np[0]]), out, rtol=0, atol=1e-15)


def test_rotate_and_axis_order():
    rng = np.random.default_rng(2)
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    v = rng.normal(size=3)
    R = quat_to_matrix(q)
    np.testing.assert_allclose(rotate(*q, *v), R @ v, rtol=0, atol=1e-15)
    np.testing.assert_allclose(rotate_inverse(*q, *v), R.T @ v, rtol=0, atol=1e-15)
    for moments in ([1.0, 2.0, 3.0], [3.0, 1.0, 2.0], [2.0, 3.0, 1.0], [1.0, 1.0, 1e-3], [2.0, 2.0, 2.0]):
        a, b, c = axis_order(*moments)
        assert sorted((a, b, c)) == [0, 1, 2] and moments[a] <= moments[b] <= moments[c]


def test_integrators_command_lists_every_method_and_times_one(capsys):
    """`rbsim integrators` (the lead registers it on the app): the table names every integrator, and
    the in-process timing gives a positive cost per body-step."""
    from rbcli.cli.integrators import integrators
    from rbcli.runner.study import measure_cost

    integrators(measure=False)
    out = capsys.readouterr().out
    for name in INTEGRATORS:
        assert name in out
    cost = measure_cost("split2", 10, 20, repeats=1)
    assert 0.0 < cost < 1e6
