"""The joint kernels against slow obvious versions: the rows against their numpy twins and their
Jacobians against central differences of the residuals, the dense solver against numpy's solve (and
its redundant rows counted), a whole step against the numpy step, every joint type held to round-off."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
from conftest import make_scene, random_bodies

from rbcli.api import prepare
from rbcli.physics.joints.dense import factor_rows, solve_rows
from rbcli.physics.joints.dense_layout import joint_graph as dense_graph
from rbcli.physics.joints.dense_layout import make_solver_work as dense_work
from rbcli.physics.joints.reference import joint_begin_numpy, joint_rows_numpy, rattle_step_numpy
from rbcli.physics.joints.rows import joint_rows
from rbcli.physics.joints.tables import JointTable, make_joint_work
from rbcli.physics.rotation import quat_multiply, quat_to_matrix
from rbcli.runner.simulation import Simulation
from rbcli.scene.compile import compile_model
from rbcli.scene.joint_spec import JointSpec

G = np.array([0.0, 0.0, -9.81])


def chain(seed: int = 3, extra: tuple[JointSpec, ...] = ()):  # noqa: ANN201
    """Five random bodies (random clouds, poses and momenta) held by one joint of each type: a hinge to
    the world, then ball, fixed, slider and distance joints between neighbours. The weld is kept as its 6
    constraint rows (compile_model(merge_welds=False)): scenes merge welded bodies into one, but the rows
    stay a tested joint type."""
    bodies = random_bodies(5, seed)
    x = [b.position for b in bodies]
    joints = (
        JointSpec("hinge", "hinge", ("b0", "world"), anchor=x[0] + [0.3, 0.0, 0.1], axis=np.array([0.0, 0.6, 0.8])),
        JointSpec("ball", "ball", ("b0", "b1"), anchor=0.5 * (x[0] + x[1])),
        JointSpec("fixed", "fixed", ("b1", "b2"), anchor=0.5 * (x[1] + x[2])),
        JointSpec("slider", "slider", ("b2", "b3"), anchor=0.5 * (x[2] + x[3]), axis=np.array([0.6, 0.8, 0.0])),
        JointSpec("distance", "distance", ("b4", "b3"),
                  anchors=np.array([bodies[4].particle_position[0], bodies[3].particle_position[1]])),
        *extra,
    )  # fmt: skip
    spec = replace(make_scene(bodies, integrator="split2", gravity=G), joints=joints)
    return prepare(replace(spec, compiled_model=compile_model(spec, merge_welds=False)))


def _perturbed(compiled, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    rng = np.random.default_rng(seed)
    x = compiled.initial_state.x + 0.05 * rng.normal(size=compiled.initial_state.x.shape)
    q = compiled.initial_state.q + 0.05 * rng.normal(size=compiled.initial_state.q.shape)
    return x, q / np.linalg.norm(q, axis=1, keepdims=True)


def _compiled_rows(table: JointTable, x: np.ndarray, q: np.ndarray):  # noqa: ANN202
    work = make_joint_work(table)
    worst = joint_rows(table, x, q, work.jac_a, work.jac_b, work.residual, True)
    return worst, work


def test_rows_match_their_numpy_twins_for_every_type():
    table = chain().model.joint
    assert table.row_count.tolist() == [5, 3, 6, 5, 1]
    x, q = _perturbed(chain())
    worst, work = _compiled_rows(table, x, q)
    g, ga, gb = joint_rows_numpy(table, x, q)
    np.testing.assert_allclose(work.residual, g, rtol=0, atol=1e-14)
    np.testing.assert_allclose(work.jac_a, ga, rtol=0, atol=1e-14)
    np.testing.assert_allclose(work.jac_b, gb, rtol=0, atol=1e-14)
    assert worst == np.abs(g).max() > 1e-3  # the perturbation really broke every joint


def _moved(x: np.ndarray, q: np.ndarray, velocity: np.ndarray, epsilon: float) -> tuple[np.ndarray, np.ndarray]:
    """The configuration after a time epsilon at velocity (v, omega) per body: x + eps v, exp(eps omega) q."""
    omega = velocity[:, 3:]
    angle = np.linalg.norm(omega, axis=1)
    turn = np.concatenate([np.cos(0.5 * epsilon * angle)[:, None],
                           (np.sin(0.5 * epsilon * angle) / angle)[:, None] * omega], axis=1)  # fmt: skip
    return x + epsilon * velocity[:, :3], quat_multiply(turn, q)


def test_jacobians_are_the_rates_of_the_residuals():
    """G V = d g / dt along any velocity V, checked by central differences (error eps^2 + round-off /
    eps: ~1e-10 at eps = 1e-5), independently of how the rows were derived."""
    compiled = chain()
    table = compiled.model.joint
    x, q = _perturbed(compiled, seed=2)
    _, work = _compiled_rows(table, x, q)
    velocity = np.random.default_rng(5).normal(size=(x.shape[0], 6))
    epsilon = 1e-5
    ahead, behind = _moved(x, q, velocity, epsilon), _moved(x, q, velocity, -epsilon)
    rate = (joint_rows_numpy(table, *ahead)[0] - joint_rows_numpy(table, *behind)[0]) / (2 * epsilon)
    predicted = np.zeros_like(rate)
    for j in range(table.kind.shape[0]):
        rows = slice(table.row_start[j], table.row_start[j] + table.row_count[j])
        predicted[rows] += work.jac_a[rows] @ velocity[table.body_a[j]]
        if table.body_b[j] >= 0:
            predicted[rows] += work.jac_b[rows] @ velocity[table.body_b[j]]
    np.testing.assert_allclose(predicted, rate, rtol=0, atol=1e-8)


def _dense_problem(compiled):  # noqa: ANN001, ANN202
    """The solver's inputs at a perturbed configuration of `compiled`, and A = G W G^T built densely."""
    table = compiled.model.joint
    x, q = _perturbed(compiled, seed=3)
    _, work = _compiled_rows(table, x, q)
    R = quat_to_matrix(q)
    inv_mass = 1.0 / compiled.model.body_mass
    inv_inertia = np.einsum("bij,bj,bkj->bik", R, (1.0 / compiled.model.body_inertia), R)
    rows, n = work.residual.shape[0], x.shape[0]
    G = np.zeros((rows, 6 * n))
    for j in range(table.kind.shape[0]):
        r = slice(table.row_start[j], table.row_start[j] + table.row_count[j])
        G[r, 6 * table.body_a[j] : 6 * table.body_a[j] + 6] += work.jac_a[r]
        if table.body_b[j] >= 0:
            G[r, 6 * table.body_b[j] : 6 * table.body_b[j] + 6] += work.jac_b[r]
    W = np.zeros((6 * n, 6 * n))
    for b in range(n):
        W[6 * b : 6 * b + 3, 6 * b : 6 * b + 3] = inv_mass[b] * np.eye(3)
        W[6 * b + 3 : 6 * b + 6, 6 * b + 3 : 6 * b + 6] = inv_inertia[b]
    return table, work, inv_mass, inv_inertia, G @ W @ G.T


