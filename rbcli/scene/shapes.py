"""Shapes filled with particles, and the mass properties of particle clouds.

Sampling: a cubic lattice of spacing `s`, cell-centred and symmetric about the shape's origin, keeps the
lattice points inside the shape. Each point stands for one cubic cell of volume s^3, so with a density
each particle carries `density * s^3` and the cloud's mass converges to the solid's as s -> 0 (with an
error of order s / size from cells cut by the surface). The per-axis point count round(extent / s) makes a
box whose edges are multiples of s come out exact.

Mass properties: a particle of radius r is a solid sphere (own inertia 2/5 m r^2 about its centre); without
a radius it is a point mass, as in the tutorial's precomputation.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

SHAPE_TYPES = ("box", "sphere", "cylinder", "capsule", "ellipsoid")

# more lattice points than this is a typo in spacing, not a simulation anyone wants to start from a scene
MAX_LATTICE_POINTS = 2_000_000

# an inertia eigenvalue this small relative to the largest is zero to rounding: the body cannot rotate
# about that axis with finite angular velocity, so the free-body equations (I^-1 L) break down
DEGENERATE_INERTIA_RATIO = 1e-12

_AXIS_INDEX = {"x": 0, "y": 1, "z": 2}


class SamplingError(ValueError):
    """A shape that cannot be sampled as asked (too coarse or too fine a spacing)."""


@dataclass(frozen=True)
class MassProperties:
    """Mass properties of a particle cloud in its own (body) frame.

    mass [kg]; centre_of_mass [m], shape (3,); inertia [kg m^2], shape (3, 3), about the centre of mass;
    principal_moments [kg m^2], shape (3,), ascending; principal_axes, shape (3, 3), columns are the axes.
    """

    mass: float
    centre_of_mass: np.ndarray
    inertia: np.ndarray
    principal_moments: np.ndarray
    principal_axes: np.ndarray


def mass_properties(
    particle_position: np.ndarray, particle_mass: np.ndarray, particle_radius: np.ndarray | None = None
) -> MassProperties:
    """Mass, centre of mass and inertia about it: I = sum m (|r|^2 1 - r r^T) + sum 2/5 m a^2 1.

    r is a particle's offset from the centre of mass, a its radius (solid-sphere term; zero for points).
    """
    x = np.asarray(particle_position, dtype=float).reshape(-1, 3)
    m = np.asarray(particle_mass, dtype=float).reshape(-1)
    with np.errstate(over="ignore", invalid="ignore"):
        total = float(m.sum())
        com = (m[:, None] * x).sum(axis=0) / total
        r = x - com
        r2 = np.einsum("ni,ni->n", r, r)
        inertia = np.eye(3) * float((m * r2).sum()) - np.einsum("n,ni,nj->ij", m, r, r)
        if particle_radius is not None:
            a = np.broadcast_to(np.asarray(particle_radius, dtype=float), m.shape)
            inertia += np.eye(3) * float((0.4 * m * a * a).sum())
    inertia = 0.5 * (inertia + inertia.T)
    if not (np.isfinite(total) and np.all(np.isfinite(inertia))):  # overflow from absurd inputs
        return MassProperties(total, com, inertia, np.full(3, np.nan), np.full((3, 3), np.nan))
    moments, axes = np.linalg.eigh(inertia)
    return MassProperties(total, com, inertia, moments, axes)


def inertia_degeneracy(props: MassProperties) -> str | None:
    """Why a cloud cannot be a rigid body (a zero principal moment), or None when it can."""
    if not np.all(np.isfinite(props.principal_moments)) or not np.all(np.isfinite(props.centre_of_mass)):
        return "its mass or inertia overflows (positions or masses far too large)"
    largest = float(props.principal_moments[-1])
    if not largest > 0.0:
        return "all particles are at one point, so the body has no rotational inertia at all"
    if float(props.principal_moments[0]) < DEGENERATE_INERTIA_RATIO * largest:
        return (
            "the particles lie on one line, so the body has no inertia about that line "
            f"(principal moments {_fmt3(props.principal_moments)} kg m^2)"
        )
    return None


def _fmt3(v: np.ndarray) -> str:
    return "[" + ", ".join(f"{x:.4g}" for x in v) + "]"


def _axial(shape: Mapping[str, Any]) -> int:
    return _AXIS_INDEX[shape.get("axis", "z")]


def shape_volume(shape: Mapping[str, Any]) -> float:
    """Volume of a primitive [m^3] (for `count`, which sets spacing = (volume / count)^(1/3)).

    Products of float64 rather than `**`: absurd sizes give inf (then refused), not OverflowError.
    """
    kind = shape["type"]
    with np.errstate(over="ignore"):
        if kind == "box":
            return float(np.prod(np.asarray(shape["size"], dtype=float)))
        if kind == "ellipsoid":
            return float(4.0 / 3.0 * np.pi * np.prod(np.asarray(shape["radii"], dtype=float)))
        r = np.float64(shape["radius"])
        if kind == "sphere":
            return float(4.0 / 3.0 * np.pi * r * r * r)
        if kind == "cylinder":
            return float(np.pi * r * r * np.float64(shape["height"]))
        if kind == "capsule":
            return float(np.pi * r * r * np.float64(shape["height"]) + 4.0 / 3.0 * np.pi * r * r * r)
    raise ValueError(f"unknown shape type {kind!r}")


def shape_half_extents(shape: Mapping[str, Any]) -> np.ndarray:
    """Half edge lengths of the shape's axis-aligned bounding box [m], shape (3,)."""
    kind = shape["type"]
    if kind == "box":
        return 0.5 * np.asarray(shape["size"], dtype=float)
    if kind == "sphere":
        return np.full(3, float(shape["radius"]))
    if kind == "ellipsoid":
        return np.asarray(shape["radii"], dtype=float)
    half = np.full(3, float(shape["radius"]))
    half[_axial(shape)] = 0.5 * shape["height"] + (shape["radius"] if kind == "capsule" else 0.0)
    return half


