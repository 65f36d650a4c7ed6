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
        True, "--measure/--no-measure", help="Time every integrator in-process (compiles on first use)."
    ),
) -> None:
    """List the integrators: order, symplectic, what they conserve exactly, force evaluations per step,
    and the measured cost per body-step on this machine."""
    from rich.console import Console
    from rich.table import Table

    from rbcli.physics.integrators import INTEGRATORS

    console = Console()
    table = Table(title="rbsim integrators (docs/integrators.md)")
    table.add_column("name", no_wrap=True)
    for column in ("order", "symplectic", "conserves exactly", "forces/step", "adaptive"):
        table.add_column(column, justify="right" if column in ("order", "forces/step") else "left")
    if measure:
        table.add_column(f"ns / body-step ({MEASURE_BODIES} bodies)", justify="right")
    for info in INTEGRATORS.values():
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


def measure_cost(name: str, body_count: int, steps: int, *, repeats: int = 3, seed: int = 0) -> float:
    """Wall-clock nanoseconds per body-step of integrator `name`'s compiled chunk loop, best of `repeats`.

    Random particle-cloud bodies under uniform gravity, nothing recorded; one warm-up call first so
    compilation is not timed.
    """
    import time

    import numpy as np

    from rbcli.physics.forces import build_force_tables
    from rbcli.physics.integrators import get_integrator
    from rbcli.physics.model import build_model
    from rbcli.physics.step import empty_buffers

    kernel = get_integrator(name).load()
    rng = np.random.default_rng(seed)
    model, _ = build_model(
        [f"b{i}" for i in range(body_count)],
        [rng.normal(size=(5, 3)) for _ in range(body_count)],
        [rng.uniform(0.5, 2.0, size=5) for _ in range(body_count)],
    )
    q = rng.normal(size=(body_count, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    x, P, L = (rng.normal(size=(body_count, 3)) for _ in range(3))
    forces = build_force_tables(np.array([0.0, 0.0, -9.81]), body_count=body_count)
    kmodel = model.kernel()
    F, tau = np.zeros((body_count, 3)), np.zeros((body_count, 3))
    scratch = np.zeros((body_count, kernel.SCRATCH_WIDTH))
    frames = empty_buffers(1, body_count)
    never = np.iinfo(np.int64).max  # record_every: no frame is due during the timing

    def chunk(n: int) -> None:
        kernel.run_chunk(kmodel, forces, 1e-3, 0, n, never, x, q, P, L, F, tau, scratch, frames, 0)

    chunk(2)
    best = float("inf")
    for _ in range(repeats):
        started = time.perf_counter()
        chunk(steps)
        best = min(best, time.perf_counter() - started)
    return best / (steps * body_count) * 1e9
