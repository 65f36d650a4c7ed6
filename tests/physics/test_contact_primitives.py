"""Primitive contact kernels (physics/contact/primitives.py, primitive_boxes.py, box_box.py) against numpy
references.

References, independent of the kernels' algorithms:
- the distance of two cores (a sphere's centre, a capsule's segment): the distance from a's core point
  at s to b's core is convex in s, minimised by golden-section search to rounding;
- a core against a box: the signed distance to the box along the core, likewise convex; where the core
  enters the box, the penetration depth is the distance from the origin to the boundary of the
  Minkowski difference core - box (scipy's ConvexHull of the vertex differences: the depth is the least
  facet distance), and so is box-box's;
- a plane: the lowest core point or box vertex.
A primitive's surface is its signed distance sdf = 0 (sphere |x - c| - r, capsule the distance to its
segment - r, box the box's). Each manifold point p with depth d and normal n stands for b's surface point
p + d/2 n and a's p - d/2 n; both lie in their shapes (sdf <= tol), and at the deepest point, and
at every box-box face point, on their surfaces (|sdf| <= tol). The tolerance 1e-9 m is rounding in
shapes of size ~1 m, far below what a wrong formula gives (a sign, a swapped axis, a missing half: mm).
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from rbcli.physics.contact.box_box import EDGE_FEATURE
from rbcli.physics.contact.manifold import MANIFOLD_POINTS, make_manifold
from rbcli.physics.contact.primitive_boxes import AXIS_PREFERENCE
from rbcli.physics.contact.primitives import (
    PRIMITIVE_BOX,
    PRIMITIVE_CAPSULE,
    PRIMITIVE_SPHERE,
    primitive_pair,
    primitive_plane,
)
from rbcli.physics.rotation import quat_from_axis_angle, quat_to_matrix, random_unit_quaternions

SPHERE, CAPSULE, BOX = PRIMITIVE_SPHERE, PRIMITIVE_CAPSULE, PRIMITIVE_BOX
TOL = 1e-9
PAIRS = [(a, b) for a in (SPHERE, CAPSULE, BOX) for b in (SPHERE, CAPSULE, BOX)]
NAMES = {SPHERE: "sphere", CAPSULE: "capsule", BOX: "box"}


class Shape:
    """A primitive as the kernels take it: kind, centre c, rotation R (columns: axes), size."""

    def __init__(self, kind: int, c: np.ndarray, R: np.ndarray, size: np.ndarray) -> None:
        self.kind, self.c, self.R, self.size = kind, np.asarray(c, float), np.asarray(R, float), np.asarray(size, float)

    def moved(self, Q: np.ndarray, T: np.ndarray) -> Shape:
        return Shape(self.kind, Q @ self.c + T, Q @ self.R, self.size)

    def shifted(self, d: np.ndarray) -> Shape:
        return Shape(self.kind, self.c + d, self.R, self.size)

    @property
    def radius(self) -> float:
        return 0.0 if self.kind == BOX else float(self.size[0])

    @property
    def half(self) -> float:
        return float(self.size[1]) if self.kind == CAPSULE else 0.0

    def core_vertices(self) -> np.ndarray:
        if self.kind == BOX:
            signs = np.array([[(v >> k) & 1 for k in range(3)] for v in range(8)]) * 2.0 - 1.0
            return self.c + (signs * self.size) @ self.R.T
        u = self.R[:, 2]
        return np.array([self.c - self.half * u, self.c + self.half * u])

    def sdf(self, x: np.ndarray) -> np.ndarray:
        x = np.atleast_2d(x)
        if self.kind == BOX:
            return box_sdf(x, self.c, self.R, self.size)
        return segment_distance(x, self.c, self.R[:, 2], self.half) - self.size[0]


def segment_distance(x: np.ndarray, c: np.ndarray, u: np.ndarray, h: float) -> np.ndarray:
    s = np.clip((x - c) @ u, -h, h)
    return np.linalg.norm(x - (c + s[:, None] * u), axis=1)


def box_sdf(x: np.ndarray, c: np.ndarray, R: np.ndarray, h: np.ndarray) -> np.ndarray:
    q = np.abs((x - c) @ R) - h
    return np.linalg.norm(np.maximum(q, 0.0), axis=1) + np.minimum(q.max(axis=1), 0.0)


def golden_min(f, lo: float, hi: float) -> float:  # noqa: ANN001
    """min of a convex f on [lo, hi] (golden-section search to rounding, ends included)."""
    best = min(f(lo), f(hi))
    g = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = lo, hi
    for _ in range(120):
        x1, x2 = b - g * (b - a), a + g * (b - a)
        if f(x1) <= f(x2):
            b = x2
        else:
            a = x1
    return min(best, f(0.5 * (a + b)))


def minkowski_depth(a: np.ndarray, b: np.ndarray) -> float:
    """The penetration depth of hull(a) and hull(b) (> 0), or minus a lower bound of their distance."""
    hull = ConvexHull((a[:, None, :] - b[None, :, :]).reshape(-1, 3))
    offsets = hull.equations[:, 3]  # n . x + offset <= 0 inside; the origin's distance to facet i: -offset_i
    return float(-offsets.max()) if offsets.max() > 0 else float((-offsets).min())


def reference_depth(a: Shape, b: Shape) -> float:
    """The deepest overlap of a and b [m] (negative: separated by at least its size)."""
    if a.kind == BOX and b.kind == BOX:
        return minkowski_depth(a.core_vertices(), b.core_vertices())
    if a.kind == BOX:
        a, b = b, a
    u = a.R[:, 2]

    def along(s: float) -> float:
        return float(b.sdf(a.c + s * u)[0] if b.kind == BOX else b.sdf(a.c + s * u)[0] + b.radius)

    inner = golden_min(along, -a.half, a.half)
    if b.kind == BOX and inner <= 0.0:
        return a.radius + minkowski_depth(a.core_vertices(), b.core_vertices())
    return a.radius + b.radius - inner


def run_pair(a: Shape, b: Shape) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    out = make_manifold()
    n = primitive_pair(a.kind, a.c, a.R, a.size, b.kind, b.c, b.R, b.size, out)
    assert 0 <= n <= MANIFOLD_POINTS
    return out.point[:n].copy(), out.normal[:n].copy(), out.depth[:n].copy(), out.feature[:n].copy()


def run_plane(a: Shape, p0: np.ndarray, n0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    out = make_manifold()
    n = primitive_plane(a.kind, a.c, a.R, a.size, p0, n0, out)
    assert 0 <= n <= MANIFOLD_POINTS
    return out.point[:n].copy(), out.normal[:n].copy(), out.depth[:n].copy(), out.feature[:n].copy()


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    return quat_to_matrix(random_unit_quaternions(rng, 1)[0])


def random_shape(rng: np.random.Generator, kind: int, R: np.ndarray | None = None) -> Shape:
    if kind == SPHERE:
        size = np.array([rng.uniform(0.05, 0.5), 0.0, 0.0])
    elif kind == CAPSULE:
        size = np.array([rng.uniform(0.05, 0.3), rng.uniform(0.05, 0.6), 0.0])
    else:
        size = rng.uniform(0.05, 0.6, 3)
    return Shape(kind, np.zeros(3), random_rotation(rng) if R is None else R, size)


def bound(s: Shape) -> float:
    return float(np.linalg.norm(s.size)) if s.kind == BOX else s.radius + s.half


def check_manifold(a: Shape, b: Shape, ref: float, result) -> None:  # noqa: ANN001
    """The manifold of a and b against the reference depth `ref` (module docstring)."""
    point, normal, depth, feature = result
    both_boxes = a.kind == BOX and b.kind == BOX
    if ref > TOL:
        assert len(depth) >= 1, f"overlap {ref:.3g} m found no contact"
    if ref < -TOL:
        assert len(depth) == 0, f"separated by {-ref:.3g} m, found {depth}"
    if len(depth) == 0:
        return
    assert np.allclose(np.linalg.norm(normal, axis=1), 1.0, atol=1e-12)
    assert np.all(depth > 0.0)
    assert len(set(feature.tolist())) == len(feature), f"features not distinct: {feature}"
    # box-box: a face axis may be taken over an edge axis up to 1 / AXIS_PREFERENCE deeper
    assert depth.max() <= (ref / AXIS_PREFERENCE if both_boxes or BOX in (a.kind, b.kind) else ref) + TOL
    # a capsule's segment inside a box: its points are the segment clipped to the face of the chosen axis
    core_inside = BOX in (a.kind, b.kind) and not both_boxes and ref > a.radius + b.radius + TOL
    if core_inside:
        radius = a.radius + b.radius
        assert radius - TOL <= depth.max() <= radius + (ref - radius) / AXIS_PREFERENCE + TOL
    elif not both_boxes:
        assert abs(depth.max() - ref) <= TOL, f"deepest {depth.max():.12g} against reference {ref:.12g}"
    else:  # the incident face holds the other box's deepest corner; here it is over the reference face
        assert depth.max() >= ref - TOL, f"deepest {depth.max():.12g} against reference {ref:.12g}"
    on_b = b.sdf(point + 0.5 * depth[:, None] * normal)
    on_a = a.sdf(point - 0.5 * depth[:, None] * normal)
    assert np.all(on_a <= TOL) and np.all(on_b <= TOL), (on_a, on_b)
    exact = feature < EDGE_FEATURE if both_boxes else depth == depth.max()
    # (a segment inside a box: the face's point of a tilted segment lies under the capsule's surface)
    if not core_inside or a.kind == BOX:
        assert np.all(np.abs(on_a[exact]) <= TOL), (on_a, feature)
    if not core_inside or b.kind == BOX:
        assert np.all(np.abs(on_b[exact]) <= TOL), (on_b, feature)


def placed_pair(rng: np.random.Generator, ka: int, kb: int, parallel: bool = False) -> tuple[Shape, Shape]:
    """b at a random pose, a at a random offset from overlapping deeply to apart; `parallel`: a capsule
    or box a with b's own rotation (parallel axes, edges and faces)."""
    b = random_shape(rng, kb)
    a = random_shape(rng, ka, R=b.R.copy() if parallel else None)
    direction = rng.standard_normal(3)
    direction /= np.linalg.norm(direction)
    a = a.shifted(direction * rng.uniform(0.0, 1.1) * (bound(a) + bound(b)) + rng.normal(scale=0.1, size=3))
    T = rng.normal(size=3)
    return a.moved(np.eye(3), T), b.moved(np.eye(3), T)


