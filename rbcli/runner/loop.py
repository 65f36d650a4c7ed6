"""The run loop: owns time, chunks of compiled steps, recording cadence, divergence and interrupts.

Python regains control only between chunks: to hand a block of frames to the sinks, report progress,
or stop. Chunks are sized to ~0.2 s of work so Ctrl-C and progress stay responsive.
"""

from __future__ import annotations

import signal
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from types import FrameType
from typing import TYPE_CHECKING, Any

import numpy as np

from rbcli._version import __version__
from rbcli.physics.energy import CONTACT_INVARIANT_NAMES, INVARIANT_NAMES, JOINT_INVARIANT_NAMES
from rbcli.record.frame import FrameBlock, RunHeader, RunSummary, Sink
from rbcli.runner.blocks import recorded_joint_names, recorded_model
from rbcli.runner.divergence import GUARD_STEPS, JUMP_FACTOR, EnergyGuard, explain, likely_cause
from rbcli.runner.recorder import Recorder
from rbcli.scene.compile import CompiledScene

if TYPE_CHECKING:
    from rbcli.runner.simulation import Simulation

# Frame buffers are sized to about this many bytes so memory stays flat however long the run.
BLOCK_BYTES = 8 * 1024 * 1024
MAX_BLOCK_FRAMES = 1024
# frames computed are handed to the recorder at least this often (the loss bound of a killed run)
HAND_OVER_SECONDS = 1.0
CHUNK_SECONDS = 0.2
# a checkpoint (everything carried between steps, for `rbsim run --resume`) goes with a handed-over block
# at most this often, and always with the last block: ~13 float64 per body each, small beside the frames
CHECKPOINT_SECONDS = 10.0

ProgressCallback = Callable[[int, int], None]


