"""The numpy side of the O(n) joint solver (joints/solver.py): its graph and work arrays, built once at
compile time without numba, so loading and validating a jointed scene never imports numba."""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from rbcli.physics.joints.solver_graph import build_graph_arrays


class JointGraph(NamedTuple):
    """The joint graph in elimination order (solver_graph.py), built once at compile time; read-only.

    node: a tree joint (NODE_JOINT, its row_count multipliers) or a hub body (NODE_BODY, 6 velocities);
    nodes are numbered in elimination order, every node before its parent.
    """

    body_ground: np.ndarray  # bool (body_count,): static or kinematic, acts as the world
    joint_node: np.ndarray  # int64 (joint_count,): node of a tree joint, -1 for a loop joint
    node_kind: np.ndarray  # int64 (node_count,): NODE_JOINT or NODE_BODY
    node_item: np.ndarray  # int64 (node_count,): the node's joint or body index
    node_parent: np.ndarray  # int64 (node_count,): parent node (a larger index), -1 for a root
    node_edge_body: np.ndarray  # int64 (node_count,): the body the edge to the parent passes through, -1: root
    node_offset: np.ndarray  # int64 (node_count + 1,): each node's slice of the node vector
    node_child_start: np.ndarray  # int64 (node_count + 1,): each node's slice of node_child
    node_child: np.ndarray  # int64 (node_count - root_count,): children of each node (smaller indices)
    body_node: np.ndarray  # int64 (body_count,): node of a hub body, -1 for an eliminated or unjointed body
    loop_joint: np.ndarray  # int64 (loop_row_count,): joint of each loop row
    loop_local: np.ndarray  # int64 (loop_row_count,): its row within the joint
    joint_loop_first: np.ndarray  # int64 (joint_count,): first loop row of a loop joint, -1 for a tree joint
    loop_body: np.ndarray  # int64 (loop_body_count,): moving bodies that loop rows touch
    body_loop_slot: np.ndarray  # int64 (body_count,): index into loop_body, -1
    loop_entry_start: np.ndarray  # int64 (loop_body_count + 1,): each loop body's slice of entry_joint
    entry_joint: np.ndarray  # int64 (entry_count,): joints on each loop body (tree joints, then loop joints)
    row_total: np.ndarray  # int64 (1,): the number of rows, sum of row_count


class SolverWork(NamedTuple):
    """The solver's mutable arrays, allocated once (make_solver_work; Data owns them); sizes O(n + k^2)."""

    # blocks are (block_dim, block_dim), block_dim the largest node dimension (3 for a ball chain, 6 with hubs)
    node_D: np.ndarray  # (node_count, block_dim, block_dim): D_i = L_i Delta_i L_i^T, unit L_i below the diagonal
    node_inv_pivot: np.ndarray  # (node_count, block_dim): 1 / Delta_i, 0 for a dropped (redundant) row
    node_Y: np.ndarray  # (node_count, block_dim, block_dim): Y_i = L_i^-1 H_ip, (dim_i, dim_parent)
    vec: np.ndarray  # (node vector size,): the tree solve's right-hand side and solution
    block: np.ndarray  # (6, 6): an edge block H_ip being formed
    jw: np.ndarray  # (6, 6): rows times W_b of one joint at one body
    pivot_scale: np.ndarray  # (6,): the row scales of the block being factored
    joint_scale: np.ndarray  # (joint_count, 6): A_rr = sum over the joint's bodies of J_r W J_r^T
    redundant_row: np.ndarray  # int64 (row_total,): the rows found redundant by the last factor, first `count`
    loop_S: np.ndarray  # (k, k): the loop rows' Schur complement, then its pivoted LDL^T
    loop_inv_pivot: np.ndarray  # (k,)
    loop_perm: np.ndarray  # int64 (k,): pivot order of S
    loop_rank: np.ndarray  # int64 (1,): pivots kept
    loop_vec: np.ndarray  # (k,): loop-row right-hand side, then multipliers
    loop_g: np.ndarray  # (loop_body_count, 6): W_b G_L^T lambda_L at each loop body
    loop_u: np.ndarray  # (loop_body_count, 6): W_b G_T^T lambda_T at each loop body
    loop_inv_mass: np.ndarray  # (loop_body_count,): copies of the loop bodies' W (solve_rows gets no model)
    loop_inv_inertia: np.ndarray  # (loop_body_count, 3, 3)
    entry_jac: np.ndarray  # (entry_count, 6, 6): rows of entry_joint[e] at its loop body (copied by factor)
    # iterative refinement, only with loops (sizes 0 without): copies of the rows and W, A lambda's scratch
    refine_jac_a: np.ndarray  # (row_total, 6)
    refine_jac_b: np.ndarray  # (row_total, 6)
    refine_inv_mass: np.ndarray  # (body_count,)
    refine_inv_inertia: np.ndarray  # (body_count, 3, 3)
    refine_body: np.ndarray  # (body_count, 6): G^T lambda, then W G^T lambda
    refine_residual: np.ndarray  # (row_total,): rhs - A lambda
    refine_correction: np.ndarray  # (row_total,)


def joint_graph(body_a: np.ndarray, body_b: np.ndarray, body_ground: np.ndarray, row_count: np.ndarray) -> JointGraph:
    """The JointGraph of a scene's joints (numpy, once at compile time); ValueError for a malformed graph."""
    return JointGraph(**build_graph_arrays(body_a, body_b, body_ground, row_count))


def make_solver_work(graph: JointGraph) -> SolverWork:
    """SolverWork sized for `graph`: O(nodes + rows + loop_rows^2) floats."""
    nodes, joints = graph.node_kind.shape[0], graph.joint_node.shape[0]
    k, loop_bodies = graph.loop_joint.shape[0], graph.loop_body.shape[0]
    rows_refined = int(graph.row_total[0]) if k else 0
    block_dim = int(np.diff(graph.node_offset).max()) if nodes else 1
    bodies_refined = graph.body_ground.shape[0] if k else 0
    return SolverWork(
        node_D=np.zeros((nodes, block_dim, block_dim)),
        node_inv_pivot=np.zeros((nodes, block_dim)),
        node_Y=np.zeros((nodes, block_dim, block_dim)),
        vec=np.zeros(int(graph.node_offset[-1])),
        block=np.zeros((6, 6)),
        jw=np.zeros((6, 6)),
        pivot_scale=np.zeros(6),
        joint_scale=np.zeros((joints, 6)),
        redundant_row=np.zeros(int(graph.row_total[0]), dtype=np.int64),
        loop_S=np.zeros((k, k)),
        loop_inv_pivot=np.zeros(k),
        loop_perm=np.zeros(k, dtype=np.int64),
        loop_rank=np.zeros(1, dtype=np.int64),
        loop_vec=np.zeros(k),
        loop_g=np.zeros((loop_bodies, 6)),
        loop_u=np.zeros((loop_bodies, 6)),
        loop_inv_mass=np.zeros(loop_bodies),
        loop_inv_inertia=np.zeros((loop_bodies, 3, 3)),
        entry_jac=np.zeros((graph.entry_joint.shape[0], 6, 6)),
        refine_jac_a=np.zeros((rows_refined, 6)),
        refine_jac_b=np.zeros((rows_refined, 6)),
        refine_inv_mass=np.zeros(bodies_refined),
        refine_inv_inertia=np.zeros((bodies_refined, 3, 3)),
        refine_body=np.zeros((bodies_refined, 6)),
        refine_residual=np.zeros(rows_refined),
        refine_correction=np.zeros(rows_refined),
    )
