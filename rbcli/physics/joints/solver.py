"""The joints' multiplier solve A lambda = rhs, A = G W G^T, in O(n) on loop-free joint graphs (Baraff 1996).

Rows are grouped by joint: joint j connects body_a[j] and body_b[j] (-1 = the world) and owns the rows
row_start[j] .. row_start[j] + row_count[j] - 1 (1..6 of them). Row r's Jacobian is jac_a[r] (6,) on body
a's (v, omega) and jac_b[r] on body b's, world frame: the row's velocity error is
jac_a[r] . (v_a, omega_a) + jac_b[r] . (v_b, omega_b). Ground bodies (body_ground: static, kinematic) act as
the world. W_b = blockdiag(I3 / M_b, R_b I0_b^-1 R_b^T) [1/kg, 1/(kg m^2)] (inv_mass, inv_inertia_world).

Method (docs/joint_solver.md): the augmented system H [y; x] = [0; -rhs], H = [[W^-1, G^T], [G, 0]], has
x = lambda (y = -W G^T lambda). Its graph over bodies and tree joints is a forest (solver_graph.py): bodies
of degree <= 2 are eliminated analytically, the rest is factored by block LDL^T leaves first, no fill-in:

    D_i = H_ii - sum over children c of H_ci^T D_c^-1 H_ci = L_i Delta_i L_i^T,    Y_i = L_i^-1 H_ip

(p: i's parent; D_c^-1 H_ci's product is Y_c^T Delta_c^-1 Y_c, so L_i^-T never enters the factor), and
solved leaves first and then root first through Y (_tree_solve), every node's work a few d x d products.
Loop joints' rows (k of them) are auxiliary (Baraff section 7): the tree's factor gives the Schur
complement S = A_LL - A_LT A_TT^-1 A_TL column by column (k tree solves), S is factored densely with
diagonal pivoting (O(n k + k^3)), and a solve is two tree solves plus O(k^2).

Redundant rows: a pivot below PIVOT_TOLERANCE times its row's own scale A_rr (in a joint's block or in
S) marks the row redundant; its multiplier is set to 0 (the row is dropped from the elimination). For a
consistent rhs that is an exact solution of A lambda = rhs, the same one a compliance c on that row alone
gives for any c > 0 ((A + c e_r e_r^T) lambda = rhs is solved by the solution with lambda_r = 0), without a
compliance's 1 / c amplification of round-off. The rows are listed in SolverWork.redundant_row.

Both kernels are STEP_KERNEL (no NRT: they cannot allocate); every array lives in SolverWork.
"""

from __future__ import annotations

import numba

from rbcli.physics.joints.solver_graph import NODE_JOINT
from rbcli.physics.joints.solver_layout import JointGraph, SolverWork, joint_graph, make_solver_work  # noqa: F401
from rbcli.physics.kernel_link import separately_compiled
from rbcli.physics.step import STEP_KERNEL

# A pivot |d| <= PIVOT_TOLERANCE * A_rr is a redundant row. Round-off leaves ~eps A_rr (1e-16..1e-15) in
# the pivot of an exactly dependent row (parallel hinge axes in a loop: the dependency is structural, and
# axes off parallel by delta give a pivot ~delta^2). Legitimately small pivots exist: a straight hinge
# chain's out-of-plane bending makes A like a beam operator (cond ~ n^4) and its smallest pivot is
# ~3.5e-7 (100 / n)^3 A_rr (3.5e-13 at 10,000 links, measured): 1e-14 keeps those up to ~30,000 links.
PIVOT_TOLERANCE = 1e-14


@numba.njit(cache=True, inline="always")
def _moving(graph, body) -> bool:  # noqa: ANN001
    return body >= 0 and not graph.body_ground[body]


@numba.njit(cache=True, inline="always")
def _w_row(inv_mass, inv_inertia, row, out) -> None:  # noqa: ANN001
    """out = W row: (row[0:3] / M, I^-1 row[3:6])."""
    for c in range(3):
        out[c] = inv_mass * row[c]
    for c in range(3):
        out[3 + c] = inv_inertia[c, 0] * row[3] + inv_inertia[c, 1] * row[4] + inv_inertia[c, 2] * row[5]


