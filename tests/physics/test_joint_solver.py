"""The O(n) multiplier solver (rbcli/physics/joints/solver.py) against a dense numpy solve of A = G W G^T.

Reference: A built densely from the same rows (G: rows x 6 bodies, W = blockdiag(I3 / M, I_world^-1)) and
np.linalg.solve (lstsq for rank-deficient A). Tolerance of a forward error: a backward-stable solve of
A lambda = rhs has |lambda - lambda_ref| / |lambda_ref| <= c eps cond(A) (Higham, "Accuracy and Stability of
Numerical Algorithms", 7.1); both solves are backward stable, so the test asks for 100 eps cond(A), and at
least 1e-12 (the systems with masses of 0.1..10 kg have cond(A) ~ 1e2..1e5: 1e-12 is the bound there).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from rbcli.physics.joints.solver import factor_rows, joint_graph, make_solver_work, solve_rows
from rbcli.physics.joints.solver_graph import NODE_BODY, NODE_JOINT, redundancy_by_joint

ROOT = Path(__file__).resolve().parents[2]
EPS = np.finfo(float).eps


def random_system(rng, body_count, pairs, counts=None, ground=None, mass_range=(1e-3, 1e3)):  # noqa: ANN001, ANN201
    """Random rows (normal entries, both sides), masses and principal moments log-uniform over mass_range
    [kg, kg m^2], random world orientations."""
    a = np.array([p[0] for p in pairs], dtype=np.int64)
    b = np.array([p[1] for p in pairs], dtype=np.int64)
    counts = rng.integers(1, 7, len(pairs)) if counts is None else np.asarray(counts, dtype=np.int64)
    lo, hi = np.log(mass_range)
    inv_inertia = np.empty((body_count, 3, 3))
    for i in range(body_count):
        rotation, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        inv_inertia[i] = rotation @ np.diag(np.exp(-rng.uniform(lo, hi, 3))) @ rotation.T
    rows = int(counts.sum())
    return {
        "body_a": a,
        "body_b": b,
        "ground": np.zeros(body_count, bool) if ground is None else np.asarray(ground, bool),
        "row_count": counts,
        "row_start": np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64),
        "jac_a": rng.normal(size=(rows, 6)),
        "jac_b": rng.normal(size=(rows, 6)),
        "inv_mass": np.exp(-rng.uniform(lo, hi, body_count)),
        "inv_inertia": inv_inertia,
    }


def dense_matrices(s):  # noqa: ANN001, ANN201
    """G (rows, 6 N) and W (6 N, 6 N) of the system, ground bodies' columns zero: the obvious version."""
    n = s["ground"].shape[0]
    G = np.zeros((s["jac_a"].shape[0], 6 * n))
    W = np.zeros((6 * n, 6 * n))
    for j in range(s["body_a"].shape[0]):
        rows = slice(s["row_start"][j], s["row_start"][j] + s["row_count"][j])
        for body, jac in ((s["body_a"][j], s["jac_a"]), (s["body_b"][j], s["jac_b"])):
            if body >= 0 and not s["ground"][body]:
                G[rows, 6 * body : 6 * body + 6] = jac[rows]
    for i in np.flatnonzero(~s["ground"]):
        W[6 * i : 6 * i + 3, 6 * i : 6 * i + 3] = np.eye(3) * s["inv_mass"][i]
        W[6 * i + 3 : 6 * i + 6, 6 * i + 3 : 6 * i + 6] = s["inv_inertia"][i]
    return G, W


def fast_solve(s, rhs):  # noqa: ANN001, ANN201
    """(redundant count, lambda, graph, work) from the solver under test."""
    graph = joint_graph(s["body_a"], s["body_b"], s["ground"], s["row_count"])
    work = make_solver_work(graph)
    rows = (s["row_start"], s["row_count"], s["body_a"], s["body_b"])
    count = factor_rows(graph, work, *rows, s["jac_a"], s["jac_b"], s["inv_mass"], s["inv_inertia"])
    out = np.full_like(rhs, np.nan)
    solve_rows(graph, work, *rows, rhs, out)
    return count, out, graph, work


