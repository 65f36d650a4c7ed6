"""The recording side of a run: frame buffers in, FrameBlocks out to the sinks, in a background thread.

The runner fills a frame buffer inside the compiled chunk (which releases the GIL), hands it over with
`submit`, and takes the next free buffer with `buffer`. A recording thread turns each filled buffer into
a FrameBlock (compiled output derivation, invariants) and writes it to every sink in order, then returns
the buffer to the pool. So on a machine with a spare core the encoding, compression and file writes of
one block overlap the integration of the next, instead of adding to it.

- Memory stays flat: `pool` buffers exist; when the writer falls behind, `buffer` waits for one
  (back-pressure) rather than queueing without bound.
- Order and content do not depend on threading: blocks are written one at a time, in step order, so
  files are byte-identical with `threaded=False` (tested).
- Nothing is lost: `finish` waits until every submitted block is written; the runner calls it on every
  path (completed, diverged, interrupted, or an exception) before closing the sinks.
- A sink that raises stops the writing of later blocks; the error is raised in the runner's thread at
  its next `buffer`, `submit` or `finish`, and every sink is still closed.
- The thread starts with the first full buffer handed over mid-run: a run whose frames fit in one
  buffer (most short runs, and every run that records only its first and last states) writes its one
  block inline and pays no thread start (~0.2 ms, a fifth of a 1,000-step one-body run).
"""

from __future__ import annotations

import queue
import threading
from collections.abc import Iterable, Sequence

import numpy as np

from rbcli.physics.step import FrameBuffers, empty_buffers
from rbcli.record.frame import Checkpoint, FrameBlock, RunHeader, RunSummary, Sink
from rbcli.runner.blocks import make_block, recorded_joint_count, recorded_joint_names
from rbcli.scene.compile import CompiledScene

# Buffers in flight: one being filled, one being written, one ready; more only adds memory.
POOL_BUFFERS = 3
_WAIT_SECONDS = 0.05  # how often a waiting runner re-checks for a recording error


class Recorder:
    """Owns the sinks of a run and the frame buffers the chunks fill (see the module docstring)."""

    def __init__(self, compiled: CompiledScene, sinks: Sequence[Sink], capacity: int, *, threaded: bool = True) -> None:
        self._compiled = compiled
        self._sinks = list(sinks)
        self._threaded = threaded
        n = compiled.model.body_count
        self._free: queue.Queue[FrameBuffers] = queue.Queue()
        # welds recording their reactions: beside each buffer, the state one step before each of its frames
        self._previous: dict[int, np.ndarray] = {}
        for _ in range(POOL_BUFFERS if threaded else 1):
            buffers = empty_buffers(capacity, n, recorded_joint_count(compiled))
            if compiled.parts is not None and recorded_joint_names(compiled):
                self._previous[id(buffers)] = np.full((capacity, n, 13), np.nan)
            self._free.put(buffers)
        self._todo: queue.Queue[tuple[FrameBuffers, int, Checkpoint | None] | None] = queue.Queue()
        self._thread: threading.Thread | None = None
        self._error: BaseException | None = None
        self.frames_written = 0

    def open(self, header: RunHeader) -> None:
        """Open every sink (here, so a sink that cannot open fails the run before it starts)."""
        for sink in self._sinks:
            sink.open(header)

    def buffer(self) -> FrameBuffers:
        """A free frame buffer to fill; waits while all are being written."""
        while True:
            self._raise_if_failed()
            try:
                return self._free.get(timeout=_WAIT_SECONDS)
            except queue.Empty:
                continue

    def previous(self, buffers: FrameBuffers) -> np.ndarray | None:
        """The array beside `buffers` for the state one step before each frame (scenes with welds that
        record the joint_forces stream: runner/weld_reactions.py), else None."""
        return self._previous.get(id(buffers))

    def write_blocks(self, blocks: Iterable[FrameBlock]) -> None:
        """Write ready-made blocks to every sink, in this thread, before any buffer is submitted (a
        resumed run's frames copied from its log)."""
        if self._thread is not None:
            raise RuntimeError("write_blocks after the recording thread started")
        for block in blocks:
            for sink in self._sinks:
                sink.write(block)
            self.frames_written += len(block)

    def submit(
        self, buffers: FrameBuffers, frames: int, *, last: bool = False, checkpoint: Checkpoint | None = None
    ) -> None:
        """Hand over the first `frames` frames of a buffer; the buffer must not be touched afterwards.
        last: no buffer follows (a run's final block is written inline when no thread was needed).
        checkpoint: the run's carried state now (at or after the buffer's last frame), written after the
        block to the sinks that keep checkpoints (record.frame.CheckpointSink)."""
        self._raise_if_failed()
        if self._threaded and self._thread is None and not last and frames:
            self._thread = threading.Thread(target=self._work, name="rbsim-recorder", daemon=True)
            self._thread.start()
        if frames == 0 and checkpoint is None:
            self._free.put(buffers)
        elif self._thread is not None:
            self._todo.put((buffers, frames, checkpoint))
        else:
            self._write(buffers, frames, checkpoint)
            self._free.put(buffers)

    def finish(self) -> None:
        """Wait until every submitted block is written; raise the error of a sink that failed."""
        if self._thread is not None:
            self._todo.put(None)
            self._thread.join()
            self._thread = None
        self._raise_if_failed()

    def close(self, summary: RunSummary) -> None:
        """Close every sink (each one, even when another fails); raise the first failure afterwards."""
        failure: BaseException | None = None
        for sink in self._sinks:
            try:
                sink.close(summary)
            except Exception as exc:  # noqa: BLE001 - the others must still close
                failure = failure or exc
        if failure is not None:
            raise failure

    def _write(self, buffers: FrameBuffers, frames: int, checkpoint: Checkpoint | None = None) -> None:
        if frames:
            self._write_block(buffers, frames)
        if checkpoint is not None:
            for sink in self._sinks:
                write = getattr(sink, "write_checkpoint", None)
                if write is not None:
                    write(checkpoint)

    def _write_block(self, buffers: FrameBuffers, frames: int) -> None:
        b = buffers
        # the last frames before a divergence hold huge numbers whose squares overflow to inf in the
        # invariants: that is what the log should show, without numpy warnings on the terminal
        previous = self.previous(b)
        with np.errstate(over="ignore", invalid="ignore"):
            block = make_block(
                self._compiled, b.step[:frames], b.x[:frames], b.q[:frames], b.P[:frames], b.L[:frames],
                b.contact[:frames], b.joint[:frames], None if previous is None else previous[:frames],
            )  # fmt: skip
            for sink in self._sinks:
                sink.write(block)
        self.frames_written += frames

    def _work(self) -> None:
        while (item := self._todo.get()) is not None:
            buffers, frames, checkpoint = item
            try:
                if self._error is None:
                    self._write(buffers, frames, checkpoint)
            except BaseException as exc:  # noqa: BLE001 - handed to the runner's thread
                self._error = exc
            finally:
                self._free.put(buffers)

    def _raise_if_failed(self) -> None:
        if self._error is not None:
            raise self._error
