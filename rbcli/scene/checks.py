"""Physics sanity checks on a compiled scene that are warnings, not errors: a dt too large for a spring
or for the contacts, and an integrator that is a poor match for contact.

A spring of stiffness k between a body point and the world (or another body) is an oscillator of
angular frequency omega = sqrt(k / m_eff), with 1/m_eff = sum over its body ends of 1/M + |r|^2 / I_min
(r: the point's offset from the centre of mass; I_min: the smallest principal moment — the stiffest
way the point can move, a conservative bound). Explicit and splitting integrators (leapfrog, split2)
are stable only for omega dt < 2 (Hairer, Lubich & Wanner, Geometric Numerical Integration, I.5.4 for
Stormer-Verlet), and resolve the motion only well below it (~10 steps per period).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from rbcli.physics.contact.parameters import (
    DEPTH_FRACTION,
    MAX_AUTO_SUBSTEPS,
    SUBSTEP_SAFETY,
    TRAVEL_FRACTION,
    substeps_needed,
    travel_step,
)
from rbcli.physics.integrators import implicit_contact
from rbcli.scene.force_specs import BodyPoint, ForceSpring
from rbcli.scene.spec import SceneIssue

if TYPE_CHECKING:  # for the annotations only: compile.py runs these checks (CompiledScene.warnings)
    from rbcli.scene.compile import CompiledScene


def _inverse_effective_mass(compiled: CompiledScene, end: BodyPoint) -> float:
    spec, model = compiled.simulated_spec, compiled.model  # welds merged: the model's bodies
    b = model.body_names.index(end.body)
    body = spec.bodies[b]
    start = int(model.body_particle_start[b])
    centre = body.particle_position[0] - model.particle_offset_user[start]  # centre of mass, user frame
    if end.particle is not None:
        point = body.particle_position[end.particle]
    elif end.point is not None:
        point = np.asarray(end.point, dtype=np.float64)
    else:
        point = centre
    r2 = float(np.sum((point - centre) ** 2))
    return 1.0 / model.body_mass[b] + r2 / float(model.body_inertia[b].min())


def contact_warnings(compiled: CompiledScene) -> list[SceneIssue]:
    """The contacts' stable step against the (sub-)step that runs; euler-matrix with contact."""
    contact, spec = compiled.contact, compiled.spec
    if contact is None or spec.contact is None:
        return []
    issues = []
    step = compiled.settings.dt / compiled.settings.substeps
    # with a tolerance dt is only the output spacing: the adaptive steps stay under the stable step
    # an implicit contact step (reduced-implicit) is stable at any stiffness: no stable step to keep
    implicit = implicit_contact(compiled.settings.integrator)
    if compiled.settings.tolerance is None and step >= contact.stable_step and not implicit:
        substeps = f" ({compiled.settings.substeps} sub-steps)" if compiled.settings.substeps > 1 else ""
        issues.append(
            SceneIssue(
                spec.contact.location,
                f"the step {step:.3g} s{substeps} is above the contacts' stable step {contact.stable_step:.3g} s "
                f"(body '{contact.limiting_body}', stiffness {contact.stiffness:.3g} N/m per contact sphere): "
                "contacts will gain energy and bodies pass through each other",
                "contact.substeps: auto (sub-steps chosen from the stable step), a smaller dt, or a lower "
                "material stiffness",
                severity="warning",
            )
        )
    issues += impact_warnings(compiled)
    if compiled.settings.integrator == "euler-matrix":
        issues.append(
            SceneIssue(
                spec.contact.location,
                "euler-matrix (explicit Euler, the tutorial's) gains energy in every contact: bounces grow and "
                "resting bodies jitter",
                "integrator: split2 (the default with contact) or semi-implicit",
                severity="warning",
            )
        )
    return issues