def check_against_dense(s, rng, solves=2) -> None:  # noqa: ANN001
    """Full-rank A: lambda within max(1e-12, 100 eps cond(A)) of np.linalg.solve, nothing reported redundant;
    the factor reused for several right-hand sides (as the integration's simplified Newton does)."""
    G, W = dense_matrices(s)
    A = G @ W @ G.T
    tolerance = max(1e-12, 100 * EPS * np.linalg.cond(A))
    graph = joint_graph(s["body_a"], s["body_b"], s["ground"], s["row_count"])
    work = make_solver_work(graph)
    rows = (s["row_start"], s["row_count"], s["body_a"], s["body_b"])
    assert factor_rows(graph, work, *rows, s["jac_a"], s["jac_b"], s["inv_mass"], s["inv_inertia"]) == 0
    for _ in range(solves):
        rhs = rng.normal(size=A.shape[0])
        out = np.full_like(rhs, np.nan)
        solve_rows(graph, work, *rows, rhs, out)
        reference = np.linalg.solve(A, rhs)
        error = np.linalg.norm(out - reference) / np.linalg.norm(reference)
        assert error <= tolerance, (error, tolerance)


def random_tree_pairs(rng, body_count, world_probability=0.1):  # noqa: ANN001, ANN201
    """Each body i > 0 jointed to a random earlier body (or the world), sides a/b in random order."""
    pairs = [(-1, 0)]
    for i in range(1, body_count):
        parent = -1 if rng.random() < world_probability else int(rng.integers(0, i))
        pairs.append((parent, i) if rng.random() < 0.5 else (i, parent))
    return pairs


@pytest.mark.parametrize("links", [1, 2, 7, 200])
@pytest.mark.parametrize("both_ends", [False, True])
def test_chains_match_dense_solve(links: int, both_ends: bool) -> None:
    """Chains tied to the world at one end (a tree) or both (a loop through the world)."""
    rng = np.random.default_rng(links + 1000 * both_ends)
    pairs = [(-1, 0)] + [(i, i + 1) for i in range(links - 1)] + ([(links - 1, -1)] if both_ends else [])
    # at most 6 rows per link in all, so A has full rank: tree joints 1..5 rows, the loop joint <= links
    counts = np.r_[rng.integers(1, 6, links), rng.integers(1, min(6, links) + 1, 1)] if both_ends else None
    s = random_system(rng, links, pairs, counts=counts)
    check_against_dense(s, rng)
    graph = joint_graph(s["body_a"], s["body_b"], s["ground"], s["row_count"])
    assert np.all(graph.node_kind == NODE_JOINT)  # a chain's bodies (degree <= 2) are all eliminated
    assert (graph.loop_joint.size > 0) == both_ends


@pytest.mark.parametrize("seed", range(6))
def test_random_trees_match_dense_solve(seed: int) -> None:
    """Random branching (hubs of degree >= 3 stay nodes), row counts 1..6, masses and inertias 1e-3..1e3."""
    rng = np.random.default_rng(seed)
    pairs = random_tree_pairs(rng, 40)
    s = random_system(rng, 40, pairs)
    check_against_dense(s, rng)
    graph = joint_graph(s["body_a"], s["body_b"], s["ground"], s["row_count"])
    parents = graph.node_parent
    assert np.all((parents == -1) | (parents > np.arange(parents.size)))  # every node before its parent
    world_joints = sum(1 for a, b in pairs if -1 in (a, b))  # each starts a tree of its own: no loop
    assert graph.loop_joint.size == 0 and np.count_nonzero(parents == -1) == world_joints


