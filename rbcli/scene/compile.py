"""Compile a validated SceneSpec into the model (with its contact, joint and kinematic tables), the
initial state and the force tables, once. Who builds which table: compile_contact.py the contact
table, compile_forces.py the force tables and the kinematic bodies' table (their schedules are one
table), compile_joints.py the joint table; this module gives the model its tables."""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, fields, replace
from typing import TypedDict, Unpack, cast

import numpy as np

from rbcli.physics.forces import ForceTables
from rbcli.physics.frames import internal_orientation
from rbcli.physics.model import Model, build_model
from rbcli.physics.rotation import quat_rotate, quat_rotate_inverse
from rbcli.physics.state import STATE_LIMIT, State
from rbcli.scene.compile_contact import ContactSummary, compile_contact, kinematic_initial_state, kinematic_rows
from rbcli.scene.compile_forces import compile_force_tables
from rbcli.scene.contact_speed import impact_bound
from rbcli.scene.parts import PartView
from rbcli.scene.spec import SceneError, SceneIssue, SceneSpec


@dataclass(frozen=True)
class RunOptions:
    """What one run changes of its scene's `simulation:` settings; None keeps the scene's value. One object
    from where the options are given (`rbsim run`'s --dt ... --compression, the keywords of `prepare`,
    `simulate` and `Simulation`) to `run_settings`, the one place they meet the scene and are checked.

    dt [s]: the step (with a tolerance: the spacing of the recorded times). duration [s]: simulated time.
    integrator: a registry name (`rbsim integrators`). record_every: record every N-th grid step.
    tolerance [dimensionless]: run adaptively with this error budget. compression: the MCAP chunk
    compression of `run_to_file` ("zstd", "lz4" or "none").
    """

    dt: float | None = None
    duration: float | None = None
    integrator: str | None = None
    record_every: int | None = None
    tolerance: float | None = None
    compression: str | None = None

    def given(self) -> dict[str, object]:
        """The options set (not None), by name: what a refusal names as the override that caused it."""
        return {f.name: getattr(self, f.name) for f in fields(self) if getattr(self, f.name) is not None}

    def merged(self, overrides: RunOverrides) -> RunOptions:
        """These options with the keyword overrides of a public function (`prepare(scene, dt=1e-3)`) set;
        a keyword given as None is not given, as everywhere else (it keeps the value here)."""
        given = cast(RunOverrides, {key: value for key, value in overrides.items() if value is not None})
        return replace(self, **given) if given else self


class RunOverrides(TypedDict, total=False):
    """RunOptions as keyword arguments (`rbcli.simulate(scene, dt=1e-3)`): the same names and types."""

    dt: float | None
    duration: float | None
    integrator: str | None
    record_every: int | None
    tolerance: float | None
    compression: str | None


@dataclass(frozen=True)
class RunSettings:
    """Time stepping and recording of one run. steps = ceil(duration / dt)."""

    dt: float
    steps: int
    integrator: str
    record_every: int
    streams: tuple[str, ...]
    seed: int = 0
    compression: str = "zstd"  # MCAP chunk compression ("zstd", "lz4", "none")
    tolerance: float | None = None  # adaptive: error budget of the run; dt is then the grid of output times
    substeps: int = 1  # integrator steps per dt (contact sub-stepping)

    @property
    def duration(self) -> float:
        return self.steps * self.dt


@dataclass(frozen=True)
class CompiledModel:
    """What compiling a scene builds that no run setting changes: the model (with its contact, joint and
    kinematic tables), the force tables and the initial state. Built once per scene (while loading it);
    runs differ only in their RunSettings."""

    model: Model
    forces: ForceTables
    initial_state: State
    contact: ContactSummary | None = None  # None: the scene has no contact section
    # with welds (scene/welds.py): the scene's bodies as parts of the simulated bodies (every output shows the
    # parts), the simulated scene the model was compiled from, and what the merge could not keep exactly
    parts: PartView | None = None
    simulated: SceneSpec | None = None
    warnings: tuple[SceneIssue, ...] = ()


