"""Scene files to `SceneSpec`: safe YAML with locations, schema validation, semantic checks.

    read (yaml_located) ─▶ merge `defaults` ─▶ JSON Schema (all errors) ─▶ finite numbers ─▶ resolve
                                                                             (simulation, bodies, forces)

Every stage reports to one `IssueCollector`, so a scene gets all its problems at once, each located at
file:line:col. A subtree with schema errors is not resolved further (its numbers cannot be trusted), but
every other subtree still is. `schemas/scene.schema.json` is the single source of truth for the format.
"""

from __future__ import annotations

import math
import os
from dataclasses import replace
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from rbcli.scene.bodies import MAX_GENERATED_BODIES, SAMPLING_KEYS, BodyResolver
from rbcli.scene.chains import ChainPlan, chain_joints, chain_links
from rbcli.scene.issues import IssueCollector
from rbcli.scene.schema_errors import SchemaErrorFormatter
from rbcli.scene.schema_path import scene_schema
from rbcli.scene.spec import (
    SCENE_FORMAT_VERSION,
    BodySpec,
    ContactSpec,
    ForceSpec,
    RecordSpec,
    SceneError,
    SceneIssue,
    SceneSpec,
    SimulationSpec,
    SourceLocation,
)
from rbcli.scene.yaml_located import (
    MAX_SCENE_BYTES,
    LocatedDocument,
    YamlPath,
    decode_scene_bytes,
    parse_located_yaml,
)

if TYPE_CHECKING:
    from collections.abc import Sequence

    from rbcli.scene.joint_spec import JointSpec

# alternatives: a body that gives one of a group replaces whatever `defaults` gives from that group
EXCLUSIVE_GROUPS = (
    ("particles", "shape", "mesh", "compound"),
    ("velocity", "momentum"),
    ("angular_momentum", "angular_velocity"),
    ("spacing", "count"),
    ("density", "mass"),
)

# the `bodies:` entries that stand for several bodies (bodies.py, chains.py)
GENERATORS = ("grid", "random", "chain")

# the integrator of a scene with contact that names none (euler-matrix, the tutorial's, warns with contact)
CONTACT_DEFAULT_INTEGRATOR = "split2"

# the integrator of a scene with joints that names none (nor its coordinates): where the joints form trees,
# reduced-rk4 in joint coordinates, which `rbsim study` shows cheaper than split2 at every accuracy
# measured (docs/trees.md, "Which integrator a jointed scene gets"); else split2, the maximal integrator
# that holds loops and distance joints (docs/joints.md)
TREES_DEFAULT_INTEGRATOR = "reduced-rk4"
JOINTS_DEFAULT_INTEGRATOR = "split2"
# ... and where such a tree scene has contact of shapes whose contacts at once cannot pass the implicit
# solve's capacity (`implicit_contact_fits`): reduced-implicit, whose stiff contact needs no sub-steps
# (docs/contact.md "Implicit contact": the capsule ragdoll's 2 sub-steps where an explicit step needs 22)
TREES_CONTACT_DEFAULT_INTEGRATOR = "reduced-implicit"

# the integrator of a scene in joint coordinates (`coordinates: reduced`) that names none: fourth order,
# cheaper than split2 with RATTLE at every accuracy the pendulum's study measures (docs/trees.md)
REDUCED_DEFAULT_INTEGRATOR = "reduced-rk4"

# a run longer than this many steps is more likely a unit slip (dt in ms?) than intended
MANY_STEPS = 1_000_000_000


@cache
def _validator() -> Any:
    from rbcli.scene.schema_validator import scene_validator

    return scene_validator(scene_schema())


def load_scene(path: str | Path) -> SceneSpec:
    """Read, validate and resolve a scene file; SceneError with every issue (located) if it has errors."""
    spec, issues = analyse_scene(path)
    if spec is None:
        raise SceneError(issues)
    return spec


def check_scene(path: str | Path) -> list[SceneIssue]:
    """Every error and warning of a scene file, in file order (empty: valid and clean)."""
    return analyse_scene(path)[1]


def load_scene_text(text: str | bytes, file: str = "<string>", base_dir: str | Path | None = None) -> SceneSpec:
    """Like `load_scene` for scene text; mesh paths resolve against `base_dir` (default: current directory)."""
    spec, issues = analyse_scene_text(text, file, base_dir)
    if spec is None:
        raise SceneError(issues)
    return spec


