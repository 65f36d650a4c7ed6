"""The total wrench of all force terms on every body: the one function integrators call."""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics.forces import ForceTables
from rbcli.physics.forces.gravity import accumulate_gravity, gravity_potential


@numba.njit(cache=True)
def accumulate_wrench(model, forces, t, x, q, P, L, F, tau) -> None:  # noqa: ANN001 - numba types
    """Set F [N] and tau [N m] (body_count, 3), world frame, to the sum of the scene's force terms."""
    F[:, :] = 0.0
    if forces.has_torque:
        tau[:, :] = 0.0
    if forces.has_gravity:
        accumulate_gravity(model.body_mass, forces.gravity, F)


def wrench_numpy(model, forces: ForceTables, t: float, x, q, P, L) -> tuple[np.ndarray, np.ndarray]:  # noqa: ANN001
    """Plain numpy reference of `accumulate_wrench` (tests)."""
    F = np.zeros_like(x)
    tau = np.zeros_like(x)
    if forces.has_gravity:
        F += model.body_mass[:, None] * forces.gravity
    return F, tau


def potential_energy(model, forces: ForceTables, x: np.ndarray, q: np.ndarray) -> np.ndarray:  # noqa: ANN001
    """Total potential energy [J] of the conservative terms; x: (..., body_count, 3) -> (...)."""
    V = np.zeros(x.shape[:-2])
    if forces.has_gravity:
        V = V + gravity_potential(model.body_mass, forces.gravity, x).sum(axis=-1)
    return V
