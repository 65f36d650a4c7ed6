"""Force terms: each accumulates a wrench (F, tau) per body for a given state and time.

Force types are data: `ForceTables` holds one parameter table per type, empty (or switched off) when the
scene does not use it, so the compiled step does no work for terms a scene does not have. Adding a
force type = one module here with a compiled `accumulate_*` kernel (+ numpy reference and, when
conservative, a potential energy), one table field, and one line in `accumulate_wrench`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np


class ForceTables(NamedTuple):
    """Every force term of a scene as arrays (numba-friendly).

    gravity: uniform field [m/s^2], (3,), world; acts at the centre of mass, so no torque.
    has_gravity: False when the scene has no gravity (the term is skipped).
    has_torque: False when no term can produce a torque: integrators may skip the torque kick.
    """

    gravity: np.ndarray
    has_gravity: bool
    has_torque: bool


def build_force_tables(gravity: np.ndarray | None) -> ForceTables:
    """Tables for a scene's force terms (gravity only, so far)."""
    g = np.zeros(3) if gravity is None else np.asarray(gravity, dtype=np.float64).copy()
    return ForceTables(
        gravity=g, has_gravity=gravity is not None and bool(np.any(g != 0.0)), has_torque=False
    )


def force_terms_present(forces: ForceTables) -> tuple[str, ...]:
    """Names of the terms the compiled wrench will evaluate (for tests and `--verbose`)."""
    return ("gravity",) if forces.has_gravity else ()
