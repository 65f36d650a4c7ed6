"""Divergence: which body blew up, in which quantity, when, and the likely cause; and a guard that stops
a run whose bodies' energies jump by orders of magnitude between chunks, before they reach overflow.

The compiled chunks stop at the first recording step whose state is non-finite or above 1e100
(physics/step.py); `explain` reads that state (never recorded: the log ends at the last good frame) and
names the first body at fault by its scene name. Likely causes, the first that applies:
  the step is above the contacts' stable step (docs/contact.md);
  the step is above a spring's stability limit (the warning `rbsim validate` prints);
  explicit Euler (euler-matrix, euler-quat) on a body spinning fast for the step (|omega| dt > 0.5);
  otherwise the step is too large for the forces at play.
All arithmetic on the blown-up state runs under np.errstate(all="ignore"): no numpy warning reaches the
terminal, only rbsim's own message.
"""

from __future__ import annotations

import math

import numpy as np

from rbcli.physics.integrators import implicit_contact
from rbcli.scene.compile import CompiledScene

# a body's kinetic energy growing more than this factor between two chunk checks, above the floor
JUMP_FACTOR = 1e6
# the floor, per kg of the scene: 1e6 J/kg is a speed of 1.4 km/s, beyond any scene rbsim is built for
# (bodies at rest or kicked by an impulse grow from ~0 without tripping the guard)
FLOOR_PER_KG = 1e6
# the guard compares the recorded frames at multiples of this many steps (rounded up to whole
# recording intervals): a fixed grid, so a run stops at the same step however its chunks fall
GUARD_STEPS = 1000
FAST_SPIN = 0.5  # |omega| dt above which explicit Euler's energy gain per step is large
EXPLICIT_EULER = ("euler-matrix", "euler-quat")


def _angular_speed(compiled: CompiledScene, q: np.ndarray, L: np.ndarray) -> np.ndarray:
    """|omega| per body [rad/s], omega = R I^-1 R^T L (principal frame: R^T L then / I)."""
    from rbcli.physics.rotation import quat_rotate_inverse

    with np.errstate(all="ignore"):
        m = quat_rotate_inverse(q, L)
        return np.linalg.norm(m / compiled.model.body_inertia, axis=1)


def kinetic_energy(compiled: CompiledScene, q: np.ndarray, P: np.ndarray, L: np.ndarray) -> np.ndarray:
    """Kinetic energy per body [J], translation plus rotation."""
    from rbcli.physics.rotation import quat_rotate_inverse

    with np.errstate(all="ignore"):
        mass = compiled.model.body_mass
        m = quat_rotate_inverse(q, L)
        return 0.5 * (P * P).sum(axis=1) / mass + 0.5 * (m * m / compiled.model.body_inertia).sum(axis=1)


def explain(compiled: CompiledScene, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray, t: float) -> str:
    """'body <name>: <quantity> ... at t = ... s; likely cause: ...' for a diverged state."""
    names = compiled.model.body_names
    with np.errstate(all="ignore"):
        speed = np.linalg.norm(P, axis=1) / compiled.model.body_mass
        spin = _angular_speed(compiled, q, L)
        checks = [
            ("position", np.linalg.norm(x, axis=1), "m"),
            ("speed", speed, "m/s"),
            ("angular speed", spin, "rad/s"),
            ("orientation", np.abs(q).max(axis=1), ""),
        ]
        limit = 1e100
        culprit = None
        for b in range(len(names)):
            for quantity, values, unit in checks:
                value = float(values[b])
                if not math.isfinite(value) or value > limit:
                    culprit = (b, quantity, value, unit)
                    break
            if culprit is not None:
                break
        if culprit is None:  # no single value past the limit: the body with the largest kinetic energy
            energy = kinetic_energy(compiled, q, P, L)
            b = int(np.nanargmax(np.where(np.isfinite(energy), energy, np.inf)))
            culprit = (b, "kinetic energy", float(energy[b]), "J")
    b, quantity, value, unit = culprit
    shown = "not finite" if not math.isfinite(value) else f"{value:.3g} {unit}".strip()
    return f"body '{names[b]}': {quantity} {shown} at t = {t:.6g} s; likely cause: {likely_cause(compiled, b)}"


def likely_cause(compiled: CompiledScene, body: int) -> str:
    """The first known cause that applies to this scene and run settings (module docstring)."""
    settings = compiled.settings
    step = settings.dt / max(1, settings.substeps)
    contact = compiled.contact
    implicit = implicit_contact(settings.integrator)  # (its step is not bounded by the stable step)
    if contact is not None and settings.tolerance is None and step >= contact.stable_step and not implicit:
        return (f"the step {step:.3g} s is above the contacts' stable step {contact.stable_step:.3g} s: set "
                "contact.substeps: auto or a smaller dt")  # fmt: skip
    springs = [w for w in compiled.warnings if "stability limit" in w.message]
    if springs:
        where = f" ({springs[0].location})" if springs[0].location else ""
        return f"dt = {settings.dt:g} s is above a spring's stability limit{where}: use a smaller dt"
    if settings.integrator in EXPLICIT_EULER:
        initial = compiled.initial_state
        spin = _angular_speed(compiled, initial.q, initial.L)
        if float(spin[body]) * settings.dt > FAST_SPIN:
            rate = float(spin[body])
            return (f"{settings.integrator} (explicit Euler) gains energy on a body spinning at {rate:.3g} rad/s "
                    f"with dt = {settings.dt:g} s: use split2 or a smaller dt")  # fmt: skip
    return (f"dt = {settings.dt:g} s is too large for the forces at play with {settings.integrator}: try a "
            "smaller dt or split2 / rk4")  # fmt: skip


class EnergyGuard:
    """Stops a run whose bodies' kinetic energies jump by more than JUMP_FACTOR between two checks and
    above the floor (FLOOR_PER_KG x the body's mass); the runner checks recorded frames every
    GUARD_STEPS steps (O(bodies) numpy per check, negligible beside the steps between)."""

    def __init__(self, compiled: CompiledScene) -> None:
        self.compiled = compiled
        self.floor = FLOOR_PER_KG * compiled.model.body_mass
        self.previous: np.ndarray | None = None

    def check(self, q: np.ndarray, P: np.ndarray, L: np.ndarray) -> int | None:
        """The body that jumped (its index), or None; remembers this state's energies."""
        energy = kinetic_energy(self.compiled, q, P, L)
        previous, self.previous = self.previous, energy
        if previous is None:
            return None
        with np.errstate(all="ignore"):
            jumped = (energy > JUMP_FACTOR * previous) & (energy > self.floor)
        if not jumped.any():
            return None
        return int(np.flatnonzero(jumped)[0])