@numba.njit(cache=True, inline="always")
def _dot6(u, v) -> float:  # noqa: ANN001
    return u[0] * v[0] + u[1] * v[1] + u[2] * v[2] + u[3] * v[3] + u[4] * v[4] + u[5] * v[5]


@numba.njit(cache=True, inline="always")
def _ldl_block(D, inv_pivot, dim, scale, tol) -> int:  # noqa: ANN001
    """In-place LDL^T of the symmetric dim x dim block D (its lower triangle), no pivoting; returns the
    bitmask of dropped rows (|d_k| <= tol * scale[k]: its L column and 1 / d_k set to 0)."""
    dropped = 0
    for k in range(dim):
        s = D[k, k]
        for t in range(k):
            s -= D[k, t] * D[k, t] * D[t, t]
        if abs(s) <= tol * scale[k]:
            dropped |= 1 << k
            D[k, k] = 0.0
            inv_pivot[k] = 0.0
            for i in range(k + 1, dim):
                D[i, k] = 0.0
            continue
        D[k, k] = s
        inv_pivot[k] = 1.0 / s
        for i in range(k + 1, dim):
            v = D[i, k]
            for t in range(k):
                v -= D[i, t] * D[k, t] * D[t, t]
            D[i, k] = v * inv_pivot[k]
    return dropped


@numba.njit(cache=True, inline="always")
def _joint_jac(j, body, body_a, jac_a, jac_b):  # noqa: ANN001, ANN202
    """The Jacobian array holding joint j's rows at `body` (its side a or b)."""
    return jac_a if body_a[j] == body else jac_b


@numba.njit(cache=True, inline="always")
def _tree_solve(graph, work, row_start, row_count, rhs, out, from_rows, to_rows) -> None:  # noqa: ANN001
    """work.vec = H_T^-1 z over the forest, from factor_rows' D_i = L_i Delta_i L_i^T, Y_i = L_i^-1 H_ip.

    z = work.vec, or with from_rows [0 at hubs; -rhs at tree joints] read in the first sweep; with to_rows
    the tree joints' multipliers are also written to `out` in the second. With U_ip = D_i^-1 H_ip =
    L_i^-T Delta_i^-1 Y_i, H_T = U^T D U: leaves first z_i -= sum over children c of Y_c^T s_c (= U_ci^T z_c)
    and s_i = Delta_i^-1 L_i^-1 z_i; root first x_i = L_i^-T (s_i - Delta_i^-1 Y_i x_p) (= w_i - U_ip x_p).
    """
    x, Y, D, inv = work.vec, work.node_Y, work.node_D, work.node_inv_pivot
    off, parent, kind, item = graph.node_offset, graph.node_parent, graph.node_kind, graph.node_item
    child_start, child = graph.node_child_start, graph.node_child
    nodes = parent.shape[0]
    for i in range(nodes):
        o, d = off[i], off[i + 1] - off[i]
        if from_rows:
            if kind[i] == NODE_JOINT:
                rs = row_start[item[i]]
                for r in range(d):
                    x[o + r] = -rhs[rs + r]
            else:
                for r in range(d):
                    x[o + r] = 0.0
        for e in range(child_start[i], child_start[i + 1]):
            c = child[e]
            oc, dc = off[c], off[c + 1] - off[c]
            for col in range(d):
                v = 0.0
                for r in range(dc):
                    v += Y[c, r, col] * x[oc + r]
                x[o + col] -= v
        for r in range(d):  # t_i = L_i^-1 z_i, then s_i = Delta_i^-1 t_i (the substitution needs t unscaled)
            v = x[o + r]
            for t in range(r):
                v -= D[i, r, t] * x[o + t]
            x[o + r] = v
        for r in range(d):
            x[o + r] *= inv[i, r]
    for i in range(nodes - 1, -1, -1):
        o, d, p = off[i], off[i + 1] - off[i], parent[i]
        if p >= 0:
            op, dp = off[p], off[p + 1] - off[p]
            for r in range(d):
                v = 0.0
                for c in range(dp):
                    v += Y[i, r, c] * x[op + c]
                x[o + r] -= inv[i, r] * v
        for r in range(d - 1, -1, -1):
            v = x[o + r]
            for t in range(r + 1, d):
                v -= D[i, t, r] * x[o + t]
            x[o + r] = v
        if to_rows and kind[i] == NODE_JOINT:
            rs = row_start[item[i]]
            for r in range(d):
                out[rs + r] = x[o + r]


