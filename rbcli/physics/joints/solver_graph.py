"""The joint graph ordered once for the O(n) multiplier solver (numpy, at compile time): solver.py's JointGraph.

Nodes and edges (Baraff 1996, "Linear-time dynamics using Lagrange multipliers", sections 4-7): the augmented
matrix H = [[M, G^T], [G, 0]] has a node per moving body (6 unknowns: its velocity) and per joint (its
row_count multipliers), an edge per body-joint incidence. Ground bodies (static, kinematic) and the world
are not nodes: their columns of G are dropped. The edges of joints taken in index order build a spanning
forest by union-find, with the world (all ground bodies) as one extra vertex: a joint whose two ends are
already connected closes a cycle and is a LOOP joint (its rows are auxiliary, Baraff section 7); so is every
world joint of a component after its first (a chain fixed at both ends is a loop through the world).

Body elimination (an equivalent of Baraff's factorisation with fewer operations, exact, no fill-in): a body
of tree degree 1 or 2 is eliminated first, analytically, since its block of H is M_b and M_b^-1 = W_b is
known. Eliminating it adds -J_jb W_b J_jb^T to its joints' diagonal blocks and, for degree 2, the block
-J_jb W_b J_kb^T between its two joints j and k: on a chain this is the block-tridiagonal A = G W G^T.
Eliminating a vertex of degree <= 2 of a tree leaves a tree (a leaf disappears, a degree-2 vertex becomes
an edge), so no fill-in ever appears. Bodies of degree >= 3 ("hubs") stay nodes: eliminating them would
join all their joints pairwise (a star of n joints would make A dense, O(n^2) memory, O(n^3) work), while
as nodes they cost one 6 x 6 block each. The remaining forest (tree joints + hubs) is ordered leaves first
(reverse breadth-first order from each root), so every node precedes its parent and the block LDL^T
elimination has no fill-in: O(n) memory and work on any tree.

Roots: a component's world joint (if it has one) is its root. A world joint whose only moving body is a
hub has a zero diagonal block (no eliminated body feeds it); as a leaf its pivot would be zero, as the
root it receives its hub's Schur complement first.
"""

from __future__ import annotations

from collections import deque

import numpy as np

NODE_JOINT = 0  # a node holding one joint's multipliers (row_count unknowns)
NODE_BODY = 1  # a node holding a hub body's velocity (6 unknowns)
MAX_JOINT_ROWS = 6


def _int_array(values: object, name: str, dims: int) -> np.ndarray:
    out = np.ascontiguousarray(np.asarray(values), dtype=np.int64)
    if out.ndim != dims:
        raise ValueError(f"{name} must have {dims} dimension(s), got shape {out.shape}")
    return out


