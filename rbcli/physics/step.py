"""Chunks of steps in compiled code: the runner calls `run_chunk` and gets control back only to
record a block of frames, check for divergence or report progress."""

from __future__ import annotations

import numba
import numpy as np

# |value| above this counts as a blow-up: far beyond any physical scene in SI units, far below
# overflow, so a divergence is caught while the state is still printable.
BLOWUP_LIMIT = 1e100

STATUS_OK = 0
STATUS_DIVERGED = 1


@numba.njit(cache=True)
def state_is_sane(x, q, P, L) -> bool:  # noqa: ANN001
    """True when every state value is finite and below BLOWUP_LIMIT in magnitude."""
    for arr in (x, P, L):
        for b in range(arr.shape[0]):
            for k in range(3):
                if not (abs(arr[b, k]) < BLOWUP_LIMIT):  # also False for NaN
                    return False
    for b in range(q.shape[0]):
        for k in range(4):
            if not (abs(q[b, k]) < BLOWUP_LIMIT):
                return False
    return True


@numba.njit(cache=True)
def run_chunk(
    step, model, forces, dt, step0, n_steps, record_every,  # noqa: ANN001
    x, q, P, L, F, tau, scratch,
    out_step, out_x, out_q, out_P, out_L, frame0,
):  # fmt: skip
    """Advance up to n_steps from step index step0 (time t = step * dt, never accumulated).

    After every step whose index is a multiple of record_every, check the state and copy it into the
    out_* buffers at the next frame slot; stop early when the buffers are full or the state diverged.
    Returns (steps_done, frames_filled, status).
    """
    frames = frame0
    capacity = out_step.shape[0]
    for k in range(n_steps):
        t = (step0 + k) * dt
        step(model, forces, t, dt, x, q, P, L, F, tau, scratch)
        index = step0 + k + 1
        if index % record_every == 0:
            if not state_is_sane(x, q, P, L):
                return k + 1, frames, STATUS_DIVERGED
            out_step[frames] = index
            out_x[frames] = x
            out_q[frames] = q
            out_P[frames] = P
            out_L[frames] = L
            frames += 1
            if frames == capacity:
                return k + 1, frames, STATUS_OK
    if not state_is_sane(x, q, P, L):
        return n_steps, frames, STATUS_DIVERGED
    return n_steps, frames, STATUS_OK


def empty_buffers(capacity: int, body_count: int) -> dict[str, np.ndarray]:
    """Frame buffers for `run_chunk`."""
    return {
        "step": np.zeros(capacity, dtype=np.int64),
        "x": np.zeros((capacity, body_count, 3)),
        "q": np.zeros((capacity, body_count, 4)),
        "P": np.zeros((capacity, body_count, 3)),
        "L": np.zeros((capacity, body_count, 3)),
    }