def test_star_keeps_its_hub_as_a_node() -> None:
    """One body with 50 joints (A would be a dense 50-joint block): the hub is one 6-unknown node."""
    rng = np.random.default_rng(7)
    for pairs in ([(0, i) for i in range(1, 51)], [(0, i) for i in range(1, 51)] + [(-1, 0)]):
        s = random_system(rng, 51, pairs, mass_range=(0.1, 10.0))
        check_against_dense(s, rng)
        graph = joint_graph(s["body_a"], s["body_b"], s["ground"], s["row_count"])
        assert graph.body_node[0] >= 0 and np.count_nonzero(graph.node_kind == NODE_BODY) == 1
        assert graph.node_kind.size == len(pairs) + 1 and graph.loop_joint.size == 0


def test_forest_of_floating_and_grounded_trees() -> None:
    """Three trees (one tied to the world, two floating) and two unjointed bodies in one system."""
    rng = np.random.default_rng(11)
    pairs, offset = [], 0
    for size, grounded in ((12, True), (9, False), (15, False)):
        tree = random_tree_pairs(rng, size, world_probability=0.0)[1:]
        pairs += [(a + offset, b + offset) for a, b in tree] + ([(-1, offset)] if grounded else [])
        offset += size
    s = random_system(rng, offset + 2, pairs)
    check_against_dense(s, rng)
    graph = joint_graph(s["body_a"], s["body_b"], s["ground"], s["row_count"])
    assert np.count_nonzero(graph.node_parent == -1) == 3


def test_ground_body_in_the_middle_of_a_chain() -> None:
    """Body 2 is static: it splits the chain and ties both parts to the world (the first part through both
    ends, a loop through the world), and its columns are dropped."""
    rng = np.random.default_rng(3)
    pairs = [(-1, 0), (0, 1), (1, 2), (2, 3), (3, 4), (4, 5)]
    ground = np.array([False, False, True, False, False, False])
    s = random_system(rng, 6, pairs, counts=[3, 2, 3, 5, 6, 4], ground=ground)
    check_against_dense(s, rng)
    graph = joint_graph(s["body_a"], s["body_b"], s["ground"], s["row_count"])
    assert set(graph.loop_joint) == {2}


def ladder_pairs(rungs: int) -> list[tuple[int, int]]:
    """Two rails of `rungs` bodies (0..rungs-1 and rungs..2 rungs-1) and a rung between each pair: rungs-1 loops."""
    rails = [(i, i + 1) for i in range(rungs - 1)] + [(rungs + i, rungs + i + 1) for i in range(rungs - 1)]
    return [(-1, 0), *rails, *((i, rungs + i) for i in range(rungs))]


@pytest.mark.parametrize("seed", range(3))
def test_loops_match_dense_solve(seed: int) -> None:
    """Four-bar of random rows (full rank), a ladder with 5 loops, random trees with extra loop joints."""
    rng = np.random.default_rng(100 + seed)
    four_bar = random_system(rng, 3, [(-1, 0), (0, 1), (1, 2), (2, -1)], counts=[3, 3, 3, 3])
    check_against_dense(four_bar, rng)
    ladder = random_system(rng, 12, ladder_pairs(6), counts=rng.integers(1, 4, 17), mass_range=(0.1, 10.0))
    check_against_dense(ladder, rng)
    assert joint_graph(ladder["body_a"], ladder["body_b"], ladder["ground"], ladder["row_count"]).loop_joint.size > 0
    pairs = random_tree_pairs(rng, 30)
    extra = [tuple(int(v) for v in rng.choice(30, 2, replace=False)) for _ in range(4)]
    s = random_system(rng, 30, pairs + extra, counts=np.r_[rng.integers(1, 7, 30), rng.integers(1, 3, 4)])
    check_against_dense(s, rng)


