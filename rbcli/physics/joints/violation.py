"""The joints' constraint violation of recorded states, per frame (the joint invariants).

For each frame k: the largest |g| over every row at (x_k, q_k) [m or rad] and the largest |G V| at its
velocities [m/s or rad/s], evaluated afresh from the recorded state with the same rows the stages hold
(rows.py), so a recording shows what the state satisfies, not what a stage reported. Called by the
recording thread (runner/blocks.py) on the internal principal-frame states, only for scenes with joints.
"""

from __future__ import annotations

import numba

from rbcli.physics.joints.impulses import row_velocities
from rbcli.physics.joints.rows import joint_rows
from rbcli.physics.kernel_link import separately_compiled


@separately_compiled
@numba.njit(cache=True)
def joint_violations(model, table, work, x, q, P, L, out) -> None:  # noqa: ANN001
    """out[k] = (max |g|, max |G V|) of frame k of the (K, N, ...) states; work: a JointWork (scratch)."""
    for k in range(x.shape[0]):
        out[k, 0] = joint_rows(table, x[k], q[k], work.jac_a, work.jac_b, work.residual, True)
        out[k, 1] = row_velocities(model, table, work, q[k], P[k], L[k])