def analyse_scene(path: str | Path) -> tuple[SceneSpec | None, list[SceneIssue]]:
    """(spec or None when there are errors, all issues) for a scene file."""
    file = str(path)
    try:
        with open(path, "rb") as handle:
            raw = handle.read(MAX_SCENE_BYTES + 1)
            size = os.fstat(handle.fileno()).st_size
    except OSError as exc:
        reason = exc.strerror or str(exc)
        return None, [SceneIssue(None, f"cannot read scene file '{file}': {reason}", "a readable YAML file")]
    if len(raw) > MAX_SCENE_BYTES:  # only the first bytes were read: the error gives the file's real size
        try:
            decode_scene_bytes(raw, file, max(size, len(raw)))
        except SceneError as exc:
            return None, exc.issues
    return analyse_scene_text(raw, file, Path(path).resolve().parent)


def analyse_scene_text(
    text: str | bytes, file: str = "<string>", base_dir: str | Path | None = None
) -> tuple[SceneSpec | None, list[SceneIssue]]:
    """(spec or None when there are errors, all issues) for scene text."""
    try:
        decoded = decode_scene_bytes(text, file) if isinstance(text, bytes) else text
        doc = parse_located_yaml(decoded, file)
    except SceneError as exc:
        return None, exc.issues
    return _analyse(doc, decoded, Path(base_dir) if base_dir is not None else None, file)


