"""What a run will cost before it runs: its CPU time estimated from measured costs per (sub-)step, and the
warning when it will take more than a minute (issue 47 item 3).

The estimate, in CPU seconds of one core, once the kernels are compiled (a first run of a new kind of
scene compiles first: docs/performance.md, "Start-up"):

    steps x sub-steps x (force evaluations x (COST_BODY B + COST_SPHERE S + COST_SHAPE P) + COST_ROW R)

B bodies, S contact spheres that touch (a shape body's lattice is its mass only), P contact shapes
(boxes and capsules that touch as themselves), R joint constraint rows (in joint coordinates, a reduced
integrator: COST_LINK per tree link and force evaluation instead of the rows and the links' COST_BODY,
forward kinematics and ABA at ~0.1-0.15 us a link: docs/trees.md); force evaluations per step of
the integrator (split2 1, rk4 4: its registry entry). The costs are what the shipped scenes measure on
the 2-core machine rbsim is developed on, warm, one thread (benchmarks/bench_run_cost.py prints the
estimate beside the measured time of each): a free body's split2 step ~0.1 us, a touching contact
sphere ~0.2 us (the 1,000-ball pile), a contact shape ~0.8 us (the box stack), a joint row ~0.7 us (the
RATTLE step's Newton, 0.45 us a row on a 10-link hinge chain to ~1 us with contact on the capsule
ragdoll). They say which minute a run takes, not its second: measured at 0.46-2.25 times the estimate
on nine shipped scenes (docs/contact.md, "What a run will cost"). An adaptive run's steps are chosen as
it goes: the estimate is its output grid's, a floor.

`rbsim validate` prints the estimate of every scene, `rbsim run` of a run estimated at SAY_FROM seconds
or more. A run estimated above LONG_RUN seconds is warned about at validation and at the start of `rbsim run`,
naming the largest term (the sub-steps and what sets them, the contact spheres, the shapes, the joint
rows or the steps themselves) and what would change it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from rbcli.scene.spec import SceneIssue

if TYPE_CHECKING:
    from rbcli.scene.compile import CompiledScene

COST_BODY = 0.1e-6  # [s] per body per force evaluation of a (sub-)step
COST_SPHERE = 0.2e-6  # [s] per touching contact sphere per force evaluation
COST_SHAPE = 0.8e-6  # [s] per contact shape (box, capsule) per force evaluation
COST_ROW = 0.7e-6  # [s] per joint constraint row per (sub-)step
COST_LINK = 0.15e-6  # [s] per tree link per force evaluation in joint coordinates (forward kinematics + ABA)
LONG_RUN = 60.0  # [s] of CPU: a run estimated above it is warned about
SAY_FROM = 1.0  # [s] of CPU: `rbsim run` says its estimate as it starts from this on (validate always does)


@dataclass(frozen=True)
class RunCost:
    """A run's estimated CPU time [s] and its parts (module docstring)."""

    seconds: float
    steps: int
    substeps: int
    parts: dict[str, float]  # [s] per driver: "bodies", "contact spheres", "contact shapes", "joint rows"
    counts: dict[str, int]  # the same drivers' counts
    adaptive: bool  # an adaptive run: the estimate is its output grid's, a floor

    def describe(self) -> str:
        """One line: `estimated run: ~2.3 CPU-s (3,000 steps x 22 sub-steps; joint rows 1.4 s, ...)`."""
        steps = f"{self.steps:,} steps" + (f" x {self.substeps} sub-steps" if self.substeps > 1 else "")
        parts = ", ".join(f"{name} {_duration(value)}" for name, value in self.largest() if value > 0.0)
        floor = "at least " if self.adaptive else ""
        return f"estimated run: {floor}~{_duration(self.seconds)} of CPU once compiled ({steps}; {parts})"

    def largest(self) -> list[tuple[str, float]]:
        return sorted(self.parts.items(), key=lambda item: -item[1])


