"""Per-body torque flags (`ForceTables.torque_body`): exactly the bodies some term can turn are flagged,
the wrench's tau is zero for every other body, and an integrator that takes its torque path only for
flagged bodies gives the same trajectories as the old all-bodies torque path."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import as_runner_passes, make_scene, random_bodies

from rbcli.api import prepare
from rbcli.physics.data import make_data
from rbcli.physics.forces import build_force_tables, make_force_data, spring_table, terms_with_torque
from rbcli.physics.forces.wrench import accumulate_wrench, wrench_numpy
from rbcli.physics.integrators import get_integrator
from rbcli.physics.step import STATUS_OK, empty_buffers
from rbcli.scene.force_specs import (
    BodyPoint,
    ForceAtPoint,
    ForceDrag,
    ForceField,
    ForceImpulse,
    ForceSpring,
    ForceTorque,
    Schedule,
)

G = np.array([0.0, 0.0, -9.81])
BODIES = 6
OFF = np.array([0.2, -0.1, 0.3])  # a point in a body's user frame: off the centre of mass of random_bodies


def _compiled(forces, bodies=BODIES, integrator="euler-matrix", dt=1e-2, seed=4):  # noqa: ANN001, ANN202
    scene = make_scene(random_bodies(bodies, seed=seed), gravity=G, dt=dt, integrator=integrator)
    return prepare(replace(scene, forces=tuple(forces)))


CASES = {
    "one off-centre spring": (
        [ForceSpring(end_a=BodyPoint(body="b2", point=OFF), anchor=np.zeros(3), stiffness=10.0)],
        [2],
    ),
    "spring centred end a, off-centre end b": (
        [ForceSpring(end_a=BodyPoint(body="b1"), end_b=BodyPoint(body="b4", point=OFF), stiffness=10.0)],
        [4],
    ),
    "spring off-centre end a, centred end b": (
        [ForceSpring(end_a=BodyPoint(body="b1", particle=2), end_b=BodyPoint(body="b4"), stiffness=10.0)],
        [1],
    ),
    "centred springs, world anchor off the origin": (
        [
            ForceSpring(end_a=BodyPoint(body="b0"), anchor=np.array([1.0, 2.0, 3.0]), stiffness=10.0),
            ForceSpring(end_a=BodyPoint(body="b3"), end_b=BodyPoint(body="b5"), stiffness=1.0, damping=0.5),
        ],
        [],
    ),
    "torque term": ([ForceTorque(body="b3", vector=np.array([0.0, 0.0, 1.0]))], [3]),
    "scheduled torque, off for now": ([ForceTorque(body="b5", vector=np.ones(3), schedule=Schedule(start=9.0))], [5]),
    "centred force": ([ForceAtPoint(at=BodyPoint(body="b1"), vector=np.ones(3), frame="body")], []),
    "off-centre force": ([ForceAtPoint(at=BodyPoint(body="b1", point=OFF), vector=np.ones(3))], [1]),
    "force at a particle": ([ForceAtPoint(at=BodyPoint(body="b0", particle=1), vector=np.ones(3))], [0]),
    "field on two bodies": ([ForceField(per="mass", bodies=("b1", "b4"), value=np.ones(3))], [1, 4]),
    "linear drag on all": ([ForceDrag(linear=0.1, quadratic=0.2)], []),
    "angular drag on one": ([ForceDrag(bodies=("b3",), angular_linear=0.1), ForceDrag(linear=0.1)], [3]),
    "off-centre impulse (acts on L directly)": (
        [ForceImpulse(at=BodyPoint(body="b2", point=OFF), time=0.1, vector=np.ones(3))],
        [],
    ),
}


@pytest.mark.parametrize("case", list(CASES))
def test_exactly_the_bodies_a_term_can_turn_are_flagged(case):
    specs, expected = CASES[case]
    forces = _compiled(specs).forces
    assert forces.torque_body.shape == (BODIES,) and forces.torque_body.dtype == np.bool_
    assert not forces.torque_body.flags.writeable
    assert np.flatnonzero(forces.torque_body).tolist() == expected
    # the scene-level switch is "any body", and agrees with the per-term report
    assert forces.has_torque == bool(expected) == bool(terms_with_torque(**forces._asdict()))


def test_table_rows_must_name_bodies_in_range():
    spring = spring_table(body_a=[3], point_a=[[0.1, 0.0, 0.0]], body_b=[-1], point_b=[[0.0, 0.0, 0.0]],
                          stiffness=[1.0], rest_length=[0.0], damping=[0.0])  # fmt: skip
    assert build_force_tables(G, body_count=4, spring=spring).torque_body.tolist() == [False, False, False, True]
    with pytest.raises(ValueError, match="spring body_a"):
        build_force_tables(G, body_count=3, spring=spring)


# every term, on a few bodies; b4 and b5 are touched only by torque-free terms, b6 and b7 by none
EVERY_TERM = [
    ForceSpring(end_a=BodyPoint(body="b0", point=OFF), anchor=np.array([0.0, 0.0, 2.0]), stiffness=10.0, damping=0.3),
    ForceSpring(end_a=BodyPoint(body="b1", point=OFF), end_b=BodyPoint(body="b4"), stiffness=5.0, rest_length=0.5),
    ForceTorque(body="b2", vector=np.array([0.1, 0.2, 0.3]), frame="body"),
    ForceField(per="particle", bodies=("b3",), value=np.array([0.0, 1.0, 0.0]), gradient=np.eye(3) * 0.5),
    ForceAtPoint(at=BodyPoint(body="b5"), vector=np.array([1.0, 0.0, 0.0]), frame="body"),
    ForceAtPoint(at=BodyPoint(body="b2", particle=3), vector=np.array([0.0, 0.0, 2.0])),
    ForceDrag(bodies=("b1", "b5"), linear=0.2, quadratic=0.1),
    ForceDrag(bodies=("b3",), angular_linear=0.05, angular_quadratic=0.02),
]


def test_wrench_tau_is_right_for_flagged_bodies_and_exactly_zero_for_the_others():
    """Compiled wrench against its numpy twin at several random states: the same F and tau (1e-12), tau
    written everywhere (a NaN sentinel is cleared), and tau == 0 exactly, in both, for every unflagged
    body (what lets the integrators skip them); flagged bodies do get a torque."""
    compiled = _compiled(EVERY_TERM, bodies=8)
    forces, kmodel = compiled.forces, compiled.model.kernel()
    assert np.flatnonzero(forces.torque_body).tolist() == [0, 1, 2, 3]
    rng = np.random.default_rng(11)
    for trial in range(5):
        s = compiled.initial_state.copy()
        s.x += rng.normal(size=s.x.shape)
        s.q[:] = rng.normal(size=s.q.shape)
        s.q /= np.linalg.norm(s.q, axis=1, keepdims=True)
        s.P += rng.normal(size=s.P.shape)
        s.L += rng.normal(size=s.L.shape)
        F, tau = np.full_like(s.x, np.nan), np.full_like(s.x, np.nan)
        accumulate_wrench(
            kmodel, forces, kmodel.contact, make_force_data(kmodel), 0.1 * trial, s.x, s.q, s.P, s.L, F, tau
        )
        F_np, tau_np = wrench_numpy(kmodel, forces, 0.1 * trial, s.x, s.q, s.P, s.L)
        np.testing.assert_allclose(F, F_np, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tau, tau_np, rtol=0, atol=1e-12)
        unflagged = ~forces.torque_body
        assert np.all(tau[unflagged] == 0.0) and np.all(tau_np[unflagged] == 0.0)
        assert np.all(np.abs(tau[forces.torque_body]).max(axis=1) > 1e-3)


def _mixed(integrator: str, dt: float = 0.01):  # noqa: ANN202
    """Five spinning bodies under gravity; one off-centre spring on b0 (the only flagged body) and a
    centred spring on b1 (a force, no torque); b2..b4 fly free."""
    springs = (
        ForceSpring(end_a=BodyPoint(body="b0", point=OFF), anchor=np.array([0.0, 0.0, 1.0]), stiffness=40.0,
                    rest_length=0.5, damping=0.2),
        ForceSpring(end_a=BodyPoint(body="b1"), anchor=np.array([1.0, 0.0, 0.0]), stiffness=20.0),
    )  # fmt: skip
    compiled = _compiled(springs, bodies=5, integrator=integrator, dt=dt, seed=8)
    assert np.flatnonzero(compiled.forces.torque_body).tolist() == [0]
    return compiled


def _every_body(count: int) -> np.ndarray:
    """torque_body flagging every body, read-only as the compiled tables' are (a writable array is another
    numba type: a loop compiled for it alone)."""
    flags = np.ones(count, dtype=np.bool_)
    flags.flags.writeable = False
    return flags


def _run_chunk(name, compiled, forces, steps):  # noqa: ANN001, ANN202
    """The integrator's run_chunk over `steps` steps of the compiled scene with these force tables."""
    from rbcli.physics.data import make_data

    chunk = get_integrator(name).chunk()
    data = make_data(compiled.initial_state, compiled.model, chunk.SCRATCH_WIDTH, forces=compiled.forces)
    n, dt = compiled.model.body_count, compiled.settings.dt
    never = np.iinfo(np.int64).max
    handles = as_runner_passes(compiled.model.kernel(), forces, data.kernel(), empty_buffers(1, n))
    done, _, status = chunk.run_chunk(*handles[:3], dt, 0, steps, never, handles[3], 0)
    assert (done, status) == (steps, STATUS_OK)
    return data.state