def _analyse(
    doc: LocatedDocument, text: str, base_dir: Path | None, file: str
) -> tuple[SceneSpec | None, list[SceneIssue]]:
    issues = IssueCollector(doc, file)
    data = doc.value
    if not isinstance(data, dict):
        issues.error((), "a scene must be a mapping", "keys such as name, simulation and bodies")
        return None, issues.sorted()
    if _newer_format(data, issues):
        return None, issues.sorted()
    data = _merge_defaults(doc, data)
    # a walk over every number only when the reader saw a non-finite one (or one beyond int64)
    bad_paths = _check_finite(data, (), issues) if doc.suspect_numbers else set()
    errors = sorted(_validator().iter_errors(data), key=lambda e: list(map(str, e.absolute_path)))
    bad_paths |= SchemaErrorFormatter(scene_schema(), issues).report(errors, skip_paths=bad_paths)

    def clean(prefix: YamlPath) -> bool:
        return not any(p[: len(prefix)] == prefix or prefix[: len(p)] == p for p in bad_paths)

    simulation = _simulation(data["simulation"], issues) if "simulation" in data and clean(("simulation",)) else None
    bodies: list[BodySpec] = []
    resolver = BodyResolver(issues, base_dir)
    entries = data["bodies"] if isinstance(data.get("bodies"), list) else []
    chains: list[ChainPlan] = []
    for i, entry in enumerate(entries):
        if not clean(("bodies", i)):
            continue
        if "grid" in entry:
            bodies.extend(resolver.grid(entry, ("bodies", i)))
        elif "random" in entry:
            bodies.extend(resolver.random(entry, ("bodies", i)))
        elif "chain" in entry:
            links, plan = chain_links(resolver, entry, ("bodies", i))
            bodies.extend(links)
            if plan is not None:
                chains.append(plan)
        else:
            body = resolver.body(entry, ("bodies", i))
            if body is not None:
                bodies.append(body)
    _check_unique_names(entries, issues)
    forces = _forces(data, clean, issues)
    contact = None
    if "contact" not in data:
        refused: set[SourceLocation] = set()  # a generator's bodies share its location: told once
        for body in bodies:
            if (body.static or body.kinematic) and body.location is not None and body.location not in refused:
                refused.add(body.location)
                what = "static" if body.static else "kinematic"
                issues.issues.append(SceneIssue(body.location, f"body '{body.name}': {what} bodies need contact",
                                                "a `contact:` section (docs/contact.md)"))  # fmt: skip
        _warn_materials_without_contact(entries, issues)
    _warn_streams_without_their_section(data, issues)
    # the contact section's parts are checked apart (a schema error in its material still lets its planes
    # and the bodies be checked: a scene gets all its problems at once); the section itself must be a mapping
    if "contact" in data and isinstance(data["contact"], dict) and ("contact",) not in bad_paths:
        from rbcli.scene.contact_spec import check_contact_bodies, contact_from_mapping

        contact = contact_from_mapping(data["contact"], issues, clean)
        check_contact_bodies(bodies, entries, issues)
        if simulation is not None and "integrator" not in data["simulation"] and simulation.coordinates != "reduced":
            # the tutorial's default (euler-matrix) gains energy in every bounce; split2 is symplectic,
            # second order and evaluates the contact forces once per step
            simulation = replace(simulation, integrator=CONTACT_DEFAULT_INTEGRATOR)
    joints, chain_joint_names = chain_joints(chains, bodies, issues) if chains else ([], {})
    if isinstance(data.get("joints"), list):
        from rbcli.scene.joint_spec import joints_from_list

        names = [b.name for b in bodies]
        joints += joints_from_list(data["joints"], names, issues, clean, taken=chain_joint_names)
    if joints and simulation is not None:
        if "integrator" not in data["simulation"] and simulation.coordinates != "reduced":  # the one that holds them
            default = _joints_default(data["simulation"], bodies, joints)
            fits = contact is not None and implicit_contact_fits(bodies, contact, joints)
            if default == TREES_DEFAULT_INTEGRATOR and fits:
                default = TREES_CONTACT_DEFAULT_INTEGRATOR
            simulation = replace(simulation, integrator=default)
        if any(joint.kind != "fixed" for joint in joints):  # welds are merged bodies (scene/welds.py)
            _check_joint_integrator(data["simulation"], simulation, issues)
    if issues.error_count or simulation is None:
        return None, issues.sorted()
    gravity = data.get("gravity")
    spec = SceneSpec(
        name=str(data.get("name") or Path(file).stem),
        simulation=simulation,
        bodies=tuple(bodies),
        gravity=None if gravity is None else _frozen_vector(gravity),
        forces=forces,
        contact=contact,
        joints=tuple(joints),
        source_path=file,
        source_text=text,
    )
    warnings = issues.sorted()
    # the compile step finds what only the assembled scene shows (force terms naming unknown bodies or
    # particles, singular inertia): run it here so `validate` reports it, still without simulating
    from rbcli.scene.compile import compile_model, compile_scene

    try:
        spec = replace(spec, warnings=tuple(warnings), compiled_model=compile_model(spec))
    except SceneError as exc:
        return None, sorted([*warnings, *exc.issues], key=SceneIssue.order)
    # spec.warnings are the load's own; the stability warnings depend on the dt that runs, so each
    # CompiledScene computes them for its settings (here: the scene's, for `validate`)
    try:
        return spec, compile_scene(spec).warnings
    except ValueError as exc:  # a run setting the checks above let through: located, never a traceback
        where = issues.locate(("simulation",), key=True)
        return None, sorted([*warnings, SceneIssue(where, f"simulation: {exc}")], key=SceneIssue.order)


# a stream that records what one section of the scene makes: without it the stream records nothing
_STREAM_SECTIONS = {"contacts": "contact", "joint_forces": "joints"}


def _warn_streams_without_their_section(data: dict[str, Any], issues: IssueCollector) -> None:
    """A warning at `record.streams` for a stream whose section the scene lacks (`contacts` without
    `contact:`, `joint_forces` without `joints:`): the run would record nothing on it."""
    record = data.get("simulation", {}).get("record") if isinstance(data.get("simulation"), dict) else None
    streams = record.get("streams") if isinstance(record, dict) else None
    if not isinstance(streams, list):
        return
    for i, stream in enumerate(streams):
        section = _STREAM_SECTIONS.get(stream) if isinstance(stream, str) else None
        if section == "joints" and _has_chain(data):
            continue  # a chain brings its joints
        if section is not None and not data.get(section):
            issues.add(("simulation", "record", "streams", i),
                       f"stream {stream!r} records nothing in a scene without `{section}:`",
                       f"a `{section}:` section, or no {stream!r} stream", severity="warning")  # fmt: skip


def _has_chain(data: dict[str, Any]) -> bool:
    bodies = data.get("bodies")
    return isinstance(bodies, list) and any(isinstance(entry, dict) and "chain" in entry for entry in bodies)


