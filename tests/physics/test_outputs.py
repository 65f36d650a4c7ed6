"""The compiled output derivation equals its numpy twins (frames.py, energy.py) to round-off."""

import math

import numpy as np
from conftest import make_scene, random_bodies

from rbcli.api import prepare
from rbcli.physics.energy import invariants, invariants_from_totals, kinetic_energy
from rbcli.physics.frames import body_angular_velocity, body_velocity, user_orientation
from rbcli.physics.outputs import TOTALS_WIDTH, derive_outputs
from rbcli.physics.rotation import quat_normalize


def test_compiled_outputs_match_numpy_references():
    compiled = prepare(make_scene(random_bodies(9), gravity=[0.0, 0.0, -9.81]))
    model = compiled.model
    rng = np.random.default_rng(3)
    # slightly off-unit quaternions, so the norm defect is not round-off
    q = quat_normalize(rng.normal(size=(4, 9, 4))) * rng.uniform(0.999, 1.001, size=(4, 9, 1))
    x, P, L = rng.normal(size=(4, 9, 3)), rng.normal(size=(4, 9, 3)), rng.normal(size=(4, 9, 3))
    q_user, v, omega, totals = np.empty_like(q), np.empty_like(P), np.empty_like(L), np.empty((4, TOTALS_WIDTH))
    derive_outputs(model.body_mass, 1 / model.body_inertia, model.body_frame_q, x, q, P, L, q_user, v, omega, totals)
    np.testing.assert_allclose(q_user, user_orientation(model, q), atol=1e-15)
    np.testing.assert_allclose(v, body_velocity(model, P), rtol=1e-15)
    np.testing.assert_allclose(omega, body_angular_velocity(model, q, L), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(totals[:, 0], kinetic_energy(model, P, L, omega), rtol=1e-13)
    # every invariant from the compiled sums equals the numpy formulas (energy.invariants)
    compiled_inv = invariants_from_totals(model, compiled.forces, x, q, totals)
    numpy_inv = invariants(model, compiled.forces, x, q, P, L, omega)
    assert list(compiled_inv) == list(numpy_inv)
    for name, series in numpy_inv.items():
        np.testing.assert_allclose(compiled_inv[name], series, rtol=1e-12, atol=1e-13, err_msg=name)
    assert compiled_inv["quaternion_norm_defect"].min() > 1e-6


def test_a_non_finite_body_shows_in_the_quaternion_norm_defect():
    model = prepare(make_scene(random_bodies(3))).model
    q = np.tile([1.0, 0.0, 0.0, 0.0], (1, 3, 1))
    q[0, 1, 2] = math.nan  # the middle body: a running max that skipped NaN would report 0
    zeros = np.zeros((1, 3, 3))
    out = np.empty_like(q), np.empty_like(zeros), np.empty_like(zeros), np.empty((1, TOTALS_WIDTH))
    derive_outputs(model.body_mass, 1 / model.body_inertia, model.body_frame_q, zeros, q, zeros, zeros, *out)
    assert math.isnan(out[3][0, 7])
