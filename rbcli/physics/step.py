"""Shared pieces of the chunk loops (physics/chunk_loop.py, physics/adaptive_loop.py): the frame
buffers, the recording stage `record_if_due`, the divergence check, the chunk status codes and
`model_bodies`, the model's body arrays that the loops hand every stage.

A chunk returns (steps_done, frames_filled, status): STATUS_OK (ran n_steps), STATUS_FULL (the frame
buffers are full: flush them and call again), STATUS_DIVERGED (the last step left a non-finite or
blown-up state, which was not recorded), STATUS_NO_ROOM (called with full buffers: a runner bug; nothing
written). Time is t = step * dt, never accumulated.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numba
import numpy as np

from rbcli.physics import kernel_cache
from rbcli.physics.model import KernelBodies

kernel_cache.install()  # loads of the kernels skip numba's registry build (kernel_cache.py)

# columns of FrameBuffers.contact (physics/contact/tables.py FRAME_STAT_COUNT; step.py imports no contact code)
CONTACT_STATS = 4

# |value| above this counts as a blow-up: far beyond any physical scene in SI units, far below
# overflow, so a divergence is caught while the state is still printable.
BLOWUP_LIMIT = 1e100

STATUS_OK = 0
STATUS_DIVERGED = 1
STATUS_FULL = 2
# (3 is the adaptive chunk's STATUS_STEP_TOO_SMALL)
# A chunk was called with no room left in its frame buffers: a runner bug, reported instead of writing
# past the end of the buffer (numba does not check indices).
STATUS_NO_ROOM = 4

# Options for per-step kernels that allocate nothing: numba's reference counting (NRT) otherwise does an
# atomic increment and decrement on every array passed at every call (~10 ns each; the model and force
# tables hold ~55 arrays), which was ~75 % of a one-body split2 step. A kernel that allocates fails to
# compile with these options, loudly, rather than misbehaving. `_nrt` is a numba option without a public
# spelling; the test suite compiles every kernel, so a numba that drops it is caught at once.
STEP_KERNEL: dict[str, Any] = {"cache": True, "_nrt": False, "error_model": "numpy"}

# The per-step entry points the chunk loops call (each integrator's `step`, the force pass): numba inlines
# them into their caller's IR. A call passes every array of the model, force tables and work as ~8
# scalars each, by value: ~700 scalars for a contact scene, twice per step (loop -> step -> force
# pass), which was ~300 of the 660 ns of a split2 step of two far-apart bodies with contact (~170 of
# the 310 ns without). Inlined, the tuples are taken apart once per chunk.
STEP_ENTRY: dict[str, Any] = {**STEP_KERNEL, "inline": "always"}

# Options for the chunk loops the runner calls from Python: they release the GIL, so a recording thread
# (runner.recorder) encodes and writes the previous block while the next chunk runs on another core.
# No NRT, as the step kernels (and for the same reason: the step entry points are inlined into the
# loop, where each array taken from a tuple would be increfed and decrefed every step).
CHUNK_KERNEL: dict[str, Any] = {"cache": True, "nogil": True, "_nrt": False, "error_model": "numpy"}
# error_model "numpy" (both options): a float division by zero gives inf or nan, as IEEE arithmetic does,
# instead of numba's default Python ZeroDivisionError, which escaped a diverging rk4 run as a traceback;
# the state check then stops the run with rbsim's own divergence message. Finite results are the same.


class FrameBuffers(NamedTuple):
    """Preallocated recorded frames: step (K,) int64, x (K,N,3), q (K,N,4), P (K,N,3), L (K,N,3),
    contact (K, CONTACT_STATS): the contact statistics of each recorded state (zeros without contact;
    contact/tables.py STAT_*, contact/state.py: contacts, deepest overlap [m], energy in the contact
    springs [J], and the run's contact history overflows so far), and joint (K, J, 12): each joint's
    reaction over the (sub-)step that ended at the frame [N, N m] (joints/stages.py joint_record; J = 0
    when the buffers do not record them)."""

    step: np.ndarray
    x: np.ndarray
    q: np.ndarray
    P: np.ndarray
    L: np.ndarray
    contact: np.ndarray
    joint: np.ndarray


def empty_buffers(capacity: int, body_count: int, joint_count: int = 0) -> FrameBuffers:
    """Frame buffers for `run_chunk`; joint_count > 0 records the joints' reactions (the joint_forces stream)."""
    return FrameBuffers(
        np.zeros(capacity, dtype=np.int64),
        np.zeros((capacity, body_count, 3)),
        np.zeros((capacity, body_count, 4)),
        np.zeros((capacity, body_count, 3)),
        np.zeros((capacity, body_count, 3)),
        np.zeros((capacity, CONTACT_STATS)),
        np.zeros((capacity, joint_count, 12)),
    )


@numba.njit(cache=True, inline="always")
def model_bodies(model):  # noqa: ANN001, ANN201
    """The body and particle arrays of a KernelModel (or KernelBodies) as a KernelBodies: what a chunk loop
    passes every stage and integrator as `model`. Its numba type is the same whichever tables the scene
    has, so a stage kernel compiled for one kind of scene serves all (physics/kernel_link.py), and a
    call passes no table it does not use; the loop passes the tables by name."""
    return KernelBodies(
        model.body_mass, model.body_inertia, model.body_inertia_inv, model.particle_offset, model.particle_mass,
        model.body_particle_start, model.body_particle_count, model.body_frame,
    )  # fmt: skip


@numba.njit(cache=True)
def state_is_sane(x, q, P, L) -> bool:  # noqa: ANN001
    """True when every state value is finite and below BLOWUP_LIMIT in magnitude."""
    for b in range(x.shape[0]):
        for k in range(3):
            # written as "not (a < limit)" so that NaN also fails
            if not (abs(x[b, k]) < BLOWUP_LIMIT and abs(P[b, k]) < BLOWUP_LIMIT and abs(L[b, k]) < BLOWUP_LIMIT):
                return False
        for k in range(4):
            if not (abs(q[b, k]) < BLOWUP_LIMIT):
                return False
    return True


@numba.njit(cache=True, inline="always")  # inlined: a call per step costs ~10 ns per array argument
def record_if_due(index, record_every, x, q, P, L, frames, filled):  # noqa: ANN001
    """After step `index`: when it is a recording step, check the state and copy it into the next frame.

    Returns (filled, status); status is STATUS_DIVERGED for a bad state (not recorded), STATUS_FULL
    when this frame filled the buffers, and STATUS_NO_ROOM (nothing written) when the buffers were
    already full: the caller must hand over a full buffer before it steps again.
    """
    if index % record_every != 0:
        return filled, STATUS_OK
    if not state_is_sane(x, q, P, L):
        return filled, STATUS_DIVERGED
    if filled >= frames.step.shape[0]:  # never write past the buffer, whatever the caller did
        return filled, STATUS_NO_ROOM
    # element loops, not slice copies (frames.x[filled] = x): numba compiles a formatted shape-mismatch
    # error message for every array-to-slice assignment, 2.2-2.6 s of a first run; a copy is bitwise
    # the same either way
    frames.step[filled] = index
    fx, fq, fP, fL = frames.x, frames.q, frames.P, frames.L
    for b in range(x.shape[0]):
        for k in range(3):
            fx[filled, b, k] = x[b, k]
            fP[filled, b, k] = P[b, k]
            fL[filled, b, k] = L[b, k]
        for k in range(4):
            fq[filled, b, k] = q[b, k]
    filled += 1
    if filled == frames.step.shape[0]:
        return filled, STATUS_FULL
    return filled, STATUS_OK


@numba.njit(cache=True)
def chunk_status(x, q, P, L) -> int:  # noqa: ANN001
    """Status at the end of a chunk: the state is checked even when no frame was due."""
    return STATUS_OK if state_is_sane(x, q, P, L) else STATUS_DIVERGED