def _warn_materials_without_contact(entries: list[Any], issues: IssueCollector) -> None:
    """A warning at each body's (or generator template's) `material` key in a scene without `contact:`:
    nothing collides there, so the material is ignored, which a user who wrote one did not mean. A warning,
    not an error as for `static: true`: the scene still runs as written. A material from `defaults` sits at
    one place in the file and is reported there once (IssueCollector keeps one issue per location)."""
    for i, entry in enumerate(entries):
        if not isinstance(entry, dict):
            continue
        kind = _generator_kind(entry)
        owner = entry.get(kind) if kind is not None else None
        target = owner.get("template") if isinstance(owner, dict) else entry
        if not isinstance(target, dict) or "material" not in target:
            continue
        path = ("bodies", i, "material") if kind is None else ("bodies", i, kind, "template", "material")
        name = (owner or {}).get("name") if kind is not None else entry.get("name")
        issues.add(path, f"body '{name}': a material does nothing in a scene without `contact:` (no body collides)",
                   "a `contact:` section (docs/contact.md), or no material", key=True, severity="warning",
                   dedupe_key="material without contact")  # fmt: skip


def _joints_default(written: dict[str, Any], bodies: list[BodySpec], joints: list[JointSpec]) -> str:
    """The integrator of a jointed scene that names none: reduced-rk4 where its joints (other than welds,
    which are merged bodies) form trees and it does not say `coordinates: maximal`, else split2 (the
    caller takes reduced-implicit for trees whose contacts fit its solve)."""
    from rbcli.physics.tree.table import MAX_LIMIT_ROWS
    from rbcli.scene.joint_spec import joints_form_trees

    moving = any(joint.kind != "fixed" for joint in joints)
    if moving and "coordinates" not in written and joints_form_trees(bodies, joints, MAX_LIMIT_ROWS):
        return TREES_DEFAULT_INTEGRATOR
    return JOINTS_DEFAULT_INTEGRATOR


# the most contact points a pair can make (manifold.py's table): a sphere touches at 1, a capsule at 2, a
# box at 4 (box-box clipped to 4; a box's vertices on a plane, the 4 deepest)
_PRIMITIVE_POINTS = {"sphere": 1, "capsule": 2, "box": 4}


def implicit_contact_fits(bodies: list[BodySpec], contact: ContactSpec, joints: Sequence[JointSpec] = ()) -> bool:
    """Whether every contact the scene can have at once fits reduced-implicit's solve (IMPLICIT_CAPACITY):
    the points of every pair of colliding bodies and of each body against every plane, at most, sum to the
    capacity or fewer. A sphere, capsule or box that touches as its shape makes 1, 2 or 4 points with a
    plane or a shape (box-box 4, a capsule with a capsule or a box 2, a sphere with anything 1); a body that
    touches through contact spheres (a particle cloud, a welded body's parts) one per sphere, each against
    each sphere or shape of the other body; a sampled lattice (a mesh, `primitives: false`) has no bound
    from its names: False. Pairs a joint holds without `collide: true` never touch. An upper bound from the
    names alone (the capsule ragdoll: 51 of 128; the particle ragdoll's 16 spheres: 92)."""
    from rbcli.physics.contact.tables import IMPLICIT_CAPACITY  # (numpy only: loading a scene compiles nothing)

    apart = {frozenset(joint.bodies) for joint in joints if not joint.collide}
    shapes: list[tuple[str, int, int]] = []  # (name, points as a shape (0: spheres), spheres)
    for body in bodies:
        if not body.collide:
            continue
        if body.contact_spheres is not None:
            shapes.append((body.name, 0, len(body.contact_spheres[1])))
        elif body.contact_primitive is not None and contact.primitives:
            shapes.append((body.name, _PRIMITIVE_POINTS[body.contact_primitive[0]], 1))
        elif body.contact_geometry == "sphere":
            shapes.append((body.name, 1, 1))
        elif body.contact_geometry == "particles":
            shapes.append((body.name, 0, len(body.particle_mass)))
        else:
            return False
    total = sum(points or spheres for _, points, spheres in shapes) * len(contact.planes)
    for i, (name_a, a, na) in enumerate(shapes):
        for name_b, b, nb in shapes[i + 1 :]:
            if frozenset((name_a, name_b)) in apart:
                continue
            if a and b:  # shape and shape: box-box 4; a sphere with anything 1; else (capsules, capsule-box) 2
                total += 1 if min(a, b) == 1 else (4 if a == b == 4 else 2)
            else:  # spheres: each against each sphere or shape of the other
                total += na * nb
            if total > IMPLICIT_CAPACITY:  # past it already (a scene of 10^4 links: no 10^8 pairs counted)
                return False
    return total <= IMPLICIT_CAPACITY