@pytest.mark.parametrize(("ka", "kb"), PAIRS, ids=[f"{NAMES[a]}-{NAMES[b]}" for a, b in PAIRS])
def test_random_poses_against_the_reference(ka, kb):
    """Random sizes, poses and offsets (a third with parallel axes), each also just separated (-1e-7 m)
    and just touching (+1e-7 m) along the kernel's own normal, and deep: the count, the deepest depth and
    the points' surfaces against the reference."""
    rng = np.random.default_rng(1000 + 3 * ka + kb)
    overlapping = 0
    for case in range(150):
        a, b = placed_pair(rng, ka, kb, parallel=case % 3 == 0)
        ref = reference_depth(a, b)
        result = run_pair(a, b)
        check_manifold(a, b, ref, result)
        if len(result[2]) == 0:
            continue
        overlapping += 1
        deepest = int(np.argmax(result[2]))
        n, d = result[1][deepest], result[2][deepest]
        for gap in (1e-7, -1e-7):  # moved apart along n until just separated, then just touching
            moved = a.shifted(n * (d + gap))
            check_manifold(moved, b, reference_depth(moved, b), run_pair(moved, b))
    assert overlapping >= 40  # the offsets cover overlap as well as separation


@pytest.mark.parametrize("kind", [SPHERE, CAPSULE, BOX], ids=["sphere", "capsule", "box"])
def test_planes_against_the_reference(kind):
    """Against a plane: depth r - min (x - p0) . n over the core's ends or the box's vertices; every point
    of a capsule end or box vertex below the plane (box: the 4 deepest), on the surfaces."""
    rng = np.random.default_rng(7 + kind)
    for case in range(200):
        a = random_shape(rng, kind)
        if case % 4 == 0:  # flat: a capsule's axis along the plane, a box's face on it: 2 or 4 touch at once
            a = Shape(kind, a.c, yaw(np.pi / 2, (0, 1, 0)) if kind == CAPSULE else np.eye(3), a.size)
        n0 = rng.standard_normal(3) if case % 4 else np.array([0.0, 0.0, 1.0])
        n0 /= np.linalg.norm(n0)
        p0 = rng.normal(size=3)
        reach = bound(a) if case % 4 else a.radius + (a.size[2] if kind == BOX else 0.0)
        a = a.shifted(p0 + n0 * rng.uniform(-1.0, 1.2) * reach - a.c)
        point, normal, depth, feature = run_plane(a, p0, n0)
        lows = a.radius - (a.core_vertices() - p0) @ n0 if kind != SPHERE else np.array([a.radius - (a.c - p0) @ n0])
        below = np.sort(lows[lows > 0.0])[::-1][:MANIFOLD_POINTS]
        assert np.allclose(np.sort(depth)[::-1], below, atol=TOL)
        if len(depth):
            assert np.allclose(normal, n0, atol=0.0)
            assert len(set(feature.tolist())) == len(feature)
            assert np.allclose((point - p0) @ n0, -0.5 * depth, atol=TOL)  # halfway: the plane side
            on_a = a.sdf(point - 0.5 * depth[:, None] * normal)  # a capsule's higher end: inside a
            assert np.all(on_a <= TOL) and abs(on_a[np.argmax(depth)]) <= TOL
    flat = Shape(kind, [0, 0, 0.0], np.eye(3), [0.3, 0.2, 0.1])
    point, _, depth, feature = run_plane(flat.shifted([0, 0, flat.radius + (0.1 if kind == BOX else 0) - 1e-3]),
                                         np.zeros(3), np.array([0, 0, 1.0]))  # fmt: skip
    assert len(depth) == {SPHERE: 1, CAPSULE: 1, BOX: 4}[kind]  # the capsule's axis is z: it stands on an end
    if kind == CAPSULE:
        lying = Shape(CAPSULE, [0, 0, 0.3 - 1e-3], quat_to_matrix(quat_from_axis_angle([1, 0, 0], np.pi / 2)),
                      [0.3, 0.2, 0])  # fmt: skip
        point, _, depth, feature = run_plane(lying, np.zeros(3), np.array([0, 0, 1.0]))
        assert len(depth) == 2 and np.allclose(depth, 1e-3) and sorted(feature) == [0, 1]