def _duration(seconds: float) -> str:
    if seconds < 0.1:
        return f"{seconds:.2g} s"
    if seconds < 120.0:
        return f"{seconds:.2g} s" if seconds < 10.0 else f"{seconds:.0f} s"
    if seconds < 7200.0:
        return f"{seconds / 60.0:.0f} min"
    return f"{seconds / 3600.0:.1f} h"


def run_cost(compiled: CompiledScene) -> RunCost:
    """The estimate of the module docstring for a compiled scene and its run settings."""
    from rbcli.physics.contact.tables import touching_spheres
    from rbcli.physics.integrators import get_integrator

    settings, model = compiled.settings, compiled.model
    evaluations = max(1, get_integrator(settings.integrator).force_evals)
    counts = {"bodies": model.body_count, "contact spheres": 0, "contact shapes": 0, "joint rows": 0, "tree links": 0}
    if model.contact is not None:
        counts["contact spheres"] = touching_spheres(model.contact)
        counts["contact shapes"] = int(np.count_nonzero(model.contact.primitive_kind >= 0))
    if model.tree is not None:  # joint coordinates: every dynamic body a link, the joints hold by construction
        counts["tree links"] = int(model.tree.parent.shape[0])
        counts["bodies"] -= counts["tree links"]
    elif model.joint is not None:
        counts["joint rows"] = int(model.joint.row_count.sum())
    sub_steps = settings.steps * settings.substeps
    per = {"bodies": COST_BODY * evaluations, "contact spheres": COST_SPHERE * evaluations,
           "contact shapes": COST_SHAPE * evaluations, "joint rows": COST_ROW,
           "tree links": COST_LINK * evaluations}  # fmt: skip
    parts = {name: sub_steps * per[name] * counts[name] for name in counts}
    return RunCost(
        seconds=float(sum(parts.values())),
        steps=settings.steps,
        substeps=settings.substeps,
        parts=parts,
        counts=counts,
        adaptive=settings.tolerance is not None,
    )


def run_cost_warnings(compiled: CompiledScene) -> list[SceneIssue]:
    """A warning, at the scene's `contact` section (its sub-steps and stiffness) or else at its `dt`, when
    the run is estimated above LONG_RUN seconds: the estimate, its largest term and what would change it."""
    cost = run_cost(compiled)
    if not cost.seconds > LONG_RUN:
        return []
    name, value = cost.largest()[0]
    settings = compiled.settings
    drives = f"{name} ({cost.counts[name]:,}: {_duration(value)} of it)"
    changes = []
    if cost.substeps > 1 and compiled.contact is not None:
        contact = compiled.contact
        body = f", set by body '{contact.limiting_body}'" if contact.limiting_body else ""
        drives += (
            f", over {cost.substeps} sub-steps a step: the contacts' stable step is {contact.stable_step:.3g} s{body} "
            f"at {contact.stiffness:.3g} N/m"
        )
        changes.append("fewer sub-steps (a softer material stiffness, a lower drop or speed, or heavier light parts")
        from rbcli.physics.integrators import implicit_contact

        if not implicit_contact(settings.integrator):  # (docs/contact.md "Implicit contact")
            changes[-1] += (
                "; for a few contacts at once, as a ragdoll's, integrator: reduced-implicit, whose stiffness sets none"
            )
        changes[-1] += ")"
    if name == "contact spheres":
        changes.append("fewer contact spheres (a larger spacing, or `shape:` bodies that touch as their boxes and "
                       "capsules)")  # fmt: skip
    elif name == "joint rows":
        changes.append("fewer joints or bodies")
    elif name in ("bodies", "tree links"):
        changes.append("fewer bodies")
    changes.append(f"a shorter duration or a larger dt than {settings.dt:g} s")
    floor = "at least " if cost.adaptive else ""
    message = (
        f"the run is estimated at {floor}~{_duration(cost.seconds)} of CPU once compiled ({cost.steps:,} steps "
        f"x {cost.substeps} sub-steps), mostly {drives}"
    )
    section = compiled.spec.contact  # the sub-steps' and contacts' section, else the scene's dt
    location = section.location if section is not None else compiled.spec.simulation.location
    return [SceneIssue(location, message, "; or ".join(changes), severity="warning")]
