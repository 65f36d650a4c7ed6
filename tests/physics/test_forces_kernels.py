"""Compiled force kernels against their plain numpy references, and potentials against forces.

Every term is compared alone and all together on random bodies, states and times (the compiled
kernel and the numpy twin share no code, so agreement to round-off checks both). The potential
energies are checked as what they claim to be: F_b = -dV/dx_b and tau_b = -dV/dphi_b (phi a small
world rotation of body b about its centre of mass), by central differences.
"""

from dataclasses import replace

import numpy as np
import pytest
from conftest import make_scene, random_bodies

from rbcli.api import prepare
from rbcli.physics.forces import force_terms_present
from rbcli.physics.forces.impulse import apply_impulses, impulses_numpy
from rbcli.physics.forces.schedule import schedule_value, schedule_values_numpy
from rbcli.physics.forces.tables import make_force_data
from rbcli.physics.forces.wrench import accumulate_wrench, potential_energy, wrench_numpy
from rbcli.physics.rotation import quat_multiply
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
RAMP = Schedule(kind="piecewise_linear", times=(0.0, 0.4, 0.4, 1.0), values=(0.0, 2.0, -1.0, 0.5), start=0.1)
SINE = Schedule(kind="sine", amplitude=1.5, frequency=2.0, phase=0.3, offset=0.2, stop=0.9)
WINDOW = Schedule(start=0.25, stop=0.75, value=3.0)

rng = np.random.default_rng(7)
ASYM = rng.normal(size=(3, 3))
SYM = ASYM + ASYM.T

TERMS = {
    "field": [
        ForceField(per="mass", bodies=("b0", "b3"), value=np.array([0.1, -0.2, 0.3]), gradient=SYM),
        ForceField(
            per="particle",
            bodies=None,
            value=np.array([1.0, 0.0, -0.5]),
            gradient=ASYM,
            origin=np.array([0.3, 0.2, 0.1]),
            schedule=SINE,
        ),  # fmt: skip
    ],
    "point_force": [
        ForceAtPoint(at=BodyPoint(body="b1", point=np.array([0.4, -0.3, 0.2])), vector=np.array([1.0, 2.0, -3.0])),
        ForceAtPoint(
            at=BodyPoint(body="b1", particle=2), vector=np.array([0.5, 0.0, 1.0]), frame="body", schedule=RAMP
        ),  # fmt: skip
        ForceAtPoint(at=BodyPoint(body="b4"), vector=np.array([0.0, 1.0, 0.0]), schedule=WINDOW),
    ],
    "torque": [
        ForceTorque(body="b2", vector=np.array([0.1, 0.2, 0.3])),
        ForceTorque(body="b0", vector=np.array([-0.3, 0.0, 0.2]), frame="body", schedule=SINE),
    ],
    "spring": [
        ForceSpring(
            end_a=BodyPoint(body="b0", point=np.array([0.1, 0.2, 0.3])),
            anchor=np.array([1.0, 0.0, 2.0]),
            stiffness=30.0,
            rest_length=0.5,
            damping=0.7,
        ),  # fmt: skip
        ForceSpring(
            end_a=BodyPoint(body="b1", particle=0),
            end_b=BodyPoint(body="b2", point=np.array([0.0, 0.5, 0.0])),
            stiffness=12.0,
            rest_length=1.5,
            damping=0.4,
        ),  # fmt: skip
        ForceSpring(end_a=BodyPoint(body="b3"), end_b=BodyPoint(body="b4", particle=4), stiffness=5.0),
    ],
    "drag": [
        ForceDrag(bodies=("b0", "b2"), linear=0.3, quadratic=0.1, angular_linear=0.05, angular_quadratic=0.02),
        ForceDrag(linear=0.1),
        ForceDrag(bodies=("b4",), angular_quadratic=0.3),
    ],
}


def compiled_with(forces, bodies=None, gravity=G):  # noqa: ANN001, ANN201
    scene = make_scene(bodies if bodies is not None else random_bodies(5, seed=3), gravity=gravity)
    return prepare(replace(scene, forces=tuple(forces)))