def matched(first, second, flip: float) -> None:  # noqa: ANN001
    """The manifolds `first` and `second` hold the same points and depths, normals times `flip`."""
    p1, n1, d1, _ = first
    p2, n2, d2, _ = second
    assert len(d1) == len(d2), (d1, d2)
    for i in range(len(d1)):
        j = int(np.argmin(np.linalg.norm(p2 - p1[i], axis=1)))
        assert np.allclose(p1[i], p2[j], atol=1e-9) and abs(d1[i] - d2[j]) <= 1e-9, (p1, p2, d1, d2)
        assert np.allclose(n1[i], flip * n2[j], atol=1e-9)


@pytest.mark.parametrize(("ka", "kb"), PAIRS, ids=[f"{NAMES[a]}-{NAMES[b]}" for a, b in PAIRS])
def test_symmetry_and_invariance(ka, kb):
    """a-b is b-a with the normals turned round (the same points and depths), and moving both shapes by one
    rigid motion moves the manifold with them."""
    rng = np.random.default_rng(50 + 3 * ka + kb)
    for case in range(60):
        a, b = placed_pair(rng, ka, kb, parallel=case % 3 == 0)
        forward = run_pair(a, b)
        matched(forward, run_pair(b, a), -1.0)
        Q, T = random_rotation(rng), rng.normal(size=3)
        p, n, d, f = forward
        moved = run_pair(a.moved(Q, T), b.moved(Q, T))
        matched((p @ Q.T + T, n @ Q.T, d, f), moved, 1.0)
        assert sorted(moved[3].tolist()) == sorted(f.tolist())


