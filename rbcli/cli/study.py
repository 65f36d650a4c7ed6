"""`rbsim study SCENE`: work-precision study of every integrator on a scene (error against cost).

Writes <out>/<scene>-study.csv and .json (every number), and a work-precision plot as .png and .svg
(cost bars: the fastest to the slowest timing sample); prints a table; with `--rerun x.rrd` also the
study for the Rerun viewer (`record/rerun_sink.py: write_study_rrd`). MuJoCo's rows come from
`runner/mujoco_twin.py` when mujoco is installed. matplotlib, numba, rerun and the study itself are
imported inside the functions so that `rbsim --help` stays instant.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import TYPE_CHECKING, Annotated

import typer

from rbcli.cli import messages
from rbcli.cli.exit_codes import ExitCode

if TYPE_CHECKING:
    from rich.table import Table

    from rbcli.runner.study import StudyResult, StudyRun

EXIT_INVALID = ExitCode.INVALID
# --quick: three steps (dt, dt/2, dt/4), at most this many coarse steps, a short timing per point: the
# whole command in a few seconds once kernels are cached.
QUICK_DT_EXPONENTS = (0, -1, -2)
QUICK_MAX_STEPS = 100
QUICK_TOLERANCES = (1e-4, 1e-8)  # adaptive methods: two tolerances instead of five
QUICK_MIN_TIME = 0.05  # [s] of timing per point with --quick (0.2 s otherwise)
# The plot's size in pixels is PLOT_SIZE_INCHES * PLOT_DPI (tests check the PNG header against it).
PLOT_SIZE_INCHES = (12.0, 5.0)
PLOT_DPI = 100
# Log axes cannot show 0; errors below this (round-off of exact methods) are drawn at it.
PLOT_ERROR_FLOOR = 1e-16
# A second-panel error this small for every run is round-off: the panel shows the energy drift instead.
NEGLIGIBLE_ERROR = 1e-12

TABLE_COLUMNS = (
    "integrator",
    "dt [s]",
    "steps",
    "max rot err [rad]",
    "max pos err [m]",
    "energy drift",
    "ns/body-step",
    "order (nominal)",
    "cost spread (max/min)",
)
# Width of the table when the output is not a terminal (a file, a pipe, CI logs): wide enough for
# every column, instead of rich's 80-column default that would truncate them.
REPORT_WIDTH = 132


def study(
    scene: Annotated[Path, typer.Argument(metavar="SCENE", help="Scene YAML file")],
    integrator: Annotated[
        list[str] | None,
        typer.Option(
            "--integrator", "-i", metavar="NAME", help="Integrator to study (repeat for several) [default: all]"
        ),
    ] = None,
    dt: Annotated[
        list[float] | None,
        typer.Option(
            "--dt",
            metavar="SECONDS",
            help="Step size [s] (repeat; ratios powers of 2) [default: the scene's dt x 2^(3..-3)]",
        ),
    ] = None,
    duration: Annotated[
        float | None,
        typer.Option("--duration", metavar="SECONDS", help="Simulated time [s] [default: the scene's]"),
    ] = None,
    out: Annotated[
        Path,
        typer.Option(
            "--out", metavar="FOLDER", help="Folder for the CSV, JSON and plots [default: outputs]", show_default=False
        ),
    ] = Path("outputs"),
    quick: Annotated[
        bool,
        typer.Option("--quick", help="Three steps, a short run, 0.05 s of timing per point (for CI)"),
    ] = False,
    min_time: Annotated[
        float | None,
        typer.Option(
            "--min-time",
            min=0.0,
            metavar="SECONDS",
            help="Time [s] spent timing each (integrator, dt) point (CPU time of the run's thread, serially in "
            "this process); the median and the spread over samples are reported [default: 0.2; 0.05 with --quick]",
        ),
    ] = None,
    mujoco: Annotated[
        bool | None,
        typer.Option(
            "--mujoco/--no-mujoco",
            help="Add MuJoCo's Euler and RK4 rows (free bodies under uniform gravity) [default: when mujoco is "
            "installed]",
            show_default=False,
        ),
    ] = None,
    rerun: Annotated[
        Path | None,
        typer.Option(
            "--rerun",
            metavar="FILE",
            help="Also write the study to this .rrd: the errors and costs as Rerun scalars per integrator "
            "(timelines dt and cost) and the plot as an image",
        ),
    ] = None,
) -> None:
    """Run SCENE with every integrator at several step sizes; report error against cost and fitted orders."""
    from rich.console import Console
    from rich.measure import Measurement

    from rbcli.api import load_scene
    from rbcli.runner.study import DEFAULT_MIN_TIME, default_dts, write_study_files
    from rbcli.runner.study import study as run_study
    from rbcli.scene.spec import SceneError

    err = Console(stderr=True, highlight=False)
    console = Console(highlight=False)
    if not console.is_terminal:
        console = Console(highlight=False, width=REPORT_WIDTH)
    if not scene.is_file():
        messages.error(f"scene file not found: {scene}", expected="a path to a YAML scene file")
        raise typer.Exit(EXIT_INVALID)
    try:
        spec = load_scene(scene)
    except SceneError as exc:
        for issue in exc.issues:
            messages.issue(issue, scene)
        raise typer.Exit(EXIT_INVALID) from None
    if rerun is not None and rerun.suffix != ".rrd":
        messages.error(f"--rerun writes an .rrd file, got {rerun}")
        raise typer.Exit(EXIT_INVALID)
    dts = list(dt) if dt else None
    tolerances = None
    if quick:
        dts = dts or [spec.simulation.dt * 2.0**k for k in QUICK_DT_EXPONENTS]
        duration = duration or min(spec.simulation.duration, QUICK_MAX_STEPS * max(dts))
        tolerances = QUICK_TOLERANCES
    timing = min_time if min_time is not None else (QUICK_MIN_TIME if quick else DEFAULT_MIN_TIME)
    try:
        with _progress_bar(err) as progress:
            result = run_study(
                spec,
                integrators=integrator or None,
                dts=dts or default_dts(spec.simulation.dt),
                tolerances=tolerances,
                duration=duration,
                min_time=timing,
                progress=progress,
                mujoco=mujoco,
            )
    except (KeyError, ValueError, RuntimeError) as exc:  # unknown integrator, bad steps, failed reference
        messages.error(str(exc.args[0] if exc.args else exc))
        raise typer.Exit(EXIT_INVALID) from None

    table = render_table(result)
    wanted = Measurement.get(console, console.options.update_width(REPORT_WIDTH), table).maximum
    if wanted > console.width:  # never cut numbers: a narrow terminal wraps the lines instead
        console = Console(highlight=False, width=wanted, force_terminal=console.is_terminal)
    console.print(table)
    csv_path, json_path = write_study_files(result, out)
    png, svg = plot_work_precision(result, out / f"{result.scene_name}-study")
    written = [csv_path, json_path, png, svg]
    if rerun is not None:
        write_study_rerun(result, png, rerun)
        written.append(rerun)
    for path in written:
        messages.status(f"wrote {path}")


@contextmanager
def _progress_bar(console) -> Iterator[Callable[[float, float, str], None] | None]:  # noqa: ANN001
    """A transient rich progress bar on stderr, yielding the study's progress callback (None when
    stderr is not a terminal: no bar in logs and pipes)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    if not console.is_terminal:
        yield None
        return
    columns = (TextColumn("study"), BarColumn(), TextColumn("{task.fields[label]}"), TimeElapsedColumn())
    with Progress(*columns, console=console, transient=True) as bar:
        task = bar.add_task("study", total=1.0, label="")

        def progress(done: float, total: float, label: str) -> None:
            bar.update(task, completed=done, total=total, label=label)

        yield progress