def impact_warnings(compiled: CompiledScene) -> list[SceneIssue]:
    """Impacts the contacts cannot take (scene/contact_speed.py): the speed bound of a body whose spheres
    would go deeper than DEPTH_FRACTION r, and `substeps: auto` capped at MAX_AUTO_SUBSTEPS below what its
    travel and stability rules need. Each names the speed and the speed that the scene does take."""
    contact, spec, settings = compiled.contact, compiled.spec, compiled.settings
    if contact is None or spec.contact is None or contact.impact is None or settings.tolerance is not None:
        return []
    impact = contact.impact
    issues = []
    deep = impact.deep
    if deep is not None:
        others = f" ({deep.count - 1} more bod{'y' if deep.count == 2 else 'ies'} too)" if deep.count > 1 else ""
        issues.append(
            SceneIssue(
                spec.contact.location,
                f"body '{deep.body}' can hit at up to {deep.speed:.3g} m/s (its initial speed and fall): with "
                f"{deep.stiffness:.3g} N/m per contact sphere, a sphere landing first may go {deep.depth:.2g} "
                f"radii deep, more than {DEPTH_FRACTION:g}{others}; this stiffness takes {deep.speed_taken:.3g} m/s",
                f"a material stiffness of at least {deep.stiffness_needed:.3g} N/m for that body (with substeps: "
                "auto), or a lower speed or drop",
                severity="warning",
            )
        )
    if spec.contact.substeps is None:
        travel = travel_step(impact.speed, impact.radius)
        needed = substeps_needed(settings.dt, contact.stable_step, travel)
        if needed > MAX_AUTO_SUBSTEPS:
            h = settings.dt / MAX_AUTO_SUBSTEPS
            taken = TRAVEL_FRACTION * impact.radius / h
            stable = SUBSTEP_SAFETY * contact.stable_step
            why = (f"body '{impact.body}' can move at up to {impact.speed:.3g} m/s and its spheres may move "
                   f"{TRAVEL_FRACTION:g} of the smallest radius, {impact.radius:.3g} m, per sub-step")  # fmt: skip
            if h <= stable:  # stable at the cap: the travel rule asks for more, and the cap sets the speed
                why += f"; at {MAX_AUTO_SUBSTEPS:,} sub-steps it takes {taken:.3g} m/s"
            else:
                why += f", and the contacts' stable step is {contact.stable_step:.3g} s"
            issues.append(
                SceneIssue(
                    spec.contact.location,
                    f"substeps: auto would need {needed:,} sub-steps per step of {settings.dt:.3g} s ({why}); it "
                    f"stops at {MAX_AUTO_SUBSTEPS:,}, so contacts may be missed or unstable",
                    "a smaller dt, lower speeds, or a softer material",
                    severity="warning",
                )
            )
    return issues


def stability_warnings(compiled: CompiledScene) -> list[SceneIssue]:
    """One warning per spring whose oscillation the scene's dt cannot follow stably (omega dt >= 2), and
    the contact warnings (`contact_warnings`)."""
    dt = compiled.settings.dt
    issues = contact_warnings(compiled)
    for force in compiled.simulated_spec.forces:  # the springs as simulated (welded ends re-expressed)
        if not isinstance(force, ForceSpring) or force.stiffness <= 0.0:
            continue
        inv_mass = _inverse_effective_mass(compiled, force.end_a)
        if force.end_b is not None:
            inv_mass += _inverse_effective_mass(compiled, force.end_b)
        omega = float(np.sqrt(force.stiffness * inv_mass))
        limit = 2.0 / omega
        if dt >= limit:
            issues.append(
                SceneIssue(
                    force.location,
                    f"dt = {dt:g} s is above the stability limit 2/omega = {limit:.3g} s of this spring "
                    f"(omega = sqrt(k / m_eff) = {omega:.3g} rad/s): explicit and splitting integrators blow up",
                    f"dt below {limit:.3g} s, and about {2 * np.pi / omega / 10:.3g} s to resolve its period",
                    severity="warning",
                )
            )
    return issues