def yaw(angle: float, axis=(0, 0, 1)) -> np.ndarray:  # noqa: ANN001
    return quat_to_matrix(quat_from_axis_angle(np.asarray(axis, float), angle))


def test_box_resting_flat_on_a_bigger_box_has_four_points():
    """A box (yawed 0.3 rad) sunk d = 1 mm into a bigger box's top: its 4 bottom corners, each at depth d,
    halfway through the overlap (z = top - d/2), normal +z; the same from b-a; lifted 1 mm, nothing."""
    big = Shape(BOX, [0.1, -0.2, 0.0], np.eye(3), [1.0, 0.8, 0.25])
    small = Shape(BOX, [0.3, 0.1, 0.25 + 0.1 - 1e-3], yaw(0.3), [0.2, 0.15, 0.1])
    point, normal, depth, feature = run_pair(small, big)
    assert len(depth) == 4 and np.allclose(depth, 1e-3, atol=1e-12)
    assert np.allclose(normal, [0, 0, 1.0]) and np.allclose(point[:, 2], 0.25 - 0.5e-3)
    corners = small.core_vertices()
    corners = corners[corners[:, 2] < small.c[2]]
    assert np.allclose(np.sort(point[:, :2], axis=0), np.sort(corners[:, :2], axis=0))
    assert np.all(feature < EDGE_FEATURE)
    matched((point, normal, depth, feature), run_pair(big, small), -1.0)
    assert len(run_pair(small.shifted([0, 0, 2e-3]), big)[2]) == 0


