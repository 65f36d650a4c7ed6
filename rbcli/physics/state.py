"""The state: struct of arrays over bodies, with world angular momentum L as the state variable.

x: centre of mass [m], (body_count, 3), world.  q: unit quaternion (w, x, y, z), (body_count, 4),
world-from-PRINCIPAL-frame (see model.py).  P: linear momentum [kg m/s], (body_count, 3), world.
L: angular momentum about the centre of mass [kg m^2/s], (body_count, 3), world.
step: step index; time is t = step * dt (never accumulated, so long runs keep exact times).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# The largest magnitude of any state component a run accepts (physics/step.py BLOWUP_LIMIT: a state beyond
# it counts as diverged); here, without numba, so that `validate` can refuse an initial state beyond it.
STATE_LIMIT = 1e100


@dataclass
class State:
    """Mutable simulation state (the integrators update the arrays in place)."""

    x: np.ndarray
    q: np.ndarray
    P: np.ndarray
    L: np.ndarray
    step: int = 0

    def copy(self) -> State:
        return State(self.x.copy(), self.q.copy(), self.P.copy(), self.L.copy(), self.step)
