"""`rbsim run SCENE`: integrate a scene and record every step to an .mcap or .rrd file."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from types import FrameType
from typing import TYPE_CHECKING

import typer

from rbcli.cli import messages
from rbcli.cli.exit_codes import ExitCode, signal_exit
from rbcli.runner.threads import AUTO, PARALLEL_MIN_BODIES, parse_threads
from rbcli.runner.threads import ENV as THREADS_ENV

if TYPE_CHECKING:
    from rbcli.runner.compile_progress import CompileProgress
    from rbcli.runner.simulation import Simulation
    from rbcli.scene.compile import CompiledScene, RunOptions

_STOP_SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")  # each ends a run at a step boundary (_stop_signals)
COMPRESSIONS = ("zstd", "lz4", "none")  # as schemas/scene.schema.json's record.compression
OUTPUT_SUFFIXES = (".mcap", ".rrd")  # as record/sinks.py FORMATS
# Planned work above which `run` asks for --allow-large: 1e10 body-steps is hours on one core at the
# rates of docs/performance.md; a mistyped --dt or --duration (1e-300, 1e9) plans far more.
MAX_BODY_STEPS = 10**10


def complete_integrator(incomplete: str) -> list[str]:
    """Shell completion of --integrator: the registry's names (no kernel is imported)."""
    from rbcli.api import list_integrators

    return [info.name for info in list_integrators() if info.name.startswith(incomplete)]


def complete_compression(incomplete: str) -> list[str]:
    return [name for name in COMPRESSIONS if name.startswith(incomplete)]