def _factor_and_solve(table, work, inv_mass, inv_inertia, rhs):  # noqa: ANN001, ANN202
    """The dense implementation of the solver interface (the run's stages use joints/solver.py, tested
    against dense numpy solves in test_joint_solver.py)."""
    graph = dense_graph(table.body_a, table.body_b, table.body_ground, table.row_count)
    solver = dense_work(graph)
    dropped = factor_rows(graph, solver, table.row_start, table.row_count, table.body_a, table.body_b,
                          work.jac_a, work.jac_b, inv_mass, inv_inertia)  # fmt: skip
    out = np.zeros_like(rhs)
    solve_rows(graph, solver, table.row_start, table.row_count, table.body_a, table.body_b, rhs, out)
    return dropped, out


def test_dense_solver_matches_numpy():
    table, work, inv_mass, inv_inertia, A = _dense_problem(chain())
    rhs = np.random.default_rng(7).normal(size=A.shape[0])
    dropped, out = _factor_and_solve(table, work, inv_mass, inv_inertia, rhs)
    assert dropped == 0
    np.testing.assert_allclose(out, np.linalg.solve(A, rhs), rtol=1e-9)


def test_dense_solver_drops_redundant_rows_and_still_meets_a_consistent_right_hand_side():
    """The ball joint given twice: its three rows repeat, A is singular of rank R - 3; the solver counts
    3 dropped rows and its answer meets any right-hand side in A's range exactly (rhs = A y)."""
    x = [b.position for b in random_bodies(5, 3)]  # chain()'s bodies
    twice = chain(extra=(JointSpec("again", "ball", ("b0", "b1"), anchor=0.5 * (x[0] + x[1])),))
    table, work, inv_mass, inv_inertia, A = _dense_problem(twice)
    assert np.linalg.matrix_rank(A) == A.shape[0] - 3
    rhs = A @ np.random.default_rng(8).normal(size=A.shape[0])
    dropped, out = _factor_and_solve(table, work, inv_mass, inv_inertia, rhs)
    assert dropped == 3
    np.testing.assert_allclose(A @ out, rhs, rtol=0, atol=1e-10 * np.abs(rhs).max())