def _check_joint_integrator(written: dict[str, Any], simulation: SimulationSpec, issues: IssueCollector) -> None:
    """A located error when the scene's integrator (or tolerance) cannot hold joints: `check_integrator`
    decides, at the key the scene wrote (an integrator the loader chose is always one that can)."""
    from rbcli.physics.integrators import check_integrator

    refusal = check_integrator(simulation.integrator, tolerance=simulation.tolerance is not None, joints=True)
    if refusal is not None:
        key = refusal.key if refusal.key in written else "integrator"
        issues.error(("simulation", key), refusal.reason, refusal.expected, key=key == "tolerance")


def _frozen_vector(value: list[float]) -> Any:
    v = np.asarray(value, dtype=float).reshape(3)
    v.flags.writeable = False
    return v


def _forces(data: dict[str, Any], clean: Any, issues: IssueCollector) -> tuple[ForceSpec, ...]:
    """Typed force specs from `forces:` (scene/force_specs.py maps each entry; docs/forces.md)."""
    from rbcli.scene.force_specs import force_spec_from_mapping

    entries = data["forces"] if isinstance(data.get("forces"), list) else []
    forces = []
    for i, entry in enumerate(entries):
        if not clean(("forces", i)):
            continue
        try:
            forces.append(force_spec_from_mapping(entry, issues.locate(("forces", i))))
        # the schema's `forces` is a placeholder until the forces issue fills it in, so the mapper still sees
        # unvalidated values and may fail in any way; each failure is this entry's error, not a crash
        except Exception as exc:  # noqa: BLE001
            issues.error(("forces", i), f"cannot read this force: {exc}", "a force entry as docs/forces.md describes")
    return tuple(forces)


def _newer_format(data: dict[str, Any], issues: IssueCollector) -> bool:
    """A scene written for a newer format: one located error, and nothing else checked (its other keys may
    be ones this rbsim does not know, and a screen of "unknown key" errors would hide the reason)."""
    version = data.get("version", SCENE_FORMAT_VERSION)
    if isinstance(version, int) and not isinstance(version, bool) and version > SCENE_FORMAT_VERSION:
        issues.error(
            ("version",),
            f"scene format version {version} is newer than this rbsim understands (it reads up to "
            f"version {SCENE_FORMAT_VERSION})",
            f"a newer rbsim (pip install -U rbsim), or a scene written for version {SCENE_FORMAT_VERSION}",
        )
        return True
    return False


# ---- defaults -----------------------------------------------------------------------------------------
def _merge_defaults(doc: LocatedDocument, data: dict[str, Any]) -> dict[str, Any]:
    """`defaults` merged into each body and generator template (locations copied from `defaults`)."""
    defaults = data.get("defaults")
    bodies = data.get("bodies")
    if not isinstance(defaults, dict) or not defaults or not isinstance(bodies, list):
        return data
    merged_bodies = []
    for i, entry in enumerate(bodies):
        if not isinstance(entry, dict):
            merged_bodies.append(entry)
            continue
        kind = _generator_kind(entry)
        if kind is None:
            merged_bodies.append(_merge_into(doc, defaults, entry, ("bodies", i), skip=("name",)))
            continue
        gen = entry[kind]
        if not isinstance(gen, dict) or not isinstance(gen.get("template"), dict):
            merged_bodies.append(entry)
            continue
        skip = ["name", "position"]
        if kind == "random" and gen.get("random_orientation") is True:
            skip.append("orientation")
        template = _merge_into(doc, defaults, gen["template"], ("bodies", i, kind, "template"), skip=tuple(skip))
        merged_bodies.append({**entry, kind: {**gen, "template": template}})
    return {**data, "bodies": merged_bodies}


