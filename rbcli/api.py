"""The Python API: the same functions the CLI calls.

import rbcli
scene = rbcli.load_scene("scenes/t_handle.yaml")
traj = rbcli.simulate(scene, dt=1e-3, duration=2.0, integrator="euler-matrix")
traj.x  # (T, N, 3) centre-of-mass positions [m]

sim = rbcli.Simulation(scene, integrator="split2")   # compiled once
sim.step(1000); sim.state.omega; sim.set_state(v=...); sim.reset(); sim.run(2.0, sinks=[...])
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Unpack

from rbcli.physics import integrators as _integrators
from rbcli.physics.contact.tables import IMPLICIT_CAPACITY  # noqa: F401 - the CLI's run warning names it
from rbcli.physics.integrators import (
    INTEGRATORS,
    REDUCED_INTEGRATORS,
    IntegratorInfo,
    IntegratorRefusal,
    get_integrator,
)
from rbcli.record.frame import RunSummary, Sink
from rbcli.record.memory_sink import SinkMemory, Trajectory
from rbcli.runner.simulation import BodyState, Simulation, SimulationDiverged
from rbcli.scene.compile import CompiledScene, RunOptions, RunOverrides, compile_scene
from rbcli.scene.spec import SceneSpec

if TYPE_CHECKING:
    from rbcli.runner.loop import ProgressCallback
    from rbcli.runner.resume import ResumePlan

__all__ = [
    "BodyState", "RunOptions", "Simulation", "SimulationDiverged", "load_scene", "prepare", "resume_to_file",
    "run_to_file", "simulate",
]  # fmt: skip


def load_scene(path: str | Path) -> SceneSpec:
    """Read, validate and resolve a scene file; raises SceneError listing every located issue."""
    from rbcli.scene.load import load_scene as _load

    return _load(path)


def list_integrators() -> tuple[IntegratorInfo, ...]:
    """The integrators rbsim offers, in the registry's order: name, order, symplectic, what each conserves,
    force evaluations per step, adaptive (metadata only: no kernel is imported or compiled); the ones in
    joint coordinates (`reduced`: articulated trees, docs/trees.md) last."""
    return (*INTEGRATORS.values(), *REDUCED_INTEGRATORS.values())


def check_integrator(name: str, *, tolerance: bool = False) -> IntegratorRefusal | None:
    """None when `name` can run (with `tolerance`: adaptively), else why not: the registry's one check,
    which scene files, overrides and the CLI all use (metadata only: nothing compiled)."""
    return _integrators.check_integrator(name, tolerance=tolerance)


def integrator_info(name: str) -> IntegratorInfo:
    """One integrator's registry entry; KeyError names the known ones."""
    return get_integrator(name)


def prepare(
    scene: SceneSpec | str | Path, options: RunOptions | None = None, **overrides: Unpack[RunOverrides]
) -> CompiledScene:
    """Load (when given a path) and compile a scene with run options (RunOptions: dt, duration, integrator,
    record_every, tolerance, compression), given as one object, as keywords, or both (keywords win).

    compression: MCAP chunk compression for `run_to_file` ("zstd", "lz4" or "none").

    tolerance: run adaptively (an adaptive integrator such as dopri5) with this error budget; dt is then
    the spacing of the output times, not the step.
    """
    spec = scene if isinstance(scene, SceneSpec) else load_scene(scene)
    return compile_scene(spec, options, **overrides)


def simulate(
    scene: SceneSpec | str | Path,
    options: RunOptions | None = None,
    *,
    sinks: Sequence[Sink] = (),
    on_diverge: str = "raise",
    **overrides: Unpack[RunOverrides],
) -> Trajectory:
    """Run a scene once and return its recorded Trajectory (also streaming to any extra sinks): the same
    as `Simulation(scene, ...).run(sinks=[memory, *sinks])`. For repeated runs of one scene, make a
    Simulation once and call its `run` or `step`: compiling is then paid once. Run options as `prepare`.

    on_diverge: "raise" (SimulationDiverged, carrying the partial trajectory) or "return".
    """
    sim = Simulation(scene, options, **overrides)
    memory = SinkMemory()
    summary = sim.run(sinks=[memory, *sinks])
    trajectory = memory.trajectory()
    if summary.status == "diverged" and on_diverge == "raise":
        raise SimulationDiverged(summary.message, trajectory)
    return trajectory