def build_graph_arrays(body_a: object, body_b: object, body_ground: object, row_count: object) -> dict[str, np.ndarray]:
    """The JointGraph's arrays (solver.py documents each) from the joints' bodies and row counts.

    Raises ValueError for out-of-range bodies, row counts outside 1..6, a joint attached twice to one body
    and a joint with no moving body (its rows would constrain nothing).
    """
    a = _int_array(body_a, "body_a", 1)
    b = _int_array(body_b, "body_b", 1)
    counts = _int_array(row_count, "row_count", 1)
    ground = np.ascontiguousarray(np.asarray(body_ground, dtype=bool))
    body_count, joint_count = ground.shape[0], a.shape[0]
    if b.shape[0] != joint_count or counts.shape[0] != joint_count:
        raise ValueError("body_a, body_b and row_count must have one entry per joint")
    for name, ends in (("body_a", a), ("body_b", b)):
        bad = np.flatnonzero((ends < -1) | (ends >= body_count))
        if bad.size:
            j = bad[0]
            raise ValueError(f"joint {j}: {name} = {ends[j]} is not a body index; expected -1..{body_count - 1}")
    bad = np.flatnonzero((counts < 1) | (counts > MAX_JOINT_ROWS))
    if bad.size:
        raise ValueError(f"joint {bad[0]}: {counts[bad[0]]} rows; expected 1..{MAX_JOINT_ROWS}")
    bad = np.flatnonzero((a == b) & (a >= 0))
    if bad.size:
        raise ValueError(f"joint {bad[0]} connects body {a[bad[0]]} to itself; expected two different bodies")
    moving_a = (a >= 0) & ~ground[np.maximum(a, 0)]
    moving_b = (b >= 0) & ~ground[np.maximum(b, 0)]
    bad = np.flatnonzero(~moving_a & ~moving_b)
    if bad.size:
        raise ValueError(f"joint {bad[0]} connects no moving body; expected one that is not static or kinematic")

    # spanning forest by union-find; vertex body_count is the world (every ground body and -1)
    root = list(range(body_count + 1))

    def find(v: int) -> int:
        while root[v] != v:
            root[v] = root[root[v]]
            v = root[v]
        return v

    end_a = np.where(moving_a, a, body_count)
    end_b = np.where(moving_b, b, body_count)
    in_tree = np.zeros(joint_count, dtype=bool)
    for j in range(joint_count):
        ra, rb = find(int(end_a[j])), find(int(end_b[j]))
        if ra != rb:
            root[ra] = rb
            in_tree[j] = True

    # tree joints per moving body (both ends), the degree that decides elimination
    body_joints: list[list[int]] = [[] for _ in range(body_count)]
    for j in np.flatnonzero(in_tree):
        for end, moving in ((a[j], moving_a[j]), (b[j], moving_b[j])):
            if moving:
                body_joints[int(end)].append(int(j))
    hub = np.array([len(js) >= 3 for js in body_joints], dtype=bool)

    # the contracted forest: vertex j < joint_count is tree joint j, joint_count + h is hub body h;
    # each neighbour is stored with the body the edge passes through
    vertex_count = joint_count + body_count
    neighbours: list[list[tuple[int, int]]] = [[] for _ in range(vertex_count)]
    for body, js in enumerate(body_joints):
        if hub[body]:
            for j in js:
                neighbours[j].append((joint_count + body, body))
                neighbours[joint_count + body].append((j, body))
        elif len(js) == 2:
            neighbours[js[0]].append((js[1], body))
            neighbours[js[1]].append((js[0], body))
    present = np.zeros(vertex_count, dtype=bool)
    present[:joint_count] = in_tree
    present[joint_count:] = hub
    world_joint = in_tree & ~(moving_a & moving_b)
    starts = [*np.flatnonzero(world_joint), *np.flatnonzero(present & ~np.pad(world_joint, (0, body_count)))]
    seen = np.zeros(vertex_count, dtype=bool)
    bfs: list[int] = []
    bfs_parent = np.full(vertex_count, -1, dtype=np.int64)
    bfs_edge_body = np.full(vertex_count, -1, dtype=np.int64)
    for start in starts:
        if seen[start]:
            continue
        seen[start] = True
        queue = deque([int(start)])
        while queue:
            v = queue.popleft()
            bfs.append(v)
            for w, via in neighbours[v]:
                if not seen[w]:
                    seen[w] = True
                    bfs_parent[w], bfs_edge_body[w] = v, via
                    queue.append(w)
    order = np.array(bfs[::-1], dtype=np.int64)  # leaves first: every vertex after its children
    node_of_vertex = np.full(vertex_count, -1, dtype=np.int64)
    node_of_vertex[order] = np.arange(order.size)
    node_kind = np.where(order < joint_count, NODE_JOINT, NODE_BODY).astype(np.int64)
    node_item = np.where(order < joint_count, order, order - joint_count).astype(np.int64)
    parent_vertex = bfs_parent[order]
    node_parent = np.where(parent_vertex >= 0, node_of_vertex[np.maximum(parent_vertex, 0)], -1).astype(np.int64)
    node_dim = np.where(node_kind == NODE_JOINT, counts[np.minimum(node_item, max(joint_count - 1, 0))], 6)
    node_offset = np.zeros(order.size + 1, dtype=np.int64)
    node_offset[1:] = np.cumsum(node_dim)

    # loop rows, the moving bodies they touch, and per such body the joints whose rows couple there
    loop_joints = np.flatnonzero(~in_tree)
    loop_joint = np.repeat(loop_joints, counts[loop_joints]).astype(np.int64)
    loop_local = np.concatenate([np.arange(counts[j]) for j in loop_joints] or [loop_joint]).astype(np.int64)
    joint_loop_first = np.full(joint_count, -1, dtype=np.int64)
    if loop_joints.size:
        joint_loop_first[loop_joints] = np.concatenate([[0], np.cumsum(counts[loop_joints])[:-1]])
    loop_ends = [int(e) for j in loop_joints for e, m in ((a[j], moving_a[j]), (b[j], moving_b[j])) if m]
    loop_body = np.array(sorted(set(loop_ends)), dtype=np.int64)
    body_loop_slot = np.full(body_count, -1, dtype=np.int64)
    body_loop_slot[loop_body] = np.arange(loop_body.size)
    body_loop_joints: dict[int, list[int]] = {int(body): [] for body in loop_body}
    for j in loop_joints:
        for end, moving in ((a[j], moving_a[j]), (b[j], moving_b[j])):
            if moving:
                body_loop_joints[int(end)].append(int(j))
    entry_joint: list[int] = []
    entry_start = [0]
    for body in loop_body:  # tree joints first, then the loop joints on this body
        entry_joint += body_joints[int(body)] + body_loop_joints[int(body)]
        entry_start.append(len(entry_joint))
    return {
        "body_ground": ground,
        "joint_node": node_of_vertex[:joint_count].copy(),
        "node_kind": node_kind,
        "node_item": node_item,
        "node_parent": node_parent,
        "node_edge_body": bfs_edge_body[order].astype(np.int64),
        "node_offset": node_offset,
        "node_child_start": np.concatenate(
            [[0], np.cumsum(np.bincount(node_parent[node_parent >= 0], minlength=order.size))]
        ).astype(np.int64),
        "node_child": np.flatnonzero(node_parent >= 0)[np.argsort(node_parent[node_parent >= 0], kind="stable")].astype(
            np.int64
        ),
        "body_node": node_of_vertex[joint_count:].copy(),
        "loop_joint": loop_joint,
        "loop_local": loop_local,
        "joint_loop_first": joint_loop_first,
        "loop_body": loop_body,
        "body_loop_slot": body_loop_slot,
        "loop_entry_start": np.array(entry_start, dtype=np.int64),
        "entry_joint": np.array(entry_joint, dtype=np.int64),
        "row_total": np.array([counts.sum()], dtype=np.int64),
    }