def test_tilted_box_edge_has_two_points_and_a_corner_one():
    """Tilted about x by 0.2 rad so its lowest edge is 1 mm into the bigger box: 2 points, the edge's
    ends, at depth 1 mm; tilted about x and y: its lowest corner alone."""
    big = Shape(BOX, [0, 0, 0.0], np.eye(3), [1.0, 1.0, 0.25])
    tilt = yaw(0.2, (1, 0, 0))
    box = Shape(BOX, [0, 0, 0.0], tilt, [0.2, 0.15, 0.1])
    box = box.shifted([0, 0, 0.25 - box.core_vertices()[:, 2].min() - 1e-3])
    point, normal, depth, _ = run_pair(box, big)
    assert len(depth) == 2 and np.allclose(depth, 1e-3, atol=1e-12) and np.allclose(normal, [0, 0, 1.0])
    assert np.isclose(abs(point[0, 0] - point[1, 0]), 0.4)  # the two ends of the 0.4 m edge
    corner = Shape(BOX, [0, 0, 0.0], yaw(0.3, (0, 1, 0)) @ tilt, [0.2, 0.15, 0.1])
    corner = corner.shifted([0, 0, 0.25 - corner.core_vertices()[:, 2].min() - 1e-3])
    assert np.allclose(run_pair(corner, big)[2], [1e-3])


def test_box_edges_crossing_give_one_edge_point():
    """Two long boxes turned 45 deg about x and about y, so a's lowest edge (along x) crosses b's highest
    edge (along y) 1 mm deep: one point, the edges' midway, normal +z, depth 1 mm."""
    h = np.array([0.5, 0.1, 0.1])
    a = Shape(BOX, [0, 0, 0.0], yaw(np.pi / 4, (1, 0, 0)), h)
    b = Shape(BOX, [0, 0, 0.0], yaw(np.pi / 4, (0, 1, 0)), h[[1, 0, 2]])
    a = a.shifted([0, 0, 2 * 0.1 * np.sqrt(2) - 1e-3])
    point, normal, depth, feature = run_pair(a, b)
    assert len(depth) == 1 and feature[0] >= EDGE_FEATURE
    assert np.isclose(depth[0], 1e-3, atol=1e-12) and np.allclose(normal, [[0, 0, 1.0]], atol=1e-12)
    assert np.allclose(point[0], [0, 0, 0.1 * np.sqrt(2) - 0.5e-3], atol=1e-12)