def test_a_compiled_step_matches_the_numpy_step():
    """20 split2 steps of the jointed chain (compiled chunk: RATTLE, rattle.py) against the numpy step
    (reference.rattle_step_numpy), from random momenta that the first step's joint_begin projects onto
    the joints."""
    compiled = chain()
    sim = Simulation(compiled)
    sim.step(20)
    s = compiled.initial_state.copy()
    model, forces = compiled.model.kernel(), compiled.forces
    for k in range(20):
        joint_begin_numpy(model, model.joint, s.x, s.q, s.P, s.L)
        rattle_step_numpy(model, forces, model.joint, k * 1e-3, 1e-3, s.x, s.q, s.P, s.L)
    got = sim.data.state
    for name in ("x", "q", "P", "L"):
        np.testing.assert_allclose(getattr(got, name), getattr(s, name), rtol=0, atol=1e-11, err_msg=name)


def test_every_joint_type_holds_to_round_off():
    """After 2000 steps of the tumbling chain under gravity every row's residual, evaluated by the numpy
    twin from the state, is at round-off (<= 1e-12 m or rad: measured ~1e-15), and so is every row's
    rate G V (<= 1e-12 m/s or rad/s) after the velocity stage."""
    compiled = chain()
    sim = Simulation(compiled)
    sim.step(2000)
    s = sim.data.state
    table = compiled.model.joint
    g, ga, gb = joint_rows_numpy(table, s.x, s.q)
    assert np.abs(g).max() <= 1e-12, np.abs(g).max()
    R = quat_to_matrix(s.q)
    omega = np.einsum("bij,bj,bkj,bk->bi", R, (1.0 / compiled.model.body_inertia), R, s.L)
    velocity = np.concatenate([s.P / compiled.model.body_mass[:, None], omega], axis=1)
    rate = np.zeros_like(g)
    for j in range(table.kind.shape[0]):
        rows = slice(table.row_start[j], table.row_start[j] + table.row_count[j])
        rate[rows] = ga[rows] @ velocity[table.body_a[j]]
        if table.body_b[j] >= 0:
            rate[rows] += gb[rows] @ velocity[table.body_b[j]]
    assert np.abs(rate).max() <= 1e-12, np.abs(rate).max()
    stats = sim.data.joint.stats
    assert stats[1] <= 1e-12 and stats[2] <= 1e-12 and stats[3] == 0