def random_state(n, seed=0):  # noqa: ANN001, ANN201
    r = np.random.default_rng(seed)
    q = r.normal(size=(n, 4))
    return (
        r.normal(size=(n, 3)),
        q / np.linalg.norm(q, axis=1, keepdims=True),
        r.normal(size=(n, 3)),
        r.normal(size=(n, 3)),
    )


@pytest.mark.parametrize("term", [*TERMS, "all"])
@pytest.mark.parametrize("t", [0.0, 0.2, 0.4, 0.55, 0.8, 1.2])
def test_compiled_wrench_matches_numpy_reference(term, t):
    """Same F and tau [N, N m] from the compiled kernel and the numpy twin; 1e-12 is ~100 ulps of
    the largest terms (k l ~ 100 N), far below any modelling error and far above round-off order."""
    forces = [f for specs in TERMS.values() for f in specs] if term == "all" else TERMS[term]
    compiled = prepare(replace(make_scene(random_bodies(5, seed=3), gravity=G), forces=tuple(forces)))
    assert term == "all" or force_terms_present(compiled.forces, compiled.model.contact) == ("gravity", term)
    km, tables = compiled.model.kernel(), compiled.forces
    for seed in range(3):
        x, q, P, L = random_state(5, seed)
        F, tau = np.zeros((5, 3)), np.zeros((5, 3))
        accumulate_wrench(km, tables, km.contact, make_force_data(km), t, x, q, P, L, F, tau)
        F_ref, tau_ref = wrench_numpy(compiled.model, tables, t, x, q, P, L)
        np.testing.assert_allclose(F, F_ref, rtol=0, atol=1e-12)
        np.testing.assert_allclose(tau, tau_ref, rtol=0, atol=1e-12)


def test_schedule_kernel_matches_numpy_and_definition():
    """s(t): 0 outside [start, stop); ramp interpolates, right-continuous (the step at 0.4 takes its
    later value from 0.4 on); sine = offset + amplitude sin(2 pi f t + phase); a window is a constant `value`."""
    tables = compiled_with([ForceTorque(body="b0", vector=np.ones(3), schedule=s) for s in (RAMP, SINE, WINDOW)]).forces
    sched = tables.schedule
    times = np.linspace(-0.5, 1.5, 401)
    for j in range(3):
        compiled_values = np.array([schedule_value(sched, j, t) for t in times])
        reference = np.array([schedule_values_numpy(sched, np.array([j]), t)[0] for t in times])
        np.testing.assert_allclose(compiled_values, reference, rtol=0, atol=1e-15)
    assert schedule_value(sched, -1, 123.0) == 1.0
    assert schedule_value(sched, 0, 0.05) == 0.0  # before the ramp's start
    assert schedule_value(sched, 0, 0.2) == pytest.approx(1.0)  # halfway up 0 -> 2 over [0, 0.4]
    assert schedule_value(sched, 0, 0.4 - 1e-12) == pytest.approx(2.0) and schedule_value(sched, 0, 0.4) == -1.0
    assert schedule_value(sched, 0, 5.0) == 0.5  # held after the last knot
    assert schedule_value(sched, 1, 0.9) == 0.0 and schedule_value(sched, 1, 0.5) == pytest.approx(
        0.2 + 1.5 * np.sin(2 * np.pi * 2.0 * 0.5 + 0.3)
    )
    assert [schedule_value(sched, 2, t) for t in (0.2, 0.25, 0.7, 0.75)] == [0.0, 3.0, 3.0, 0.0]


def test_apply_impulses_matches_numpy_reference():
    impulses = [
        ForceImpulse(at=BodyPoint(body="b1", point=np.array([0.3, 0.1, -0.2])), time=0.5, vector=np.array([1.0, 2, 3])),
        ForceImpulse(at=BodyPoint(body="b1", particle=3), time=0.52, vector=np.array([0.0, -1, 0.5]), frame="body"),
        ForceImpulse(at=BodyPoint(body="b3"), time=0.7, vector=np.array([4.0, 0, 0])),
    ]
    compiled = compiled_with(impulses)
    km, tables = compiled.model.kernel(), compiled.forces
    x, q, P, L = random_state(5, 1)
    P2, L2 = P.copy(), L.copy()
    for t_prev, t_next, expected in [(0.4, 0.5, 0), (0.5, 0.55, 2), (0.55, 0.7, 0), (0.7, 0.8, 1)]:
        assert apply_impulses(km, tables, make_force_data(km), t_prev, t_next, x, q, P, L) == expected
        assert impulses_numpy(tables.impulse, t_prev, t_next, q, P2, L2) == expected
        np.testing.assert_allclose(P, P2, rtol=0, atol=1e-15)
        np.testing.assert_allclose(L, L2, rtol=0, atol=1e-15)


