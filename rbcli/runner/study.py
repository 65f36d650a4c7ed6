"""Work-precision study: every integrator at a range of step sizes, error against cost.

For each (integrator, dt) the scene is run once for accuracy (recorded at a cadence common to all
runs, so every run is compared at the same times) and `repeats` more times for cost (the compiled
step loop alone, kernels warmed up first so compilation is excluded; the median is kept).

Reference: when the compiled scene has no force term other than uniform gravity, every body's motion
is known exactly: its centre of mass moves as x0 + v0 t + g t^2 / 2 and it rotates torque-free
(Euler-Poinsot, `analysis/exact.py`). Otherwise the reference is the most accurate registered method at
dt_ref = dt_min / 16, and its own error is estimated by the difference to a run at 2 dt_ref (for a
method of order p that difference is (2^p - 1) times the fine run's error: a conservative estimate).

Step sizes are dt_base 2^-k (or any set with a rational common multiple), so recorded times t = k T_out
coincide across runs; the duration is rounded up to a whole number of the coarsest step.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from rbcli.analysis.errors import (
    ROTATION_SATURATION,
    OrderFit,
    ReferencePath,
    admits_exact_solution,
    conserved_quantities,
    exact_reference,
    fit_order,
    invariant_drifts,
    roundoff_floor,
    run_errors,
    smoothness_notes,
)
from rbcli.physics.integrators import INTEGRATORS, IntegratorInfo, get_integrator
from rbcli.record.memory_sink import Trajectory
from rbcli.scene.compile import CompiledScene, compile_scene
from rbcli.scene.spec import RecordSpec, SceneSpec

# Default step sizes: 7 values dt_scene * 2^(3..-3), 1.8 decades centred on the scene's dt.
DEFAULT_DT_EXPONENTS = (3, 2, 1, 0, -1, -2, -3)
# Default tolerances for adaptive methods: 2 decades per point over 8 decades.
DEFAULT_TOLERANCES = (1e-2, 1e-4, 1e-6, 1e-8, 1e-10)
# About this many recorded frames per run: enough to catch the maximum error of a smooth error curve,
# few enough that recording costs nothing next to the steps.
TARGET_FRAMES = 400
# The numerical reference runs this much finer than the finest studied step.
REFERENCE_REFINEMENT = 16
# Among methods of the highest registered order, the reference is the first of these.
REFERENCE_PREFERENCE = ("split4", "exact4", "rk4", "split2", "euler-matrix")
# A timed measurement shorter than this is repeated within the measurement (timer resolution and
# call overhead stay below ~1 %).
MIN_TIMED_SECONDS = 0.01
BASELINE_INTEGRATOR = "euler-matrix"
EXACT_INTEGRATOR = "exact"

Progress = Callable[[float, float, str], None]


@dataclass(frozen=True)
class StudyRun:
    """One (integrator, dt) run: its errors against the reference, invariant drift and cost.

    Errors are maxima over bodies and recorded times (…_max) and at the final time (…_final):
    rotation [rad] (geodesic angle), position [m] (centre of mass). Drifts are relative,
    max_t |I(t) - I(0)| / |I(0)|, and None where the scene does not conserve the quantity.
    seconds_per_step [s] is the median wall time of the compiled step loop; ns_per_body_step divides
    by the body count; cost_per_sim_second [s/s] = wall seconds per simulated second. Adaptive runs
    (tolerance set): steps are the accepted steps, dt their mean, rejected_steps the others (which
    cost force evaluations and time too).
    """

    integrator: str
    dt: float
    tolerance: float | None
    steps: int
    force_evals: int
    status: str
    rotation_error_max: float
    position_error_max: float
    rotation_error_final: float
    position_error_final: float
    energy_drift: float | None
    momentum_drift: float | None
    angular_momentum_drift: float | None
    seconds_per_step: float
    ns_per_body_step: float
    cost_per_sim_second: float
    rejected_steps: int = 0


@dataclass(frozen=True)
class ReferenceInfo:
    """What the runs are compared against.

    kind: "exact" or "numerical". For a numerical reference: its integrator and dt [s], and the
    estimate of its own error (max over the run of |ref(dt_ref) - ref(2 dt_ref)|, rotation [rad] and
    position [m]).
    """

    kind: str
    description: str
    integrator: str | None = None
    dt: float | None = None
    rotation_error_estimate: float | None = None
    position_error_estimate: float | None = None


@dataclass(frozen=True)
class IntegratorFit:
    """Fitted orders of one integrator (rotation and position errors) and the registry's order."""

    integrator: str
    nominal_order: int
    symplectic: bool
    rotation: OrderFit
    position: OrderFit