def _generator_kind(entry: dict[str, Any]) -> str | None:
    """The generator a body entry is (`grid`, `random`, `chain`), or None for one body."""
    return next((kind for kind in GENERATORS if kind in entry), None)


def _merge_into(
    doc: LocatedDocument, defaults: dict[str, Any], target: dict[str, Any], path: YamlPath, skip: tuple[str, ...]
) -> dict[str, Any]:
    merged = dict(target)
    explicit_particles = "particles" in target or ("particles" in defaults and not _gives_source(target))
    for key, value in defaults.items():
        if key in target or key in skip:
            continue
        group = next((g for g in EXCLUSIVE_GROUPS if key in g), ())
        if any(k in target for k in group):
            continue
        if explicit_particles and key in SAMPLING_KEYS:
            continue  # sampling settings mean nothing to a body given by its particles
        merged[key] = value
        doc.copy_locations(("defaults", key), (*path, key))
    return merged


def _gives_source(entry: dict[str, Any]) -> bool:
    return any(k in entry for k in EXCLUSIVE_GROUPS[0])


# ---- numbers ------------------------------------------------------------------------------------------
def _check_finite(value: Any, path: YamlPath, issues: IssueCollector) -> set[YamlPath]:
    """Report non-finite floats (.nan, .inf) and integers too large for a float64 or int64.

    Lists of plain numbers (a large scene's particle data) are scanned without building a path per item:
    a path is made only for a container or a bad number."""
    bad: set[YamlPath] = set()

    def report(item: Any, where: YamlPath) -> None:
        if isinstance(item, float):
            issues.error(where, f"{item} is not a finite number", "a finite number")
        else:
            issues.error(where, "integer is too large", "an integer below 2^63 in magnitude")
        bad.add(where)

    stack: list[tuple[Any, YamlPath]] = [(value, path)]
    while stack:
        item, where = stack.pop()
        if isinstance(item, dict):
            stack.extend((v, (*where, k)) for k, v in item.items())
        elif isinstance(item, list):
            for i, v in enumerate(item):
                kind = type(v)
                if kind is float:
                    if v - v != 0.0:  # inf - inf and nan - nan are nan: one test for both
                        report(v, (*where, i))
                elif kind is int:
                    if not -(2**63) < v < 2**63:
                        report(v, (*where, i))
                elif kind is list or kind is dict:
                    stack.append((v, (*where, i)))
        elif isinstance(item, float) and not math.isfinite(item):
            report(item, where)
        elif isinstance(item, int) and not isinstance(item, bool) and abs(item) >= 2**63:
            report(item, where)
    return bad


# ---- simulation ---------------------------------------------------------------------------------------
def _simulation(sim: dict[str, Any], issues: IssueCollector) -> SimulationSpec | None:
    path: YamlPath = ("simulation",)
    before = issues.error_count
    dt = float(sim["dt"])
    coordinates = str(sim.get("coordinates", "maximal"))
    default = REDUCED_DEFAULT_INTEGRATOR if coordinates == "reduced" else "euler-matrix"
    integrator = str(sim.get("integrator", default))
    from rbcli.physics.integrators import REDUCED_INTEGRATORS, check_integrator

    refusal = check_integrator(integrator, tolerance="tolerance" in sim)
    if refusal is not None:
        shown = refusal.naming(integrator) if refusal.key == "integrator" else refusal.reason
        issues.error((*path, refusal.key), shown, refusal.expected, key=refusal.key == "tolerance")
    elif coordinates == "reduced" and integrator not in REDUCED_INTEGRATORS:
        issues.error((*path, "integrator"), f"integrator {integrator!r} runs in maximal coordinates, and "
                     "simulation.coordinates is reduced", f"integrator: {', '.join(REDUCED_INTEGRATORS)} "
                     "(docs/trees.md), or coordinates: maximal")  # fmt: skip
    elif "coordinates" in sim and coordinates == "maximal" and integrator in REDUCED_INTEGRATORS:
        issues.error((*path, "integrator"), f"integrator {integrator!r} runs in joint coordinates, and "
                     "simulation.coordinates is maximal", "coordinates: reduced, or a maximal integrator")  # fmt: skip
    if "steps" in sim:
        duration = int(sim["steps"]) * dt
    else:
        duration = float(sim["duration"])
        steps = duration / dt
        if not math.isfinite(steps):
            issues.error((*path, "duration"), "duration / dt overflows", "a number of steps below 1e300")
        elif steps < 1.0 - 1e-9:
            issues.error((*path, "dt"), f"dt = {dt:g} s is longer than duration = {duration:g} s", "dt <= duration")
        elif abs(steps - round(steps)) > 1e-6 * max(1.0, steps):
            issues.warning(
                (*path, "duration"),
                f"duration / dt = {steps:.6g} is not a whole number of steps",
                "a duration that is a multiple of dt (or give steps)",
            )
    if math.isfinite(duration / dt) and duration / dt > MANY_STEPS:
        issues.warning(
            (*path, "dt"), f"{duration / dt:.3g} steps: a very long run", "check the units of dt and duration"
        )
    record = _record(sim.get("record", {}), dt, issues)
    if issues.error_count > before or record is None:
        return None
    return SimulationSpec(
        dt=dt,
        duration=duration,
        integrator=integrator,
        coordinates=coordinates,
        tolerance=float(sim["tolerance"]) if "tolerance" in sim else None,
        record=record,
        output=sim.get("output"),
        seed=int(sim.get("seed", 0)),
        location=issues.locate((*path, "dt")),
    )