# One integrator of each way of taking a torque (each compiles two chunk loops here, ~7 CPU-s apiece cold):
# euler-matrix (L += h tau in the world frame, as euler-quat and semi-implicit), semi-implicit-gyro (tau
# turned into the body frame), rk4 (tau at each stage, as dopri5, whose error-controlled loop the last
# test runs), split2 (kicks around the damping flow; split4 composes it) and exact (torque-free bodies in
# closed form; exact4 composes its flows)
TORQUE_PATHS = ("euler-matrix", "semi-implicit-gyro", "rk4", "split2", "exact")


def _bits(state):  # noqa: ANN001, ANN202
    return np.concatenate([a.ravel() for a in (state.x, state.q, state.P, state.L)]).view(np.uint64)


@pytest.mark.parametrize("name", TORQUE_PATHS)
def test_per_body_torque_path_is_bitwise_the_all_bodies_path(name):
    """The mixed scene with its own flags against the same tables with every body flagged (the old
    behaviour: torque path for all): bit for bit equal, for the flagged body (the same arithmetic) and for
    the free ones (their tau is exactly 0, and a zero kick is the identity in every method: split2's
    T_c(h/2) after a zero kick recomputes the very (cos, sin) it reuses without one). Except `exact`'s
    free bodies: without a torque flag it evaluates them in closed form from their anchor, flagged it
    chains the flow through the kicks, which agree to round-off (1e-13 here)."""
    compiled = _mixed(name)
    tables = compiled.forces.kernel()  # as Simulation passes them: only the stages the scene has compile
    all_bodies = tables._replace(torque_body=_every_body(compiled.model.body_count))
    per_body = _run_chunk(name, compiled, tables, 200)
    old = _run_chunk(name, compiled, all_bodies, 200)
    if name == "exact":
        flagged = np.flatnonzero(compiled.forces.torque_body)
        for field in "xqPL":
            a, b = getattr(per_body, field), getattr(old, field)
            assert np.array_equal(a[flagged], b[flagged]), field
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * max(1.0, np.abs(b).max()), err_msg=field)
    else:
        assert np.array_equal(_bits(per_body), _bits(old))
    # and the flagged body really takes the torque path: with the torque switched off scene-wide (no
    # flag involved) its L comes out otherwise, while the free bodies' L does not notice
    no_torque = _run_chunk(name, compiled, tables._replace(has_torque=False), 200)
    assert not np.allclose(per_body.L[0], no_torque.L[0], rtol=1e-6, atol=0)
    assert np.array_equal(per_body.L[1:], no_torque.L[1:])