def shape_contains(shape: Mapping[str, Any], points: np.ndarray) -> np.ndarray:
    """Which points [m], shape (n, 3), lie inside the shape (boundary included, to rounding)."""
    kind = shape["type"]
    slack = 1.0 + 1e-12
    if kind == "box":
        return np.all(np.abs(points) <= 0.5 * np.asarray(shape["size"]) * slack, axis=1)
    if kind == "sphere":
        radius = np.float64(shape["radius"]) * slack
        return np.einsum("ni,ni->n", points, points) <= radius * radius
    if kind == "ellipsoid":
        scaled = points / np.asarray(shape["radii"], dtype=float)
        return np.einsum("ni,ni->n", scaled, scaled) <= slack**2
    k = _axial(shape)
    radial = np.delete(points, k, axis=1)
    rho2 = np.einsum("ni,ni->n", radial, radial)
    half = 0.5 * shape["height"]
    r = shape["radius"] * slack
    if kind == "cylinder":
        return (rho2 <= r * r) & (np.abs(points[:, k]) <= half * slack)
    if kind == "capsule":  # distance to the axis segment [-half, half] at most r
        beyond = np.maximum(np.abs(points[:, k]) - half, 0.0)
        return rho2 + beyond * beyond <= r * r
    raise ValueError(f"unknown shape type {kind!r}")


def lattice(half_extents: np.ndarray, spacing: float, centre: np.ndarray | None = None) -> np.ndarray:
    """Cell-centred cubic lattice points covering a box, symmetric about `centre`, shape (n, 3) [m].

    Per axis round(2 h / s) points (at least one) at centre + s (k - (n - 1) / 2).
    """
    if not (np.isfinite(spacing) and spacing > 0 and np.all(np.isfinite(half_extents))):
        raise SamplingError(f"cannot sample with spacing {spacing:.4g} m over extents {half_extents} m")
    with np.errstate(over="ignore"):
        counts_float = np.maximum(1.0, np.rint(2.0 * np.asarray(half_extents, dtype=float) / spacing))
        total = float(np.prod(counts_float))
    if not total <= MAX_LATTICE_POINTS:  # also catches inf and nan before any allocation
        raise SamplingError(
            f"spacing {spacing:.4g} m would give about {total:.3g} lattice points "
            f"(limit {MAX_LATTICE_POINTS:,}); use a larger spacing or a smaller count"
        )
    counts = counts_float.astype(np.int64)
    axes = [spacing * (np.arange(n) - 0.5 * (n - 1)) for n in counts]
    grid = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    return grid if centre is None else grid + np.asarray(centre, dtype=float)


def sample_shape(shape: Mapping[str, Any], spacing: float) -> np.ndarray:
    """Lattice points [m] inside a primitive at `spacing`, body frame, shape (n, 3); n >= 1."""
    points = lattice(shape_half_extents(shape), spacing)
    inside = points[shape_contains(shape, points)]
    if len(inside) == 0:
        raise SamplingError(f"spacing {spacing:.4g} m is too coarse: no lattice point falls inside the shape")
    return inside


def spacing_for_count(volume: float, count: int) -> float:
    """Lattice spacing [m] that fills `volume` [m^3] with about `count` particles."""
    return float(np.cbrt(np.float64(volume) / count))
