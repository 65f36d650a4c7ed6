"""`rbsim run --resume LOG`: continue a stopped run from the last checkpoint in its .mcap log, bit for bit.

A run records a checkpoint (record.frame.Checkpoint: everything carried between steps, in the internal
frame) with a block at most every CHECKPOINT_SECONDS of wall time and when it stops (a signal, the end).
Resuming rebuilds the run from the log alone: the scene text attached to it and the run parameters of its
`rbsim` metadata record (integrator, dt, duration, record_every, tolerance), restores the checkpoint into
a Simulation of it, and writes a new log that holds the old frames before the checkpoint, copied as
recorded, then the continued run. Its states are bit for bit those of a run never stopped (tested), since
a step depends only on what the checkpoint holds and the chunk boundaries do not matter.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from rbcli.record.frame import Checkpoint, FrameBlock, RunSummary, Sink
from rbcli.scene.compile import CompiledScene, step_count

if TYPE_CHECKING:
    from rbcli.runner.simulation import Simulation


class ResumeError(ValueError):
    """The log cannot be resumed; the message says why and what to do."""


@dataclass(frozen=True)
class ResumePlan:
    """A log read for resuming: the compiled run it came from and the checkpoint to continue from."""

    log: Path
    compiled: CompiledScene
    checkpoint: Checkpoint
    total_steps: int  # the whole run's steps (the log's duration / dt)
    record_every: int
    log_status: str  # how the old run ended: "interrupted", "truncated" (killed), ...


def plan_resume(log: str | Path, *, compression: str | None = None) -> ResumePlan:
    """Read `log` (an rbsim .mcap file, complete or cut short by a kill) and rebuild its run; ResumeError
    when it cannot be resumed (no checkpoint, completed or diverged, another format)."""
    from rbcli.record.mcap_layout import METADATA_RUN, METADATA_SUMMARY
    from rbcli.record.mcap_recovery import read_mcap_resume_point
    from rbcli.record.read import RecordingTooNew, check_format_version, recording_format
    from rbcli.scene.compile import compile_scene
    from rbcli.scene.load import load_scene_text

    path = Path(log)
    if not path.is_file():
        raise ResumeError(f"{path}: no such log file")
    if recording_format(path) != "mcap":
        raise ResumeError(f"{path}: only .mcap logs hold checkpoints; record to .mcap to be able to resume")
    try:
        point = read_mcap_resume_point(path)
    except ValueError as exc:
        raise ResumeError(f"{path}: {exc}") from None
    run = point.metadata.get(METADATA_RUN)
    if run is None or not point.scene_text:
        raise ResumeError(f"{path}: not an rbsim log (no run parameters or scene attached)")
    try:
        check_format_version(path, run)  # a newer layout's checkpoint could be misread
    except RecordingTooNew as exc:
        raise ResumeError(str(exc)) from None
    status = point.metadata.get(METADATA_SUMMARY, {}).get("status", "truncated")
    if status == "completed":
        raise ResumeError(f"{path}: the run completed; nothing to resume")
    if status == "diverged":
        raise ResumeError(f"{path}: the run diverged; resuming would diverge again (change dt or the integrator)")
    if point.checkpoint is None:
        raise ResumeError(
            f"{path}: the log holds no checkpoint (a run writes one when it stops and at most every "
            "10 s while it runs; this one was killed before its first)"
        )
    scene_path = run.get("scene_path") or None
    base_dir = Path(scene_path).parent if scene_path else path.parent
    spec = load_scene_text(point.scene_text, scene_path or f"{path} (attached scene.yaml)", base_dir)
    tolerance = float(run["tolerance"]) if run.get("tolerance") else None
    dt, duration = float(run["dt"]), float(run["duration"])
    compiled = compile_scene(
        spec, dt=dt, duration=duration, integrator=run["integrator"], record_every=int(run["record_every"]),
        tolerance=tolerance, compression=compression,
    )  # fmt: skip
    if compiled.scene_sha256 != run.get("scene_sha256", compiled.scene_sha256):
        raise ResumeError(f"{path}: the attached scene does not match the run's scene_sha256 (damaged log?)")
    total = step_count(duration, dt)
    if point.checkpoint.step >= total:
        raise ResumeError(f"{path}: the run reached its last step {total}; nothing to resume")
    return ResumePlan(path, compiled, point.checkpoint, total, compiled.settings.record_every, status)


def _copied_frames(plan: ResumePlan) -> Iterator[FrameBlock]:
    """The log's frames before the checkpoint, as recorded (the particles and contacts streams, which the
    log does not hold in a form read back here, recomputed from each frame's state)."""
    from rbcli.physics.frames import internal_orientation
    from rbcli.physics.rotation import quat_to_matrix
    from rbcli.record.mcap_recovery import iter_mcap_frames_before
    from rbcli.runner.blocks import frame_contacts, recorded_model
    from rbcli.scene.parts import merged_state

    compiled = plan.compiled
    model = recorded_model(compiled)  # the recorded bodies: with welds, the scene's parts
    particles = "particles" in compiled.settings.streams
    contacts = "contacts" in compiled.settings.streams and compiled.contact is not None
    body_of = np.repeat(np.arange(model.body_count), model.body_particle_count)
    for block in iter_mcap_frames_before(plan.log, plan.checkpoint.step):
        if particles:  # x + R(q_user) r_user: the recorded pose moves the user-frame cloud
            R = quat_to_matrix(block.q)[:, body_of]
            block.particle_position = block.x[:, body_of] + np.einsum("kpij,pj->kpi", R, model.particle_offset_user)
        if contacts:
            x, q, P, L = block.x, internal_orientation(model, block.q), block.P, block.L
            if compiled.parts is not None:  # the simulated bodies' states, which the contacts are of
                states = [merged_state(compiled.parts, compiled.model, *(a[k] for a in (x, q, P, L)))
                          for k in range(len(block))]  # fmt: skip
                x, q, P, L = (np.stack([s[i] for s in states]) for i in range(4))
            block.contact_point, block.contact_force = frame_contacts(compiled, x, q, P, L)
        yield block


def resume_run(
    plan: ResumePlan,
    sinks: Sequence[Sink],
    *,
    progress=None,  # noqa: ANN001 - runner.loop.ProgressCallback
    threaded: bool = True,
    sim: Simulation | None = None,
) -> RunSummary:
    """Continue the planned run to its end, writing the old frames and then the new ones to `sinks`.
    sim: a Simulation of `plan.compiled` to continue in (one whose kernels are loaded already; default:
    a new one); the checkpoint is restored into it."""
    from rbcli.runner.loop import run_simulation
    from rbcli.runner.simulation import Simulation

    if sim is None:
        sim = Simulation(plan.compiled)
    elif sim.compiled is not plan.compiled:
        raise ValueError("resume_run: the Simulation must be of the plan's compiled scene")
    sim.restore(plan.checkpoint)
    start = plan.checkpoint.step
    return run_simulation(
        sim, sinks, steps=plan.total_steps - start, record_every=plan.record_every, progress=progress,
        threaded=threaded, prefix=_copied_frames(plan), header_steps=plan.total_steps,
        record_first=start % plan.record_every == 0,
    )  # fmt: skip