# ---------------------------------------------------------------------------------------------------
# table


def format_error(value: float | None, status: str = "completed") -> str:
    """An error or drift as the table shows it: 3 significant digits, "diverged" or "—"."""
    if status != "completed":
        return status
    if value is None or not math.isfinite(value):
        return "—"
    return f"{value:.2e}"


def format_order(fitted: float | None, nominal: int) -> str:
    """Fitted order with the registry's in brackets, e.g. "4.02 (4)"; "— (4)" when not fitted."""
    return f"{'—' if fitted is None else f'{fitted:.2f}'} ({nominal})"


def format_spread(run: StudyRun) -> str:
    """The timing spread of a run as the table shows it: slowest over fastest sample, e.g. "1.04x"."""
    spread = run.cost_spread
    return f"{spread:.2f}x" if math.isfinite(spread) else "—"


def table_rows(result: StudyResult) -> list[list[str]]:
    """The table's cells, one row per run (TABLE_COLUMNS); adaptive runs show their tolerance."""
    rows = []
    for run in result.runs:
        name, order = run.integrator, format_order(result.fitted_order(run.integrator), run.nominal_order)
        if run.tolerance is not None:
            name, order = f"{run.integrator} tol={run.tolerance:.0e}", "adaptive"
        errors = (run.rotation_error_max, run.position_error_max, run.energy_drift)
        rows.append(
            [name, f"{run.dt:.4g}", str(run.steps), *(format_error(e, run.status) for e in errors),
             f"{run.ns_per_body_step:.0f}", order, format_spread(run)]
        )  # fmt: skip
    return rows


