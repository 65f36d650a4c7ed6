"""Which recorded invariants (physics/energy.py) a scene's own force terms keep constant.

A kept quantity changes in a run only by the integrator's error, so its change is a drift that measures
the method; any other quantity is changed by the forces themselves (momentum under gravity, energy under
drag), and its change says nothing about accuracy. The rules follow from the exact motion under the
scene's terms, with F_ext and tau_ext the total external force and torque about the world origin:

- energy_total (T + V): kept when every term has a potential that V counts (forces/wrench.py
  potential_energy): gravity, springs without damping, fields with a symmetric gradient and no schedule,
  unscheduled world-frame point forces. Body-frame or scheduled forces, pure torques, drag, impulses
  and contact (damping, friction, moving kinematic bodies) do work that no potential accounts for.
- energy_kinetic: kept only without any term; energy_potential: kept (at 0) when no term has a
  potential (gravity, springs, fields, point forces, contact springs).
- momentum_i, the total momentum's component i: dP/dt = F_ext. Gravity adds M g, so P_i is kept when
  g_i = 0; a spring between two bodies pulls both ends equally and oppositely, and a pure torque adds no
  force. Every other term (anchored springs, fields, point forces, drag, impulses, contact) changes all
  three components.
- angular_momentum_i about the origin: dL/dt = tau_ext. Gravity's torque is M x_com x g, whose component
  along e_i vanishes for every position only when g is along e_i (g_j = 0 for j != i); spring pair forces
  are equal, opposite and along the line joining their ends, so their torques cancel. The norm is kept
  when all three components are.
- quaternion_norm_defect is |q| - 1, zero in the exact motion under any force: always a drift.
- Joints (ideal constraints) do no work, so they leave energy_total as the forces make it, unless a joint
  has a damper, a motor (work done by the drive) or limits (a stop is inelastic); a joint to the
  world or to a static or kinematic body is an external force and torque (momentum and angular momentum
  change), while joints between moving bodies act equally and oppositely at one point and keep both. The
  joint violations (joint_position_violation, joint_velocity_violation) are zero in the exact motion:
  always a drift.
- Anything else (the contact series) is a changing quantity, not an invariant.

When a rule cannot tell (contact between free bodies alone would keep momentum), it says "changed": a
kept quantity shown as a change hides nothing alarming, while a changing one shown as a drift reads as a
failure.
"""

from __future__ import annotations

import numpy as np

from rbcli.physics.forces import ForceTables, force_terms_present
from rbcli.physics.forces.field import field_is_conservative
from rbcli.physics.forces.point_force import point_force_is_conservative
from rbcli.physics.model import Model


def conserved_invariants(model: Model, forces: ForceTables, names: tuple[str, ...] | list[str]) -> dict[str, bool]:
    """For each invariant name, True when the scene's force terms (its force tables, and the model's
    contact and joints) keep it constant (module docstring)."""
    terms = set(force_terms_present(forces, model.contact))
    g = np.asarray(forces.gravity, dtype=np.float64) if "gravity" in terms else np.zeros(3)
    internal_springs = "spring" not in terms or bool(np.all(forces.spring.body_b >= 0))
    # a term that can add a net external force (and torque) in any direction
    external = bool(terms - {"gravity", "spring", "torque"}) or not internal_springs
    joint = model.joint
    if joint is not None:
        ends = np.concatenate([joint.body_a, joint.body_b[joint.body_b >= 0]])
        external = external or bool(np.any(joint.body_b < 0) or np.any(joint.body_ground[ends]))
    force_free = not external  # apart from gravity (and pure torques, which add no force)
    torque_free = force_free and "torque" not in terms

    kept: dict[str, bool] = {}
    # joint dampers, motors and limit stops do work on the bodies
    driven = joint is not None and bool(
        np.any(joint.damping > 0.0) or np.any(joint.motor_cap > 0.0)
        or np.any(np.isfinite(joint.limit_lower)) or np.any(np.isfinite(joint.limit_upper))
        or np.any(joint.cone[:, 8:] > 0.0)
    )  # fmt: skip
    kept["energy_total"] = _conservative(forces, terms) and not driven
    kept["energy_kinetic"] = not terms and not driven
    kept["energy_potential"] = not (terms & {"gravity", "spring", "field", "point_force", "contact"})
    for i, axis in enumerate("xyz"):
        kept[f"momentum_{axis}"] = force_free and g[i] == 0.0
        along_axis = all(g[j] == 0.0 for j in range(3) if j != i)
        kept[f"angular_momentum_{axis}"] = torque_free and along_axis
    kept["angular_momentum_norm"] = all(kept[f"angular_momentum_{axis}"] for axis in "xyz")
    kept["quaternion_norm_defect"] = True
    kept["joint_position_violation"] = kept["joint_velocity_violation"] = True
    return {name: kept.get(name, False) for name in names}


def _conservative(forces: ForceTables, terms: set[str]) -> bool:
    """Every term has a potential, as `forces.wrench.potential_energy` counts them: gravity, undamped
    springs, unscheduled fields with a symmetric gradient, unscheduled world-frame point forces."""
    if terms - {"gravity", "spring", "field", "point_force"}:
        return False
    if "spring" in terms and np.any(forces.spring.damping != 0.0):
        return False
    if "field" in terms and not np.all(field_is_conservative(forces.field)):
        return False
    return not ("point_force" in terms and not np.all(point_force_is_conservative(forces.point_force)))