def frame_capacity(body_count: int) -> int:
    """Frames per buffer: about BLOCK_BYTES of recorded state (13 float64 per body), at least 1 frame.

    The one place buffer sizes come from. At 40,330 bodies and more this is 1 frame: the runner must
    then hand over the buffer after every recorded frame (it does so before each chunk it starts)."""
    return int(np.clip(BLOCK_BYTES // max(1, 13 * 8 * body_count), 1, MAX_BLOCK_FRAMES))


def run_header(compiled: CompiledScene, *, steps: int | None = None, record_every: int | None = None) -> RunHeader:
    """The header every sink receives before the first frame (steps and record_every: what this run
    uses when it is not the scene's own)."""
    spec, model, settings = compiled.spec, recorded_model(compiled), compiled.settings
    return RunHeader(
        scene_name=spec.name,
        scene_text=spec.source_text,
        scene_path=spec.source_path,
        scene_sha256=compiled.scene_sha256,
        body_names=model.body_names,
        body_mass=model.body_mass.copy(),
        body_particle_offset=tuple(
            model.particle_offset_user[model.particle_slice(b)].copy() for b in range(model.body_count)
        ),
        integrator=settings.integrator,
        dt=settings.dt,
        duration=(settings.steps if steps is None else steps) * settings.dt,
        record_every=settings.record_every if record_every is None else record_every,
        streams=settings.streams,
        rbsim_version=__version__,
        seed=settings.seed,
        tolerance=settings.tolerance,
        joint_names=recorded_joint_names(compiled),
        invariant_names=(
            (
                *INVARIANT_NAMES,
                *(CONTACT_INVARIANT_NAMES if compiled.contact is not None else ()),
                *(JOINT_INVARIANT_NAMES if compiled.model.joint is not None else ()),
            )
            if "invariants" in settings.streams
            else ()
        ),
    )


class _InterruptFlag:
    """SIGINT sets a flag checked between chunks (main thread only), so a chunk is never cut mid-way."""

    def __init__(self) -> None:
        self.set = False
        self._previous: Callable[[int, FrameType | None], Any] | int | None = None  # the handler to restore

    def __enter__(self) -> _InterruptFlag:
        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGINT, self._handle)
        return self

    def _handle(self, signum, frame) -> None:  # noqa: ANN001
        self.set = True

    def __exit__(self, *exc: object) -> None:
        if self._previous is not None:
            signal.signal(signal.SIGINT, self._previous)


def run_simulation(
    sim: Simulation,
    sinks: Sequence[Sink],
    *,
    steps: int,
    record_every: int,
    progress: ProgressCallback | None = None,
    threaded: bool = True,
    prefix: Iterable[FrameBlock] = (),
    header_steps: int | None = None,
    record_first: bool = True,
) -> RunSummary:
    """Advance `sim` by `steps` grid steps from its current state, recording its current state, every
    `record_every`-th grid step and the last state; always closes the sinks.

    A resumed run (runner/resume.py) passes the frames its log already holds as `prefix` (written first),
    the whole run's step count as `header_steps` (the header's duration), and record_first False when
    the state it starts from is not on the recording grid (the uninterrupted run has no frame there)."""
    from rbcli.physics.step import STATUS_DIVERGED, STATUS_NO_ROOM

    compiled, settings, state = sim.compiled, sim.settings, sim.data.state
    too_small = -1  # STATUS_STEP_TOO_SMALL, which only the adaptive chunk returns: imported only for it
    if sim.adaptive:
        from rbcli.physics.adaptive import STATUS_STEP_TOO_SMALL as too_small
    capacity = frame_capacity(sim.model.body_count)
    every = record_every
    start, total = state.step, state.step + steps
    recorder = Recorder(compiled, sinks, capacity, threaded=threaded)
    guard = EnergyGuard(compiled)
    guard_every = every * max(1, -(-GUARD_STEPS // every))  # a multiple of every near GUARD_STEPS
    recorder.open(run_header(compiled, steps=steps if header_steps is None else header_steps, record_every=every))
    recorder.write_blocks(prefix)
    buf = recorder.buffer()

    def record_current(frames: int) -> int:
        buf.step[frames] = state.step
        for key in ("x", "q", "P", "L"):
            getattr(buf, key)[frames] = getattr(state, key)
        contact = sim.data.force.contact
        if contact is None:
            buf.contact[frames] = 0.0
        else:  # the current state's (as the chunks' contact_record stage writes them)
            from rbcli.physics.contact.state import record_contact_state

            record_contact_state(sim.model.contact, contact, state.x, state.q, buf.contact, frames)
        if buf.joint.shape[1]:  # the last step's reactions (joint_record's), unknown before any step
            buf.joint[frames] = sim.last_reactions() if sim.reactions_known else np.nan
        previous = recorder.previous(buf)
        if previous is not None:  # welds: the state before the last step, their reactions' other end
            previous[frames] = sim.previous_state()
        return frames + 1

    handed_at = checkpointed_at = time.perf_counter()

    def hand_over(frames: int) -> int:
        """Submit a buffer (with a checkpoint when one is due) and take a fresh one; returns the frames
        now in the buffer (0)."""
        nonlocal buf, handed_at, checkpointed_at
        handed_at = time.perf_counter()
        checkpoint = None
        if frames and handed_at - checkpointed_at >= CHECKPOINT_SECONDS:
            checkpoint, checkpointed_at = sim.checkpoint(), handed_at
        recorder.submit(buf, frames, checkpoint=checkpoint)
        buf = recorder.buffer()
        return 0

    status, message = "completed", ""
    stopped_at: int | None = None  # the step the guard stopped at (the state itself ran on to the chunk's end)
    try:
        frames = record_current(0) if record_first else 0  # the current state is the first frame
        chunk_steps = max(1, min(steps, 64))
        with _InterruptFlag() as interrupted:
            while state.step < total:
                started = time.perf_counter()
                todo = min(chunk_steps, total - state.step)
                if sim.adaptive and state.step + todo < total:
                    # adaptive: end chunks on recorded grid points, so the steps do not depend on chunking
                    todo = min(max(every, todo - todo % every), total - state.step)
                if frames == capacity:  # a chunk needs room for at least one frame
                    frames = hand_over(frames)
                before = frames
                done, frames, code = sim.advance(todo, every, buf, frames, recorder.previous(buf))
                state.step += int(done)
                elapsed = time.perf_counter() - started
                if code == STATUS_NO_ROOM:
                    raise RuntimeError(f"internal error: frame buffer full at step {state.step} (please report)")
                if code == STATUS_DIVERGED:
                    status = "diverged"
                    t = state.step * settings.dt
                    why = explain(sim.compiled, state.x, state.q, state.P, state.L, t)
                    message = f"diverged at step {state.step}: {why}"
                    break
                # the energy guard looks at recorded frames on a fixed grid of steps, so where a run is
                # stopped does not depend on the wall-clock-sized chunks (same scene, same log)
                jump = None
                for row in range(before, frames):
                    if buf.step[row] % guard_every == 0:
                        body = guard.check(buf.q[row], buf.P[row], buf.L[row])
                        if body is not None:
                            jump = (row, body)
                            break
                if jump is not None:
                    row, body = jump
                    frames = row  # the log ends at the last frame before the jump
                    status = "diverged"
                    name = sim.compiled.model.body_names[body]
                    energy = guard.previous[body] if guard.previous is not None else float("nan")
                    at = stopped_at = int(buf.step[row])
                    message = (
                        f"diverged at step {at}: body '{name}': kinetic energy grew more than "
                        f"{JUMP_FACTOR:.0e}-fold in {guard_every} steps, to {energy:.3g} J at "
                        f"t = {at * settings.dt:.6g} s; likely cause: {likely_cause(sim.compiled, body)}"
                    )
                    break
                if code == too_small:
                    status = "diverged"
                    message = (
                        f"tolerance {settings.tolerance:g} not reachable at step {state.step} "
                        f"(t = {state.step * settings.dt:.6g} s): the adaptive step fell below 1e-12 t; "
                        "loosen the tolerance or check the scene for a singularity"
                    )
                    break
                # a full buffer, or frames waiting for HAND_OVER_SECONDS: a killed run then loses at most
                # about that much of its log (the MCAP sink closes a chunk per block, docs/robustness.md)
                if frames == capacity or (frames and time.perf_counter() - handed_at >= HAND_OVER_SECONDS):
                    frames = hand_over(frames)
                if progress is not None:
                    progress(state.step - start, steps)
                if interrupted.set:
                    status, message = (
                        "interrupted",
                        f"interrupted at step {state.step} (t = {state.step * settings.dt:.6g} s)",
                    )
                    break
                # aim each chunk at CHUNK_SECONDS of work, growing or shrinking by at most 4x per chunk
                rate = done / max(elapsed, 1e-9)
                chunk_steps = int(np.clip(rate * CHUNK_SECONDS, max(1, chunk_steps // 4), chunk_steps * 4))
            if status != "diverged" and state.step % every != 0:
                if frames == capacity:
                    frames = hand_over(frames)
                frames = record_current(frames)  # always record the final state
            # the last block carries the state the run stopped at, so an interrupted run can resume from it
            last_checkpoint = sim.checkpoint() if status != "diverged" else None
            recorder.submit(buf, frames, last=True, checkpoint=last_checkpoint)
            recorder.finish()
    except BaseException as exc:  # a failing sink or an unexpected error: still leave readable files
        try:
            recorder.finish()  # what was handed over is written (a failed sink's own error is the one raised)
        except BaseException:  # noqa: BLE001
            pass
        message = f"{type(exc).__name__}: {exc}"
        summary = RunSummary("error", state.step, recorder.frames_written, state.step * settings.dt, message)
        try:
            recorder.close(summary)
        except Exception:  # noqa: BLE001 - the original error is the one to report
            pass
        raise
    counts = sim.data.adaptive_counters
    end = state.step if stopped_at is None else stopped_at
    overflow, overflow_body = contact_overflow(sim)
    summary = RunSummary(
        status, end, recorder.frames_written, end * settings.dt, message,
        steps_accepted=None if counts is None else int(counts[0]),
        steps_rejected=None if counts is None else int(counts[1]),
        contact_history_overflow=overflow, contact_overflow_body=overflow_body,
        implicit_contact_overflow=implicit_overflow(sim),
    )  # fmt: skip
    recorder.close(summary)
    return summary


def contact_overflow(sim) -> tuple[int | None, str]:  # noqa: ANN001 - a Simulation
    """(contacts so far whose tangential history found no free slot, the body of the first of them);
    (None, "") without contact."""
    from rbcli.physics.contact.tables import COUNT_OVERFLOW

    work = sim.data.force.contact
    if work is None:
        return None, ""
    sphere = int(work.overflow_sphere[0])
    body = sim.model.body_names[int(sim.model.contact.sphere_body[sphere])] if sphere >= 0 else ""
    return int(work.counters[COUNT_OVERFLOW]), body


def implicit_overflow(sim) -> int | None:  # noqa: ANN001 - a Simulation
    """reduced-implicit: the contacts so far past its solve's capacity (contact/implicit_rows.py), which kept
    their explicit force; None in any other run."""
    work = sim.data.force.contact
    if work is None or work.implicit_count is None:
        return None
    return int(work.implicit_count[1])