def run(
    scene: Path | None = typer.Argument(None, metavar="SCENE", help="Scene YAML file (omit with --resume)."),
    output: Path | None = typer.Option(
        None,
        "--output",
        "-o",
        metavar="FILE",
        help="Output file, .mcap or .rrd, written as <name>.partial.<ext> and renamed when the run ends "
        "[default: the scene's simulation.output, else outputs/<scene name>.rrd]",
    ),
    dt: float | None = typer.Option(None, "--dt", metavar="SECONDS", help="Time step [s] [default: the scene's]"),
    duration: float | None = typer.Option(
        None, "--duration", metavar="SECONDS", help="Simulated time [s] [default: the scene's]"
    ),
    integrator: str | None = typer.Option(
        None,
        "--integrator",
        metavar="NAME",
        autocompletion=complete_integrator,
        help="Integrator (`rbsim integrators` lists them) [default: the scene's]",
    ),
    record_every: int | None = typer.Option(
        None, "--record-every", metavar="N", help="Record every N-th step, N >= 1 [default: the scene's, else 1]"
    ),
    tolerance: float | None = typer.Option(
        None,
        "--tolerance",
        metavar="TOL",
        help="Adaptive stepping (dopri5) with this error budget per step [dimensionless]; dt becomes the "
        "spacing of the recorded times [default: the scene's, else fixed steps]",
    ),
    compression: str | None = typer.Option(
        None,
        "--compression",
        metavar="NAME",
        autocompletion=complete_compression,
        help="MCAP chunk compression: zstd (smallest), lz4 (a little faster) or none (fastest, ~35% larger) "
        "[default: the scene's, else zstd]",
    ),
    allow_large: bool = typer.Option(
        False, "--allow-large", help=f"Run even when the run plans more than {MAX_BODY_STEPS:.0e} body-steps"
    ),
    threads: str | None = typer.Option(
        None,
        "--threads",
        metavar="N",
        help="Threads for the step (a positive integer, 'all', or 'auto': one or every core, re-chosen "
        f"as the run goes by measured speed); scenes under {PARALLEL_MIN_BODIES} bodies and integrators "
        "other than split2 run on one [default: $RBSIM_THREADS, else auto]",
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar and no summary line"),
    resume: Path | None = typer.Option(
        None,
        "--resume",
        metavar="LOG",
        help="Continue the stopped run this .mcap log holds (a signal, or a kill: its .partial.mcap) from its "
        "last checkpoint, bit for bit, into a new complete log [default output: <log>.resumed.mcap]",
    ),
) -> None:
    """Integrate SCENE and record it; exits 1 on an invalid scene or output (writing nothing), 3 on divergence."""
    from rbcli.api import RunOptions, Simulation, check_integrator

    if threads is not None:  # checked first, then this process's RBSIM_THREADS: every run path reads it there
        try:
            value = AUTO if threads.strip().lower() == AUTO else str(parse_threads(threads, "--threads"))
        except ValueError as exc:
            raise messages.fail(str(exc), code=ExitCode.USAGE) from None
        os.environ[THREADS_ENV] = value
    options = RunOptions(dt=dt, duration=duration, integrator=integrator, record_every=record_every,
                         tolerance=tolerance, compression=compression)  # fmt: skip
    if resume is not None:
        fixed = [f"--{name.replace('_', '-')}" for name in options.given() if name != "compression"]
        if scene is not None or fixed:
            extra = ["SCENE"] if scene is not None else []
            raise messages.fail(
                f"--resume continues the run as its log recorded it; drop {', '.join(extra + fixed)}",
                code=ExitCode.USAGE,
            )
        _resume(resume, output, compression, quiet, threads)
        return
    if scene is None:
        raise messages.fail("no scene to run", expected="a SCENE, or --resume LOG to continue a stopped run",
                            code=ExitCode.USAGE)  # fmt: skip
    if not scene.is_file():
        raise messages.fail(f"scene file not found: {scene}", expected="a path to a YAML scene file")
    # the closed sets first, each with a "did you mean": nothing is loaded for a mistyped name
    if integrator is not None:
        refusal = check_integrator(integrator)
        if refusal is not None:
            raise messages.fail(f"--integrator {integrator!r}: {refusal.reason}", expected=refusal.expected)
    if compression is not None and compression not in COMPRESSIONS:
        raise messages.fail_unknown("--compression", compression, COMPRESSIONS, "compression")
    if output is not None and not (output.is_dir() or str(output).endswith(os.sep)):
        suffix = output.suffix.lower()
        if suffix not in OUTPUT_SUFFIXES:
            guess = messages.suffix_guess(output, OUTPUT_SUFFIXES)
            raise messages.fail(
                f"--output {str(output)!r}: unknown format {suffix or '(no extension)'!r}{guess}",
                expected="a file name ending in .mcap or .rrd",
            )
    with _stop_signals() as stops:  # the whole rest of the command: no signal raises in it (_stop_signals)
        compiled, target = _prepare_run(scene, output, options, allow_large)
        for warning in compiled.warnings:
            messages.issue(warning, scene)
        if not quiet:  # what it will cost, from a second on (scene/run_cost.py; over a minute a warning says why)
            from rbcli.scene.run_cost import SAY_FROM, run_cost

            cost = run_cost(compiled)
            if cost.seconds >= SAY_FROM:
                messages.status(cost.describe())
        _end_if_stopped(stops, "before the run started")
        sim = Simulation(compiled, threads=threads)  # the one that runs: its kernels are loaded first
        _load_kernels(sim, quiet, stops)
        _run_and_report(sim, target, quiet, stops)


def _prepare_run(
    scene: Path, output: Path | None, options: RunOptions, allow_large: bool
) -> tuple[CompiledScene, Path]:
    """(the compiled scene, the output path), each checked before any work; on an invalid scene, option or
    output, the error (located where it can be) and typer.Exit."""
    from rbcli.api import integrator_info, prepare
    from rbcli.record.output_file import OutputError, check_output, default_output_path, expected_run_bytes
    from rbcli.scene.spec import SceneError

    try:
        compiled = prepare(scene, options)
        integrator_info(compiled.settings.integrator)  # an unknown name: KeyError listing the known ones
        scene_output = compiled.spec.simulation.output
        target = output or (Path(scene_output) if scene_output else default_output_path(compiled.spec.name))
        # before any work: a folder, an unknown format, an unwritable place, another run on it, a too-full disk
        try:
            check_output(target, expected_bytes=expected_run_bytes(compiled, target))
        except OutputError as exc:
            if not allow_large:  # too much work is the first thing to say (a too-full disk often follows from it)
                _check_planned_work(compiled, options, also=str(exc))
            raise
        if not allow_large:
            _check_planned_work(compiled, options)
    except SceneError as exc:
        messages.issues(exc.issues, scene)
        raise typer.Exit(ExitCode.INVALID) from None
    except (KeyError, ValueError) as exc:
        where = exc.where if isinstance(exc, _TooMuchWork) else None
        message = _name_the_option(str(exc.args[0] if exc.args else exc), options.given())
        raise messages.fail(message, where=where) from None
    return compiled, target


def _resume(log: Path, output: Path | None, compression: str | None, quiet: bool, threads: str | None) -> None:
    """`run --resume LOG`: plan from the log alone, check the output, then run as `run` does."""
    from rbcli.api import Simulation, resume_to_file
    from rbcli.record.output_file import OutputError, check_output, expected_run_bytes
    from rbcli.runner.resume import ResumeError, plan_resume
    from rbcli.scene.spec import SceneError

    if compression is not None and compression not in COMPRESSIONS:
        raise messages.fail_unknown("--compression", compression, COMPRESSIONS, "compression")
    with _stop_signals() as stops:
        try:
            plan = plan_resume(log, compression=compression)
            target = output or resumed_output_path(log)
            if target.resolve() == log.resolve():
                raise ValueError(f"{target}: the resumed log must go to another file than the one it resumes")
            check_output(target, expected_bytes=expected_run_bytes(plan.compiled, target))
        except SceneError as exc:  # the attached scene no longer loads (a mesh file it names changed or went away)
            messages.issues(exc.issues, log)
            raise typer.Exit(ExitCode.INVALID) from None
        except (ResumeError, OutputError, ValueError, KeyError) as exc:
            raise messages.fail(str(exc.args[0] if exc.args else exc)) from None
        if not quiet:
            t = plan.checkpoint.t
            messages.status(f"resuming {log} ({plan.log_status}) at step {plan.checkpoint.step} (t = {t:.6g} s)")
        _end_if_stopped(stops, "before the run started")
        sim = Simulation(plan.compiled, threads=threads)  # resume_to_file restores the checkpoint into it
        _load_kernels(sim, quiet, stops)
        _run_and_report(
            sim, target, quiet, stops, start=plan.checkpoint.step,
            run=lambda path, progress: resume_to_file(plan, path, progress=progress, simulation=sim),
        )  # fmt: skip


def resumed_output_path(log: Path) -> Path:
    """Where `run --resume LOG` writes by default: outputs/x.mcap and outputs/x.partial.mcap (a killed
    run's) both give outputs/x.resumed.mcap."""
    stem = log.name[: -len(log.suffix)] if log.suffix else log.name
    stem = stem.removesuffix(".partial")
    return log.with_name(f"{stem}.resumed{log.suffix or '.mcap'}")


def _run_and_report(sim: Simulation, target: Path, quiet: bool, stops: _Stops, run=None, start: int = 0) -> None:  # noqa: ANN001
    """Run the Simulation `sim` to `target` (with `run(target, progress)`, default `run_to_file` of `sim`),
    then say how the run ended (one line for an interruption: where the log is and up to which step and
    time it holds); raises typer.Exit with the exit status. start: the step the run starts from."""
    from rbcli.record.output_file import OutputError, partial_path

    compiled = sim.compiled
    try:
        summary, wall = _run_with_progress(sim, target, quiet, stops, run, start)
    except OutputError as exc:  # the output was taken or went away after the check
        raise messages.fail(str(exc)) from None
    except (OSError, ValueError, KeyboardInterrupt) as exc:  # the disk or a sink failed
        kept = partial_path(os.path.realpath(target))
        note = f"the log up to the stop is in {kept}" if kept.is_file() else f"{target} is unchanged"
        if isinstance(exc, KeyboardInterrupt):
            messages.status(f"interrupted; {note}")
            raise typer.Exit(stops.exit_status()) from None
        raise messages.fail(f"{type(exc).__name__}: {exc}; {note}") from None
    settings = compiled.settings
    if not quiet:
        from rbcli.api import integrator_info

        implicit = integrator_info(settings.integrator).implicit_contact  # (the stable step does not bind it)
        rate = (summary.steps - start) * compiled.model.body_count / max(wall, 1e-9)
        messages.status(
            f"{summary.status}: {summary.steps - start} steps x {compiled.model.body_count} bodies "
            f"({settings.integrator}, dt = {settings.dt:g} s) in {wall:.2f} s "
            f"({rate:.3g} body-steps/s); {summary.frames} frames -> {target}"
            + (
                f"; adaptive: {summary.steps_accepted} steps accepted, {summary.steps_rejected} rejected"
                if summary.steps_accepted is not None
                else ""
            )
            + (f"; {compiled.contact.describe(settings.substeps, implicit)}" if compiled.contact is not None else "")
            + f"; {sim.threads_report()}"
        )
    if summary.contact_history_overflow:
        messages.warning(
            f"contact: body '{summary.contact_overflow_body}' had a contact sphere with more contacts at once than "
            f"its history slots hold ({summary.contact_history_overflow} contact evaluations over the run, all "
            "bodies): their friction restarted each step without its tangential spring (docs/contact.md)",
            expected="contact spheres of similar sizes, so that none touches more than 12 others",
        )
    if summary.implicit_contact_overflow:
        from rbcli.api import IMPLICIT_CAPACITY

        messages.warning(
            f"contact: {summary.implicit_contact_overflow} contact evaluations over the run were past the "
            f"implicit solve's {IMPLICIT_CAPACITY} contacts a step and kept their explicit force, which is "
            'unstable above the contacts\' stable step (docs/contact.md "Implicit contact")',
            expected="fewer bodies in contact at once, or an explicit integrator with contact.substeps: auto",
        )
    if summary.status == "diverged":
        messages.error(f"{summary.message}; the log up to that point is complete: {target}")
        raise typer.Exit(ExitCode.DIVERGED)
    if summary.status == "interrupted":
        # a Ctrl-C in the loop goes to the loop's own handler, so only SIGINT is missing from `received`
        by = f" by {signal.Signals(stops.received[0]).name}" if stops.received else " by SIGINT"
        messages.status(f"{summary.message}{by}; the log up to that point is complete: {target}")
        raise typer.Exit(stops.exit_status())


def _name_the_option(message: str, given: dict[str, object]) -> str:
    """An override's error as the option that gave it: run_settings says `dt=nan: why`; `--dt nan: why`."""
    for key, value in given.items():
        if value is not None and message.startswith(f"{key}="):
            shown = f"{value:g}" if isinstance(value, float) else str(value)
            return f"--{key.replace('_', '-')} {shown}: {message.split(': ', 1)[-1]}"
    tolerance = given.get("tolerance")
    if tolerance is not None and message.startswith("a tolerance needs"):  # the fixed-step integrator case
        return f"--tolerance {tolerance:g}: {message}"
    return message


class _TooMuchWork(ValueError):
    """`_check_planned_work`'s refusal, located at the scene's dt when the scene's dt and duration set it."""

    def __init__(self, message: str, where: object | None) -> None:
        super().__init__(message)
        self.where = where


def _check_planned_work(compiled: CompiledScene, options: RunOptions, also: str = "") -> None:
    """_TooMuchWork (a ValueError) when the run plans more than MAX_BODY_STEPS body-steps (steps x
    sub-steps x bodies), naming the options that set the step count, or located at the scene's dt when
    they are the scene's; `also`: another refusal to add to the same line."""
    settings, bodies = compiled.settings, compiled.model.body_count
    planned = settings.steps * settings.substeps * bodies
    if planned <= MAX_BODY_STEPS:
        return
    steps_from = (("dt", options.dt), ("duration", options.duration))
    named = [f"--{name} {value:g}" for name, value in steps_from if value is not None]
    source = " and ".join(named) if named else "the scene's dt and duration"
    raise _TooMuchWork(
        f"{source}: the run plans {settings.steps:.3g} steps x {bodies:,} bod{'y' if bodies == 1 else 'ies'}"
        + (f" x {settings.substeps} sub-steps" if settings.substeps > 1 else "")
        + f" = {planned:.3g} body-steps, more than the {MAX_BODY_STEPS:.0e} rbsim runs without asking; "
        "check the units of dt and duration, or pass --allow-large to run it anyway" + (f"; {also}" if also else ""),
        None if named else compiled.spec.simulation.location,
    )


class _Stops:
    """The stop signals a run received, and how they reach the run loop (see `_stop_signals`)."""

    def __init__(self) -> None:
        self.received: list[int] = []
        self.handler: Callable[[int, FrameType | None], None] | None = None

    def forward(self) -> None:
        """Set the run loop's stop flag when the loop runs (its SIGINT handler is installed)."""
        loop = signal.getsignal(signal.SIGINT)
        if loop is not self.handler and callable(loop):
            loop(signal.SIGINT, None)

    def exit_status(self) -> int:
        """128 + the first stop signal (130 SIGINT, 143 SIGTERM, 129 SIGHUP); 130 for Ctrl-C in the loop."""
        return signal_exit(self.received[0]) if self.received else int(ExitCode.SIGINT)


@contextlib.contextmanager
def _stop_signals() -> Iterator[_Stops]:
    """SIGINT (Ctrl-C), SIGTERM (kill, a job scheduler's or container's stop) and SIGHUP (a closed
    terminal) end the command: before the run, with nothing written; in the run, at the end of a chunk,
    with the log up to there complete and renamed into place.

    - While the scene loads and its kernels load or compile (the output not opened yet), a signal ends
      the command with exit 128 + the signal, one line, no file: after loading (`_end_if_stopped`), or
      at the next safe point of numba's compile (runner/compile_progress.py: a raise anywhere in a compile
      broke numba's cache save, issue 44).
    - While the run loop runs, a signal sets its stop flag (the loop's own SIGINT handler).
    - Between the kernels and the loop (opening the output and the sinks), the stop waits for the end of
      the first chunk (the progress callback forwards it), so a signal never lands half-way through
      opening a file.
    - After the loop (finalising: the last blocks, the MCAP summary and index, the rename), a further
      signal is recorded and ignored: it cannot cut the log short. Once a stop signal arrived, the stop
      signals stay ignored when the block ends, until the process exits (SIGKILL still ends it).
    A handler never raises, so no signal interrupts a file write half-way."""
    stops = _Stops()
    if threading.current_thread() is not threading.main_thread():
        yield stops
        return

    def handle(signum: int, frame: FrameType | None) -> None:
        stops.received.append(int(signum))
        stops.forward()

    stops.handler = handle
    numbers = [getattr(signal, name) for name in _STOP_SIGNALS if hasattr(signal, name)]
    previous = {number: signal.signal(number, handle) for number in numbers}
    try:
        yield stops
    finally:
        for number, handler in previous.items():
            signal.signal(number, signal.SIG_IGN if stops.received else handler)


def _end_if_stopped(stops: _Stops, when: str) -> None:
    """A stop signal before the run loop (`when`) ends the command here: one line, exit 128 + the signal,
    nothing written (the output is opened by the run)."""
    if stops.received:
        messages.status(f"stopped by {signal.Signals(stops.received[0]).name} {when}; nothing written")
        raise typer.Exit(stops.exit_status())


def _load_kernels(sim: Simulation, quiet: bool, stops: _Stops) -> None:
    """Load the kernels `sim`'s run calls from numba's cache, compiling those it lacks (a scene's first run,
    or the first after the physics sources changed); the compile is shown (_CompileStatus) and a stop
    signal during it ends the command, nothing written."""
    from rbcli.runner.compile_progress import CompileInterrupted, watch_compiles

    shown = _CompileStatus(quiet)
    try:
        with watch_compiles(shown.update, stop_requested=lambda: bool(stops.received)) as progress:
            sim.load_kernels()
    except CompileInterrupted:
        pass
    done = progress()
    shown.end(done, stopped=bool(stops.received))
    compiling = "while compiling kernels (those finished are cached for the next run)"
    _end_if_stopped(stops, compiling if done.functions else "while loading the kernels")


# what makes the runner's KernelHandles (physics/kernel_handle.py), compiled once per table type just before
# the chunk loop: a pipe's one line names the loop instead
_HANDLE_STORE = "rbcli.physics.kernel_handle."


class _CompileStatus:
    """How `rbsim run` shows numba compiling its kernels (cache loads show nothing: they fire no compile
    event): on a terminal one line rewritten as the compile goes, `compiling kernels: 14 functions, 23 s —
    rbcli.physics.contact.search.find_contacts`; elsewhere (a pipe, a log) one line when compiling starts;
    then a line with what it took; nothing with -q."""

    def __init__(self, quiet: bool) -> None:
        self.quiet = quiet
        self.live = not quiet and messages.can_rewrite_status()
        self.shown = False

    def update(self, progress: CompileProgress) -> None:
        if self.quiet:
            return
        if self.live:
            count = f"{progress.functions} function{'s' if progress.functions != 1 else ''}"
            now = f" — {progress.current}" if progress.current else ""
            messages.live_status(f"compiling kernels: {count}, {progress.seconds:.0f} s{now}")
        elif not self.shown:
            if not progress.current or progress.current.startswith(_HANDLE_STORE):  # the loop comes next: name it
                return
            messages.status(f"compiling kernels, from {progress.current} (once: later runs load them from the cache)…")
        self.shown = True

    def end(self, progress: CompileProgress, stopped: bool) -> None:
        if not self.shown and not self.quiet and progress.functions:  # only the handles' stores compiled
            messages.status("compiling kernels (once: later runs load them from the cache)…")
            self.shown = True
        if not self.shown:
            return
        if self.live:
            messages.end_live_status()
        if not stopped:
            messages.status(f"compiled kernels: {progress.functions} functions in {progress.seconds:.1f} s")


def _run_with_progress(sim: Simulation, target: Path, quiet: bool, stops: _Stops, run=None, start: int = 0):  # noqa: ANN001, ANN202
    from rbcli.api import run_to_file

    compiled = sim.compiled
    if run is None:

        def run(path: Path, progress):  # noqa: ANN001, ANN202
            return run_to_file(sim, path, progress=progress)

    started = time.perf_counter()
    if quiet or not sys.stderr.isatty():

        def forward_stop(done: int, total: int) -> None:
            if stops.received:  # a signal that came before the loop ran: stop after this chunk
                stops.forward()

        summary = run(target, forward_stop)
        return summary, time.perf_counter() - started
    from rich.console import Console  # only for the bar, on a terminal
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    err = Console(stderr=True, highlight=False, soft_wrap=True)

    columns = (TextColumn("simulating"), BarColumn(), TextColumn("t = {task.fields[t]:.4g} s"), TimeRemainingColumn())
    with Progress(*columns, console=err, transient=True) as bar:
        task = bar.add_task("run", total=compiled.settings.steps - start, t=start * compiled.settings.dt)
        dt = compiled.settings.dt

        def progress(done: int, total: int) -> None:
            if stops.received:
                stops.forward()
            bar.update(task, completed=done, total=total, t=(start + done) * dt)

        summary = run(target, progress)
    return summary, time.perf_counter() - started
