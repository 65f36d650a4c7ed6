"""Invariants of the motion: energies and momenta, vectorised over frames and bodies.

T = sum_b (|P_b|^2 / (2 M_b) + L_b . omega_b / 2);  V from the conservative force terms;
P_total = sum_b P_b;  L_origin = sum_b (x_b x P_b + L_b) (about the world origin);
quaternion_norm_defect = max_b | |q_b| - 1 | of the state (orthonormality of R = R(q) follows from it).
For a free body these are exact constants of motion; their drift measures an integrator.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.forces import ForceTables
from rbcli.physics.forces.wrench import potential_energy
from rbcli.physics.model import Model
from rbcli.physics.outputs import TOTAL_ANGULAR_MOMENTUM, TOTAL_KINETIC, TOTAL_MOMENTUM, TOTAL_QUATERNION_DEFECT

INVARIANT_NAMES = (
    "energy_kinetic",
    "energy_potential",
    "energy_total",
    "momentum_x",
    "momentum_y",
    "momentum_z",
    "angular_momentum_x",
    "angular_momentum_y",
    "angular_momentum_z",
    "angular_momentum_norm",
    "quaternion_norm_defect",
)

# added for scenes with contact, of the recorded state (physics/contact/state.py): its contacts, the
# deepest overlap [m], the energy stored in the contact springs [J] (also counted in energy_potential
# and energy_total, so a bounce does not look like a loss of energy while the springs hold it), and the
# contacts so far whose tangential history found no free slot (cumulative; their friction restarted)
CONTACT_INVARIANT_NAMES = ("contact_count", "contact_max_overlap", "contact_energy", "contact_history_overflow")

# added for scenes with joints: the largest constraint violation over every joint row of the frame's
# state, in position |g| [m or rad] and velocity |G V| [m/s or rad/s] (physics/joints/violation.py)
JOINT_INVARIANT_NAMES = ("joint_position_violation", "joint_velocity_violation")


def kinetic_energy(model: Model, P: np.ndarray, L: np.ndarray, omega: np.ndarray) -> np.ndarray:
    """Total kinetic energy [J] per frame, (K,): sum_b |P_b|^2/(2 M_b) + L_b . omega_b / 2."""
    return (np.einsum("kbi,kbi->kb", P, P) / (2.0 * model.body_mass)).sum(-1) + 0.5 * np.einsum("kbi,kbi->k", L, omega)


def invariants(
    model: Model, forces: ForceTables, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray,
    omega: np.ndarray,
) -> dict[str, np.ndarray]:  # fmt: skip
    """Invariant time series for frames of shape (K, body_count, ...); each value has shape (K,)."""
    return invariants_from_kinetic(model, forces, x, q, P, L, kinetic_energy(model, P, L, omega))


def invariants_from_totals(
    model: Model, forces: ForceTables, x: np.ndarray, q: np.ndarray, totals: np.ndarray
) -> dict[str, np.ndarray]:
    """As `invariants`, from the per-frame sums (K, 8) of the compiled `outputs.derive_outputs`;
    only the potential energy is computed here."""
    kinetic, potential = totals[:, TOTAL_KINETIC], potential_energy(model, forces, x, q)
    momentum, ang = totals[:, TOTAL_MOMENTUM], totals[:, TOTAL_ANGULAR_MOMENTUM]
    return _named(kinetic, potential, momentum, ang, totals[:, TOTAL_QUATERNION_DEFECT])


def invariants_from_kinetic(
    model: Model, forces: ForceTables, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray,
    kinetic: np.ndarray,
) -> dict[str, np.ndarray]:  # fmt: skip
    """As `invariants`, given the total kinetic energy per frame (K,) already computed."""
    potential = potential_energy(model, forces, x, q)
    momentum = P.sum(axis=1)
    # sum_b x_b x P_b + L_b, written out: np.cross on (K, N, 3) is several times slower
    ang = np.stack(
        [
            (x[..., 1] * P[..., 2] - x[..., 2] * P[..., 1]).sum(1),
            (x[..., 2] * P[..., 0] - x[..., 0] * P[..., 2]).sum(1),
            (x[..., 0] * P[..., 1] - x[..., 1] * P[..., 0]).sum(1),
        ],
        axis=-1,
    ) + L.sum(axis=1)
    return _named(kinetic, potential, momentum, ang, np.abs(np.linalg.norm(q, axis=-1) - 1.0).max(axis=-1))


def _named(
    kinetic: np.ndarray, potential: np.ndarray, momentum: np.ndarray, ang: np.ndarray, defect: np.ndarray
) -> dict[str, np.ndarray]:
    """The INVARIANT_NAMES series (each (K,), contiguous) from their parts."""
    series = {
        "energy_kinetic": kinetic,
        "energy_potential": potential,
        "energy_total": kinetic + potential,
        "momentum_x": momentum[:, 0],
        "momentum_y": momentum[:, 1],
        "momentum_z": momentum[:, 2],
        "angular_momentum_x": ang[:, 0],
        "angular_momentum_y": ang[:, 1],
        "angular_momentum_z": ang[:, 2],
        "angular_momentum_norm": np.linalg.norm(ang, axis=-1),
        "quaternion_norm_defect": defect,
    }
    return {name: np.ascontiguousarray(series[name], dtype=np.float64) for name in INVARIANT_NAMES}