@numba.njit(**STEP_KERNEL)
def _init_blocks(graph, work, row_start, row_count, body_a, body_b, jac_a, jac_b, inv_mass, inv_inertia_world) -> None:  # noqa: ANN001, E501
    """Row scales A_rr of every joint and the diagonal blocks H_ii: -sum J W J^T over a tree joint's
    eliminated bodies, M_b = W_b^-1 for a hub."""
    jw = work.jw
    for j in range(row_start.shape[0]):
        m, rs, node = row_count[j], row_start[j], graph.joint_node[j]
        for r in range(m):
            work.joint_scale[j, r] = 0.0
        if node >= 0:
            D = work.node_D[node]
            for r in range(m):
                for c in range(m):
                    D[r, c] = 0.0
        for side in range(2):
            body = body_a[j] if side == 0 else body_b[j]
            if not _moving(graph, body):
                continue
            jac = jac_a if side == 0 else jac_b
            for r in range(m):
                _w_row(inv_mass[body], inv_inertia_world[body], jac[rs + r], jw[r])
                work.joint_scale[j, r] += _dot6(jac[rs + r], jw[r])
            if node >= 0 and graph.body_node[body] < 0:  # eliminated body: -J W J^T, lower triangle
                for r in range(m):
                    for c in range(r + 1):
                        D[r, c] -= _dot6(jac[rs + r], jw[c])
    for i in range(graph.node_kind.shape[0]):
        if graph.node_kind[i] == NODE_JOINT:
            continue
        b, D = graph.node_item[i], work.node_D[i]
        for r in range(6):
            for c in range(6):
                D[r, c] = 0.0
        for c in range(3):
            D[c, c] = 1.0 / inv_mass[b]
        Iw = inv_inertia_world[b]  # the world inertia R I0 R^T = (R I0^-1 R^T)^-1, by cofactors
        c00 = Iw[1, 1] * Iw[2, 2] - Iw[1, 2] * Iw[2, 1]
        c01 = Iw[1, 2] * Iw[2, 0] - Iw[1, 0] * Iw[2, 2]
        c02 = Iw[1, 0] * Iw[2, 1] - Iw[1, 1] * Iw[2, 0]
        inv_det = 1.0 / (Iw[0, 0] * c00 + Iw[0, 1] * c01 + Iw[0, 2] * c02)
        D[3, 3] = c00 * inv_det
        D[4, 3] = c01 * inv_det
        D[5, 3] = c02 * inv_det
        D[4, 4] = (Iw[0, 0] * Iw[2, 2] - Iw[0, 2] * Iw[2, 0]) * inv_det
        D[5, 4] = (Iw[0, 1] * Iw[2, 0] - Iw[0, 0] * Iw[2, 1]) * inv_det
        D[5, 5] = (Iw[0, 0] * Iw[1, 1] - Iw[0, 1] * Iw[1, 0]) * inv_det


@numba.njit(cache=True, inline="always")
def _edge_block(graph, work, i, row_start, row_count, body_a, jac_a, jac_b, inv_mass, inv_inertia_world) -> None:  # noqa: ANN001, E501
    """work.block = H_ip, the block between node i and its parent (dim_i x dim_parent)."""
    p, body, H = graph.node_parent[i], graph.node_edge_body[i], work.block
    if graph.node_kind[i] != NODE_JOINT:  # hub child, joint parent: G^T's block J_pb^T
        k = graph.node_item[p]
        jac = _joint_jac(k, body, body_a, jac_a, jac_b)
        for s in range(row_count[k]):
            for c in range(6):
                H[c, s] = jac[row_start[k] + s, c]
        return
    j = graph.node_item[i]
    jac = _joint_jac(j, body, body_a, jac_a, jac_b)
    if graph.node_kind[p] != NODE_JOINT:  # joint child, hub parent: G's block J_jb
        for r in range(row_count[j]):
            for c in range(6):
                H[r, c] = jac[row_start[j] + r, c]
        return
    k = graph.node_item[p]  # joint child, joint parent through the eliminated body: -J_jb W_b J_kb^T
    jac_k = _joint_jac(k, body, body_a, jac_a, jac_b)
    for s in range(row_count[k]):
        _w_row(inv_mass[body], inv_inertia_world[body], jac_k[row_start[k] + s], work.jw[s])
    for r in range(row_count[j]):
        for s in range(row_count[k]):
            H[r, s] = -_dot6(jac[row_start[j] + r], work.jw[s])