@dataclass(frozen=True)
class CompiledScene:
    """Everything a run needs, built once: constant model, force tables, initial state, settings."""

    spec: SceneSpec
    model: Model
    forces: ForceTables
    initial_state: State
    settings: RunSettings
    contact: ContactSummary | None = None
    parts: PartView | None = None  # the scene's bodies on the simulated ones (welds: CompiledModel.parts)
    simulated: SceneSpec | None = None  # the scene the model was compiled from (welds merged); None: spec
    weld_warnings: tuple[SceneIssue, ...] = ()

    @property
    def simulated_spec(self) -> SceneSpec:
        """The scene as simulated: welded bodies merged into one (scene/welds.py), else the scene itself."""
        return self.simulated if self.simulated is not None else self.spec

    @property
    def scene_sha256(self) -> str:
        return hashlib.sha256(self.spec.source_text.encode()).hexdigest()

    @property
    def warnings(self) -> list[SceneIssue]:
        """The scene's load-time warnings and those of the settings that actually run (a spring's
        stability limit against the effective dt, whatever the scene's own dt was)."""
        from rbcli.scene.checks import stability_warnings
        from rbcli.scene.run_cost import run_cost_warnings

        issues = [*self.spec.warnings, *self.weld_warnings, *stability_warnings(self), *run_cost_warnings(self)]
        simulated = self.simulated_spec
        if simulated.joints:
            from rbcli.scene.compile_joints import redundant_row_warnings

            issues += redundant_row_warnings(simulated.joints, self.model.joint, self.model, self.initial_state)
        return sorted(issues, key=SceneIssue.order)


def step_count(duration: float, dt: float) -> int:
    """Number of steps covering duration; a duration within 1e-9 relative of a multiple of dt is
    taken as that multiple (so 20 s at dt = 0.001 is 20000 steps, not 20001 by round-off)."""
    return max(1, math.ceil(duration / dt * (1.0 - 1e-9)))


def compile_scene(
    spec: SceneSpec, options: RunOptions | None = None, **overrides: Unpack[RunOverrides]
) -> CompiledScene:
    """Model, forces and initial state (compiled once per spec: reused from loading when there) with the
    run settings: the scene's, changed by `options` and then by keyword overrides (RunOptions' fields)."""
    base = spec.compiled_model if isinstance(spec.compiled_model, CompiledModel) else compile_model(spec)
    settings = run_settings(
        spec, (options or RunOptions()).merged(overrides), contact=base.contact, jointed=base.model.joint is not None
    )
    model, state = base.model, base.initial_state.copy()
    from rbcli.physics.integrators import REDUCED_INTEGRATORS

    if settings.integrator in REDUCED_INTEGRATORS:  # the trees in joint coordinates (scene/compile_trees.py)
        model = replace(model, tree=_trees(spec if base.simulated is None else base.simulated, base))
    return CompiledScene(spec, model, base.forces, state, settings, base.contact, base.parts, base.simulated,
                         base.warnings)  # fmt: skip


def _trees(simulated: SceneSpec, base: CompiledModel):  # noqa: ANN202 - TreeTable
    """The model's trees for a reduced integrator (scene/compile_trees.py), refused where they cannot hold
    the scene."""
    from rbcli.scene.compile_trees import compile_trees

    return compile_trees(base.model, base.initial_state, simulated.bodies, simulated.joints)


def compile_model(spec: SceneSpec, *, merge_welds: bool = True) -> CompiledModel:
    """The model, force tables and initial state of a validated scene; SceneError for what only the
    assembled scene shows (singular inertia, a force naming an unknown body or particle). Bodies joined by
    `fixed` joints are merged into one simulated body (scene/welds.py); merge_welds=False keeps them as
    bodies held by 6-row constraints instead (the joint kernels' tests: a weld's rows stay tested)."""
    if merge_welds and any(joint.kind == "fixed" for joint in spec.joints):
        return _compile_welded(spec)
    model, centres = _bodies_model(spec)
    state = initial_state(spec, model)
    _check_initial_state(spec, state)
    body_index = {name: i for i, name in enumerate(model.body_names)}
    contact, summary = compile_contact(spec, model, centres, state) if spec.contact is not None else (None, None)
    if contact is not None and spec.joints:  # a joint's two bodies do not collide unless it asks
        contact = contact._replace(excluded_pair=_jointed_pairs(spec, body_index, model.body_mass.shape[0]))
    motions = kinematic_rows(spec, model, state) if spec.contact is not None else []
    forces, kinematic_motions = compile_force_tables(
        spec.gravity, spec.forces, model, body_index, centres, contact, motions
    )
    model = replace(model, kinematic=kinematic_motions)
    if contact is not None:
        model = replace(model, contact=contact)
    kinematic_initial_state(model, forces.schedule, state)
    if summary is not None and contact is not None:  # the speeds need the initial state, kinematic ones too
        summary = replace(summary, impact=impact_bound(spec, model, state, contact))
    if spec.joints:
        from rbcli.scene.compile_joints import compile_joints

        joints = compile_joints(spec.joints, spec.bodies, model, centres, state, has_contact=spec.contact is not None)
        model = replace(model, joint=joints)
    return CompiledModel(model, forces, state, summary)


