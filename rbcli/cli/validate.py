"""`rbsim validate`: check scene files (and sweep files, docs/sweeps.md) and print every issue on
stderr as `file:line:col: error: message; expected ...` (cli/messages.py); the verdict per file
("ok (...)"; with -v each body's mass properties, the joints, what the run will cost and which kernels
it needs) goes to stdout.

Nothing is simulated or written. Exit status: 0 when every file is valid (warnings allowed), 1 when any
file has errors or cannot be read, 2 for usage errors (cli/exit_codes.py).
"""

from __future__ import annotations

from collections import Counter
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
        bool,
        typer.Option(
            "-v",
            "--verbose",
            help="Also print each body's mass, centre of mass and principal inertia, the joints (by type, "
            "constraint rows, loops), the run's size (steps, body-steps) and the kernel families it compiles",
        ),
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
        compiled = _compiled(spec)
        contact = getattr(spec.compiled_model, "contact", None)
        if contact is not None:
            auto = spec.contact is not None and spec.contact.substeps is None
            substeps = compiled.settings.substeps if not isinstance(compiled, str) else None
            from rbcli.api import integrator_info

            # an implicit contact step is not bounded by the stable step (the line says so)
            implicit = not isinstance(compiled, str) and integrator_info(compiled.settings.integrator).implicit_contact
            line = contact.describe(substeps, implicit)
            if auto:  # say how many auto chose (describe prints a count above 1)
                line += " (auto)" if substeps is not None and substeps > 1 else "; sub-steps: auto"
            typer.echo(f"  {line}")
        if not isinstance(compiled, str):
            from rbcli.scene.run_cost import run_cost

            typer.echo(f"  {run_cost(compiled).describe()}")
        if verbose:
            if spec.joints:
                typer.echo(f"  {_joints_line(spec)}")
            for line in _run_lines(spec):
                typer.echo(f"  {line}")
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


def _compiled(spec):  # noqa: ANN001, ANN202 - a SceneSpec -> CompiledScene, or why its run cannot be planned
    """The scene compiled with its own run settings (its sub-steps and cost), or the reason it cannot be
    run as it stands (a str: `_run_lines` says it)."""
    from rbcli.scene.compile import compile_scene

    try:
        return compile_scene(spec)
    except ValueError as exc:
        return str(exc)


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


def _joints_line(spec) -> str:  # noqa: ANN001 - a SceneSpec with joints
    """The joints by type, their constraint rows, and the loops they close: a joint whose two ends the
    earlier joints already connect (through the world too) closes a loop, and the solver takes its rows as
    auxiliary rows (docs/joint_solver.md, "Loops")."""
    import numpy as np

    kinds = Counter(joint.kind for joint in spec.joints)
    text = "joints: " + ", ".join(f"{count} {kind}" for kind, count in kinds.items())
    compiled = spec.compiled_model
    if compiled.parts is not None:  # welds merge bodies (scene/welds.py): they have no rows
        merged = int(np.count_nonzero(~compiled.parts.alone))
        bodies = len(set(compiled.parts.part_body[~compiled.parts.alone].tolist()))
        text += f"; welds merge {merged} bodies into {bodies}" if merged else "; welds to the world: static"
    table = compiled.model.joint
    if table is None:
        return text + "; no constraint rows"
    text += f"; {int(table.row_count.sum()):,} constraint rows"
    closing = [int(j) for j in (table.graph.joint_node < 0).nonzero()[0]]  # the solver's loop joints
    if not closing:
        return text + "; no loop"
    joints = (compiled.simulated or spec).joints  # the table's joints: welds merged
    names = ", ".join(repr(joints[j].name) for j in closing)
    loops = f"{len(closing)} loop{'s' * (len(closing) != 1)}"
    return text + f"; {loops}, closed by {names} ({table.graph.loop_joint.shape[0]:,} auxiliary rows)"


def _run_lines(spec) -> list[str]:  # noqa: ANN001 - a SceneSpec
    """What running the scene as it stands costs (bodies, particles, contact spheres, steps, body-steps =
    steps x sub-steps x bodies, as `rbsim run` counts them) and the kernel families its chunk loop
    compiles: each combination is compiled by its first run on a machine and loaded from numba's cache
    after (docs/performance.md, "Start-up")."""
    from rbcli.api import force_terms
    from rbcli.scene.compile import compile_scene
    from rbcli.scene.compile_contact import touching_spheres  # (physics, through the scene)

    try:
        compiled = compile_scene(spec)
    except ValueError as exc:  # settings that cannot run: say so here, the run refuses them the same way
        return [f"cost: the run cannot be planned: {exc}"]
    settings, bodies = compiled.settings, compiled.model.body_count
    particles = sum(len(body.particle_mass) for body in spec.bodies)
    kernel_tables = compiled.model.kernel()  # None for each table the loop compiles without
    size = [f"{bodies:,} bod{'y' if bodies == 1 else 'ies'}", f"{particles:,} particles"]
    if kernel_tables.contact is not None:
        touching = touching_spheres(compiled.model.contact)  # a shape's lattice spheres: its mass only
        shapes = int((compiled.model.contact.primitive_kind >= 0).sum())
        if touching or not shapes:
            size.append(f"{touching:,} contact spheres")
        if shapes:
            size.append(f"{shapes:,} contact shape{'s' * (shapes != 1)}")
    steps = f"{settings.steps:,} steps of {settings.dt:g} s"
    if settings.substeps > 1:
        steps += f" x {settings.substeps} sub-steps"
    body_steps = settings.steps * settings.substeps * bodies
    if settings.tolerance is None:
        cost = f"{steps} ({settings.integrator}): {body_steps:,} body-steps"
    else:  # an adaptive run lands a step on every recorded time, and takes as many more as its error needs
        cost = (
            f"{steps} on the output grid ({settings.integrator}, tolerance {settings.tolerance:g}): at least "
            f"{body_steps:,} body-steps"
        )
    forces = [term for term in force_terms(spec) if term != "contact"]
    families = ["free bodies"]
    if set(forces) - {"gravity"}:  # one loop serves every mix of force types (forces/tables.py KernelForceTables)
        families.append(f"forces ({', '.join(forces)}: the loop of every mix of force types)")
    elif forces:
        families.append(f"forces ({', '.join(forces)})")
    optional = {"contact": kernel_tables.contact, "kinematic": kernel_tables.kinematic, "joints": kernel_tables.joint}
    families += [name for name, table in optional.items() if table is not None]
    loop = f"{settings.integrator} {'adaptive ' if settings.tolerance is not None else ''}loop"
    lines = []
    tree = compiled.model.tree
    if tree is not None:  # a reduced integrator: the state is the joints' coordinates (docs/trees.md)
        links, rates = int(tree.parent.shape[0]), int(tree.dof_start[-1])
        roots = int((tree.parent < 0).sum())
        lines.append(f"joint coordinates ({settings.integrator}): {links:,} link{'s' * (links != 1)} in {roots:,} "
                     f"tree{'s' * (roots != 1)}, {rates:,} degree{'s' * (rates != 1)} of freedom")  # fmt: skip
    return lines + [
        f"cost: {', '.join(size)}, {cost}",
        f"kernels: the {loop} for {' + '.join(families)} (compiled by the first run of this combination on a "
        "machine, then loaded from numba's cache)",
    ]


def _vector(v) -> str:
    # rounding leaves ~1e-18 where a symmetric cloud's centre is exactly 0; print that as 0
    return "[" + ", ".join(f"{(x if abs(x) > 1e-12 else 0.0):.6g}" for x in v) + "]"