def render_table(result: StudyResult) -> Table:
    """A rich table of the runs, grouped by integrator, captioned with the reference used."""
    from rich import box
    from rich.table import Table
    from rich.text import Text

    ref = result.reference
    caption = f"reference: {ref.description}"
    if ref.kind == "numerical":
        caption += (
            f"; reference error estimate: rotation {format_error(ref.rotation_error_estimate)} rad, "
            f"position {format_error(ref.position_error_estimate)} m"
        )
    caption += (
        f". Errors: max over bodies and {result.frame_count} recorded times over {result.duration:g} s; "
        f"order fitted on the {result.primary_error} error."
    )
    caption += (
        f"\ncost: median CPU time of the compiled loop over samples ({result.min_time:g} s of timing per point, "
        "serial, call overhead taken off); spread = slowest / fastest sample."
    )
    caption += "".join(f"\nnote: {note}" for note in result.notes)
    title = Text(f"Work-precision study: {result.scene_name}")
    # a compact box, units on a second header line: narrow enough for most terminals
    table = Table(title=title, caption=Text(caption), caption_justify="left", box=box.SIMPLE_HEAD, pad_edge=False)
    for i, column in enumerate(TABLE_COLUMNS):  # Text: "[s]" would otherwise be read as rich markup
        header = Text(column.replace("max ", "").replace(" [", "\n[").replace(" (", "\n(").replace(" drift", "\ndrift"))
        table.add_column(header, justify="left" if i == 0 else "right", no_wrap=True)
    runs = result.runs
    for i, cells in enumerate(table_rows(result)):
        last_of_group = i + 1 == len(runs) or runs[i + 1].integrator != runs[i].integrator
        table.add_row(*cells, end_section=last_of_group)
    return table


# ---------------------------------------------------------------------------------------------------
# plot


def _finite(value: float | None) -> bool:
    return value is not None and math.isfinite(value)


def integrator_style(name: str, index: int) -> dict:
    """Line style of an integrator in every figure: `exact` black stars, the `euler-matrix` baseline
    grey dashed squares, the others tab10 colours by their index in the study."""
    from rbcli.runner.study import BASELINE_INTEGRATOR, EXACT_INTEGRATOR

    if name == EXACT_INTEGRATOR:
        return dict(color="black", marker="*", markersize=9, linewidth=2.5, linestyle="-")
    if name == BASELINE_INTEGRATOR:
        return dict(color="0.35", marker="s", markersize=4, linewidth=1.5, linestyle="--")
    if name.startswith("mujoco-"):  # the other engine: its own dash-dot lines and triangles
        return dict(color=f"C{index % 10}", marker="^", markersize=5, linewidth=1.5, linestyle="-.")
    return dict(color=f"C{index % 10}", marker="o", markersize=4, linewidth=1.5, linestyle="-")


def _panels(result: StudyResult) -> list[tuple[str, str]]:
    """(StudyRun field, axis label) of the two panels: the primary error first; the second is the
    other error, or the energy drift when that error is round-off for every run (e.g. position in a
    torque-free scene, where the centre of mass moves exactly in every method)."""
    done = [r for r in result.runs if r.status == "completed"]
    rotation = ("rotation_error_max", "max rotation error [rad]")
    position = ("position_error_max", "max position error [m]")
    energy = ("energy_drift", "energy drift max |E(t) - E(0)| / |E(0)|")
    first, second = (rotation, position) if result.primary_error == "rotation" else (position, rotation)
    if max((getattr(r, second[0]) for r in done), default=0.0) <= NEGLIGIBLE_ERROR and "energy" in result.conserved:
        second = energy
    return [first, second]


