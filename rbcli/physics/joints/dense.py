"""The dense fallback of the joint solver: A = G W G^T assembled densely, factored by Cholesky.

A_rs = sum over the bodies c that rows r and s share of G_rc W_c G_sc^T, with W_c = blockdiag(I3 / M_c,
R_c I0_c^-1 R_c^T) (zero for the world and ground bodies). A is symmetric positive semi-definite; it is
singular exactly when rows are redundant (a loop that constrains a direction twice). Cholesky-
Banachiewicz row by row; a pivot that falls to <= REDUNDANT_PIVOT of its row's own diagonal is a row
that is (to round-off) a combination of earlier rows: it is dropped (its multiplier fixed at 0, the
limit of an ever larger regularisation, so a consistent right-hand side is still met exactly: the
dropped row is then satisfied by the others) and counted. O(R^3) per factorisation, O(R^2) per solve:
for the scenes of slice 1 (a few joints); the O(n) sparse solver (jointsolve) replaces it behind the
same two kernels (docs/joints.md).
"""

from __future__ import annotations

import numba

from rbcli.physics.joints.dense_layout import REDUNDANT_PIVOT
from rbcli.physics.step import STEP_KERNEL


@numba.njit(**STEP_KERNEL)
def factor_rows(graph, work, row_start, row_count, body_a, body_b, jac_a, jac_b, inv_mass, inv_inertia_world):  # noqa: ANN001, ANN201
    """Factor A = G W G^T into work.matrix (lower Cholesky factor); returns the rows dropped as redundant."""
    A, wj_a, wj_b, dropped = work.matrix, work.wj_a, work.wj_b, work.dropped
    joints = row_start.shape[0]
    for j in range(joints):
        for r in range(row_start[j], row_start[j] + row_count[j]):
            _weighted(body_a[j], jac_a, wj_a, r, inv_mass, inv_inertia_world)
            _weighted(body_b[j], jac_b, wj_b, r, inv_mass, inv_inertia_world)
    for j in range(joints):
        aj, bj = body_a[j], body_b[j]
        for k in range(j + 1):
            ak, bk = body_a[k], body_b[k]
            shared = (aj >= 0 and (aj == ak or aj == bk)) or (bj >= 0 and (bj == ak or bj == bk))
            for r in range(row_start[j], row_start[j] + row_count[j]):
                for s in range(row_start[k], row_start[k] + row_count[k]):
                    if s > r:
                        break
                    value = 0.0
                    if shared:
                        if aj >= 0 and aj == ak:
                            value += _dot6(jac_a, r, wj_a, s)
                        if aj >= 0 and aj == bk:
                            value += _dot6(jac_a, r, wj_b, s)
                        if bj >= 0 and bj == ak:
                            value += _dot6(jac_b, r, wj_a, s)
                        if bj >= 0 and bj == bk:
                            value += _dot6(jac_b, r, wj_b, s)
                    A[r, s] = value
    rows = graph.row_total
    redundant = 0
    for i in range(rows):
        for c in range(i):
            if dropped[c]:
                A[i, c] = 0.0
                continue
            total = A[i, c]
            for m in range(c):
                total -= A[i, m] * A[c, m]
            A[i, c] = total / A[c, c]
        diagonal = A[i, i]
        pivot = diagonal
        for m in range(i):
            pivot -= A[i, m] * A[i, m]
        if not pivot > REDUNDANT_PIVOT * diagonal:  # also a zero row (a joint between ground bodies)
            dropped[i] = 1
            A[i, i] = 1.0
            redundant += 1
        else:
            dropped[i] = 0
            A[i, i] = pivot**0.5
    return redundant


@numba.njit(**STEP_KERNEL)
def solve_rows(graph, work, row_start, row_count, body_a, body_b, rhs, out) -> None:  # noqa: ANN001
    """out = A^-1 rhs with the factor of `factor_rows` (dropped rows: multiplier 0)."""
    A, dropped = work.matrix, work.dropped
    rows = graph.row_total
    for i in range(rows):  # L y = rhs
        if dropped[i]:
            out[i] = 0.0
            continue
        total = rhs[i]
        for m in range(i):
            total -= A[i, m] * out[m]
        out[i] = total / A[i, i]
    for i in range(rows - 1, -1, -1):  # L^T x = y
        if dropped[i]:
            out[i] = 0.0
            continue
        total = out[i]
        for m in range(i + 1, rows):
            total -= A[m, i] * out[m]
        out[i] = total / A[i, i]


@numba.njit(cache=True, inline="always")
def _weighted(body, jac, wj, r, inv_mass, inv_inertia) -> None:  # noqa: ANN001
    """wj[r] = W_body jac[r] (zero for the world)."""
    if body < 0:
        for c in range(6):
            wj[r, c] = 0.0
        return
    m = inv_mass[body]
    wj[r, 0], wj[r, 1], wj[r, 2] = m * jac[r, 0], m * jac[r, 1], m * jac[r, 2]
    for c in range(3):
        wj[r, 3 + c] = (
            inv_inertia[body, c, 0] * jac[r, 3]
            + inv_inertia[body, c, 1] * jac[r, 4]
            + (inv_inertia[body, c, 2] * jac[r, 5])
        )


@numba.njit(cache=True, inline="always")
def _dot6(a, r, b, s):  # noqa: ANN001, ANN202
    return (
        a[r, 0] * b[s, 0] + a[r, 1] * b[s, 1] + a[r, 2] * b[s, 2]
        + a[r, 3] * b[s, 3] + a[r, 4] * b[s, 4] + a[r, 5] * b[s, 5]
    )  # fmt: skip
