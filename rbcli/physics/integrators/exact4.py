"""`exact4`: Suzuki's fourth-order composition of `exact` (see split4 for the weights and why).

E4(h) = E(p h) E(p h) E((1 - 4p) h) E(p h) E(p h), p = 1 / (4 - 4^(1/3)) (Suzuki 1990). Torque-free it
is as exact as `exact` (to round-off); with forces the splitting error drops to fourth order for five
force evaluations and six exact free flows per step.
"""

from __future__ import annotations

import numba

from rbcli.physics.integrators import exact
from rbcli.physics.integrators.split4 import WEIGHTS
from rbcli.physics.step import CHUNK_KERNEL, STATUS_OK, chunk_status, record_if_due

SCRATCH_WIDTH = exact.SCRATCH_WIDTH


@numba.njit(cache=True)
def step(model, forces, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One exact4 step of every body, in place (five force evaluations)."""
    exact.compose(model, forces, t, dt, WEIGHTS, x, q, P, L, F, tau, scratch)


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Numpy reference of `step`."""
    exact.compose_numpy(model, forces, t, dt, WEIGHTS, x, q, P, L)


@numba.njit(**CHUNK_KERNEL)
def run_chunk(model, forces, dt, step0, n_steps, record_every, x, q, P, L, F, tau, scratch, frames, filled):  # noqa: ANN001
    """n_steps of `step` with recording (the chunk loop of physics/step.py, one per module for caching)."""
    for k in range(n_steps):
        step(model, forces, (step0 + k) * dt, dt, x, q, P, L, F, tau, scratch)
        filled, stop = record_if_due(step0 + k + 1, record_every, x, q, P, L, frames, filled)
        if stop != STATUS_OK:
            return k + 1, filled, stop
    return n_steps, filled, chunk_status(x, q, P, L)
