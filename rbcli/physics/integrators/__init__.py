"""Registry of integrators: metadata here (cheap to import), kernels loaded on demand.

Every integrator module defines
  step(model, forces, t, dt, x, q, P, L, F, tau, scratch)   # numba njit, in place, all bodies
  step_numpy(model, forces, t, dt, x, q, P, L)               # plain numpy reference, in place
and `SCRATCH_WIDTH`, the float64 scratch columns per body its compiled step needs.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import ModuleType


@dataclass(frozen=True)
class IntegratorInfo:
    """What a user needs to choose an integrator: order, structure, conservation, cost."""

    name: str
    module: str
    order: int
    symplectic: bool
    conserves: str
    force_evals: int
    summary: str

    def load(self) -> ModuleType:
        """Import the kernel module (pulls in numba)."""
        return importlib.import_module(self.module)


_PKG = "rbcli.physics.integrators"

INTEGRATORS: dict[str, IntegratorInfo] = {
    info.name: info
    for info in [
        IntegratorInfo(
            "euler-matrix",
            f"{_PKG}.euler_matrix",
            order=1,
            symplectic=False,
            conserves="L (torque-free), P (force-free)",
            force_evals=1,
            summary="The tutorial's explicit Euler on x, P, R, L with Gram-Schmidt (baseline).",
        ),
    ]
}

DEFAULT_INTEGRATOR = "euler-matrix"


def get_integrator(name: str) -> IntegratorInfo:
    """Look an integrator up by name; KeyError lists the known ones."""
    try:
        return INTEGRATORS[name]
    except KeyError:
        raise KeyError(f"unknown integrator {name!r}; known: {', '.join(INTEGRATORS)}") from None


def integrator_names() -> tuple[str, ...]:
    return tuple(INTEGRATORS)