def _record(record: dict[str, Any], dt: float, issues: IssueCollector) -> RecordSpec | None:
    path: YamlPath = ("simulation", "record")
    every = int(record.get("every", 1))
    if "rate" in record:
        rate = float(record["rate"])
        with np.errstate(all="ignore"):
            steps_per_record = float(np.float64(1.0) / (rate * dt))
        if not math.isfinite(steps_per_record) or steps_per_record > 2**62:
            issues.error((*path, "rate"), f"record rate {rate:g} Hz is too slow to represent", "a larger rate")
            return None
        if steps_per_record < 1.0 - 1e-9:
            issues.error(
                (*path, "rate"),
                f"record rate {rate:g} Hz is faster than the step rate 1/dt = {1.0 / dt:g} Hz",
                f"a rate <= {1.0 / dt:g} Hz",
            )
            return None
        every = max(1, round(steps_per_record))
        if abs(steps_per_record - every) > 1e-6 * steps_per_record:
            issues.warning(
                (*path, "rate"),
                f"{rate:g} Hz is not a whole number of steps; recording every {every} steps "
                f"({1.0 / (every * dt):g} Hz)",
                "a rate that divides 1/dt",
            )
    streams = tuple(record.get("streams", RecordSpec().streams))
    return RecordSpec(every=every, streams=streams, compression=record.get("compression", RecordSpec().compression))


def _check_unique_names(entries: list[Any], issues: IssueCollector) -> None:
    """Duplicate body names, from the entries as written (so bodies with other errors are checked too)."""
    first: dict[str, YamlPath] = {}
    for i, entry in enumerate(entries):
        for name, name_path in _entry_names(entry, ("bodies", i)):
            if name in first:
                line = issues.locate(first[name]).line
                issues.error(
                    name_path, f"duplicate body name '{name}' (first at line {line})", "a unique name per body"
                )
            else:
                first[name] = name_path


def _entry_names(entry: Any, path: YamlPath) -> list[tuple[str, YamlPath]]:
    """Names a body entry gives: its `name`, or a generator's `<name>_<n>` (a chain's `<name><n>`) when its
    count is readable."""
    if not isinstance(entry, dict):
        return []
    for kind in GENERATORS:
        gen = entry.get(kind)
        if isinstance(gen, dict) and isinstance(gen.get("name"), str):
            count = gen.get("count")
            if kind == "grid" and isinstance(count, list) and len(count) == 3:
                count = math.prod(c if isinstance(c, int) and not isinstance(c, bool) and c > 0 else 0 for c in count)
            if not isinstance(count, int) or isinstance(count, bool) or not 0 < count <= MAX_GENERATED_BODIES:
                return []
            separator = "" if kind == "chain" else "_"
            return [(f"{gen['name']}{separator}{n}", (*path, kind, "name")) for n in range(count)]
        if gen is not None:
            return []
    name = entry.get("name")
    return [(name, (*path, "name"))] if isinstance(name, str) else []
