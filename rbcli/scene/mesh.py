"""Triangle meshes filled with particles: read a closed mesh, keep the lattice points inside it.

Reading uses trimesh when it is installed (OBJ, STL, PLY, OFF, GLB, ...); without it a small built-in
reader handles Wavefront OBJ. Containment is our own: trimesh's `contains` needs rtree or embree, and a
lattice only asks about vertical columns, for which ray parity is exact and cheap. For each lattice column
(x, y) we intersect the vertical line with every triangle whose xy-bounding box covers it; a lattice point
is inside when an odd number of crossings lie below it. Columns are nudged by a tiny irrational fraction
of the spacing so a line never passes exactly through a mesh edge or vertex (which would count twice).
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import numpy as np

from rbcli.scene.mesh_files import MeshError, check_mesh_file
from rbcli.scene.shapes import SamplingError, lattice

__all__ = ["MeshError", "read_mesh", "check_closed", "mesh_volume", "voxelise"]


def read_mesh(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices [mesh units], shape (v, 3), and triangles as vertex indices, shape (f, 3)."""
    if not path.is_file():
        raise MeshError(f"mesh file '{path}' does not exist")
    check_mesh_file(path)  # a truncated or foreign file is told so, not a reader's internals
    trimesh = _trimesh()
    if trimesh is None:
        if path.suffix.lower() != ".obj":
            raise MeshError(f"cannot read '{path.name}': only .obj meshes are supported without trimesh installed")
        return _read_obj(path)
    try:
        with _quiet_trimesh():
            mesh = trimesh.load(str(path), force="mesh", process=True)
    except Exception as exc:  # trimesh raises many kinds for bad files; all mean "unreadable"
        raise MeshError(f"cannot read mesh file '{path.name}': {exc}") from None
    vertices = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), dtype=float)
    faces = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), dtype=np.int64)
    if len(faces) == 0:
        raise MeshError(f"mesh file '{path.name}' holds no triangles")
    return vertices, faces


@contextlib.contextmanager
def _quiet_trimesh() -> Iterator[None]:
    """trimesh logs what it repairs, with tracebacks (an ASCII STL with a garbled facet normal: "failed to
    extract face_normals" and two chained tracebacks, while the mesh itself reads fine and rbsim computes
    its own normals): nothing of it is for the user, whose errors rbsim reports itself."""
    logger = logging.getLogger("trimesh")
    level = logger.level
    logger.setLevel(logging.CRITICAL + 1)
    try:
        yield
    finally:
        logger.setLevel(level)


def _trimesh() -> ModuleType | None:
    """The trimesh module, or None when it is not installed (it is optional)."""
    try:
        import trimesh
    except ImportError:
        return None
    return trimesh


