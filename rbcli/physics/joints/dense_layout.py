"""The dense fallback solver's graph and work arrays (numpy only: built when a scene compiles).

The solver interface (shared with the sparse O(n) solver, docs/joints.md): `joint_graph(body_a, body_b,
body_ground, row_count)` is built once at compile time, `make_solver_work(graph)` once per run, and the
compiled kernels `factor_rows` / `solve_rows` (dense.py) take both. For the dense fallback the graph is
only the row total and the work a dense (R, R) matrix with its Cholesky factor, the per-row W G^T
products and the rows dropped as redundant.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

# a pivot this small relative to its row's diagonal means the row repeats earlier ones: the cancellation
# of a truly redundant row leaves ~R eps of the diagonal (1e-14 for 100 rows), while independent rows
# keep pivots of order 1 of it (the rows of one joint are orthogonal directions)
REDUNDANT_PIVOT = 1e-10


class DenseGraph(NamedTuple):
    """What the dense solver needs of the joint graph: the total row count R."""

    row_total: int


class DenseWork(NamedTuple):
    """The dense solver's work: A = G W G^T and then its Cholesky factor (lower triangle) in `matrix`
    (R, R); W G_r^T per row and end in `wj_a`, `wj_b` (R, 6); `dropped` (R,) 1 for a row found
    redundant (a zero pivot), 0 otherwise."""

    matrix: np.ndarray
    wj_a: np.ndarray
    wj_b: np.ndarray
    dropped: np.ndarray


def joint_graph(body_a: np.ndarray, body_b: np.ndarray, body_ground: np.ndarray, row_count: np.ndarray) -> DenseGraph:
    """The dense solver's graph: every row couples with every other, so only the row total matters."""
    return DenseGraph(int(np.asarray(row_count, dtype=np.int64).sum()))


def make_solver_work(graph: DenseGraph) -> DenseWork:
    rows = graph.row_total
    return DenseWork(np.zeros((rows, rows)), np.zeros((rows, 6)), np.zeros((rows, 6)), np.zeros(rows, dtype=np.int64))


def redundant_rows_numpy(A: np.ndarray) -> np.ndarray:
    """The rows `factor_rows` drops as redundant for the matrix A (the same rule, in numpy): int (k,)."""
    rows = A.shape[0]
    factor = np.zeros_like(A)
    dropped = np.zeros(rows, dtype=bool)
    for i in range(rows):
        for c in range(i):
            if not dropped[c]:
                factor[i, c] = (A[i, c] - factor[i, :c] @ factor[c, :c]) / factor[c, c]
        pivot = A[i, i] - factor[i, :i] @ factor[i, :i]
        if not pivot > REDUNDANT_PIVOT * A[i, i]:
            dropped[i], factor[i, i] = True, 1.0
        else:
            factor[i, i] = np.sqrt(pivot)
    return np.flatnonzero(dropped)
