"""Uniform gravity: F = M g at the centre of mass, no torque; potential V = -M g . x."""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics import kernel_cache

kernel_cache.install()  # before this module's kernels first run: their cache is keyed on the physics sources


@numba.njit(cache=True)
def accumulate_gravity(body_mass: np.ndarray, gravity: np.ndarray, F: np.ndarray) -> None:
    """F_b += M_b g for every body."""
    for b in range(F.shape[0]):
        for k in range(3):
            F[b, k] += body_mass[b] * gravity[k]


def gravity_potential(body_mass: np.ndarray, gravity: np.ndarray, x: np.ndarray) -> np.ndarray:
    """V = -M g . x [J] per body (leading axes of x kept: (..., body_count))."""
    return -body_mass * np.einsum("...bk,k->...b", x, gravity)