@dataclass
class StudyResult:
    """Everything a study measured; `primary_error` ("rotation", or "position" when nothing rotates)
    is the error the table's fitted order and the plot's first panel use."""

    scene_name: str
    body_count: int
    duration: float
    output_interval: float
    frame_count: int
    repeats: int
    reference: ReferenceInfo
    conserved: tuple[str, ...]
    primary_error: str
    runs: list[StudyRun] = field(default_factory=list)
    fits: dict[str, IntegratorFit] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)

    def fitted_order(self, integrator: str) -> float | None:
        """Fitted order of the primary error for an integrator (None when not enough points)."""
        fit = self.fits.get(integrator)
        return None if fit is None else getattr(fit, self.primary_error).order

    def run_fitted_order(self, run: StudyRun) -> float | None:
        """The fitted order a run's row shows: its integrator's, none for adaptive (tolerance) runs."""
        return None if run.tolerance is not None else self.fitted_order(run.integrator)

    def as_dict(self) -> dict:
        """Plain JSON-able dict of every number (non-finite numbers become None)."""
        return _finite_or_none(
            {
                "scene": self.scene_name,
                "body_count": self.body_count,
                "duration": self.duration,
                "output_interval": self.output_interval,
                "frame_count": self.frame_count,
                "repeats": self.repeats,
                "reference": dataclasses.asdict(self.reference),
                "conserved": list(self.conserved),
                "primary_error": self.primary_error,
                "notes": list(self.notes),
                "runs": [dataclasses.asdict(r) | {"fitted_order": self.run_fitted_order(r)} for r in self.runs],
                "fits": {
                    name: {
                        "nominal_order": f.nominal_order,
                        "symplectic": f.symplectic,
                        "rotation": f.rotation.as_dict(),
                        "position": f.position.as_dict(),
                    }
                    for name, f in self.fits.items()
                },
            }
        )


# ---------------------------------------------------------------------------------------------------
# what the scene admits


def applicable_integrators() -> tuple[str, ...]:
    """Every registered integrator (fixed-step ones by dt, adaptive ones by tolerance), except those
    kept only to demonstrate a failure (ask for them by name)."""
    return tuple(name for name, info in INTEGRATORS.items() if not getattr(info, "demonstration", False))


def is_adaptive(info: IntegratorInfo) -> bool:
    """An integrator that chooses its own steps from a tolerance."""
    return bool(getattr(info, "adaptive", False))


# ---------------------------------------------------------------------------------------------------
# common output times


@dataclass(frozen=True)
class OutputGrid:
    """Recorded times shared by all runs: every `every_base` steps of the coarse step `base` [s].

    base_steps: coarse steps over the duration; times: (frames,) [s]; duration = base_steps * base.
    """

    base: float
    base_steps: int
    every_base: int

    @property
    def duration(self) -> float:
        return self.base_steps * self.base

    @property
    def output_interval(self) -> float:
        return self.every_base * self.base

    @property
    def times(self) -> np.ndarray:
        index = np.arange(0, self.base_steps + 1, self.every_base)
        if index[-1] != self.base_steps:  # the runner always records the final state
            index = np.append(index, self.base_steps)
        return index * self.base

    def steps_per_base(self, dt: float) -> int:
        return round(self.base / dt)


def _as_fraction(value: float) -> Fraction:
    """The simple fraction a decimal-looking step is meant to be (0.01 -> 1/100, 1/60 -> 1/60)."""
    frac = Fraction(value).limit_denominator(1_000_000)
    if abs(float(frac) - value) > 1e-12 * value:
        frac = Fraction(value)
    return frac