def hinge_rows(center_a, center_b, anchor, axis):  # noqa: ANN001, ANN201
    """(jac_a, jac_b), each (5, 6): anchor velocities equal (3 rows: v_a + w_a x r_a - v_b - w_b x r_b, with
    r = anchor - centre, so the angular block of row e_k is r x e_k) and w_a - w_b normal to the axis (2 rows)."""
    anchor, axis = np.asarray(anchor, float), np.asarray(axis, float) / np.linalg.norm(axis)
    t1 = np.cross(axis, [1.0, 0, 0] if abs(axis[0]) < 0.9 else [0, 1.0, 0])
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(axis, t1)
    jac_a, jac_b = np.zeros((5, 6)), np.zeros((5, 6))
    for k in range(3):
        e = np.eye(3)[k]
        jac_a[k] = np.r_[e, np.cross(anchor - center_a, e)]
        jac_b[k] = -np.r_[e, np.cross(anchor - center_b, e)]
    jac_a[3:, 3:] = t1, t2
    jac_b[3:, 3:] = -t1, -t2
    return jac_a, jac_b


def hinge_system(centers, joints):  # noqa: ANN001, ANN201
    """Bodies of unit mass and inertia diag(1, 2, 3) at `centers`, hinges (a, b, anchor, axis)."""
    n = len(centers)
    ja, jb = zip(
        *(hinge_rows(centers[a] if a >= 0 else 0, centers[b] if b >= 0 else 0, p, u) for a, b, p, u in joints),
        strict=True,
    )
    return {
        "body_a": np.array([j[0] for j in joints]),
        "body_b": np.array([j[1] for j in joints]),
        "ground": np.zeros(n, bool),
        "row_count": np.full(len(joints), 5),
        "row_start": 5 * np.arange(len(joints)),
        "jac_a": np.concatenate(ja),
        "jac_b": np.concatenate(jb),
        "inv_mass": np.ones(n),
        "inv_inertia": np.tile(np.diag([1.0, 0.5, 1 / 3]), (n, 1, 1)),
    }


def check_redundant(s, expected: int, joint: int, involved: list[int]) -> None:  # noqa: ANN001
    """A rank-deficient A: `expected` rows reported, all of `joint`; for a consistent rhs (= A z) the answer
    solves A lambda = rhs and gives the same constraint impulse G^T lambda as the minimum-norm lstsq one
    (G^T lambda is unique for a consistent rhs: the velocity change W G^T lambda is the projection)."""
    G, W = dense_matrices(s)
    A = G @ W @ G.T
    assert np.linalg.matrix_rank(A) == A.shape[0] - expected
    rng = np.random.default_rng(5)
    rhs = A @ rng.normal(size=A.shape[0])
    count, out, _, work = fast_solve(s, rhs)
    assert count == expected
    first = s["row_start"][joint]
    assert set(work.redundant_row[:count]) <= set(range(first, first + s["row_count"][joint]))
    assert np.all(out[work.redundant_row[:count]] == 0.0)
    graph = joint_graph(s["body_a"], s["body_b"], s["ground"], s["row_count"])
    rows = (s["row_start"], s["row_count"], work.redundant_row[:count])
    assert redundancy_by_joint(s["body_a"], s["body_b"], s["ground"], graph.joint_node, *rows) == [(involved, expected)]
    scale = np.linalg.norm(A) * np.linalg.norm(out) + np.linalg.norm(rhs)
    assert np.linalg.norm(A @ out - rhs) <= 1e-13 * scale
    reference = np.linalg.lstsq(A, rhs, rcond=None)[0]
    assert np.linalg.norm(G.T @ (out - reference)) <= 1e-12 * np.linalg.norm(G.T @ reference)


def test_planar_four_bar_has_three_redundant_rows() -> None:
    """Four hinges with parallel axes in a closed loop: 18 - 1 = 17 independent rows of 20 (mobility 1)."""
    p = np.array([[0.0, 0, 0], [0.0, 1, 0], [2.0, 1.2, 0], [2.0, 0, 0]])
    centers = [(p[0] + p[1]) / 2, (p[1] + p[2]) / 2, (p[2] + p[3]) / 2]
    z = [0, 0, 1.0]
    s = hinge_system(centers, [(-1, 0, p[0], z), (0, 1, p[1], z), (1, 2, p[2], z), (2, -1, p[3], z)])
    check_redundant(s, 3, joint=3, involved=[3, 2, 1, 0])  # the loop joint, then its cycle from its body a (2)


