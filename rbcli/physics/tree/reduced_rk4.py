"""`reduced-rk4`: the classical Runge-Kutta method in joint coordinates, integrate.py `step_rk4`; its chunk
loop is chunk_loop.run_chunk bound to it (its own cache files: run_chunk[reduced_rk4])."""

from __future__ import annotations

from rbcli.physics.tree.integrate import step_rk4 as step

SCRATCH_WIDTH = 0

__all__ = ["SCRATCH_WIDTH", "step"]
