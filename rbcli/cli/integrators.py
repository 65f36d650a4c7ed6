"""`rbsim integrators`: the integrators rbsim offers and what each conserves, from the registry (no
kernel is imported: instant); `--measure` adds what a step costs here, timed in-process.

The table is plain text in aligned columns, never cut to the terminal's or a pipe's width, so that
`rbsim integrators | grep split` and scripts see every cell whole.
"""

from __future__ import annotations

import sys

import typer

# The quick in-process timing: this many bodies for this many steps after a warm-up call, gravity on
# (a typical scene's wrench); large enough to amortise the per-call overhead, small enough to finish
# in about a second for all integrators together once compiled.
MEASURE_BODIES = 1000
MEASURE_STEPS = 200
COLUMNS = ("name", "order", "symplectic", "conserves exactly", "forces/step", "adaptive")
RIGHT_ALIGNED = frozenset({"order", "forces/step", f"ns/body-step ({MEASURE_BODIES} bodies)"})


def integrators(
    measure: bool = typer.Option(
        False,
        "--measure",
        help="Also time every integrator here, in ns per body-step (compiles each kernel on first use: "
        "about a minute with an empty cache)",
    ),
) -> None:
    """List the integrators: order, symplectic, what they conserve exactly, force evaluations per step
    (with --measure, the cost per body-step on this machine)."""
    from rbcli.api import list_integrators

    header = list(COLUMNS)
    rows = []
    for info in list_integrators():
        rows.append(
            [
                info.name + (" (demo)" if info.demonstration else ""),
                str(info.order),
                "yes" if info.symplectic else "no",
                info.conserves,
                str(info.force_evals),
                "tolerance" if info.adaptive else "",
            ]
        )
    if measure:
        from rbcli.runner.study import measure_cost  # numba, the study: only to time them

        header.append(f"ns/body-step ({MEASURE_BODIES} bodies)")
        for info, row in zip(list_integrators(), rows, strict=True):
            if sys.stderr.isatty():
                sys.stderr.write(f"\rtiming {info.name} (compiles on first use)…\x1b[K")
                sys.stderr.flush()
            row.append(f"{measure_cost(info.name, MEASURE_BODIES, MEASURE_STEPS):.0f}")
        if sys.stderr.isatty():
            sys.stderr.write("\r\x1b[K")
    typer.echo("rbsim integrators (docs/integrators.md)")
    typer.echo(plain_table(header, rows))


def plain_table(header: list[str], rows: list[list[str]]) -> str:
    """Aligned columns separated by two spaces, a dashed rule under the header; no cell is ever cut."""
    widths = [max(len(cell) for cell in column) for column in zip(header, *rows, strict=True)]

    def line(cells: list[str]) -> str:
        parts = [
            cell.rjust(width) if name in RIGHT_ALIGNED else cell.ljust(width)
            for cell, width, name in zip(cells, widths, header, strict=True)
        ]
        return "  ".join(parts).rstrip()

    return "\n".join([line(header), "  ".join("-" * w for w in widths), *(line(r) for r in rows)])