def test_capsules_side_by_side_have_two_points():
    """Parallel capsules 1 mm into each other, overlapping over x in [0, 0.3]: two points at the overlap's
    ends, both 1 mm deep, normal -y; crossed at right angles: one; laid end to end: one."""
    lying = yaw(np.pi / 2, (0, 1, 0))  # axis along x
    a = Shape(CAPSULE, [0.0, 0.0, 0.0], lying, [0.1, 0.25, 0])
    b = Shape(CAPSULE, [0.1, 0.2 - 1e-3, 0.0], lying, [0.1, 0.15, 0])
    point, normal, depth, _ = run_pair(a, b)
    assert len(depth) == 2 and np.allclose(depth, 1e-3) and np.allclose(normal, [0, -1.0, 0])
    assert np.allclose(np.sort(point[:, 0]), [-0.05, 0.25]) and np.allclose(point[:, 1], 0.1 - 0.5e-3)
    crossed = Shape(CAPSULE, [0.0, 0.0, 0.2 - 1e-3], yaw(np.pi / 2, (1, 0, 0)), [0.1, 0.25, 0])  # along y
    point, normal, depth, feature = run_pair(a, crossed)
    assert np.allclose(depth, [1e-3]) and feature[0] == 4 and np.allclose(normal, [[0, 0, -1.0]])
    end_to_end = Shape(CAPSULE, [0.25 + 0.2 + 0.15 - 1e-3, 0, 0], lying, [0.1, 0.15, 0])
    assert np.allclose(run_pair(a, end_to_end)[2], [1e-3])


def test_capsule_on_a_box_face_has_two_points_and_on_an_edge_one():
    """A capsule lying on a box's top 1 mm deep: its two ends (features 0 and 1); one end beyond the face
    is clipped at the face's edge; lying across the box's top edge (tilted 45 deg): one point."""
    box = Shape(BOX, [0, 0, 0.0], np.eye(3), [0.5, 0.4, 0.2])
    lying = yaw(np.pi / 2, (0, 1, 0))
    capsule = Shape(CAPSULE, [0.1, 0, 0.2 + 0.05 - 1e-3], lying, [0.05, 0.3, 0])
    point, normal, depth, feature = run_pair(capsule, box)
    assert len(depth) == 2 and np.allclose(depth, 1e-3) and np.allclose(normal, [0, 0, 1.0])
    assert sorted(feature.tolist()) == [0, 1] and np.allclose(np.sort(point[:, 0]), [-0.2, 0.4])
    overhang = capsule.shifted([0.3, 0, 0])
    assert np.allclose(np.sort(run_pair(overhang, box)[0][:, 0]), [0.1, 0.5])  # clipped at x = 0.5
    out = np.array([1.0, 0.0, 1.0]) / np.sqrt(2.0)  # across the edge x = 0.5, z = 0.2, axis along (1, 0, -1)
    across = Shape(CAPSULE, np.array([0.5, 0, 0.2]) + (0.05 - 1e-3) * out, yaw(0.75 * np.pi, (0, 1, 0)), [0.05, 0.3, 0])
    point, normal, depth, feature = run_pair(across, box)
    assert np.allclose(depth, [1e-3]) and np.allclose(normal, [out]) and feature[0] == 2


def test_sphere_and_capsule_deep_in_a_box():
    """A sphere whose centre is inside the box: d = r + the centre's depth under the nearest face, normal
    that face's; a capsule whose segment is inside: r + its overlap along the least axis."""
    box = Shape(BOX, [0, 0, 0.0], yaw(0.4), [0.5, 0.4, 0.2])
    sphere = Shape(SPHERE, box.c + box.R @ [0.1, 0.05, 0.15], np.eye(3), [0.1, 0, 0])
    _, normal, depth, _ = run_pair(sphere, box)
    assert np.allclose(depth, [0.1 + 0.05]) and np.allclose(normal[0], box.R[:, 2])
    capsule = Shape(CAPSULE, box.c + box.R @ [0.0, 0.0, 0.15], box.R @ yaw(np.pi / 2, (0, 1, 0)), [0.05, 0.2, 0])
    _, normal, depth, _ = run_pair(capsule, box)
    assert len(depth) == 2 and np.allclose(depth, 0.05 + 0.05) and np.allclose(normal, box.R[:, 2])
