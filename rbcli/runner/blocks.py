"""Turn raw recorded states (internal principal frame) into FrameBlocks for the sinks."""

from __future__ import annotations

import numpy as np

from rbcli.physics.energy import invariants_from_kinetic
from rbcli.physics.frames import particle_world
from rbcli.physics.outputs import derive_outputs
from rbcli.record.frame import FrameBlock
from rbcli.scene.compile import CompiledScene


def make_block(
    compiled: CompiledScene, step: np.ndarray, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray
) -> FrameBlock:
    """A FrameBlock of K frames from raw (K, N, ...) arrays; copies, so buffers can be reused."""
    model, settings = compiled.model, compiled.settings
    q_user, v, omega = np.empty_like(q), np.empty_like(P), np.empty_like(L)
    kinetic = np.empty(P.shape[:2])
    derive_outputs(model.body_mass, 1.0 / model.body_inertia, model.body_frame_q, q, P, L, q_user, v, omega, kinetic)
    block = FrameBlock(
        step=step.astype(np.int64, copy=True),
        t=step * settings.dt,
        x=x.copy(),
        q=q_user,
        v=v,
        omega=omega,
        P=P.copy(),
        L=L.copy(),
    )
    if "invariants" in settings.streams:
        block.invariants = invariants_from_kinetic(model, compiled.forces, x, q, P, L, kinetic.sum(axis=1))
    if "particles" in settings.streams:
        block.particle_position, _ = particle_world(model, x, q, P, L)
    return block