def output_grid(dts: Sequence[float], duration: float, target_frames: int = TARGET_FRAMES) -> OutputGrid:
    """The coarsest common multiple of the steps, and a cadence giving about target_frames frames.

    Raises ValueError when the steps have no common multiple within the duration (e.g. 0.01 and 0.003
    over 0.02 s): pick steps as dt 2^-k so that recorded times coincide.
    """
    fracs = [_as_fraction(dt) for dt in dts]
    num = math.lcm(*(f.numerator for f in fracs))
    den = math.gcd(*(f.denominator for f in fracs))
    base = float(Fraction(num, den))
    if base > duration * (1 + 1e-9):
        raise ValueError(
            f"the step sizes {list(dts)} have no common multiple within the duration {duration:g} s "
            f"(least common multiple {base:g} s); choose steps dt * 2^-k or a longer duration"
        )
    base_steps = max(1, math.ceil(duration / base * (1.0 - 1e-9)))
    every = max(1, round(base_steps / target_frames))
    return OutputGrid(base, base_steps, every)


def default_dts(dt: float) -> tuple[float, ...]:
    """dt 2^k for k = 3 .. -3: seven steps over 1.8 decades, coarse to fine."""
    return tuple(dt * 2.0**k for k in DEFAULT_DT_EXPONENTS)


# ---------------------------------------------------------------------------------------------------
# references


def reference_integrator() -> str:
    """The most accurate registered fixed-step method: the highest order, ties broken by
    REFERENCE_PREFERENCE (symplectic split4 before rk4); demonstration methods never."""
    candidates = [i for i in INTEGRATORS.values() if not getattr(i, "demonstration", False)]
    rank = {name: k for k, name in enumerate(REFERENCE_PREFERENCE)}
    return max(candidates, key=lambda i: (i.order, -rank.get(i.name, len(rank)))).name


# ---------------------------------------------------------------------------------------------------
# one run


def _study_spec(scene: SceneSpec) -> SceneSpec:
    """The scene recording bodies and invariants only (particles would only cost time)."""
    sim = dataclasses.replace(scene.simulation, record=RecordSpec(1, ("bodies", "invariants")), tolerance=None)
    return dataclasses.replace(scene, simulation=sim)


def _simulate(compiled: CompiledScene) -> Trajectory:
    from rbcli.record.memory_sink import SinkMemory
    from rbcli.runner.loop import run

    memory = SinkMemory()
    run(compiled, [memory])
    return memory.trajectory()


def seconds_per_step(compiled: CompiledScene, repeats: int) -> float:
    """Median wall time [s] of one step of the compiled chunk loop (no recording), over `repeats`
    measurements; the kernel must already be compiled (`runner.loop.warm_up`).

    Each measurement runs the whole run from the initial state, repeated within the measurement when
    one run is shorter than MIN_TIMED_SECONDS; the call overhead (a 0-step call: argument unboxing)
    is measured the same way and taken off, so short runs are not billed for it.
    """
    from rbcli.runner.simulation import Simulation

    sim = Simulation(compiled)
    steps = compiled.settings.steps

    def timed(count: int, times: int) -> float:
        started = time.perf_counter()
        for _ in range(times):
            sim.reset()
            sim.advance(count)  # records nothing: the loop is the steps alone
        return (time.perf_counter() - started) / times

    def median(count: int) -> float:
        inner = max(1, math.ceil(MIN_TIMED_SECONDS / max(timed(count, 1), 1e-9)))
        return float(np.median([timed(count, inner) for _ in range(max(1, repeats))]))

    whole = median(steps)
    overhead = median(0)
    # on a busy machine the difference of two medians can come out <= 0 for very short runs
    return (whole - overhead) / steps if whole > overhead else whole / steps


def measure_cost(name: str, body_count: int, steps: int, *, repeats: int = 3, seed: int = 0) -> float:
    """Wall-clock nanoseconds per body-step of integrator `name`'s compiled chunk loop, best of `repeats`.

    Random particle-cloud bodies under uniform gravity, nothing recorded; one warm-up call first so
    compilation is not timed.
    """
    from rbcli.runner.simulation import Simulation
    from rbcli.scene.spec import BodySpec, SimulationSpec

    rng = np.random.default_rng(seed)
    bodies = []
    for i in range(body_count):
        q = rng.normal(size=4)
        bodies.append(
            BodySpec(
                name=f"b{i}",
                particle_position=rng.normal(size=(5, 3)),
                particle_mass=rng.uniform(0.5, 2.0, size=5),
                position=rng.normal(size=3),
                orientation_wxyz=q / np.linalg.norm(q),
                velocity=rng.normal(size=3),
                angular_momentum=rng.normal(size=3),
            )  # fmt: skip
        )
    simulation = SimulationSpec(dt=1e-3, duration=1.0, integrator=name, record=RecordSpec(1, ("bodies",)))
    spec = SceneSpec(name="cost", simulation=simulation, bodies=tuple(bodies), gravity=np.array([0.0, 0.0, -9.81]))
    sim = Simulation(spec)
    sim.advance(2)
    best = float("inf")
    for _ in range(repeats):  # advance, not step: a demonstration method may blow up here, harmlessly
        started = time.perf_counter()
        sim.advance(steps)
        best = min(best, time.perf_counter() - started)
    return best / (steps * body_count) * 1e9