def _read_obj(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """Wavefront OBJ: `v x y z` and `f a b c ...` lines (polygons fanned into triangles; 1-based indices)."""
    vertices: list[list[float]] = []
    faces: list[list[int]] = []
    try:
        lines = path.read_text(encoding="utf-8", errors="strict").splitlines()
    except (OSError, UnicodeDecodeError) as exc:
        raise MeshError(f"cannot read mesh file '{path.name}': {exc}") from None
    for number, line in enumerate(lines, 1):
        parts = line.split()
        try:
            if parts[:1] == ["v"]:
                vertices.append([float(p) for p in parts[1:4]])
            elif parts[:1] == ["f"]:
                idx = [int(p.split("/")[0]) for p in parts[1:]]
                idx = [i - 1 if i > 0 else len(vertices) + i for i in idx]
                faces.extend([idx[0], idx[k], idx[k + 1]] for k in range(1, len(idx) - 1))
        except ValueError:
            raise MeshError(f"'{path.name}' line {number}: cannot read '{line.strip()}'") from None
    if not faces:
        raise MeshError(f"mesh file '{path.name}' holds no triangles")
    f = np.asarray(faces, dtype=np.int64)
    if f.min() < 0 or f.max() >= len(vertices):
        raise MeshError(f"mesh file '{path.name}' has a face index outside its {len(vertices)} vertices")
    return np.asarray(vertices, dtype=float), f


def check_closed(faces: np.ndarray, name: str = "") -> None:
    """Every edge shared by exactly two triangles, else the mesh (file `name`) has no inside (MeshError)."""
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    open_edges = int(np.sum(counts != 2))
    if open_edges:
        named = f" '{name}'" if name else ""
        raise MeshError(
            f"mesh{named} is not closed: {open_edges} edge(s) are not shared by exactly two triangles, "
            "so it has no well-defined inside"
        )


def mesh_volume(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Enclosed volume [units^3] by the divergence theorem: sum over triangles of a . (b x c) / 6."""
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    return abs(float(np.einsum("ni,ni->n", a, np.cross(b, c)).sum()) / 6.0)


def voxelise(vertices: np.ndarray, faces: np.ndarray, spacing: float) -> np.ndarray:
    """Lattice points [m] inside a closed mesh at `spacing`, centred on its bounding box, shape (n, 3)."""
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    points = lattice(0.5 * (hi - lo), spacing, 0.5 * (hi + lo))
    columns, column_index = np.unique(points[:, :2], axis=0, return_inverse=True)
    column_index = column_index.reshape(-1)
    # nudge the rays off edges and vertices; irrational fractions of the spacing, far below it
    nudge = spacing * np.array([1.0e-7 * np.sqrt(2.0), 1.0e-7 * np.sqrt(3.0)])
    rays = columns + nudge
    tri = vertices[faces]  # (f, 3 corners, 3)
    hit_column: list[np.ndarray] = []
    hit_z: list[np.ndarray] = []
    order = np.lexsort((rays[:, 1], rays[:, 0]))
    sorted_x = rays[order, 0]
    for t in tri:
        xmin, xmax = t[:, 0].min(), t[:, 0].max()
        start = np.searchsorted(sorted_x, xmin, side="left")
        stop = np.searchsorted(sorted_x, xmax, side="right")
        if stop <= start:
            continue
        candidates = order[start:stop]
        p = rays[candidates]
        keep = (p[:, 1] >= t[:, 1].min()) & (p[:, 1] <= t[:, 1].max())
        candidates, p = candidates[keep], p[keep]
        if len(p) == 0:
            continue
        # barycentric coordinates of the ray's (x, y) in the triangle's xy projection
        (x0, y0), (x1, y1), (x2, y2) = t[0, :2], t[1, :2], t[2, :2]
        det = (y1 - y2) * (x0 - x2) + (x2 - x1) * (y0 - y2)
        if abs(det) < 1e-300:
            continue  # triangle seen edge-on from above: a vertical line misses it (or grazes it)
        l0 = ((y1 - y2) * (p[:, 0] - x2) + (x2 - x1) * (p[:, 1] - y2)) / det
        l1 = ((y2 - y0) * (p[:, 0] - x2) + (x0 - x2) * (p[:, 1] - y2)) / det
        l2 = 1.0 - l0 - l1
        inside = (l0 >= 0) & (l1 >= 0) & (l2 >= 0)
        if inside.any():
            hit_column.append(candidates[inside])
            hit_z.append(l0[inside] * t[0, 2] + l1[inside] * t[1, 2] + l2[inside] * t[2, 2])
    keep_point = np.zeros(len(points), dtype=bool)
    if hit_column:
        cols = np.concatenate(hit_column)
        zs = np.concatenate(hit_z)
        sort = np.lexsort((zs, cols))
        cols, zs = cols[sort], zs[sort]
        bounds = np.searchsorted(cols, np.arange(len(columns) + 1))
        point_order = np.argsort(column_index, kind="stable")
        point_bounds = np.searchsorted(column_index[point_order], np.arange(len(columns) + 1))
        for c in np.nonzero(np.diff(bounds))[0]:
            crossings = zs[bounds[c] : bounds[c + 1]]
            members = point_order[point_bounds[c] : point_bounds[c + 1]]
            below = np.searchsorted(crossings, points[members, 2], side="right")
            keep_point[members] = (below % 2) == 1
    inside_points = points[keep_point]
    if len(inside_points) == 0:
        raise SamplingError(f"spacing {spacing:.4g} m is too coarse: no lattice point falls inside the mesh")
    return inside_points