@numba.njit(**STEP_KERNEL)
def _loop_to_bodies(graph, work, row_count, lam) -> None:  # noqa: ANN001
    """loop_g[b] = W_b sum over loop rows l on b of J_lb^T lam_l (lam over loop rows)."""
    for s in range(graph.loop_body.shape[0]):
        t6 = work.loop_u[s]  # scratch for J^T lam before W
        for c in range(6):
            t6[c] = 0.0
        for e in range(graph.loop_entry_start[s], graph.loop_entry_start[s + 1]):
            j = graph.entry_joint[e]
            first = graph.joint_loop_first[j]
            if first < 0:
                continue
            for r in range(row_count[j]):
                for c in range(6):
                    t6[c] += work.entry_jac[e, r, c] * lam[first + r]
        _w_row(work.loop_inv_mass[s], work.loop_inv_inertia[s], t6, work.loop_g[s])


@numba.njit(**STEP_KERNEL)
def _bodies_to_tree(graph, work, row_count, g) -> None:  # noqa: ANN001
    """vec at tree rows -= J_tb g_b over loop bodies b (the tree right-hand side -G_T g)."""
    off = graph.node_offset
    for s in range(graph.loop_body.shape[0]):
        for e in range(graph.loop_entry_start[s], graph.loop_entry_start[s + 1]):
            j = graph.entry_joint[e]
            node = graph.joint_node[j]
            if node < 0:
                continue
            for r in range(row_count[j]):
                work.vec[off[node] + r] -= _dot6(work.entry_jac[e, r], g[s])


@numba.njit(**STEP_KERNEL)
def _tree_to_bodies(graph, work, row_count, x) -> None:  # noqa: ANN001
    """loop_u[b] = W_b sum over tree joints t on b of J_tb^T lambda_t (lambda_t from the node vector x)."""
    off = graph.node_offset
    for s in range(graph.loop_body.shape[0]):
        t6 = work.loop_u[s]
        for c in range(6):
            t6[c] = 0.0
        for e in range(graph.loop_entry_start[s], graph.loop_entry_start[s + 1]):
            j = graph.entry_joint[e]
            node = graph.joint_node[j]
            if node < 0:
                continue
            for r in range(row_count[j]):
                lam = x[off[node] + r]
                for c in range(6):
                    t6[c] += work.entry_jac[e, r, c] * lam
        # in place: W t6 needs t6's angular part whole, so form it before overwriting
        a0, a1, a2 = t6[3], t6[4], t6[5]
        Iw, w = work.loop_inv_inertia[s], work.loop_inv_mass[s]
        for c in range(3):
            t6[c] *= w
        t6[3] = Iw[0, 0] * a0 + Iw[0, 1] * a1 + Iw[0, 2] * a2
        t6[4] = Iw[1, 0] * a0 + Iw[1, 1] * a1 + Iw[1, 2] * a2
        t6[5] = Iw[2, 0] * a0 + Iw[2, 1] * a1 + Iw[2, 2] * a2


@numba.njit(**STEP_KERNEL)
def _bodies_to_loop(graph, work, row_count, out, sign) -> None:  # noqa: ANN001
    """out_l += sum over l's loop bodies of J_lb . (loop_g[b] + sign loop_u[b]), for every loop row l."""
    for s in range(graph.loop_body.shape[0]):
        for e in range(graph.loop_entry_start[s], graph.loop_entry_start[s + 1]):
            j = graph.entry_joint[e]
            first = graph.joint_loop_first[j]
            if first < 0:
                continue
            for r in range(row_count[j]):
                v = 0.0
                for c in range(6):
                    v += work.entry_jac[e, r, c] * (work.loop_g[s, c] + sign * work.loop_u[s, c])
                out[first + r] += v


