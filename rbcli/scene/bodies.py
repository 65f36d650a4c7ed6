"""Validated body entries of a scene turned into `BodySpec`s: particles, orientation, initial motion.

Entries reach here already schema-valid (types, lengths, signs); what is checked here needs the numbers
together: particle counts matching mass lists, sampling parameters, inertia that is not degenerate,
orientations, and the expansion of `grid` and `random` generators.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any, overload

import numpy as np

from rbcli.physics.rotation import quat_to_matrix, random_unit_quaternions
from rbcli.scene import mesh as mesh_io
from rbcli.scene.issues import IssueCollector
from rbcli.scene.orientation import resolve_orientation
from rbcli.scene.shapes import (
    SamplingError,
    inertia_degeneracy,
    mass_properties,
    sample_shape,
    shape_volume,
    spacing_for_count,
)
from rbcli.scene.spec import BodySpec
from rbcli.scene.yaml_located import YamlPath

SAMPLED_SOURCES = ("shape", "mesh", "compound")
SAMPLING_KEYS = ("spacing", "count", "density", "mass")

# fewer lattice particles than this describe the shape too coarsely to trust its mass properties
FEW_PARTICLES = 8

# a generator typo (count: [1000, 1000, 1000]) should fail fast rather than build a billion bodies
MAX_GENERATED_BODIES = 100_000


@dataclass(frozen=True)
class ParticleCloud:
    """Particles of one body (or part): positions [m] (n, 3) in its frame, masses [kg] (n,), radii [m] or None."""

    position: np.ndarray
    mass: np.ndarray
    radius: np.ndarray | None


@dataclass
class _Mesh:
    vertices: np.ndarray
    faces: np.ndarray
    volume: float


def _cell_volume(spacing: float) -> float:
    """s^3 [m^3] as a float64 (inf on overflow, where Python's float ** would raise)."""
    s = np.float64(spacing)
    with np.errstate(over="ignore"):
        return float(s * s * s)


@overload
def _read_only(a: np.ndarray) -> np.ndarray: ...
@overload
def _read_only(a: None) -> None: ...
def _read_only(a: np.ndarray | None) -> np.ndarray | None:
    if a is not None:
        a.flags.writeable = False
    return a


def _vec(value: Any) -> np.ndarray:
    """A read-only float (3,) vector from three numbers."""
    return _read_only(np.asarray(value, dtype=float).reshape(3))


def _optional_vec(value: Any) -> np.ndarray | None:
    """`_vec`, or None for an entry left out."""
    return None if value is None else _vec(value)


class BodyResolver:
    """Resolves body entries, reporting every problem to `issues` (a body with errors gives None)."""

    def __init__(self, issues: IssueCollector, base_dir: Path | None):
        self.issues = issues
        self.base_dir = base_dir
        self._meshes: dict[tuple[str, tuple[float, ...]], _Mesh | None] = {}

    # ---- entries -----------------------------------------------------------------------------------
    def body(self, entry: dict[str, Any], path: YamlPath) -> BodySpec | None:
        """One `{name, ...}` entry."""
        proto = self.prototype(entry, path)
        if proto is None:
            return None
        position = entry.get("position", [0.0, 0.0, 0.0])
        return dataclasses.replace(proto, name=entry["name"], position=_vec(position))

    def grid(self, entry: dict[str, Any], path: YamlPath) -> list[BodySpec]:
        """`{grid: {name, count, spacing, origin?, jitter?, seed?, template}}`: bodies at origin + [i, j, k] *
        spacing, each moved by a uniform random offset within +-jitter (seeded)."""
        gen, gpath = entry["grid"], (*path, "grid")
        counts = [int(c) for c in gen["count"]]
        total = counts[0] * counts[1] * counts[2]
        if total > MAX_GENERATED_BODIES:
            self.issues.error(
                (*gpath, "count"), f"{total:,} bodies is too many", f"at most {MAX_GENERATED_BODIES:,} bodies"
            )
            return []
        proto = self.prototype(gen["template"], (*gpath, "template"))
        if proto is None:
            return []
        spacing = np.broadcast_to(np.asarray(gen["spacing"], dtype=float), (3,))
        origin = np.asarray(gen.get("origin", [0.0, 0.0, 0.0]), dtype=float)
        k, j, i = np.meshgrid(*(np.arange(c) for c in counts[::-1]), indexing="ij")
        index = np.stack([i.ravel(), j.ravel(), k.ravel()], axis=1)  # n = i + nx (j + ny k): i fastest
        with np.errstate(over="ignore", invalid="ignore"):
            positions = origin + index * spacing
            if "jitter" in gen:
                jitter = np.broadcast_to(np.asarray(gen["jitter"], dtype=float), (3,))
                rng = np.random.default_rng(int(gen.get("seed", 0)))
                positions = positions + rng.uniform(-1.0, 1.0, positions.shape) * jitter
        if not np.all(np.isfinite(positions)):
            self.issues.error(gpath, "grid positions overflow", "origin and spacing of sensible size", key=True)
            return []
        location = self.issues.locate(path)
        return [
            dataclasses.replace(proto, name=f"{gen['name']}_{n}", position=_vec(p), location=location)
            for n, p in enumerate(positions)
        ]

    def random(self, entry: dict[str, Any], path: YamlPath) -> list[BodySpec]:
        """`{random: {...}}`: positions uniform in a box, then velocities, then orientations, from one seed."""
        gen, gpath = entry["random"], (*path, "random")
        count = int(gen["count"])
        if count > MAX_GENERATED_BODIES:
            self.issues.error((*gpath, "count"), f"{count:,} bodies is too many", f"at most {MAX_GENERATED_BODIES:,}")
            return []
        lo = np.asarray(gen["box"]["min"], dtype=float)
        hi = np.asarray(gen["box"]["max"], dtype=float)
        ok = True
        if np.any(lo > hi):
            self.issues.error((*gpath, "box", "max"), "box max is below box min on some axis", "min <= max per axis")
            ok = False
        template = gen["template"]
        sigma = float(gen.get("velocity_sigma", 0.0))
        if sigma > 0 and "momentum" in template:
            self.issues.error(
                (*gpath, "velocity_sigma"),
                "velocity_sigma adds to a velocity, but the template gives momentum",
                "a template with velocity (or neither)",
                key=True,
            )
            ok = False
        spin = bool(gen.get("random_orientation", False))
        if spin and "orientation" in template:
            self.issues.error(
                (*gpath, "random_orientation"),
                "random_orientation replaces the template's orientation; give one or the other",
                "either template orientation or random_orientation: true",
                key=True,
            )
            ok = False
        proto = self.prototype(template, (*gpath, "template"))
        if proto is None or not ok:
            return []
        rng = np.random.default_rng(int(gen.get("seed", 0)))
        with np.errstate(over="ignore", invalid="ignore"):
            positions = lo + (hi - lo) * rng.random((count, 3))
        if not np.all(np.isfinite(positions)):
            self.issues.error((*gpath, "box"), "box is too large to sample", "a box of sensible size", key=True)
            return []
        base_velocity = proto.velocity if proto.velocity is not None else np.zeros(3)
        velocities = base_velocity + sigma * rng.standard_normal((count, 3)) if sigma > 0 else None
        orientations = random_unit_quaternions(rng, count) if spin else None
        bodies = []
        location = self.issues.locate(path)
        for n in range(count):
            changes: dict[str, Any] = {
                "name": f"{gen['name']}_{n}",
                "position": _vec(positions[n]),
                "location": location,
            }
            if velocities is not None:
                changes["velocity"] = _vec(velocities[n])
            if orientations is not None:
                changes["orientation_wxyz"] = _read_only(orientations[n].copy())
                if proto.angular_momentum is not None and "angular_momentum" in template:
                    changes["angular_momentum"] = self._angular_momentum(template["angular_momentum"], orientations[n])
            bodies.append(dataclasses.replace(proto, **changes))
        return bodies

    # ---- a body without name and position -------------------------------------------------------------
    def prototype(self, entry: dict[str, Any], path: YamlPath) -> BodySpec | None:
        """The body an entry (or a generator's template) describes, named "" at the origin (the generators,
        here and in scene/chains.py, copy it with each body's name and position); None with its errors."""
        before = self.issues.error_count
        cloud = self._cloud(entry, path)
        if cloud is not None and self._check_numbers(cloud, entry, path):
            self._check_inertia(cloud, entry, path)

        def report(sub: tuple, message: str, expected: str, severity: str) -> None:
            self.issues.add((*path, "orientation", *sub), message, expected, severity=severity)

        q = resolve_orientation(entry.get("orientation"), report)
        if cloud is None or q is None or self.issues.error_count > before:
            return None
        q = _read_only(q)
        angular_velocity, frame = None, "world"
        if "angular_velocity" in entry:
            w = entry["angular_velocity"]
            if isinstance(w, dict):
                frame = "body" if "body" in w else "world"
                w = w[frame]
            angular_velocity = _optional_vec(w)
        return BodySpec(
            name="",
            particle_position=_read_only(cloud.position),
            particle_mass=_read_only(cloud.mass),
            position=_vec([0.0, 0.0, 0.0]),
            orientation_wxyz=q,
            particle_radius=_read_only(cloud.radius),
            velocity=_optional_vec(entry.get("velocity")),
            momentum=_optional_vec(entry.get("momentum")),
            angular_momentum=(
                self._angular_momentum(entry["angular_momentum"], q) if "angular_momentum" in entry else None
            ),
            angular_velocity=angular_velocity,
            angular_velocity_frame=frame,
            location=self.issues.locate(path),
            **self._contact_keys(entry, path, cloud),
        )

    def _contact_keys(self, entry: dict[str, Any], path: YamlPath, cloud: ParticleCloud) -> dict[str, Any]:
        """The BodySpec's contact fields: material, static, collide and where its contact spheres come
        from (used only when the scene has a `contact:` section)."""
        from rbcli.scene.contact_spec import kinematic_from_mapping, material_from_mapping

        if "shape" in entry and entry["shape"].get("type") == "sphere":
            geometry, size = "sphere", float(entry["shape"]["radius"])
        elif ("shape" in entry or "mesh" in entry) and cloud.radius is not None and len(cloud.radius):
            geometry, size = "lattice", 2.0 * float(cloud.radius[0])
        else:
            geometry, size = "particles", 0.0
        primitive = None
        shape = entry.get("shape") if "shape" in entry and "mesh" not in entry else None
        if shape is not None and shape.get("type") == "box":
            half = 0.5 * np.asarray(shape["size"], dtype=float)
            primitive = ("box", (float(half[0]), float(half[1]), float(half[2])))
        elif shape is not None and shape.get("type") == "capsule":
            axis = {"x": 0, "y": 1, "z": 2}[shape.get("axis", "z")]
            primitive = ("capsule", (float(shape["radius"]), 0.5 * float(shape["height"]), float(axis)))
        kinematic = entry.get("kinematic", False)
        return dict(
            contact_primitive=primitive,
            material=material_from_mapping(entry.get("material"), (*path, "material"), self.issues),
            static=bool(entry.get("static", False)),
            kinematic=bool(kinematic),
            kinematic_motion=kinematic_from_mapping(kinematic, (*path, "kinematic"), self.issues)
            if isinstance(kinematic, dict)
            else None,
            collide=bool(entry.get("collide", True)),
            contact_geometry=geometry,
            contact_size=size,
        )

    @staticmethod
    def _angular_momentum(value: Any, q: np.ndarray) -> np.ndarray:
        """World-frame angular momentum from a plain list (world), {world: ...} or {body: ...} (L = R L_body)."""
        if isinstance(value, dict):
            if "body" in value:
                return _vec(quat_to_matrix(q) @ np.asarray(value["body"], dtype=float))
            value = value["world"]
        return _vec(value)

    def _check_numbers(self, cloud: ParticleCloud, entry: dict[str, Any], path: YamlPath) -> bool:
        """Particle masses that are positive and finite after sampling (a density * spacing^3 can overflow)."""
        mass = cloud.mass
        if np.all(np.isfinite(mass)) and np.all(mass > 0) and np.all(np.isfinite(cloud.position)):
            return True
        source = next(k for k in ("particles", *SAMPLED_SOURCES) if k in entry)
        self.issues.error(
            (*path, source),
            "particle masses or positions overflow or vanish in float64 (numbers far too large or small)",
            "masses, densities, sizes and spacings of physical magnitude",
            key=True,
        )
        return False

    def _check_inertia(self, cloud: ParticleCloud, entry: dict[str, Any], path: YamlPath) -> None:
        reason = inertia_degeneracy(mass_properties(cloud.position, cloud.mass, cloud.radius))
        if reason is None:
            return
        source = next(k for k in ("particles", *SAMPLED_SOURCES) if k in entry)
        at_one_point = "one point" in reason
        if at_one_point and len(cloud.mass) == 1:
            reason = "a single particle is one point, so the body has no rotational inertia at all"
        if source in ("particles", "compound"):  # lattice particles carry a radius, so never degenerate
            where = "more particles, spread in three dimensions" if at_one_point else "particles off that line"
            fix = f"{where}, a particle radius (each particle then is a small solid sphere), or a shape"
        else:
            fix = "a smaller spacing (or a larger count) so the lattice has particles in three dimensions"
        self.issues.error((*path, source), f"cannot be a rigid body: {reason}", fix, key=True)

    # ---- particles -------------------------------------------------------------------------------------
    def _cloud(self, entry: dict[str, Any], path: YamlPath) -> ParticleCloud | None:
        if "particles" in entry:
            for k in SAMPLING_KEYS:
                if k in entry:
                    self.issues.error(
                        (*path, k),
                        f"'{k}' applies to shape, mesh and compound bodies, not to explicit particles",
                        "particles with their own masses (and radius)",
                        key=True,
                    )
            return self._explicit(entry["particles"], (*path, "particles"))
        if not any(k in entry for k in SAMPLED_SOURCES):  # the schema says it first, unless a malformed
            self.issues.error(  # `defaults` stopped it before the bodies (found by fuzzing: StopIteration)
                path, "missing one of 'particles', 'shape', 'mesh', 'compound'", "exactly one of them", key=True
            )
            return None
        spacing = self._spacing(entry, path)
        if spacing is None:
            return None
        if "compound" in entry:
            return self._compound(entry, path, spacing)
        source = "shape" if "shape" in entry else "mesh"
        if "density" not in entry and "mass" not in entry:
            self.issues.error(
                path, f"a {source} body needs 'density' or 'mass'", "density [kg/m^3] or mass [kg]", key=True
            )
            return None
        points = self._sample(entry[source], source, (*path, source), spacing)
        if points is None:
            return None
        if "density" in entry:
            mass = np.full(len(points), float(entry["density"]) * _cell_volume(spacing))
        else:
            mass = np.full(len(points), float(entry["mass"]) / len(points))
        return ParticleCloud(points, mass, np.full(len(points), 0.5 * spacing))

    def _explicit(self, particles: dict[str, Any], path: YamlPath) -> ParticleCloud | None:
        position = np.asarray(particles["positions"], dtype=float).reshape(-1, 3)
        n = len(position)
        mass = self._per_particle(particles["masses"], n, (*path, "masses"), "mass")
        radius = None
        if "radius" in particles:
            radius = self._per_particle(particles["radius"], n, (*path, "radius"), "radius")
            if radius is None:
                return None
        if mass is None:
            return None
        return ParticleCloud(position, mass, radius)

    def _per_particle(self, value: Any, n: int, path: YamlPath, what: str) -> np.ndarray | None:
        if isinstance(value, list):
            if len(value) != n:
                self.issues.error(
                    path,
                    f"{len(value)} values for {n} particle positions",
                    f"one {what} per position ({n}), or a single number for all",
                )
                return None
            return np.asarray(value, dtype=float)
        return np.full(n, float(value))

    def _spacing(self, entry: dict[str, Any], path: YamlPath) -> float | None:
        """Lattice spacing [m]: given, or from `count` and the volume; None for particle-only compounds."""
        if "spacing" in entry:
            return float(entry["spacing"])
        needs_lattice = "compound" not in entry or any("particles" not in p for p in entry["compound"])
        if "count" not in entry:
            if needs_lattice:
                source = next(k for k in SAMPLED_SOURCES if k in entry)
                self.issues.error(
                    path,
                    f"a {source} body needs 'spacing' or 'count'",
                    "spacing [m] between lattice particles, or count, the approximate number of particles",
                    key=True,
                )
                return None
            return 0.0
        volume = 0.0
        parts = entry["compound"] if "compound" in entry else [entry]
        for i, part in enumerate(parts):
            ppath = (*path, "compound", i) if "compound" in entry else path
            if "shape" in part:
                volume += shape_volume(part["shape"])
            elif "mesh" in part:
                m = self._mesh(part["mesh"], (*ppath, "mesh"))
                if m is None:
                    return None
                volume += m.volume
        if volume <= 0.0:
            return 0.0
        spacing = spacing_for_count(volume, int(entry["count"]))
        if not (np.isfinite(spacing) and spacing > 0.0):
            self.issues.error((*path, "count"), "cannot derive a spacing from this count", "a sensible count", key=True)
            return None
        return spacing

    def _sample(self, source: dict[str, Any], kind: str, path: YamlPath, spacing: float) -> np.ndarray | None:
        try:
            if kind == "shape":
                points = sample_shape(source, spacing)
            else:
                m = self._mesh(source, path)
                if m is None:
                    return None
                points = mesh_io.voxelise(m.vertices, m.faces, spacing)
        except SamplingError as exc:
            self.issues.error(path, str(exc), "a spacing that fits the shape's size", key=True)
            return None
        if len(points) < FEW_PARTICLES:
            self.issues.warning(
                path,
                f"only {len(points)} particle{'s' if len(points) != 1 else ''} at spacing {spacing:.4g} m: "
                f"mass and inertia will be far from the {kind}'s",
                "a smaller spacing (or a larger count)",
                key=True,
            )
        return points

    def _mesh(self, spec: dict[str, Any], path: YamlPath) -> _Mesh | None:
        scale = np.broadcast_to(np.asarray(spec.get("scale", 1.0), dtype=float), (3,))
        file = Path(spec["file"])
        if not file.is_absolute() and self.base_dir is not None:
            file = self.base_dir / file
        cache_key = (str(file), tuple(scale))
        if cache_key not in self._meshes:
            try:
                vertices, faces = mesh_io.read_mesh(file)
                mesh_io.check_closed(faces, file.name)
                vertices = vertices * scale
                self._meshes[cache_key] = _Mesh(vertices, faces, mesh_io.mesh_volume(vertices, faces))
            except mesh_io.MeshError as exc:
                self._meshes[cache_key] = None
                self.issues.error((*path, "file"), str(exc), "a closed triangle mesh file, relative to the scene file")
        return self._meshes[cache_key]

    def _compound(self, entry: dict[str, Any], path: YamlPath, spacing: float) -> ParticleCloud | None:
        """Parts placed by offset and orientation; masses from part mass/density, body density, or body mass."""
        positions: list[np.ndarray] = []
        masses: list[np.ndarray] = []
        radii: list[np.ndarray] = []
        unspecified: list[int] = []  # parts whose particle masses come from the body's mass
        has_radius = False
        ok = True
        for i, part in enumerate(entry["compound"]):
            ppath = (*path, "compound", i)

            def report(sub: tuple, message: str, expected: str, severity: str, ppath=ppath) -> None:
                self.issues.add((*ppath, "orientation", *sub), message, expected, severity=severity)

            q = resolve_orientation(part.get("orientation"), report)
            if "particles" in part:
                cloud = self._explicit(part["particles"], (*ppath, "particles"))
                for k in ("density", "mass"):
                    if k in part:
                        self.issues.error(
                            (*ppath, k), f"'{k}' applies to shape and mesh parts", "particle masses", key=True
                        )
                        ok = False
                if cloud is None or q is None:
                    ok = False
                    continue
                points, mass, radius = cloud.position, cloud.mass, cloud.radius
                has_radius |= radius is not None
                radius = np.zeros(len(points)) if radius is None else radius
            else:
                kind = "shape" if "shape" in part else "mesh"
                sampled = self._sample(part[kind], kind, (*ppath, kind), spacing)
                if sampled is None or q is None:
                    ok = False
                    continue
                points = sampled
                has_radius = True
                radius = np.full(len(points), 0.5 * spacing)
                if "mass" in part:
                    mass = np.full(len(points), float(part["mass"]) / len(points))
                elif "density" in part or "density" in entry:
                    density = float(part.get("density", entry.get("density")))
                    mass = np.full(len(points), density * _cell_volume(spacing))
                elif "mass" in entry:
                    mass = np.full(len(points), np.nan)  # filled from the body's mass below
                    unspecified.append(len(masses))
                else:
                    self.issues.error(
                        ppath,
                        "this part needs 'density' or 'mass' (or give the body 'density' or 'mass')",
                        "density [kg/m^3] or mass [kg]",
                    )
                    ok = False
                    continue
                if not (np.all(np.isnan(mass)) or (np.all(np.isfinite(mass)) and np.all(mass > 0.0))):
                    # e.g. density 1e-323 kg/m^3 x a cell volume rounds to exactly 0: massless particles
                    if "mass" in part:
                        where, source = (*ppath, "mass"), f"mass {float(part['mass']):g} kg over {len(mass)} particles"
                    elif "density" in part:
                        where, source = (*ppath, "density"), f"density {float(part['density']):g} kg/m^3"
                    else:  # the body's density, applied to this part: located at the part
                        where, source = ppath, f"the body's density {float(entry['density']):g} kg/m^3"
                    what = "round to 0" if float(mass[0]) == 0.0 else "overflow"
                    self.issues.error(
                        where,
                        f"{source} gives this part particle masses of {float(mass[0]):g} kg at spacing {spacing:g} m, "
                        f"which {what} in float64",
                        "a density or mass of physical magnitude",
                        key=where != ppath,
                    )
                    ok = False
                    continue
            offset = np.asarray(part.get("offset", [0.0, 0.0, 0.0]), dtype=float)
            positions.append(points @ quat_to_matrix(q).T + offset)
            masses.append(mass)
            radii.append(radius)
        if not ok:
            return None
        if "mass" in entry:
            if not unspecified:
                self.issues.error(
                    (*path, "mass"),
                    "body mass is not used: every part sets its own density or mass",
                    "mass only when some shape or mesh parts give neither",
                    key=True,
                )
                return None
            n_unspecified = sum(len(masses[j]) for j in unspecified)
            share = np.float64(entry["mass"]) / n_unspecified
            if not (np.isfinite(share) and share > 0.0):
                self.issues.error(
                    (*path, "mass"),
                    f"body mass {float(entry['mass']):g} kg over {n_unspecified} particles gives particle masses "
                    f"of {float(share):g} kg, which {'round to 0' if share == 0.0 else 'overflow'} in float64",
                    "a mass of physical magnitude",
                    key=True,
                )
                return None
            for j in unspecified:
                masses[j] = np.full(len(masses[j]), float(share))
        return ParticleCloud(
            np.concatenate(positions), np.concatenate(masses), np.concatenate(radii) if has_radius else None
        )
