"""The scene's `contact:` section and the bodies' contact keys, validated into ContactSpec / MaterialSpec.

The schema has checked types and ranges (restitution in [0.01, 1] included); this adds what it cannot
say: a plane normal of zero length, a container with min >= max, a static body given a velocity, a
particle body without radii (a contact sphere needs one). Every problem is located.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from rbcli.scene.issues import IssueCollector
from rbcli.scene.spec import BodySpec, ContactSpec, KinematicSpec, MaterialSpec, PlaneSpec
from rbcli.scene.yaml_located import YamlPath


def material_from_mapping(value: dict[str, Any] | None, path: YamlPath, issues: IssueCollector) -> MaterialSpec:
    """A MaterialSpec from a `material:` mapping (missing keys: None, inherited)."""
    if not value:
        return MaterialSpec()
    stiffness = value.get("stiffness")
    # the schema holds restitution to [LOWEST_RESTITUTION, 1] (one rule: tests/scene/test_scene_contact_keys.py
    # checks that its minimum is this constant), so a value here is in range
    restitution = value.get("restitution")
    return MaterialSpec(
        stiffness=None if stiffness in (None, "auto") else float(stiffness),
        restitution=None if restitution is None else float(restitution),
        friction=None if value.get("friction") is None else float(value["friction"]),
    )


def kinematic_from_mapping(value: dict[str, Any], path: YamlPath, issues: IssueCollector) -> KinematicSpec | None:
    """The KinematicSpec of a `kinematic: {velocity, angular_velocity, pivot, schedule}` mapping (the schema
    has checked the keys and types); None, with a located error, for a schedule that cannot be."""
    from rbcli.scene.force_specs import schedule_from_mapping

    schedule = None
    if value.get("schedule") is not None:
        try:
            schedule = schedule_from_mapping(value["schedule"])
        except (TypeError, ValueError) as exc:
            issues.error((*path, "schedule"), str(exc), "a schedule as in a force's (docs/forces.md)")
            return None
    return KinematicSpec(
        velocity=_vector(value.get("velocity", [0.0, 0.0, 0.0])),
        angular_velocity=_vector(value.get("angular_velocity", [0.0, 0.0, 0.0])),
        pivot=_vector(value["pivot"]) if value.get("pivot") is not None else None,
        schedule=schedule,
    )


def _vector(value: Any) -> np.ndarray:
    out = np.asarray(value, dtype=float).reshape(3)
    out.flags.writeable = False
    return out


def _plane(point: Any, normal: Any, material: MaterialSpec, path: YamlPath, issues: IssueCollector) -> PlaneSpec | None:
    n = np.asarray(normal, dtype=float)
    length = float(np.linalg.norm(n))
    if not length > 0.0 or not np.isfinite(length):
        issues.error((*path, "normal"), "a plane normal of zero length has no direction", "a non-zero vector")
        return None
    return PlaneSpec(_vector(point), _vector(n / length), material, issues.locate(path))


def contact_from_mapping(
    section: dict[str, Any], issues: IssueCollector, clean: Callable[[YamlPath], bool] = lambda path: True
) -> ContactSpec | None:
    """ContactSpec of the `contact:` mapping; None when it has errors (they are in `issues`). `clean(path)`
    is False for a part with schema errors (already reported): that part is not read, the others are."""
    path: YamlPath = ("contact",)
    before = issues.error_count
    if not all(clean((*path, key)) for key in section):
        before = -1  # a part has schema errors: check the others, return None
    planes: list[PlaneSpec | None] = []
    ground = section.get("ground")
    if ground is not None and clean((*path, "ground")):
        entry = ground if isinstance(ground, dict) else {"height": ground}
        material = material_from_mapping({k: entry[k] for k in ("restitution", "friction") if k in entry},
                                         (*path, "ground"), issues)  # fmt: skip
        planes.append(_plane([0.0, 0.0, float(entry.get("height", 0.0))], [0.0, 0.0, 1.0], material,
                             (*path, "ground"), issues))  # fmt: skip
    for i, entry in enumerate(section.get("planes", []) if clean((*path, "planes")) else []):
        if not clean((*path, "planes", i)):
            continue
        material = material_from_mapping({k: entry[k] for k in ("restitution", "friction") if k in entry},
                                         (*path, "planes", i), issues)  # fmt: skip
        planes.append(
            _plane(entry.get("point", [0.0, 0.0, 0.0]), entry["normal"], material, (*path, "planes", i), issues)
        )
    box = section.get("container")
    if box is not None and clean((*path, "container")):
        lo, hi = np.asarray(box["min"], dtype=float), np.asarray(box["max"], dtype=float)
        cpath = (*path, "container")
        if not np.all(lo < hi):
            issues.error((*cpath, "max"), f"container max {hi.tolist()} is not above min {lo.tolist()} on every axis",
                         "max > min in x, y and z")  # fmt: skip
        else:
            material = material_from_mapping(
                {k: box[k] for k in ("restitution", "friction") if k in box}, cpath, issues
            )
            walls = [(lo, (0, 0, 1)), (lo, (1, 0, 0)), (hi, (-1, 0, 0)), (lo, (0, 1, 0)), (hi, (0, -1, 0))]
            if box.get("lid", False):
                walls.append((hi, (0, 0, -1)))
            planes.extend(_plane(point, normal, material, cpath, issues) for point, normal in walls)
    material = material_from_mapping(section.get("material") if clean((*path, "material")) else None,
                                     (*path, "material"), issues)  # fmt: skip
    substeps = section.get("substeps", 1) if clean((*path, "substeps")) else 1
    if issues.error_count > before or before < 0:
        return None
    return ContactSpec(
        planes=tuple(p for p in planes if p is not None),
        material=material,
        substeps=None if substeps == "auto" else int(substeps),
        primitives=bool(section.get("primitives", True)) if clean((*path, "primitives")) else True,
        location=issues.locate(path, key=True),
    )


def check_contact_bodies(bodies: list[BodySpec], entries: list[Any], issues: IssueCollector) -> None:
    """Errors for bodies that cannot take part in contact as written (located at their entry)."""
    for body in bodies:
        if body.location is None:
            continue
        if body.static and (body.velocity is not None or body.momentum is not None
                            or body.angular_velocity is not None or body.angular_momentum is not None):  # fmt: skip
            issues.issues.append(_located(body, "a static body never moves, so it cannot have a velocity or momentum",
                                          "static: true without velocity, momentum or angular terms"))  # fmt: skip
        if body.static and body.kinematic:
            message = "a body is static (never moves) or kinematic (moves as given), not both"
            issues.issues.append(_located(body, message, "static: true or kinematic: true"))
        if body.kinematic_motion is not None and (body.velocity is not None or body.momentum is not None
                                                  or body.angular_velocity is not None
                                                  or body.angular_momentum is not None):  # fmt: skip
            issues.issues.append(_located(body, "a kinematic body with a prescribed motion takes its velocities "
                                          "from `kinematic:` only", "velocity and angular_velocity inside "
                                          "kinematic: {...}, none beside it"))  # fmt: skip
        if body.kinematic and body.angular_momentum is not None:
            issues.issues.append(_located(body, "a kinematic body spins at a given angular velocity",
                                          "angular_velocity instead of angular_momentum"))  # fmt: skip
        if body.collide and body.contact_geometry == "particles" and body.particle_radius is None:
            issues.issues.append(_located(body, "contact needs a radius for each particle (particles.radius)",
                                          "particles.radius, a shape, or collide: false"))  # fmt: skip
    _ = entries


def _located(body: BodySpec, message: str, expected: str):  # noqa: ANN202
    from rbcli.scene.spec import SceneIssue

    return SceneIssue(body.location, f"body '{body.name}': {message}", expected)