@numba.njit(**STEP_KERNEL)
def _factor_loops(graph, work, row_start, row_count, body_a, jac_a, jac_b, inv_mass, inv_inertia_world) -> int:  # noqa: ANN001, E501
    """S = A_LL - A_LT A_TT^-1 A_TL by k tree solves, then its LDL^T with diagonal pivoting; returns the
    rows dropped (listed after `work.redundant_row`'s tree entries by factor_rows)."""
    k = graph.loop_joint.shape[0]
    for s in range(graph.loop_body.shape[0]):  # the loop bodies' W and rows, for solve_rows
        body = graph.loop_body[s]
        work.loop_inv_mass[s] = inv_mass[body]
        for r in range(3):
            for c in range(3):
                work.loop_inv_inertia[s, r, c] = inv_inertia_world[body, r, c]
        for e in range(graph.loop_entry_start[s], graph.loop_entry_start[s + 1]):
            j = graph.entry_joint[e]
            jac = _joint_jac(j, body, body_a, jac_a, jac_b)
            for r in range(row_count[j]):
                for c in range(6):
                    work.entry_jac[e, r, c] = jac[row_start[j] + r, c]
    S, lam = work.loop_S, work.loop_vec
    for col in range(k):  # column col of S: lambda_L = e_col
        for r in range(k):
            lam[r] = 0.0
        lam[col] = 1.0
        _loop_to_bodies(graph, work, row_count, lam)  # g = W G_L^T e_col
        for r in range(work.vec.shape[0]):
            work.vec[r] = 0.0
        _bodies_to_tree(graph, work, row_count, work.loop_g)
        _tree_solve(graph, work, row_start, row_count, work.vec, work.vec, False, False)  # X = A_TT^-1 A_TL e_col
        _tree_to_bodies(graph, work, row_count, work.vec)  # u = W G_T^T X
        for r in range(k):
            lam[r] = 0.0
        _bodies_to_loop(graph, work, row_count, lam, -1.0)  # G_L (g - u)
        for r in range(k):
            S[r, col] = lam[r]
    for r in range(k):  # symmetric to round-off: take the mean, so the pivoted factor sees one matrix
        for c in range(r):
            v = 0.5 * (S[r, c] + S[c, r])
            S[r, c] = v
            S[c, r] = v
        work.loop_perm[r] = r
    rank = k
    for t in range(k):  # outer-product LDL^T, the largest pivot relative to its row's scale first
        best, best_value = t, -1.0
        for i in range(t, k):
            row = work.loop_perm[i]
            value = S[i, i] / max(work.joint_scale[graph.loop_joint[row], graph.loop_local[row]], 1e-300)
            if value > best_value:
                best, best_value = i, value
        if best_value <= PIVOT_TOLERANCE:
            rank = t
            break
        if best != t:
            for c in range(k):
                S[t, c], S[best, c] = S[best, c], S[t, c]
            for r in range(k):
                S[r, t], S[r, best] = S[r, best], S[r, t]
            work.loop_perm[t], work.loop_perm[best] = work.loop_perm[best], work.loop_perm[t]
        d = S[t, t]
        work.loop_inv_pivot[t] = 1.0 / d
        for i in range(t + 1, k):
            S[i, t] *= work.loop_inv_pivot[t]
        for i in range(t + 1, k):
            for c in range(t + 1, k):
                S[i, c] -= S[i, t] * d * S[c, t]
    work.loop_rank[0] = rank
    return k - rank


