"""`rbsim validate`: check scene files (and sweep files, docs/sweeps.md) and print every issue as
`file:line:col: error: message — expected ...`.

Nothing is simulated or written. Exit status: 0 when every file is valid (warnings allowed), 1 when any
file has errors or cannot be read, 2 for usage errors (Typer's own).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer


def validate(
    files: Annotated[list[Path], typer.Argument(help="Scene files (YAML) to check.", show_default=False)],
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
            typer.echo(f"{file}: error: scene file {what} — expected a path to a YAML scene file")
            failed += 1
            continue
        if is_sweep_file(file):
            failed += 0 if _validate_sweep(file) else 1
            continue
        spec, issues = analyse_scene(file)
        for issue in issues:
            if issue.location is None:
                tail = f" — expected {issue.expected}" if issue.expected else ""
                typer.echo(f"{file}: {issue.severity}: {issue.message}{tail}")
            else:
                typer.echo(str(issue))
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
        raise typer.Exit(1)


def _validate_sweep(file: Path) -> bool:
    """Print a sweep file's issues (its base scene's too) and a summary line; True when it is valid."""
    from rbcli.sweeps.load import analyse_sweep

    sweep, issues = analyse_sweep(file)
    for issue in issues:
        typer.echo(str(issue) if issue.location is not None else f"{file}: {issue.severity}: {issue.message}")
    if sweep is None:
        return False
    axes = f"{len(sweep.axes)} ax{'is' if len(sweep.axes) == 1 else 'es'}"
    typer.echo(f"{file}: ok (sweep: {sweep.variant_count} variants of {sweep.scene_path}, {axes})")
    return True


def _vector(v) -> str:
    # rounding leaves ~1e-18 where a symmetric cloud's centre is exactly 0; print that as 0
    return "[" + ", ".join(f"{(x if abs(x) > 1e-12 else 0.0):.6g}" for x in v) + "]"
