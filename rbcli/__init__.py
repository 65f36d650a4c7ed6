"""rbsim: rigid-body dynamics from YAML scenes (package `rbcli`).

Public API: `load_scene`, `simulate`, `Simulation` (step, read and write the state, reset, run),
`BodyState`, `RunOptions` (a run's dt, duration, integrator, ... as one object), `prepare`, `run_to_file`,
`resume_to_file` (continue a stopped .mcap log bit for bit), `Trajectory` (`to_npz`, `from_npz`, `to_csv`),
`read_recording` (a .mcap or .rrd back as a Trajectory), `SimulationDiverged`, `sweep` (a scene over many
parameter values, on Dask: a pyarrow table), `__version__`. Units are SI throughout (m, kg, s, rad);
quaternions are (w, x, y, z), world-from-body.
Attributes are imported lazily so that `rbsim --help` and `rbsim validate` stay light.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

from rbcli._version import __version__

__all__ = [
    "__version__",
    "load_scene",
    "simulate",
    "Simulation",
    "BodyState",
    "RunOptions",
    "prepare",
    "run_to_file",
    "resume_to_file",
    "Trajectory",
    "read_recording",
    "SimulationDiverged",
    "sweep",
]

if TYPE_CHECKING:
    from rbcli.api import (
        BodyState,
        RunOptions,
        Simulation,
        SimulationDiverged,
        load_scene,
        prepare,
        resume_to_file,
        run_to_file,
        simulate,
    )
    from rbcli.record.memory_sink import Trajectory
    from rbcli.record.read import read_trajectory as read_recording
    from rbcli.sweeps.run import sweep


def __getattr__(name: str) -> Any:
    if name == "Trajectory":
        from rbcli.record.memory_sink import Trajectory

        return Trajectory
    if name == "read_recording":  # record/ only: reading a file compiles nothing
        from rbcli.record.read import read_trajectory

        return read_trajectory
    if name == "sweep":  # sweeps/: Dask and pyarrow are imported only when a sweep runs
        from rbcli.sweeps.run import sweep

        return sweep
    if name in __all__:
        from rbcli import api

        return getattr(api, name)
    raise AttributeError(f"module 'rbcli' has no attribute {name!r}")