@separately_compiled
@numba.njit(**STEP_KERNEL)
def factor_rows(graph, work, row_start, row_count, body_a, body_b, jac_a, jac_b, inv_mass, inv_inertia_world) -> int:  # noqa: ANN001, E501
    """Factor A = G W G^T (module docstring) into `work`; returns the number of rows found redundant,
    listed (global row indices) in work.redundant_row[:count]. O(n) for trees, O(n k + k^3) with k loop rows."""
    _init_blocks(graph, work, row_start, row_count, body_a, body_b, jac_a, jac_b, inv_mass, inv_inertia_world)
    off, count = graph.node_offset, 0
    for i in range(graph.node_kind.shape[0]):
        d, p, D = off[i + 1] - off[i], graph.node_parent[i], work.node_D[i]
        if graph.node_kind[i] == NODE_JOINT:
            j = graph.node_item[i]
            for r in range(d):
                work.pivot_scale[r] = work.joint_scale[j, r]
        else:
            for r in range(d):  # a hub's pivots are >= its mass and inertia: never dropped
                work.pivot_scale[r] = 0.0
        dropped = _ldl_block(D, work.node_inv_pivot[i], d, work.pivot_scale, PIVOT_TOLERANCE)
        if dropped:
            j = graph.node_item[i]
            for r in range(d):
                if dropped & (1 << r):
                    work.redundant_row[count] = row_start[j] + r
                    count += 1
        if p < 0:
            continue
        _edge_block(graph, work, i, row_start, row_count, body_a, jac_a, jac_b, inv_mass, inv_inertia_world)
        dp, H, Yi, Dp, inv, Z = (
            off[p + 1] - off[p],
            work.block,
            work.node_Y[i],
            work.node_D[p],
            work.node_inv_pivot[i],
            work.jw,
        )
        for r in range(d):  # Y_i = L_i^-1 H_ip, and Z = Delta_i^-1 Y_i
            for c in range(dp):
                v = H[r, c]
                for t in range(r):
                    v -= D[r, t] * Yi[t, c]
                Yi[r, c] = v
                Z[r, c] = v * inv[r]
        for a in range(dp):  # D_p -= H_ip^T D_i^-1 H_ip = Y_i^T Delta_i^-1 Y_i, lower triangle
            for c in range(a + 1):
                v = 0.0
                for r in range(d):
                    v += Yi[r, a] * Z[r, c]
                Dp[a, c] -= v
    k = graph.loop_joint.shape[0]
    if k == 0:
        return count
    _factor_loops(graph, work, row_start, row_count, body_a, jac_a, jac_b, inv_mass, inv_inertia_world)
    for r in range(work.refine_jac_a.shape[0]):
        for c in range(6):
            work.refine_jac_a[r, c] = jac_a[r, c]
            work.refine_jac_b[r, c] = jac_b[r, c]
    for b in range(work.refine_inv_mass.shape[0]):
        work.refine_inv_mass[b] = inv_mass[b]
        for r in range(3):
            for c in range(3):
                work.refine_inv_inertia[b, r, c] = inv_inertia_world[b, r, c]
    for t in range(work.loop_rank[0], k):
        row = work.loop_perm[t]
        work.redundant_row[count] = row_start[graph.loop_joint[row]] + graph.loop_local[row]
        count += 1
    return count


@numba.njit(**STEP_KERNEL)
def _residual(graph, work, row_start, row_count, body_a, body_b, rhs, lam) -> None:  # noqa: ANN001
    """work.refine_residual = rhs - G W G^T lam, from the rows copied by factor_rows: O(rows + bodies)."""
    jac_a, jac_b, impulse = work.refine_jac_a, work.refine_jac_b, work.refine_body
    for b in range(impulse.shape[0]):
        for c in range(6):
            impulse[b, c] = 0.0
    for j in range(row_start.shape[0]):
        for side in range(2):
            body = body_a[j] if side == 0 else body_b[j]
            if _moving(graph, body):
                jac = jac_a if side == 0 else jac_b
                for r in range(row_start[j], row_start[j] + row_count[j]):
                    for c in range(6):
                        impulse[body, c] += jac[r, c] * lam[r]
    for b in range(impulse.shape[0]):  # W G^T lam, in place (angular part read whole first)
        a0, a1, a2 = impulse[b, 3], impulse[b, 4], impulse[b, 5]
        Iw = work.refine_inv_inertia[b]
        for c in range(3):
            impulse[b, c] *= work.refine_inv_mass[b]
            impulse[b, 3 + c] = Iw[c, 0] * a0 + Iw[c, 1] * a1 + Iw[c, 2] * a2
    for j in range(row_start.shape[0]):
        for r in range(row_start[j], row_start[j] + row_count[j]):
            v = rhs[r]
            for side in range(2):
                body = body_a[j] if side == 0 else body_b[j]
                if _moving(graph, body):
                    jac = jac_a if side == 0 else jac_b
                    v -= _dot6(jac[r], impulse[body])
            work.refine_residual[r] = v