CONSERVATIVE = [
    ForceSpring(
        end_a=BodyPoint(body="b0", point=np.array([0.1, 0.2, 0.3])),
        anchor=np.array([1.0, 0.0, 2.0]),
        stiffness=30.0,
        rest_length=0.5,
    ),  # fmt: skip
    ForceSpring(
        end_a=BodyPoint(body="b1", particle=0),
        end_b=BodyPoint(body="b2", point=np.array([0.0, 0.5, 0.0])),
        stiffness=12.0,
        rest_length=1.5,
    ),  # fmt: skip
    ForceField(per="mass", bodies=("b0", "b3"), value=np.array([0.1, -0.2, 0.3]), gradient=SYM),
    ForceField(
        per="particle", bodies=("b4",), value=np.array([1.0, 0.0, -0.5]), gradient=SYM, origin=np.array([0.3, 0.2, 0.1])
    ),  # fmt: skip
    ForceAtPoint(at=BodyPoint(body="b2", point=np.array([0.4, -0.3, 0.2])), vector=np.array([1.0, 2.0, -3.0])),
]


def test_potential_energy_is_the_negative_gradient_of_the_conservative_wrench():
    """F_b = -dV/dx_b and tau_b = -dV/dphi_b with q_b -> exp(phi/2) q_b; central differences with
    h = 1e-5 have truncation error ~h^2 |V'''| ~ 1e-8 and round-off ~|V| 1e-16 / h ~ 1e-10."""
    compiled = compiled_with(CONSERVATIVE)
    tables, model = compiled.forces, compiled.model
    x, q, P, L = random_state(5, 4)
    F, tau = wrench_numpy(model, tables, 0.0, x, q, np.zeros_like(P), np.zeros_like(L))  # at rest: no damping
    h = 1e-5
    for b in range(5):
        for k in range(3):
            dx = np.zeros_like(x)
            dx[b, k] = h
            dV = potential_energy(model, tables, (x + dx)[None], q[None]) - potential_energy(
                model, tables, (x - dx)[None], q[None]
            )
            assert -dV[0] / (2 * h) == pytest.approx(F[b, k], abs=1e-6)
            turn = np.zeros(4)
            turn[0], turn[1 + k] = np.cos(h / 2), np.sin(h / 2)
            q_plus, q_minus = q.copy(), q.copy()
            q_plus[b] = quat_multiply(turn, q[b])
            q_minus[b] = quat_multiply(turn * [1, -1, -1, -1], q[b])
            dV = potential_energy(model, tables, x[None], q_plus[None]) - potential_energy(
                model, tables, x[None], q_minus[None]
            )
            assert -dV[0] / (2 * h) == pytest.approx(tau[b, k], abs=1e-6)


def test_non_conservative_rows_have_no_potential():
    """Scheduled, body-frame, curl (non-symmetric gradient) rows and torques contribute V = 0."""
    forces = [
        ForceAtPoint(at=BodyPoint(body="b0"), vector=np.ones(3), frame="body"),
        ForceAtPoint(at=BodyPoint(body="b0"), vector=np.ones(3), schedule=WINDOW),
        ForceField(per="mass", value=np.ones(3), gradient=ASYM),
        ForceTorque(body="b1", vector=np.ones(3)),
        ForceDrag(linear=1.0),
    ]
    compiled = compiled_with(forces, gravity=None)
    x, q, _, _ = random_state(5, 2)
    assert potential_energy(compiled.model, compiled.forces, x[None], q[None]).tolist() == [0.0]