def _bodies_model(spec: SceneSpec) -> tuple[Model, np.ndarray]:
    """The model of the scene's bodies (build_model, errors located at the body) and their user-frame
    centres of mass; kinematic bodies isotropic."""
    try:
        model, centres = build_model(
            [b.name for b in spec.bodies],
            [b.particle_position for b in spec.bodies],
            [b.particle_mass for b in spec.bodies],
            [b.particle_radius for b in spec.bodies],
        )
    except ValueError as exc:
        body = next((b for b in spec.bodies if repr(b.name) in str(exc)), None)
        raise SceneError([SceneIssue(body.location if body else None, str(exc))]) from None
    kinematic = np.array([b.kinematic for b in spec.bodies], dtype=bool)
    if kinematic.any():
        # a kinematic body spins uniformly about its given angular velocity: with an isotropic inertia
        # (the mean principal moment) torque-free rotation is exactly that, for every integrator
        inertia = model.body_inertia.copy()
        inertia[kinematic] = inertia[kinematic].mean(axis=1, keepdims=True)
        inertia.setflags(write=False)
        model = replace(model, body_inertia=inertia)
    return model, centres


def _compile_welded(spec: SceneSpec) -> CompiledModel:
    """compile_model of a scene with welds: the scene's bodies as parts (their own model, initial state and
    force tables, for the outputs and the welds' reactions), the simulated scene of the welded bodies merged
    (scene/welds.py) compiled as any scene, and the PartView between them."""
    from rbcli.scene.compile_joints import compile_joints
    from rbcli.scene.welds import merge_welds, part_view

    parts, centres = _bodies_model(spec)
    parts_state = initial_state(spec, parts)
    _check_initial_state(spec, parts_state)
    index = {name: i for i, name in enumerate(parts.body_names)}
    # what the welds' own entries say is checked as for any joint (anchors that miss each other at the
    # initial poses, both ends fixed): they hold nothing as constraints, but a wrong one is still wrong
    welds = [joint for joint in spec.joints if joint.kind == "fixed"]
    compile_joints(welds, spec.bodies, parts, centres, parts_state, has_contact=spec.contact is not None)
    # the external force and torque on each part, for the welds' reactions (runner/weld_reactions.py)
    part_forces, _ = compile_force_tables(spec.gravity, spec.forces, parts, index, centres)
    merge = merge_welds(spec, parts, centres, parts_state)
    base = compile_model(merge.spec, merge_welds=False)
    model = base.model
    static = np.array([b.static for b in merge.spec.bodies], dtype=bool)
    if static.any() and not model.contact.static_body.shape[0]:
        # a body welded to the world in a scene without contact: a contact table of no spheres holds it
        # (the contact stage zeroes a static body's wrench; its momenta are zero from the start)
        from rbcli.physics.contact.tables import contact_table

        n = model.body_count
        with np.errstate(invalid="ignore"):  # the empty bodies' boxes: inf - inf, masked there
            hold = contact_table(
                static_body=np.flatnonzero(static), body_inv_contact_mass=np.where(static, 0.0, 1.0 / model.body_mass),
                body_stiffness=np.ones(n), body_damping_ratio=np.zeros(n), body_friction=np.zeros(n),
            )  # fmt: skip
        model = replace(model, contact=hold)
    contact_parts = np.zeros(len(spec.bodies), dtype=bool)
    if spec.contact is not None:
        contact_parts[:] = [b.collide for b in spec.bodies]
    view = replace(part_view(merge, parts, model, base.initial_state, parts_state), forces=part_forces,
                   contact_parts=contact_parts)  # fmt: skip
    return CompiledModel(model, base.forces, base.initial_state, base.contact, view, merge.spec, merge.warnings)


def _jointed_pairs(spec: SceneSpec, body_index: dict[str, int], body_count: int) -> np.ndarray:
    """ContactTable.excluded_pair: the body pairs of the joints without `collide: true` (docs/joints.md)."""
    from rbcli.physics.contact.tables import excluded_pair_keys

    pairs = [(body_index[j.bodies[0]], body_index[j.bodies[1]]) for j in spec.joints
             if not j.collide and all(name in body_index for name in j.bodies)]  # fmt: skip
    return excluded_pair_keys(pairs, body_count)