def test_door_on_two_coaxial_hinges() -> None:
    """A door on a top and a bottom hinge with one axis: the second hinge's 5 rows repeat the first's."""
    s = hinge_system([np.array([0.5, 0, 1.0])], [(-1, 0, np.zeros(3), [0, 0, 1.0]), (0, -1, [0, 0, 2.0], [0, 0, 1])])
    check_redundant(s, 5, joint=1, involved=[1, 0])


def test_repeated_row_inside_a_tree_joint() -> None:
    """A tree joint whose own rows are dependent: the pivot inside its block is dropped, one row reported."""
    rng = np.random.default_rng(2)
    s = random_system(rng, 3, [(-1, 0), (0, 1), (1, 2)], counts=[3, 4, 2], mass_range=(0.1, 10.0))
    s["jac_a"][5], s["jac_b"][5] = 2 * s["jac_a"][4], 2 * s["jac_b"][4]  # joint 1's row 2 = 2 x its row 1
    check_redundant(s, 1, joint=1, involved=[1])


def test_work_arrays_grow_linearly() -> None:
    """O(n) memory: the work's size is affine in n, s(n) = s0 + c n, for a chain and a star (s(1000) - s(100)
    = 9 (s(200) - s(100))), and closing a 1,000-link chain to the world (k = 5 loop rows) adds O(n + k^2)
    (the refinement's copy of the rows and bodies: 2 x 6 x 5,005 + 19 x 1,000 floats), not n k x 6."""

    def size(pairs) -> int:  # noqa: ANN001
        ends = np.array(pairs)
        graph = joint_graph(ends[:, 0], ends[:, 1], np.zeros(ends.max() + 1, bool), np.full(len(pairs), 5))
        return sum(a.size for a in make_solver_work(graph))

    for build in (
        lambda n: [(-1, 0)] + [(i, i + 1) for i in range(n - 1)],
        lambda n: [(0, i) for i in range(1, n + 1)],
    ):
        assert size(build(1000)) - size(build(100)) == 9 * (size(build(200)) - size(build(100)))
    chain = [(-1, 0)] + [(i, i + 1) for i in range(999)]
    assert size([*chain, (999, -1)]) - size(chain) < 14 * 5005 + 19 * 1000 + 1000


def test_malformed_graphs_are_refused() -> None:
    """A joint to itself, one with no moving body and one with 7 rows: ValueError naming the joint."""
    ground = np.array([False, True])
    for a, b, counts, words in (
        ([0], [0], [3], "itself"),
        ([1], [-1], [3], "no moving body"),
        ([0], [-1], [7], "7 rows"),
        ([0], [2], [3], "not a body index"),
    ):
        with pytest.raises(ValueError, match=words):
            joint_graph(np.array(a), np.array(b), ground, np.array(counts))


