"""The compiled output derivation equals its numpy twins (frames.py, energy.py) to round-off."""

import numpy as np
from conftest import make_scene, random_bodies

from rbcli.api import prepare
from rbcli.physics.energy import kinetic_energy
from rbcli.physics.frames import body_angular_velocity, body_velocity, user_orientation
from rbcli.physics.outputs import derive_outputs
from rbcli.physics.rotation import quat_normalize


def test_compiled_outputs_match_numpy_references():
    model = prepare(make_scene(random_bodies(9))).model
    rng = np.random.default_rng(3)
    q = quat_normalize(rng.normal(size=(4, 9, 4)))
    P, L = rng.normal(size=(4, 9, 3)), rng.normal(size=(4, 9, 3))
    q_user, v, omega, kin = np.empty_like(q), np.empty_like(P), np.empty_like(L), np.empty((4, 9))
    derive_outputs(model.body_mass, 1 / model.body_inertia, model.body_frame_q, q, P, L, q_user, v, omega, kin)
    np.testing.assert_allclose(q_user, user_orientation(model, q), atol=1e-15)
    np.testing.assert_allclose(v, body_velocity(model, P), rtol=1e-15)
    np.testing.assert_allclose(omega, body_angular_velocity(model, q, L), rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(kin.sum(1), kinetic_energy(model, P, L, omega), rtol=1e-13)