def run_to_file(
    compiled: CompiledScene | Simulation,
    output: str | Path,
    *,
    progress: ProgressCallback | None = None,
) -> RunSummary:
    """Run a compiled scene from its initial state (or a Simulation from its current state: `rbsim run`
    loads its kernels first) streaming to an .mcap or .rrd file (memory stays flat).

    The run writes `x.partial.mcap` beside `x.mcap` and renames it onto `x.mcap` when it ends (completed,
    interrupted or diverged); a run that fails leaves `x.mcap` as it was (record/output_file.py).
    Raises OutputError (a ValueError) before any work when the file cannot be written, another run is
    writing it, or the disk is too full for the estimated size.
    """
    sim = compiled if isinstance(compiled, Simulation) else Simulation(compiled)
    return _to_file(sim.compiled, output, lambda sinks: sim.run(sinks=sinks, progress=progress))


def resume_to_file(
    log: str | Path | ResumePlan,
    output: str | Path,
    *,
    progress: ProgressCallback | None = None,
    compression: str | None = None,
    simulation: Simulation | None = None,
) -> RunSummary:
    """Continue the run a stopped .mcap log holds (interrupted by a signal, or killed: `log` may be the
    `x.partial.mcap` a kill left) from its last checkpoint to its planned end, writing a new complete log
    to `output`: the old frames, then the continued run, bit for bit as if never stopped
    (runner/resume.py; `log` may also be a plan_resume result). ResumeError (a ValueError) when the log
    cannot be resumed. simulation: a Simulation of the plan's compiled scene to continue in (`rbsim run
    --resume` loads its kernels first); the checkpoint is restored into it."""
    from rbcli.runner.resume import ResumePlan, plan_resume, resume_run

    plan = log if isinstance(log, ResumePlan) else plan_resume(log, compression=compression)
    log = plan.log
    if Path(output).resolve() == Path(log).resolve():
        raise ValueError(f"{output}: the resumed log must go to another file than the one it resumes")
    return _to_file(plan.compiled, output, lambda sinks: resume_run(plan, sinks, progress=progress, sim=simulation))


def _to_file(compiled: CompiledScene, output: str | Path, run) -> RunSummary:  # noqa: ANN001
    """`run(sinks)` streaming to `output` through its partial file (record/output_file.py)."""
    from rbcli.record.output_file import OutputFile, expected_run_bytes
    from rbcli.record.sinks import open_file_sink

    out = OutputFile(output, expected_bytes=expected_run_bytes(compiled, output))
    partial = out.open()
    sink = None
    try:
        sink = open_file_sink(partial, compression=compiled.settings.compression)
        summary = run([sink])
    except BaseException:
        # frames written: the sink closed the partial, a readable log up to the error; keep it
        out.abandon(keep=getattr(sink, "frames_written", 0) > 0)
        raise
    out.commit()
    return summary


def force_terms(spec: SceneSpec) -> tuple[str, ...]:
    """The force terms the scene's compiled wrench evaluates (gravity, field, point_force, torque, spring,
    drag, impulse, contact), in that order."""
    from rbcli.physics.forces import force_terms_present

    compiled = _compiled_model(spec)
    return force_terms_present(compiled.forces, compiled.model.contact)


def conserved_invariants(spec: SceneSpec, names: Sequence[str]) -> dict[str, bool]:
    """For each invariant name (a recording's invariant series), True when the scene's own force terms
    keep it constant, so that its change is the integrator's drift; False when the terms change it
    (momentum under gravity, energy under drag): physics/conservation.py has the rules."""
    from rbcli.physics.conservation import conserved_invariants as _kept

    compiled = _compiled_model(spec)
    return _kept(compiled.model, compiled.forces, tuple(names))


def _compiled_model(spec: SceneSpec):  # noqa: ANN202 - scene.compile.CompiledModel
    if spec.compiled_model is None:
        raise ValueError(f"scene {spec.name!r} has no compiled model")
    return spec.compiled_model
