"""In-memory recording: the Trajectory that `rbcli.simulate` returns."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from rbcli.record.frame import FrameBlock, RunHeader, RunSummary


@dataclass
class Trajectory:
    """Recorded frames of a run, stacked.

    t (T,) [s]; step (T,); x (T, N, 3) [m]; q (T, N, 4) wxyz world-from-body (user frame);
    v (T, N, 3) [m/s]; omega (T, N, 3) [rad/s] world; P (T, N, 3) [kg m/s]; L (T, N, 3) [kg m^2/s] world.
    invariants: name -> (T,); particle_position (T, particle_count, 3) when recorded.
    """

    body_names: tuple[str, ...]
    t: np.ndarray
    step: np.ndarray
    x: np.ndarray
    q: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    P: np.ndarray
    L: np.ndarray
    invariants: dict[str, np.ndarray] = field(default_factory=dict)
    particle_position: np.ndarray | None = None
    header: RunHeader | None = None
    summary: RunSummary | None = None

    @property
    def status(self) -> str:
        return self.summary.status if self.summary else "unknown"


class SinkMemory:
    """Collects blocks; `trajectory()` stacks them once the run is closed."""

    def __init__(self) -> None:
        self.header: RunHeader | None = None
        self.summary: RunSummary | None = None
        self.blocks: list[FrameBlock] = []

    def open(self, header: RunHeader) -> None:
        self.header = header

    def write(self, block: FrameBlock) -> None:
        self.blocks.append(block)

    def close(self, summary: RunSummary) -> None:
        self.summary = summary

    def trajectory(self) -> Trajectory:
        assert self.header is not None, "open() was never called"
        blocks = self.blocks

        def cat(name: str) -> np.ndarray:
            return np.concatenate([getattr(b, name) for b in blocks])

        inv_names = blocks[0].invariants.keys() if blocks else ()
        particles = blocks[0].particle_position is not None if blocks else False
        return Trajectory(
            body_names=self.header.body_names,
            t=cat("t"),
            step=cat("step"),
            x=cat("x"),
            q=cat("q"),
            v=cat("v"),
            omega=cat("omega"),
            P=cat("P"),
            L=cat("L"),
            invariants={k: np.concatenate([b.invariants[k] for b in blocks]) for k in inv_names},
            particle_position=cat("particle_position") if particles else None,
            header=self.header,
            summary=self.summary,
        )