# ---------------------------------------------------------------------------------------------------
# the study


def study(
    scene: SceneSpec,
    integrators: Sequence[str] | None = None,
    dts: Sequence[float] | None = None,
    tolerances: Sequence[float] | None = None,
    duration: float | None = None,
    repeats: int = 3,
    progress: Progress | None = None,
) -> StudyResult:
    """Run every integrator at every step size (adaptive ones at every tolerance) and measure error
    against the reference, invariant drift and cost; fit each integrator's empirical order.

    dts default to the scene's dt 2^(3..-3); duration to the scene's (rounded up to a whole number of
    the coarsest step). progress(done, total, label) is called as work completes (units: steps).
    """
    from rbcli.runner.loop import warm_up

    spec = _study_spec(scene)
    names = tuple(integrators) if integrators else applicable_integrators()
    infos = [get_integrator(name) for name in names]  # KeyError names the known ones
    adaptive = [i for i in infos if is_adaptive(i)]  # also by tolerance (their fixed-step rows fit the order)
    dts = tuple(sorted({float(d) for d in (dts or default_dts(spec.simulation.dt))}, reverse=True))
    if any(not (d > 0 and math.isfinite(d)) for d in dts):
        raise ValueError(f"step sizes must be positive, got {list(dts)}")
    grid = output_grid(dts, float(duration if duration is not None else spec.simulation.duration))
    times = grid.times
    base = compile_scene(spec, duration=grid.duration)
    exact = admits_exact_solution(base)
    conserved = conserved_quantities(base)

    def compiled_for(name: str, dt: float, scale: int = 1) -> CompiledScene:
        every = grid.every_base * round(grid.base / dt) * scale
        return compile_scene(spec, dt=dt / scale, duration=grid.duration, integrator=name, record_every=every)

    ref_name = None if exact else reference_integrator()
    dt_ref = min(dts) / REFERENCE_REFINEMENT
    tolerances = tuple(tolerances or DEFAULT_TOLERANCES)
    planned = [(i, dt) for i in infos for dt in dts] + [(i, grid.base) for i in adaptive for _ in tolerances]
    total = float(sum(grid.steps_per_base(dt) * grid.base_steps * (1 + repeats) for _, dt in planned))
    if ref_name is not None:
        total += 1.5 * REFERENCE_REFINEMENT * grid.steps_per_base(min(dts)) * grid.base_steps
    done = 0.0

    def report(amount: float, label: str) -> None:
        nonlocal done
        done += amount
        if progress is not None:
            progress(done, total, label)

    report(0.0, "reference")
    if exact:
        reference = ReferenceInfo("exact", "exact: free flight under uniform gravity and torque-free rotation")
        ref_path = exact_reference(base, times)
    else:
        assert ref_name is not None
        fine_c = compiled_for(ref_name, min(dts), REFERENCE_REFINEMENT)
        coarse_c = compiled_for(ref_name, min(dts), REFERENCE_REFINEMENT // 2)
        warm_up(fine_c)
        fine, coarse = _simulate(fine_c), _simulate(coarse_c)
        report(1.5 * fine_c.settings.steps, "reference")
        if fine.status != "completed" or coarse.status != "completed":
            raise RuntimeError(f"the reference run ({ref_name}, dt = {dt_ref:g} s) {fine.status}")
        ref_path = ReferencePath(fine.x, fine.q)
        rot_est, pos_est, _, _ = run_errors(coarse, ref_path)
        reference = ReferenceInfo(
            "numerical",
            f"numerical: {ref_name} at dt = {dt_ref:.4g} s (dt_min / {REFERENCE_REFINEMENT}); "
            f"its error estimated against 2 dt",
            ref_name,
            dt_ref,
            rot_est,
            pos_est,
        )

    runs: list[StudyRun] = []
    for info in infos:
        warm_up(compiled_for(info.name, dts[0]))
        for dt in dts:
            compiled = compiled_for(info.name, dt)
            runs.append(_measure(compiled, info, ref_path, times, conserved, repeats))
            report(compiled.settings.steps * (1 + repeats), f"{info.name} dt={dt:.3g}")
    notes: list[str] = []
    asked = float(duration if duration is not None else spec.simulation.duration)
    if abs(grid.duration - asked) > 1e-9 * asked:
        notes.append(f"duration {asked:g} s rounded up to {grid.duration:g} s, a whole number of the coarsest step")
    notes += smoothness_notes(base)
    for info in adaptive:
        for tol in tolerances:
            runs.append(_measure_adaptive(spec, info, tol, grid, ref_path, conserved, repeats))
            report(grid.base_steps * (1 + repeats), f"{info.name} tol={tol:.0e}")

    result = StudyResult(
        scene_name=scene.name,
        body_count=base.model.body_count,
        duration=grid.duration,
        output_interval=grid.output_interval,
        frame_count=int(times.size),
        repeats=repeats,
        reference=reference,
        conserved=conserved,
        primary_error="rotation",
        runs=runs,
        notes=notes,
    )
    if not (np.any(base.initial_state.L != 0.0) or base.forces.has_torque):
        result.primary_error = "position"  # nothing rotates: rotation errors are all zero
    length_scale = max(float(np.abs(ref_path.x).max(initial=0.0)), 1e-3)
    for info in infos:
        fixed_runs = [r for r in runs if r.integrator == info.name and r.tolerance is None]
        result.fits[info.name] = _fit(info, fixed_runs, length_scale)
    return result


def _measure(
    compiled: CompiledScene,
    info: IntegratorInfo,
    ref: ReferencePath,
    times: np.ndarray,
    conserved: tuple[str, ...],
    repeats: int,
) -> StudyRun:
    """Accuracy run plus timing runs of one fixed-step (integrator, dt)."""
    settings = compiled.settings
    traj = _simulate(compiled)
    nan = float("nan")
    if traj.status == "completed":
        if traj.t.size != times.size or not np.allclose(traj.t, times, rtol=1e-9, atol=0.0):
            raise RuntimeError(f"{info.name} at dt = {settings.dt:g} s recorded at other times than the grid")
        errors = run_errors(traj, ref)
        drifts = invariant_drifts(traj, conserved)
    else:  # diverged: errors are meaningless past the blow-up
        errors = (nan, nan, nan, nan)
        drifts = (None, None, None)
    per_step = seconds_per_step(compiled, repeats)
    return StudyRun(
        integrator=info.name,
        dt=settings.dt,
        tolerance=None,
        steps=settings.steps,
        force_evals=settings.steps * info.force_evals,
        status=traj.status,
        rotation_error_max=errors[0],
        position_error_max=errors[1],
        rotation_error_final=errors[2],
        position_error_final=errors[3],
        energy_drift=drifts[0],
        momentum_drift=drifts[1],
        angular_momentum_drift=drifts[2],
        seconds_per_step=per_step,
        ns_per_body_step=per_step / compiled.model.body_count * 1e9,
        cost_per_sim_second=per_step / settings.dt,
    )


def run_adaptive(
    compiled: CompiledScene, tolerance: float, *, trajectory: bool = True
) -> tuple[Trajectory | None, int, int]:
    """One adaptive (dopri5) run with error budget `tolerance` over the compiled scene's output grid
    (dt = the grid spacing, record_every as compiled), through the runner like `rbsim run --tolerance`.
    Returns the trajectory (None when not asked for) and the accepted and rejected step counts.
    """
    adaptive = dataclasses.replace(compiled, settings=dataclasses.replace(compiled.settings, tolerance=tolerance))
    traj = _simulate(adaptive)
    summary = traj.summary
    assert summary is not None, "run() closes every sink with a summary when it returns"
    counts = int(summary.steps_accepted or 0), int(summary.steps_rejected or 0)
    return (traj if trajectory else None), *counts


def _measure_adaptive(
    spec: SceneSpec,
    info: IntegratorInfo,
    tolerance: float,
    grid: OutputGrid,
    ref: ReferencePath,
    conserved: tuple[str, ...],
    repeats: int,
) -> StudyRun:
    """Accuracy and cost of an adaptive method at one tolerance: `steps` counts accepted steps, force
    evaluations every attempt; the timing covers whole runs with their ~TARGET_FRAMES frame copies
    (the accuracy run compiled the kernel)."""
    compiled = compile_scene(
        spec, dt=grid.base, duration=grid.duration, integrator=info.name, record_every=grid.every_base
    )
    traj, accepted, rejected = run_adaptive(compiled, tolerance)
    assert traj is not None
    samples = []
    for _ in range(max(1, repeats)):
        started = time.perf_counter()
        run_adaptive(compiled, tolerance, trajectory=False)
        samples.append(time.perf_counter() - started)
    wall = float(np.median(samples))
    nan = float("nan")
    ok = traj.status == "completed" and traj.t.size == grid.times.size
    errors = run_errors(traj, ref) if ok else (nan, nan, nan, nan)
    drifts = invariant_drifts(traj, conserved) if ok else (None, None, None)
    attempts = max(accepted + rejected, 1)
    return StudyRun(
        integrator=info.name,
        dt=grid.duration / max(accepted, 1),
        tolerance=tolerance,
        steps=accepted,
        force_evals=attempts * info.force_evals,
        status=traj.status,
        rotation_error_max=errors[0],
        position_error_max=errors[1],
        rotation_error_final=errors[2],
        position_error_final=errors[3],
        energy_drift=drifts[0],
        momentum_drift=drifts[1],
        angular_momentum_drift=drifts[2],
        seconds_per_step=wall / attempts,
        ns_per_body_step=wall / attempts / compiled.model.body_count * 1e9,
        cost_per_sim_second=wall / grid.duration,
        rejected_steps=rejected,
    )


def _fit(info: IntegratorInfo, runs: list[StudyRun], length_scale: float) -> IntegratorFit:
    """Fitted orders of the rotation and position errors over the asymptotic range."""
    dt = np.array([r.dt for r in runs])
    steps = np.array([r.steps for r in runs])
    rot = np.array([r.rotation_error_max for r in runs])
    pos = np.array([r.position_error_max for r in runs])
    return IntegratorFit(
        info.name,
        info.order,
        info.symplectic,
        fit_order(dt, rot, roundoff_floor(steps), ROTATION_SATURATION),
        # position round-off is relative to the size of the coordinates themselves
        fit_order(dt, pos, roundoff_floor(steps, length_scale)),
    )


# ---------------------------------------------------------------------------------------------------
# files

CSV_COLUMNS = (
    "integrator",
    "dt",
    "tolerance",
    "steps",
    "rejected_steps",
    "force_evals",
    "status",
    "rotation_error_max",
    "position_error_max",
    "rotation_error_final",
    "position_error_final",
    "energy_drift",
    "momentum_drift",
    "angular_momentum_drift",
    "seconds_per_step",
    "ns_per_body_step",
    "cost_per_sim_second",
    "fitted_order",
    "nominal_order",
)


def csv_text(result: StudyResult) -> str:
    """One row per run, every number at full precision (repr), empty where not applicable."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for run in result.runs:
        row = dataclasses.asdict(run) | {
            "fitted_order": result.run_fitted_order(run),
            "nominal_order": get_integrator(run.integrator).order,
        }
        writer.writerow(["" if row[c] is None else row[c] for c in CSV_COLUMNS])
    return out.getvalue()


def write_study_files(result: StudyResult, out: Path, stem: str | None = None) -> tuple[Path, Path]:
    """Write <out>/<scene>-study.csv and .json; returns their paths."""
    out.mkdir(parents=True, exist_ok=True)
    stem = stem or f"{result.scene_name}-study"
    csv_path, json_path = out / f"{stem}.csv", out / f"{stem}.json"
    csv_path.write_text(csv_text(result))
    json_path.write_text(json.dumps(result.as_dict(), indent=2) + "\n")
    return csv_path, json_path


def _finite_or_none(value):  # noqa: ANN001, ANN202 - recursive over JSON-like data
    if isinstance(value, dict):
        return {k: _finite_or_none(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_finite_or_none(v) for v in value]
    if isinstance(value, float | np.floating) and not math.isfinite(value):
        return None
    if isinstance(value, np.generic):
        return value.item()
    return value
