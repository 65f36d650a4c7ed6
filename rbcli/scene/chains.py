"""Chain generators, `bodies: - chain: {...}` (docs/scenes.md, "Chains"): links along a line, each joined
to the one before, expanded into the BodySpecs and JointSpecs the same scene written out by hand gives,
so nothing downstream (compile, contact, the joint stages, recording) knows a chain was generated.

With d = direction / |direction|, s = spacing and c = link_centre:

    link k   `<name>k`, centre of mass at start + (k + c) s d; the template's particles, orientation, motion
    joint k  `<prefix>k` (default prefix `<name>_joint`), bodies [<name>k, <name>(k-1)]; joint 0 holds
             [<name>0, attach] (a free chain, `attach: false`, has no joint 0). Ball, fixed, hinge and
             slider joints at the world point start + k s d; distance joints between the links' centres
             of mass (joint 0: link 0's and `start`, a point of `attach`)

The links are resolved in file order with the other bodies (`chain_links`); the joints once every body
is known (`chain_joints`): `attach` may name a body given further down.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from rbcli.physics.rotation import quat_rotate_inverse
from rbcli.scene.bodies import MAX_GENERATED_BODIES, BodyResolver
from rbcli.scene.issues import IssueCollector, did_you_mean
from rbcli.scene.joint_spec import MIN_AXIS_LENGTH, WORLD_NAME, JointSpec, joint_options
from rbcli.scene.shapes import mass_properties
from rbcli.scene.spec import BodySpec
from rbcli.scene.yaml_located import YamlPath

# where a link's centre of mass sits after its joint, as a fraction of the spacing: centred between joints
DEFAULT_LINK_CENTRE = 0.5


@dataclass(frozen=True)
class ChainPlan:
    """A resolved chain, what its joints need: `chain` is the entry's mapping at `path`; joint k's world
    point [m], shape (count, 3); the link's centre of mass in its own (user) frame [m], shape (3,)."""

    chain: dict[str, Any]
    path: YamlPath
    links: list[str]
    point: np.ndarray
    centre_user: np.ndarray
    attach: str | None  # WORLD_NAME, a body's name, or None for a free chain