@pytest.mark.parametrize("name", TORQUE_PATHS)
def test_free_bodies_of_a_torque_scene_move_as_in_a_torque_free_scene(name):
    """b2..b4 of the mixed scene against the same bodies in a scene without the springs (has_torque False:
    the scene-wide fast path). Every method runs the same per-body arithmetic there, bit for bit, except
    exact / exact4: they chain the free flow through the stages when the scene has torques and start
    every flow from the step's start (exact: from the body's anchor) when it has none, which agree to
    round-off (1e-13 here); and split2 / split4: the mixed scene's spring has a damper, so their kick is
    split around the damping flow (K(h/2) D(h) K(h/2), forces/damping.py) and gravity arrives in two
    halves, equal to round-off."""
    compiled = _mixed(name)
    torque_free = replace(compiled, forces=build_force_tables(G, body_count=5))
    assert not torque_free.forces.has_torque
    mixed = _run_chunk(name, compiled, compiled.forces.kernel(), 200)
    alone = _run_chunk(name, torque_free, torque_free.forces.kernel(), 200)
    for field in "xqPL":
        a, b = getattr(mixed, field)[2:], getattr(alone, field)[2:]
        if name.startswith("exact") or name in ("split2", "split4"):
            np.testing.assert_allclose(a, b, rtol=0, atol=1e-13 * max(1.0, np.abs(b).max()), err_msg=field)
        else:
            assert np.array_equal(a.view(np.uint64), b.view(np.uint64)), field


def test_adaptive_dopri5_per_body_torque_path_is_bitwise_the_all_bodies_path():
    """The error-controlled chunk (dopri5's begin / advance / error_norm): same steps, same bits; and
    not the result without torques."""
    compiled = _mixed("dopri5")
    tables = compiled.forces.kernel()
    all_bodies = tables._replace(torque_body=_every_body(5))
    results = []
    run_chunk = get_integrator("dopri5").adaptive_chunk().run_chunk
    for forces in (tables, all_bodies, tables._replace(has_torque=False)):
        data = make_data(compiled.initial_state, compiled.model, 0, adaptive=True, tolerance=1e-8, duration=2.0)
        handles = as_runner_passes(compiled.model.kernel(), forces, data.kernel(), empty_buffers(8, 5))
        done, _, status = run_chunk(*handles[:3], 0.01, 0, 200, 50, handles[3], 0)
        assert (done, status) == (200, STATUS_OK)
        results.append((_bits(data.state), data.adaptive_counters.tolist()))
    assert np.array_equal(results[0][0], results[1][0]) and results[0][1] == results[1][1]
    assert not np.array_equal(results[0][0], results[2][0])