def plot_work_precision(result: StudyResult, stem: Path) -> tuple[Path, Path]:
    """Error against cost per simulated second, log-log, one line per integrator; writes stem.png and
    stem.svg (PLOT_SIZE_INCHES at PLOT_DPI). `exact` and the `euler-matrix` baseline are marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from rbcli.runner.study import BASELINE_INTEGRATOR

    stem.parent.mkdir(parents=True, exist_ok=True)
    fig, axes = plt.subplots(1, 2, figsize=PLOT_SIZE_INCHES, dpi=PLOT_DPI)
    names = list(dict.fromkeys(r.integrator for r in result.runs))
    for ax, (key, label) in zip(axes, _panels(result), strict=True):
        for i, name in enumerate(names):
            for adaptive in (False, True):
                runs = [r for r in result.runs if r.integrator == name and (r.tolerance is not None) == adaptive]
                runs = [r for r in runs if r.status == "completed" and _finite(getattr(r, key))]
                if not runs:
                    continue
                fitted = None if adaptive else result.fitted_order(name)
                text = name + ("  adaptive (tolerance)" if adaptive else "")
                text += "" if fitted is None else f"  (p≈{fitted:.2f})"
                text += "  tutorial baseline" if name == BASELINE_INTEGRATOR else ""
                text += f"  (MuJoCo {result.mujoco_version})" if runs[0].engine == "mujoco" else ""
                style = integrator_style(name, i) | (dict(linestyle=":", marker="D") if adaptive else {})
                cost = np.array([r.cost_per_sim_second for r in runs])
                low, high = np.array([r.cost_per_sim_second_range for r in runs]).T
                error = [max(getattr(r, key), PLOT_ERROR_FLOOR) for r in runs]
                # horizontal bars: the fastest and slowest timing sample of each point
                ax.errorbar(cost, error, xerr=[cost - low, high - cost], label=text, capsize=2, **style)
        ref = result.reference
        estimate = {"rotation_error_max": ref.rotation_error_estimate}
        estimate["position_error_max"] = ref.position_error_estimate
        if ref.kind == "numerical" and estimate.get(key):
            ax.axhline(estimate[key], color="0.5", linestyle=":", linewidth=1, label="reference error estimate")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("cost: CPU seconds per simulated second (bars: fastest to slowest sample)")
        ax.set_ylabel(label)
        ax.grid(True, which="major", alpha=0.3)
    axes[0].legend(fontsize=8, loc="best")
    fig.suptitle(
        f"{result.scene_name}: error against cost ({result.reference.kind} reference, {result.duration:g} s, "
        f"{result.body_count} {'body' if result.body_count == 1 else 'bodies'})",
        fontsize=11,
    )
    fig.tight_layout()
    png, svg = stem.with_suffix(".png"), stem.with_suffix(".svg")
    fig.savefig(png, dpi=PLOT_DPI)
    fig.savefig(svg)
    plt.close(fig)
    return png, svg


# ---------------------------------------------------------------------------------------------------
# Rerun


def study_markdown(result: StudyResult) -> str:
    """The study as a markdown document: reference, timing, notes and every run's row."""
    lines = [f"# Work-precision study: {result.scene_name}", "", f"Reference: {result.reference.description}.", ""]
    lines.append(f"Errors: max over bodies and {result.frame_count} recorded times over {result.duration:g} s.")
    lines.append(f"Cost: median CPU time over timing samples, {result.min_time:g} s of timing per point, serial.")
    lines += [""] + [f"- note: {note}" for note in result.notes] + [""]
    lines += ["| " + " | ".join(TABLE_COLUMNS) + " |", "|" + "---|" * len(TABLE_COLUMNS)]
    lines += ["| " + " | ".join(cells) + " |" for cells in table_rows(result)]
    return "\n".join(lines) + "\n"


def write_study_rerun(result: StudyResult, png: Path, path: Path) -> None:
    """The study as an .rrd (`record/rerun_sink.py: write_study_rrd`): per integrator (adaptive methods
    by tolerance as `<name>-adaptive`) the errors and the cost with its spread, the plot as an image."""
    import numpy as np

    from rbcli.record.rerun_sink import StudySeries, write_study_rrd

    series = []
    for name in dict.fromkeys(r.integrator for r in result.runs):
        for adaptive in (False, True):
            rows = [
                i for i, r in enumerate(result.runs) if r.integrator == name and (r.tolerance is not None) == adaptive
            ]
            if not rows:
                continue
            runs = [result.runs[i] for i in rows]
            low_high = np.array([r.cost_per_sim_second_range for r in runs])
            cost = np.column_stack([low_high[:, 0], [r.cost_per_sim_second for r in runs], low_high[:, 1]])
            errors = {}
            for key in ("rotation_error_max", "position_error_max", "energy_drift"):
                values = [getattr(r, key) for r in runs]
                if any(v is not None for v in values):
                    errors[key] = np.array([np.nan if v is None else v for v in values], dtype=np.float64)
            label = f"{name}-adaptive" if adaptive else name
            series.append(StudySeries(label, np.array(rows), np.array([r.dt for r in runs]), cost, errors))
    path.parent.mkdir(parents=True, exist_ok=True)
    write_study_rrd(path, f"{result.scene_name} study", series, png.read_bytes(), study_markdown(result))