def test_factor_and_solve_do_not_allocate() -> None:
    """numba's allocation counter (NRT statistics, on in a fresh process) does not move over 1 or 50 rounds
    of factor + 3 solves on a graph with a loop and a hub; a kernel that allocates (np.empty) moves it, so
    the counter is live."""
    code = (
        "import numba, numpy as np\n"
        "from numba.core.runtime import rtsys\n"
        "from rbcli.physics.joints.solver import factor_rows, joint_graph, make_solver_work, solve_rows\n"
        "pairs = [(-1, 0), (0, 1), (1, 2), (2, -1), (0, 3), (0, 4), (0, 5)]\n"
        "a, b = np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])\n"
        "counts = np.array([3, 2, 3, 2, 5, 6, 4]); start = np.r_[0, np.cumsum(counts)[:-1]]\n"
        "rng = np.random.default_rng(0); R = counts.sum()\n"
        "ja, jb, im = rng.normal(size=(R, 6)), rng.normal(size=(R, 6)), np.ones(6)\n"
        "ii = np.tile(np.eye(3), (6, 1, 1)); g = joint_graph(a, b, np.zeros(6, bool), counts)\n"
        "w = make_solver_work(g); rhs = rng.normal(size=R); out = np.zeros(R)\n"
        "args = (start, counts, a, b)\n"
        "factor_rows(g, w, *args, ja, jb, im, ii); solve_rows(g, w, *args, rhs, out)\n"
        "for n in (1, 50):\n"
        "    before = rtsys.get_allocation_stats().alloc\n"
        "    for _ in range(n):\n"
        "        factor_rows(g, w, *args, ja, jb, im, ii)\n"
        "        for _ in range(3):\n"
        "            solve_rows(g, w, *args, rhs, out)\n"
        "    print(rtsys.get_allocation_stats().alloc - before)\n"
        "allocating = numba.njit(lambda n: np.empty(n).size)\n"
        "allocating(3); before = rtsys.get_allocation_stats().alloc; allocating(3)\n"
        "print(rtsys.get_allocation_stats().alloc - before)\n"
    )
    env = {**os.environ, "NUMBA_NRT_STATS": "1", "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=env, check=True)
    short, long, control = (int(v) for v in out.stdout.split())
    assert short == long == 0 and control > 0, (short, long, control)


def test_long_hinge_chain_has_no_redundant_rows() -> None:
    """3,000 straight capsule links on parallel hinges (the benchmark's links: 0.1 m, radius 0.01 m, 1000
    kg/m^3): A is beam-like (cond ~ n^4) and the smallest pivot ~1e-11 A_rr, yet no row is redundant (the
    chain has 1 dof per link). None is reported, and one velocity projection (A lambda = G v,
    v' = v - W G^T lambda) leaves |G v'| <= 1e-7 |G v| (measured 1.7e-9; eps sqrt(cond) bounds it)."""
    links, length, radius = 3000, 0.1, 0.01
    mass = 1000 * np.pi * radius**2 * (length + 4 * radius / 3)
    centers = [np.array([(i + 0.5) * length, 0, 0]) for i in range(links)]
    joints = [(i - 1, i, np.array([i * length, 0, 0]), [0, 1.0, 0]) for i in range(links)]
    s = hinge_system(centers, joints)
    s["inv_mass"][:] = 1 / mass
    s["inv_inertia"][:] = np.diag([2 / (mass * radius**2), 12 / (mass * length**2), 12 / (mass * length**2)])
    rng = np.random.default_rng(9)
    velocity = rng.normal(size=6 * links)
    rows = np.arange(5 * links)
    joint_of_row = rows // 5
    a, b = s["body_a"][joint_of_row], s["body_b"][joint_of_row]

    def g_times(v: np.ndarray) -> np.ndarray:  # G v from the rows, body a's side only where it moves
        v = v.reshape(links, 6)
        out = np.einsum("ri,ri->r", s["jac_b"], v[b])
        out[a >= 0] += np.einsum("ri,ri->r", s["jac_a"][a >= 0], v[a[a >= 0]])
        return out

    rhs = g_times(velocity)
    count, lam, _, _ = fast_solve(s, rhs)
    assert count == 0
    impulse = np.zeros((links, 6))
    np.add.at(impulse, b, s["jac_b"] * lam[:, None])
    np.add.at(impulse, a[a >= 0], s["jac_a"][a >= 0] * lam[a >= 0, None])
    change = np.concatenate([impulse[:, :3] / mass, np.einsum("bij,bj->bi", s["inv_inertia"], impulse[:, 3:])], axis=1)
    assert np.linalg.norm(g_times(velocity - change.ravel())) <= 1e-7 * np.linalg.norm(rhs)
