"""`reduced-euler`: semi-implicit Euler in joint coordinates (MuJoCo's default method), integrate.py
`step_euler`; its chunk loop is chunk_loop.run_chunk bound to it (its own cache files: run_chunk[reduced_euler])."""

from __future__ import annotations

from rbcli.physics.tree.integrate import step_euler as step

SCRATCH_WIDTH = 0

__all__ = ["SCRATCH_WIDTH", "step"]
