"""`exact4`: Suzuki's fourth-order composition of `exact` (see split4 for the weights and why).

E4(h) = E(p h) E(p h) E((1 - 4p) h) E(p h) E(p h), p = 1 / (4 - 4^(1/3)) (Suzuki 1990). Torque-free it
is as exact as `exact` (to round-off); with forces the splitting error drops to fourth order for five
force evaluations and six exact free flows per step. With dampers or drag each stage's kick is
K_c(h/2) Dis(h) K_c(h/2) (exact.compose, forces/damping.py): the stages stay symmetric, so the
composition keeps order 4 on damped scenes (a kick with the dampers inside made it first order).
"""

from __future__ import annotations

import numba

from rbcli.physics.integrators import exact
from rbcli.physics.integrators.split4 import WEIGHTS
from rbcli.physics.step import STEP_ENTRY

SCRATCH_WIDTH = exact.SCRATCH_WIDTH


@numba.njit(**STEP_ENTRY)
def step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch) -> None:  # noqa: ANN001 - numba types
    """One exact4 step of every body, in place (five force evaluations)."""
    exact.compose(model, forces, contact, force_data, t, dt, WEIGHTS, x, q, P, L, F, tau, scratch)


def step_numpy(model, forces, t, dt, x, q, P, L) -> None:  # noqa: ANN001
    """Numpy reference of `step`."""
    exact.compose_numpy(model, forces, t, dt, WEIGHTS, x, q, P, L)