def loop_cycle(
    body_a: np.ndarray, body_b: np.ndarray, body_ground: np.ndarray, in_tree: np.ndarray, joint: int
) -> list[int]:
    """The joints of the cycle that loop joint `joint` closes: itself, then the tree joints on the path
    between its two ends (the world counts as one vertex), in path order. For a loader's warning."""
    body_count = body_ground.shape[0]

    def end(body: int) -> int:
        return body if body >= 0 and not body_ground[body] else body_count

    neighbours: list[list[tuple[int, int]]] = [[] for _ in range(body_count + 1)]
    for tree_joint in np.flatnonzero(in_tree).tolist():
        u, w = end(int(body_a[tree_joint])), end(int(body_b[tree_joint]))
        neighbours[u].append((w, tree_joint))
        neighbours[w].append((u, tree_joint))
    start, goal = end(int(body_a[joint])), end(int(body_b[joint]))
    came: dict[int, tuple[int, int]] = {start: (-1, -1)}
    queue = deque([start])
    while queue and goal not in came:
        u = queue.popleft()
        for w, j in neighbours[u]:
            if w not in came:
                came[w] = (u, j)
                queue.append(w)
    path: list[int] = []
    v = goal
    while v in came and came[v][0] >= 0:
        v, step = came[v]
        path.append(step)
    return [joint, *path[::-1]]


def redundancy_by_joint(
    body_a: np.ndarray,
    body_b: np.ndarray,
    body_ground: np.ndarray,
    joint_node: np.ndarray,
    row_start: np.ndarray,
    row_count: np.ndarray,
    redundant_row: np.ndarray,
) -> list[tuple[list[int], int]]:
    """The redundant rows of a factor (SolverWork.redundant_row[:count]) grouped for a warning: for each joint
    that owns some, (the joints involved, how many rows). A loop joint's rows involve its whole cycle (e.g.
    a door's two coaxial hinges: ([door_bottom, door_top], 5)); a tree joint's rows only itself."""
    owner = np.searchsorted(row_start, redundant_row, side="right") - 1
    report = []
    for joint in np.unique(owner):
        rows = int(np.count_nonzero(owner == joint))
        if joint_node[joint] >= 0:
            report.append(([int(joint)], rows))
        else:
            report.append((loop_cycle(body_a, body_b, body_ground, joint_node >= 0, int(joint)), rows))
    return report
