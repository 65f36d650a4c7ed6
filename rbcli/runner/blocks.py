"""Turn raw recorded states (internal principal frame) into FrameBlocks for the sinks."""

from __future__ import annotations

import numpy as np

from rbcli.physics.energy import invariants
from rbcli.physics.frames import body_angular_velocity, body_velocity, particle_world, user_orientation
from rbcli.record.frame import FrameBlock
from rbcli.scene.compile import CompiledScene


def make_block(
    compiled: CompiledScene, step: np.ndarray, x: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray
) -> FrameBlock:
    """A FrameBlock of K frames from raw (K, N, ...) arrays; copies, so buffers can be reused."""
    model, settings = compiled.model, compiled.settings
    omega = body_angular_velocity(model, q, L)
    block = FrameBlock(
        step=step.astype(np.int64, copy=True),
        t=step * settings.dt,
        x=x.copy(),
        q=user_orientation(model, q),
        v=body_velocity(model, P),
        omega=omega,
        P=P.copy(),
        L=L.copy(),
    )
    if "invariants" in settings.streams:
        block.invariants = invariants(model, compiled.forces, x, q, P, L, omega)
    if "particles" in settings.streams:
        block.particle_position, _ = particle_world(model, x, q, P, L)
    return block