@separately_compiled
@numba.njit(**STEP_KERNEL)
def solve_rows(graph, work, row_start, row_count, body_a, body_b, rhs, out) -> None:  # noqa: ANN001
    """out = A^-1 rhs (shape (row_total,), rows 0 .. row_total - 1) after factor_rows; redundant rows get 0.

    With loops, one step of iterative refinement follows (out += A^-1 (rhs - A out)): the loop rows' Schur
    complement is formed from full tree solves, so its error is ~ eps cond(A_TT) |A| rather than the
    eps |A| of a Cholesky-type form; the refinement's residual, computed from the rows themselves, brings
    the result back to the accuracy of a backward-stable solve (docs/joint_solver.md). out may not alias rhs.
    """
    _solve_once(graph, work, row_start, row_count, rhs, out)
    if graph.loop_joint.shape[0] == 0:
        return
    _residual(graph, work, row_start, row_count, body_a, body_b, rhs, out)
    _solve_once(graph, work, row_start, row_count, work.refine_residual, work.refine_correction)
    for r in range(out.shape[0]):
        out[r] += work.refine_correction[r]


@numba.njit(cache=True, inline="always")
def _solve_once(graph, work, row_start, row_count, rhs, out) -> None:  # noqa: ANN001
    """out = A^-1 rhs from the factor: a tree solve, and with loops the Schur step and a second tree solve."""
    off = graph.node_offset
    _tree_solve(graph, work, row_start, row_count, rhs, out, True, True)
    k = graph.loop_joint.shape[0]
    if k == 0:
        return
    # loop rows: S lambda_L = r_L - A_LT lambda_0, then lambda_T = lambda_0 - A_TT^-1 A_TL lambda_L
    s = work.loop_vec
    for t in range(k):
        s[t] = rhs[row_start[graph.loop_joint[t]] + graph.loop_local[t]]
    for b in range(graph.loop_body.shape[0]):
        for c in range(6):
            work.loop_g[b, c] = 0.0
    _tree_to_bodies(graph, work, row_count, work.vec)
    _bodies_to_loop(graph, work, row_count, s, -1.0)
    # lambda_L = S^-1 s in place, in pivot order: entry perm[t] of s holds y_t once row t is done
    S, perm, rank, lam = work.loop_S, work.loop_perm, work.loop_rank[0], s
    for t in range(rank):
        v = s[perm[t]]
        for c in range(t):
            v -= S[t, c] * lam[perm[c]]
        lam[perm[t]] = v
    for t in range(rank):
        lam[perm[t]] *= work.loop_inv_pivot[t]
    for t in range(rank - 1, -1, -1):
        v = lam[perm[t]]
        for c in range(t + 1, rank):
            v -= S[c, t] * lam[perm[c]]
        lam[perm[t]] = v
    for t in range(rank, k):
        lam[perm[t]] = 0.0
    for t in range(k):
        out[row_start[graph.loop_joint[t]] + graph.loop_local[t]] = lam[t]
    _loop_to_bodies(graph, work, row_count, lam)
    for r in range(work.vec.shape[0]):
        work.vec[r] = 0.0
    _bodies_to_tree(graph, work, row_count, work.loop_g)
    _tree_solve(graph, work, row_start, row_count, work.vec, work.vec, False, False)
    for i in range(graph.node_kind.shape[0]):
        if graph.node_kind[i] == NODE_JOINT:
            j = graph.node_item[i]
            for r in range(row_count[j]):
                out[row_start[j] + r] -= work.vec[off[i] + r]