# Recordings store times as whole nanoseconds: int64 in .rrd, uint64 in .mcap; the smaller bound [s]
MAX_RECORDED_TIME = (2**63 - 1) * 1e-9


def _check_initial_state(spec: SceneSpec, state: State) -> None:
    """SceneError, located at each body, when its initial position, momentum or angular momentum is
    non-finite or beyond STATE_LIMIT (1e100): the run would stop at step 0 as diverged. Found by fuzzing:
    a velocity of 1e300 loaded, and `rbsim run` then failed with a SimulationDiverged traceback."""
    issues = []
    quantities = (
        ("position", "m", state.x),
        ("momentum", "kg m/s", state.P),
        ("angular momentum", "kg m^2/s", state.L),
    )
    with np.errstate(invalid="ignore"):
        bad = ~np.all([np.all(np.abs(values) <= STATE_LIMIT, axis=1) for _, _, values in quantities], axis=0)
    for b in np.flatnonzero(bad):  # only the bodies refused, each located
        body = spec.bodies[b]
        for name, unit, values in quantities:
            value = values[b]
            if not np.all(np.abs(value) <= STATE_LIMIT):  # also catches nan
                issues.append(
                    SceneIssue(
                        body.location,
                        f"body '{body.name}': initial {name} [{', '.join(f'{v:.4g}' for v in value)}] {unit} is beyond "
                        f"{STATE_LIMIT:g}, where a run counts the state as diverged",
                        "positions, velocities and angular velocities in SI units, well below 1e100",
                    )
                )
    if issues:
        raise SceneError(issues)


def run_settings(
    spec: SceneSpec,
    options: RunOptions | None = None,
    *,
    contact: ContactSummary | None = None,
    jointed: bool | None = None,
) -> RunSettings:
    """The scene's run settings with `options` applied: the one place run options meet the scene.
    contact: the compiled contacts' summary, whose stable step sets `contact.substeps: auto`. jointed:
    the compiled model has joint rows (None: the scene has joints other than welds, which are merged).

    Every value, given or the scene's, passes the checks the scene loader makes (load.py `_simulation`):
    dt and duration positive and finite, duration / dt a finite number of at least one step, a known
    integrator, a positive finite tolerance, record_every a whole number >= 1. A failing override raises
    ValueError whose message starts with `<keyword>=<value>: ` (`dt=nan: ...`), so a command line can name
    its option instead; a failing scene value (a SceneSpec built in code) starts with `simulation.<key>=`.
    """
    sim = spec.simulation
    options = options or RunOptions()
    given = options.given()
    dt, duration, integrator = options.dt, options.duration, options.integrator
    record_every, tolerance, compression = options.record_every, options.tolerance, options.compression

    def refuse(key: str, value: object, reason: str) -> ValueError:
        name = key if key in given else f"simulation.{key}"
        return ValueError(f"{name}={value!r}: {reason}")

    def number(key: str, value: object) -> float:
        """A positive, finite float (bool and non-numbers refused)."""
        try:
            x = float(value) if not isinstance(value, bool | str) else math.nan  # type: ignore[arg-type]
        except (TypeError, ValueError):
            x = math.nan
        if not (math.isfinite(x) and x > 0.0):
            unit = "" if key == "tolerance" else " of seconds"
            raise refuse(key, value, f"must be a positive, finite number{unit}")
        return x

    dt_value = number("dt", dt if dt is not None else sim.dt)
    duration_value = number("duration", duration if duration is not None else sim.duration)
    with np.errstate(all="ignore"):
        planned = float(np.float64(duration_value) / np.float64(dt_value))
    blame = "dt" if dt is not None or duration is None else "duration"
    if not math.isfinite(planned):
        raise refuse(blame, dt_value if blame == "dt" else duration_value, "duration / dt overflows float64")
    if planned < 1.0 - 1e-9:
        raise refuse(
            blame,
            dt_value if blame == "dt" else duration_value,
            f"dt = {dt_value:g} s is longer than duration = {duration_value:g} s (at least one step is needed)",
        )
    if duration_value > MAX_RECORDED_TIME:
        # found by fuzzing: --dt 4.6e16 --duration 4.6e16 ended in a struct.error traceback in the MCAP writer
        raise refuse(
            "duration",
            duration_value,
            f"longer than {MAX_RECORDED_TIME:.4g} s (292 years), the latest time a recording holds "
            "(whole nanoseconds in a signed 64-bit integer, as .mcap and .rrd store them)",
        )
    every = record_every if record_every is not None else sim.record.every
    try:
        # the compiled loops take it as an int64: 2^70 was an OverflowError traceback (found by fuzzing)
        whole = not isinstance(every, bool | str) and int(every) == every >= 1 and int(every) < 2**63
    except (TypeError, ValueError, OverflowError):
        whole = False
    if not whole:
        raise refuse("record_every", every, "must be a whole number of steps, at least 1 (and below 2^63)")
    name = integrator if integrator is not None else sim.integrator
    from rbcli.physics.integrators import check_integrator

    if jointed is None:
        jointed = any(joint.kind != "fixed" for joint in spec.joints)
    refusal = check_integrator(name, joints=jointed)
    if refusal is not None and refusal.key == "integrator":
        raise refuse("integrator", name, f"{refusal.reason}; {refusal.expected}")
    from rbcli.physics.integrators import REDUCED_INTEGRATORS

    if sim.coordinates == "reduced" and name not in REDUCED_INTEGRATORS:
        raise refuse("integrator", name, "the scene runs in joint coordinates (simulation.coordinates: reduced); "
                     f"the integrators there: {', '.join(REDUCED_INTEGRATORS)}")  # fmt: skip
    if tolerance is not None or sim.tolerance is not None:
        number("tolerance", tolerance if tolerance is not None else sim.tolerance)
    settings = RunSettings(
        dt=dt_value,
        steps=step_count(duration_value, dt_value),
        integrator=name,
        record_every=int(every),
        streams=tuple(sim.record.streams),
        seed=sim.seed,
        compression=compression or sim.record.compression,
        tolerance=tolerance if tolerance is not None else sim.tolerance,
    )
    if spec.contact is not None:
        substeps = spec.contact.substeps
        if substeps is None:
            from rbcli.physics.contact.parameters import substeps_for, travel_step

            substeps = 1
            if contact is not None:
                impact = contact.impact
                travel = travel_step(impact.speed, impact.radius) if impact is not None else math.inf
                # an implicit contact step is stable at any stiffness: only the travel sets its sub-steps
                from rbcli.physics.integrators import implicit_contact

                implicit = implicit_contact(settings.integrator)
                substeps = substeps_for(settings.dt, math.inf if implicit else contact.stable_step, travel)
        if settings.tolerance is not None:
            substeps = 1  # adaptive steps are capped at the contacts' stable step instead (physics/adaptive.py)
        settings = replace(settings, substeps=int(substeps))
    refusal = check_integrator(settings.integrator, tolerance=settings.tolerance is not None, joints=jointed)
    if refusal is not None:
        raise ValueError(refusal.reason)
    return settings


