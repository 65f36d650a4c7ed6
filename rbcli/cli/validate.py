"""`rbsim validate`: check scene files (and sweep files, docs/sweeps.md) and print every issue on
stderr as `file:line:col: error: message; expected ...` (cli/messages.py); the verdict per file
("ok (...)", the mass properties with -v) goes to stdout.

Nothing is simulated or written. Exit status: 0 when every file is valid (warnings allowed), 1 when any
file has errors or cannot be read, 2 for usage errors (cli/exit_codes.py).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from rbcli.cli import messages
from rbcli.cli.exit_codes import ExitCode


def validate(
    files: Annotated[
        list[Path], typer.Argument(metavar="FILE", help="Scene or sweep files (YAML) to check.", show_default=False)
    ],
    verbose: Annotated[
        bool, typer.Option("-v", "--verbose", help="Also print each body's mass, centre of mass and principal inertia.")
    ] = False,
) -> None:
    """Check scene files against the scene format and physics sanity rules; simulate nothing."""
    from rbcli.scene.load import analyse_scene
    from rbcli.scene.shapes import mass_properties
    from rbcli.sweeps.load import is_sweep_file

    failed = 0
    for file in files:
        if not file.is_file():
            what = "is a directory, not a scene file" if file.is_dir() else "does not exist"
            messages.error(f"scene file {what}", expected="a path to a YAML scene file", where=file)
            failed += 1
            continue
        if is_sweep_file(file):
            failed += 0 if _validate_sweep(file) else 1
            continue
        spec, issues = analyse_scene(file)
        messages.issues(issues, file)
        if spec is None:
            failed += 1
            continue
        particles = sum(len(b.particle_mass) for b in spec.bodies)
        bodies = len(spec.bodies)
        typer.echo(f"{file}: ok ({bodies} bod{'y' if bodies == 1 else 'ies'}, {particles} particles)")
        contact = getattr(spec.compiled_model, "contact", None)
        if contact is not None:
            substeps = spec.contact.substeps if spec.contact is not None else None
            typer.echo(f"  {contact.describe(substeps)}" + ("; sub-steps: auto" if substeps is None else ""))
        if verbose:
            for body in spec.bodies:
                props = mass_properties(body.particle_position, body.particle_mass, body.particle_radius)
                typer.echo(
                    f"  {body.name}: {len(body.particle_mass)} particles, mass {props.mass:.6g} kg, "
                    f"centre of mass {_vector(props.centre_of_mass)} m (body frame), "
                    f"principal inertia {_vector(props.principal_moments)} kg m^2"
                )
    if len(files) > 1:
        typer.echo(f"{len(files) - failed} of {len(files)} scene files valid")
    if failed:
        raise typer.Exit(ExitCode.INVALID)


def _validate_sweep(file: Path) -> bool:
    """Print a sweep file's issues (its base scene's too) and a summary line; True when it is valid."""
    from rbcli.sweeps.load import analyse_sweep

    sweep, issues = analyse_sweep(file)
    messages.issues(issues, file)
    if sweep is None:
        return False
    axes = f"{len(sweep.axes)} ax{'is' if len(sweep.axes) == 1 else 'es'}"
    typer.echo(f"{file}: ok (sweep: {sweep.variant_count} variants of {sweep.scene_path}, {axes})")
    return True


def _vector(v) -> str:
    # rounding leaves ~1e-18 where a symmetric cloud's centre is exactly 0; print that as 0
    return "[" + ", ".join(f"{(x if abs(x) > 1e-12 else 0.0):.6g}" for x in v) + "]"
