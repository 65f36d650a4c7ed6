"""Frozen copy of the chunk loops as they were before the step pipeline (one per integrator module,
positional state arrays, impulses applied by the runner between chunks), for split2 and rk4.

bench_pipeline.py times the chunk loops of rbcli/physics/chunk_loop.py against these in the same run
(interleaved medians): the refactor must keep the chunk kernels within 5 % of them. Do not edit
beyond following the step signature (force_data, the force pass's mutable arrays, and contact, the
model's contact table, came later).
"""

import numba

from rbcli.physics.integrators import rk4, split2
from rbcli.physics.step import CHUNK_KERNEL, STATUS_OK, chunk_status, record_if_due


@numba.njit(**CHUNK_KERNEL)
def run_chunk_split2(
    model,
    forces,
    force_data,
    dt,
    step0,
    n_steps,
    record_every,
    x,
    q,
    P,
    L,
    F,
    tau,
    scratch,
    frames,
    filled,  # noqa: ANN001
):  # noqa: ANN201
    for k in range(n_steps):
        split2.step(model, forces, model.contact, force_data, (step0 + k) * dt, dt, x, q, P, L, F, tau, scratch)
        filled, stop = record_if_due(step0 + k + 1, record_every, x, q, P, L, frames, filled)
        if stop != STATUS_OK:
            return k + 1, filled, stop
    return n_steps, filled, chunk_status(x, q, P, L)


@numba.njit(**CHUNK_KERNEL)
def run_chunk_rk4(
    model,
    forces,
    force_data,
    dt,
    step0,
    n_steps,
    record_every,
    x,
    q,
    P,
    L,
    F,
    tau,
    scratch,
    frames,
    filled,  # noqa: ANN001
):  # noqa: ANN201
    for k in range(n_steps):
        rk4.step(model, forces, model.contact, force_data, (step0 + k) * dt, dt, x, q, P, L, F, tau, scratch)
        filled, stop = record_if_due(step0 + k + 1, record_every, x, q, P, L, frames, filled)
        if stop != STATUS_OK:
            return k + 1, filled, stop
    return n_steps, filled, chunk_status(x, q, P, L)


FROZEN = {"split2": run_chunk_split2, "rk4": run_chunk_rk4}