def initial_state(spec: SceneSpec, model: Model) -> State:
    """x, q (world-from-principal), P, L of every body from the scene's initial conditions."""
    n = len(spec.bodies)
    x = np.array([b.position for b in spec.bodies], dtype=np.float64).reshape(n, 3)
    q_user = np.array([b.orientation_wxyz for b in spec.bodies], dtype=np.float64).reshape(n, 4)
    q = internal_orientation(model, q_user)
    P = np.zeros((n, 3))
    L = np.zeros((n, 3))
    with np.errstate(over="ignore", invalid="ignore"):  # M v or I w beyond float64: inf, refused by
        _fill_momenta(spec, model, q_user, q, P, L)  # _check_initial_state with the body named (fuzzing)
    return State(x=x, q=q, P=P, L=L, step=0)


def _fill_momenta(
    spec: SceneSpec, model: Model, q_user: np.ndarray, q: np.ndarray, P: np.ndarray, L: np.ndarray
) -> None:
    """P and L of every body (initial_state), from momenta or from velocities through mass and inertia."""
    for i, body in enumerate(spec.bodies):  # once per body at set-up, not in a step
        if body.momentum is not None:
            P[i] = body.momentum
        elif body.velocity is not None:
            P[i] = model.body_mass[i] * np.asarray(body.velocity, dtype=np.float64)
        if body.angular_momentum is not None:
            L[i] = body.angular_momentum
        elif body.angular_velocity is not None:
            omega = np.asarray(body.angular_velocity, dtype=np.float64)
            if body.angular_velocity_frame == "body":  # user body frame -> world
                omega = quat_rotate(q_user[i], omega)
            # L = I omega = R diag(I) R^T omega
            L[i] = quat_rotate(q[i], model.body_inertia[i] * quat_rotate_inverse(q[i], omega))
