"""`rbsim integrators`: the integrators rbsim offers, what each conserves, and what a step costs here."""

from __future__ import annotations

import typer

# The quick in-process timing: this many bodies for this many steps after a warm-up call, gravity on
# (a typical scene's wrench); large enough to amortise the per-call overhead, small enough to finish
# in about a second for all integrators together once compiled.
MEASURE_BODIES = 1000
MEASURE_STEPS = 200


def integrators(
    measure: bool = typer.Option(
        False, "--measure/--no-measure", help="Also time every integrator in-process (compiles on first use)."
    ),
) -> None:
    """List the integrators: order, symplectic, what they conserve exactly, force evaluations per step,
    and the measured cost per body-step on this machine."""
    from rich.console import Console
    from rich.table import Table

    from rbcli.api import list_integrators

    console = Console()
    table = Table(title="rbsim integrators (docs/integrators.md)")
    table.add_column("name", no_wrap=True)
    for column in ("order", "symplectic", "conserves exactly", "forces/step", "adaptive"):
        table.add_column(column, justify="right" if column in ("order", "forces/step") else "left")
    if measure:
        from rbcli.runner.study import measure_cost  # numpy, scipy, the study: only to time them

        table.add_column(f"ns / body-step ({MEASURE_BODIES} bodies)", justify="right")
    for info in list_integrators():
        row = [
            info.name + (" (demo)" if info.demonstration else ""),
            str(info.order),
            "yes" if info.symplectic else "no",
            info.conserves,
            str(info.force_evals),
            "tolerance" if info.adaptive else "",
        ]
        if measure:
            with console.status(f"timing {info.name} (compiles on first use)…"):
                row.append(f"{measure_cost(info.name, MEASURE_BODIES, MEASURE_STEPS):.0f}")
        table.add_row(*row)
    console.print(table)