def chain_links(
    resolver: BodyResolver, entry: dict[str, Any], path: YamlPath
) -> tuple[list[BodySpec], ChainPlan | None]:
    """The links of a schema-valid `{chain: {...}}` entry at `path` and its plan; ([], None) with its errors."""
    chain, cpath = entry["chain"], (*path, "chain")
    issues = resolver.issues
    count = int(chain["count"])
    if count > MAX_GENERATED_BODIES:
        issues.error((*cpath, "count"), f"{count:,} links is too many", f"at most {MAX_GENERATED_BODIES:,} links")
        return [], None
    direction = _direction(chain["direction"], (*cpath, "direction"), issues)
    proto = resolver.prototype(chain["template"], (*cpath, "template"))
    if proto is None or direction is None:
        return [], None
    start = np.asarray(chain.get("start", [0.0, 0.0, 0.0]), dtype=np.float64)
    spacing = float(chain["spacing"])
    k = np.arange(count, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        point = start + (k * spacing)[:, None] * direction
        centre = start + ((k + float(chain.get("link_centre", DEFAULT_LINK_CENTRE))) * spacing)[:, None] * direction
    if not (np.all(np.isfinite(point)) and np.all(np.isfinite(centre))):
        issues.error(cpath, "chain positions overflow", "start and spacing of sensible size", key=True)
        return [], None
    point.flags.writeable = centre.flags.writeable = False  # each link's position is a row (a read-only view)
    names = [f"{chain['name']}{i}" for i in range(count)]
    location = issues.locate(path)
    links = [
        dataclasses.replace(proto, name=name, position=c, location=location)
        for name, c in zip(names, centre, strict=True)
    ]
    attach = chain.get("attach", True)
    plan = ChainPlan(
        chain=chain,
        path=cpath,
        links=names,
        point=point,
        centre_user=_centre_user(proto),
        attach=WORLD_NAME if attach is True else None if attach is False else str(attach),
    )
    return links, plan


def chain_joints(
    plans: Sequence[ChainPlan], bodies: Sequence[BodySpec], issues: IssueCollector
) -> tuple[list[JointSpec], dict[str, YamlPath]]:
    """The joints of every chain, in chain order, and where each joint's name is given (for duplicates with
    the `joints:` list); a chain whose joints have errors gives none, its errors located in its entry."""
    by_name = {b.name: b for b in bodies}
    joints: list[JointSpec] = []
    given: dict[str, YamlPath] = {}
    for plan in plans:
        made = _joints_of(plan, by_name, issues)
        if made is None:
            continue
        name_path = (*plan.path, "joint", "name") if "name" in plan.chain["joint"] else (*plan.path, "name")
        clash = [j.name for j in made if j.name in given]
        if clash:
            line = issues.locate(given[clash[0]]).line
            more = f" and {len(clash) - 1:,} more" if len(clash) > 1 else ""
            issues.error(name_path, f"duplicate joint name '{clash[0]}'{more} (first at line {line})",
                         "a joint name prefix (`joint: {name: ...}`) no other joint's names start with")  # fmt: skip
            continue
        given.update((j.name, name_path) for j in made)
        joints.extend(made)
    return joints, given


def _joints_of(plan: ChainPlan, by_name: dict[str, BodySpec], issues: IssueCollector) -> list[JointSpec] | None:
    """One chain's JointSpecs (joint k holds link k to link k - 1, joint 0 link 0 to `attach`); None with
    located errors for its joint options or an `attach` that is no body, is ambiguous or is link 0."""
    chain, cpath = plan.chain, plan.path
    joint, jpath = chain["joint"], (*plan.path, "joint")
    before = issues.error_count
    options = joint_options(joint, jpath, issues)
    attach = plan.attach
    attach_path = (*cpath, "attach") if "attach" in chain else cpath
    if attach == WORLD_NAME and WORLD_NAME in by_name:
        issues.error(attach_path, f"a body is named '{WORLD_NAME}', so attaching to `{WORLD_NAME}` is ambiguous",
                     f"rename the body: '{WORLD_NAME}' names the fixed world frame in joints",
                     key="attach" not in chain)  # fmt: skip
    elif attach is not None and attach != WORLD_NAME and attach not in by_name:
        hint = did_you_mean(attach, [*by_name, WORLD_NAME])
        guess = f" (did you mean '{hint}'?)" if hint else ""
        issues.error(attach_path, f"no body named '{attach}'{guess}", f"a body name, '{WORLD_NAME}' or false")
    elif attach == plan.links[0]:
        issues.error(attach_path, f"link '{attach}' is attached to itself", "another body, the world or false")
    if options is None or issues.error_count > before:
        return None
    kind = str(joint["type"])
    prefix = str(joint.get("name", f"{chain['name']}_joint"))
    locations = _locations(plan, issues)
    location = issues.locate(jpath)
    centre = plan.centre_user
    between_links = _frozen(np.stack([centre, centre])) if kind == "distance" else None
    first = 0 if attach is not None else 1
    made = []
    for k in range(first, len(plan.links)):
        other = plan.links[k - 1] if k > 0 else attach
        assert other is not None
        anchor = anchors = None
        if kind != "distance":
            anchor = plan.point[k]
        elif k > 0:
            anchors = between_links
        else:
            anchors = _frozen(np.stack([centre, _attach_point(other, plan.point[0], by_name)]))
        made.append(JointSpec(
            name=f"{prefix}{k}", kind=kind, bodies=(plan.links[k], other), anchor=anchor, anchors=anchors,
            location=location, locations=locations, **options,
        ))  # fmt: skip
    return made


def _direction(value: Any, path: YamlPath, issues: IssueCollector) -> np.ndarray | None:
    """The unit direction of the chain; None with a located error for a zero (or overflowing) one."""
    v = np.asarray(value, dtype=np.float64)
    with np.errstate(over="ignore"):
        length = float(np.linalg.norm(v))
    if not length > MIN_AXIS_LENGTH:
        issues.error(path, f"a zero direction ({length:.3g}) gives the chain no line to run along", "a non-zero vector")
        return None
    if not math.isfinite(length):
        issues.error(path, "the direction's length overflows float64", "a direction of sensible size (any length)")
        return None
    return v / length


def _centre_user(body: BodySpec) -> np.ndarray:
    """A body's centre of mass in its own (user) frame [m], with the bits compile.py's model gets."""
    return mass_properties(body.particle_position, body.particle_mass, body.particle_radius).centre_of_mass


def _attach_point(name: str, point: np.ndarray, by_name: dict[str, BodySpec]) -> np.ndarray:
    """A world point [m] at the initial poses in the frame a distance joint's anchor is given in: the world's
    own, or the body's user frame, c + R(q)^T (p - x) (x its centre of mass, c that in its user frame)."""
    if name == WORLD_NAME:
        return point
    body = by_name[name]
    return _centre_user(body) + quat_rotate_inverse(body.orientation_wxyz, point - body.position)


def _locations(plan: ChainPlan, issues: IssueCollector) -> dict[str, Any]:
    """Where compile_joints' errors for a chain's joints point (JointSpec.locations): the key that decides."""
    chain, cpath = plan.chain, plan.path
    joint = chain["joint"]

    def at(key: str, fallback: YamlPath) -> Any:
        return issues.locate((*cpath, key)) if key in chain else issues.locate(fallback, key=True)

    placed = at("link_centre", (*cpath, "spacing"))
    locations = {"bodies": at("attach", cpath), "anchor": placed, "anchors": placed}
    for key in joint:
        locations[key] = issues.locate((*cpath, "joint", key))
    return locations


def _frozen(value: np.ndarray) -> np.ndarray:
    value.flags.writeable = False
    return value
