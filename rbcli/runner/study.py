"""Work-precision study: every integrator at a range of step sizes, error against cost.

For each (integrator, dt) the scene is run once for accuracy (recorded at a cadence common to all
runs, so every run is compared at the same times) and then timed (`time_kernel`): serially, in this
process, on one compiled `Simulation` reused across repeats (no compilation inside a timing), the chunk
loop alone at the study's recording cadence (no sink, no Python per step), CPU time of the running
thread. Each run's own 0-step call of the same loop is taken off it, so small scenes are billed for the
kernel and not for argument unboxing; runs are gathered into samples (the median over a sample's runs)
until min_time [s] is spent (`runner/kernel_timing.py`). Reported: the median seconds per step and the
spread (the fastest and slowest sample).

When MuJoCo is installed (the `[bench]` extra) and the scene is free bodies under uniform gravity,
MuJoCo's Euler and RK4 run the same scene (`runner/mujoco_twin.py`) as extra rows, measured the same way.

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
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING

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
    pendulum_of,
    pendulum_reference,
    roundoff_floor,
    run_errors,
    smoothness_notes,
)
from rbcli.physics.integrators import INTEGRATORS, REDUCED_INTEGRATORS, IntegratorInfo, get_integrator
from rbcli.record.memory_sink import Trajectory
from rbcli.runner.kernel_timing import KernelTiming, simulation_advance, time_kernel
from rbcli.scene.compile import CompiledScene, compile_scene
from rbcli.scene.spec import RecordSpec, SceneSpec

if TYPE_CHECKING:
    from rbcli.runner.mujoco_twin import MujocoMethod

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
# Timing: each (integrator, dt) point is timed until this much wall time [s] is spent on its runs
# (`runner/kernel_timing.py`: samples, overhead, spread).
DEFAULT_MIN_TIME = 0.2
TIMING_CLOCK = "CPU time of the serial run's thread; median and min/max over samples; call overhead taken off"
BASELINE_INTEGRATOR = "euler-matrix"
EXACT_INTEGRATOR = "exact"

Progress = Callable[[float, float, str], None]


@dataclass(frozen=True)
class StudyRun:
    """One (integrator, dt) run: its errors against the reference, invariant drift and cost.

    Errors are maxima over bodies and recorded times (…_max) and at the final time (…_final):
    rotation [rad] (geodesic angle), position [m] (centre of mass). Drifts are relative,
    max_t |I(t) - I(0)| / |I(0)|, and None where the scene does not conserve the quantity.
    seconds_per_step [s] is the median over timing samples of the compiled step loop's time per step
    (`runner/kernel_timing.py`: CPU time of the serial run's thread), seconds_per_step_min / _max the
    fastest and slowest sample (the spread), over timing_samples samples of timed_runs whole runs in
    all; wall_seconds_per_step the median of the same samples in wall time (above the CPU time only
    when other processes held the core); ns_per_body_step divides the median by the body count;
    cost_per_sim_second [s/s] = seconds of the run per simulated second (median). engine:
    "rbsim", or "mujoco" for the MuJoCo rows; nominal_order: the method's order as registered. Adaptive
    runs (tolerance set): steps are the accepted steps, dt their mean, rejected_steps the others (which
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
    seconds_per_step_min: float
    seconds_per_step_max: float
    wall_seconds_per_step: float
    timing_samples: int
    timed_runs: int
    nominal_order: int
    engine: str = "rbsim"
    rejected_steps: int = 0

    @property
    def cost_spread(self) -> float:
        """Slowest over fastest timing sample (1.0 = no spread)."""
        return self.seconds_per_step_max / self.seconds_per_step_min if self.seconds_per_step_min > 0 else math.inf

    @property
    def cost_per_sim_second_range(self) -> tuple[float, float]:
        """(fastest, slowest) sample as wall seconds per simulated second [s/s], around the median:
        rescaled by cost / median, a sample equal to the median can round an ulp past the cost (a
        negative error bar, which matplotlib refuses: seen once in CI), so each is held on its side."""
        cost = self.cost_per_sim_second
        per_step = cost / self.seconds_per_step if self.seconds_per_step > 0 else 0.0
        return min(self.seconds_per_step_min * per_step, cost), max(self.seconds_per_step_max * per_step, cost)


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
    is the error the table's fitted order and the plot's first panel use. min_time [s]: the timing
    spent per point; mujoco_version: the MuJoCo that ran the MuJoCo rows (None: not installed or not
    asked); mujoco_skipped: why there are no MuJoCo rows (None when there are); load_average: the
    machine's 1-minute load average at the start (None where the platform has none): a spread above
    the target at a load above the core count is the machine's."""

    scene_name: str
    body_count: int
    duration: float
    output_interval: float
    frame_count: int
    min_time: float
    reference: ReferenceInfo
    conserved: tuple[str, ...]
    primary_error: str
    runs: list[StudyRun] = field(default_factory=list)
    fits: dict[str, IntegratorFit] = field(default_factory=dict)
    notes: list[str] = field(default_factory=list)
    mujoco_version: str | None = None
    mujoco_skipped: str | None = None
    load_average: float | None = None  # the machine's 1-minute load average when the study began

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
                "timing": {"min_time": self.min_time, "clock": TIMING_CLOCK, "load_average": self.load_average},
                "mujoco": {"version": self.mujoco_version, "skipped": self.mujoco_skipped},
                "reference": dataclasses.asdict(self.reference),
                "conserved": list(self.conserved),
                "primary_error": self.primary_error,
                "notes": list(self.notes),
                "runs": [
                    dataclasses.asdict(r) | {"fitted_order": self.run_fitted_order(r), "cost_spread": r.cost_spread}
                    for r in self.runs
                ],
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


def applicable_integrators(*, jointed: bool = False, trees: bool = False, contact: bool = False) -> tuple[str, ...]:
    """Every registered integrator (fixed-step ones by dt, adaptive ones by tolerance), except those
    kept only to demonstrate a failure (ask for them by name); for a scene with joints, the ones that
    hold joints (integrators.check_integrator), and when its joints form trees (trees: compile_trees
    takes them) the ones in joint coordinates beside them: the two families, error against cost. One with
    implicit contact (reduced-implicit) only where the scene has contact: without it, it is reduced-euler."""
    maximal = tuple(
        name
        for name, info in INTEGRATORS.items()
        if not getattr(info, "demonstration", False) and (info.joints or not jointed)
    )
    reduced = tuple(name for name, info in REDUCED_INTEGRATORS.items() if contact or not info.implicit_contact)
    return maximal + (reduced if jointed and trees else ())


def _forms_trees(spec: SceneSpec) -> bool:
    """Whether the scene's joints compile to trees in joint coordinates (scene/compile_trees.py: no loop,
    distance joint, limit or drive), so the reduced integrators can run it."""
    from rbcli.scene.spec import SceneError

    try:
        compile_scene(spec, integrator=next(iter(REDUCED_INTEGRATORS)))
    except SceneError:
        return False
    return True


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


def reference_integrator(*, jointed: bool = False, trees: bool = False) -> str:
    """The most accurate registered fixed-step method: the highest order, ties broken by
    REFERENCE_PREFERENCE (symplectic split4 before rk4); demonstration methods never; for a scene with
    joints, among those that hold joints (reduced-rk4, fourth order, where the joints form trees)."""
    candidates = [
        i for i in INTEGRATORS.values() if not getattr(i, "demonstration", False) and (i.joints or not jointed)
    ]
    if jointed and trees:
        candidates += list(REDUCED_INTEGRATORS.values())
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
    from rbcli.runner.simulation import run

    memory = SinkMemory()
    run(compiled, [memory])
    return memory.trajectory()


def time_run(compiled: CompiledScene, min_time: float) -> KernelTiming:
    """Per-step time of the compiled scene's chunk loop (`kernel_timing.time_kernel`): one Simulation
    reused across repeats, recording at the scene's cadence into reused buffers, no sink. The kernel
    must be compiled already (`runner.simulation.warm_up`) or the first untimed run compiles it. On one
    thread: the clock is the calling thread's CPU time, and integrators are compared on equal terms."""
    from rbcli.runner.simulation import Simulation

    sim = Simulation(compiled, threads=1)
    return time_kernel(sim.reset, simulation_advance(sim, compiled.settings.record_every), compiled.settings.steps,
                       min_time)  # fmt: skip


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
    sim = Simulation(spec, threads=1)  # the cost on one core, as docs/integrators.md compares them
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
    min_time: float = DEFAULT_MIN_TIME,
    progress: Progress | None = None,
    mujoco: bool | None = None,
) -> StudyResult:
    """Run every integrator at every step size (adaptive ones at every tolerance) and measure error
    against the reference, invariant drift and cost; fit each integrator's empirical order.

    dts default to the scene's dt 2^(3..-3); duration to the scene's (rounded up to a whole number of
    the coarsest step). min_time [s]: wall time spent timing each point (0: MIN_SAMPLES single runs).
    mujoco: add MuJoCo's Euler and RK4 rows (None: when mujoco is installed and the scene is free bodies
    under uniform gravity; True: raise ValueError if mujoco is not installed; False: never).
    progress(done, total, label) is called as points complete (units: points).
    """
    from rbcli.runner.mujoco_twin import MUJOCO_METHODS, mujoco_version, refusal
    from rbcli.runner.simulation import warm_up

    if not (min_time >= 0 and math.isfinite(min_time)):
        raise ValueError(f"the minimum timing must be >= 0 s, got {min_time}")
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    spec = _study_spec(scene)
    jointed = any(joint.kind != "fixed" for joint in spec.joints)  # welds are merged bodies, no constraints
    trees = jointed and _forms_trees(spec)
    contact = spec.contact is not None
    names = tuple(integrators) if integrators else applicable_integrators(jointed=jointed, trees=trees, contact=contact)
    infos = [get_integrator(name) for name in names]  # KeyError names the known ones
    adaptive = [i for i in infos if is_adaptive(i)]  # also by tolerance (their fixed-step rows fit the order)
    dts = tuple(sorted({float(d) for d in (dts or default_dts(spec.simulation.dt))}, reverse=True))
    if any(not (d > 0 and math.isfinite(d)) for d in dts):
        raise ValueError(f"step sizes must be positive, got {list(dts)}")
    grid = output_grid(dts, float(duration if duration is not None else spec.simulation.duration))
    times = grid.times
    base = compile_scene(spec, duration=grid.duration)
    exact = admits_exact_solution(base)
    pendulum = pendulum_of(base) if base.model.joint is not None else None
    conserved = conserved_quantities(base)
    notes: list[str] = []

    version = mujoco_version() if mujoco is not False else None
    if mujoco is True and version is None:
        raise ValueError("MuJoCo rows asked for, but mujoco is not installed (pip install 'rbsim[bench]')")
    mujoco_reason = refusal(base) if version is not None else None
    if mujoco is None and version is None:
        mujoco_reason = "mujoco is not installed (pip install 'rbsim[bench]' adds MuJoCo's Euler and RK4 rows)"
    elif mujoco is False:
        mujoco_reason = "left out (mujoco=False)"
    if mujoco_reason is not None and mujoco is not False:
        notes.append(f"no MuJoCo rows: {mujoco_reason}")
    mujoco_methods = list(MUJOCO_METHODS.values()) if mujoco_reason is None else []

    def compiled_for(name: str, dt: float, scale: int = 1) -> CompiledScene:
        every = grid.every_base * round(grid.base / dt) * scale
        return compile_scene(spec, dt=dt / scale, duration=grid.duration, integrator=name, record_every=every)

    # joints: the pendulum's exact motion, else the finest run of a method that holds joints
    ref_name = None if exact or pendulum is not None else reference_integrator(jointed=jointed, trees=trees)
    dt_ref = min(dts) / REFERENCE_REFINEMENT
    tolerances = tuple(tolerances or DEFAULT_TOLERANCES)
    total = float(len(dts) * (len(infos) + len(mujoco_methods)) + len(adaptive) * len(tolerances) + 1)
    done = 0.0

    def report(label: str) -> None:
        nonlocal done
        done += 1.0
        if progress is not None:
            progress(done, total, label)

    if progress is not None:
        progress(0.0, total, "reference")
    if exact:
        reference = ReferenceInfo("exact", "exact: free flight under uniform gravity and torque-free rotation")
        ref_path = exact_reference(base, times)
    elif pendulum is not None:
        reference = ReferenceInfo(
            "exact", "exact: a rigid pendulum on a hinge, theta(t) = 2 arcsin(k sn(K - omega0 t | k^2)), period "
            f"4 K(k^2) / omega0 = {pendulum.period:.6g} s"
        )  # fmt: skip
        ref_path = pendulum_reference(base, pendulum, times)
    else:
        assert ref_name is not None
        fine_c = compiled_for(ref_name, min(dts), REFERENCE_REFINEMENT)
        coarse_c = compiled_for(ref_name, min(dts), REFERENCE_REFINEMENT // 2)
        warm_up(fine_c)
        fine, coarse = _simulate(fine_c), _simulate(coarse_c)
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
    report("reference")

    runs: list[StudyRun] = []
    for info in infos:
        warm_up(compiled_for(info.name, dts[0]))
        for dt in dts:
            compiled = compiled_for(info.name, dt)
            traj = _simulate(compiled)
            timing = time_run(compiled, min_time)
            runs.append(_study_run(info.name, info.order, compiled, traj, times, ref_path, conserved, timing,
                                   force_evals=compiled.settings.steps * info.force_evals))  # fmt: skip
            report(f"{info.name} dt={dt:.3g}")
    for method in mujoco_methods:
        for dt in dts:
            runs.append(_measure_mujoco(method, compiled_for(names[0], dt), times, ref_path, conserved, min_time))
            report(f"{method.name} dt={dt:.3g}")
    asked = float(duration if duration is not None else spec.simulation.duration)
    if abs(grid.duration - asked) > 1e-9 * asked:
        notes.append(f"duration {asked:g} s rounded up to {grid.duration:g} s, a whole number of the coarsest step")
    notes += smoothness_notes(base)
    for info in adaptive:
        for tol in tolerances:
            runs.append(_measure_adaptive(spec, info, tol, grid, ref_path, conserved, min_time))
            report(f"{info.name} tol={tol:.0e}")

    result = StudyResult(
        scene_name=scene.name,
        body_count=base.model.body_count,
        duration=grid.duration,
        output_interval=grid.output_interval,
        frame_count=int(times.size),
        min_time=min_time,
        reference=reference,
        conserved=conserved,
        primary_error="rotation",
        runs=runs,
        notes=notes,
        mujoco_version=version,
        mujoco_skipped=mujoco_reason,
        load_average=load,
    )
    if not (np.any(base.initial_state.L != 0.0) or base.forces.has_torque or base.model.joint is not None):
        result.primary_error = "position"  # nothing rotates: rotation errors are all zero (a joint turns bodies)
    length_scale = max(float(np.abs(ref_path.x).max(initial=0.0)), 1e-3)
    fitted = [(i.name, i.order, i.symplectic) for i in infos] + [(m.name, m.order, False) for m in mujoco_methods]
    for name, order, symplectic in fitted:
        fixed_runs = [r for r in runs if r.integrator == name and r.tolerance is None]
        result.fits[name] = _fit(name, order, symplectic, fixed_runs, length_scale)
    return result


def _study_run(
    name: str,
    order: int,
    compiled: CompiledScene,
    traj: Trajectory,
    times: np.ndarray,
    ref: ReferencePath,
    conserved: tuple[str, ...],
    timing: KernelTiming,
    *,
    force_evals: int,
    engine: str = "rbsim",
) -> StudyRun:
    """The row of one fixed-step (integrator, dt): errors of its recorded run and its timing."""
    settings = compiled.settings
    nan = float("nan")
    if traj.status == "completed":
        if traj.t.size != times.size or not np.allclose(traj.t, times, rtol=1e-9, atol=0.0):
            raise RuntimeError(f"{name} at dt = {settings.dt:g} s recorded at other times than the grid")
        errors = run_errors(traj, ref)
        drifts = invariant_drifts(traj, conserved)
    else:  # diverged: errors are meaningless past the blow-up
        errors = (nan, nan, nan, nan)
        drifts = (None, None, None)
    return StudyRun(
        integrator=name,
        dt=settings.dt,
        tolerance=None,
        steps=settings.steps,
        force_evals=force_evals,
        status=traj.status,
        rotation_error_max=errors[0],
        position_error_max=errors[1],
        rotation_error_final=errors[2],
        position_error_final=errors[3],
        energy_drift=drifts[0],
        momentum_drift=drifts[1],
        angular_momentum_drift=drifts[2],
        seconds_per_step=timing.median,
        ns_per_body_step=timing.median / compiled.model.body_count * 1e9,
        cost_per_sim_second=timing.median / settings.dt,
        seconds_per_step_min=timing.low,
        seconds_per_step_max=timing.high,
        wall_seconds_per_step=timing.wall,
        timing_samples=timing.samples,
        timed_runs=timing.runs,
        nominal_order=order,
        engine=engine,
    )


def _measure_mujoco(
    method: MujocoMethod,
    compiled: CompiledScene,
    times: np.ndarray,
    ref: ReferencePath,
    conserved: tuple[str, ...],
    min_time: float,
) -> StudyRun:
    """A MuJoCo row: the twin recorded at the study's cadence, then `mj_step(nstep=steps)` timed as
    rbsim's loop is (same samples, the 0-step call's overhead taken off)."""
    from rbcli.runner.mujoco_twin import MujocoTwin

    twin = MujocoTwin(compiled, method)
    traj = twin.trajectory(compiled.settings.steps, compiled.settings.record_every)
    with twin.quiet_warnings():  # a diverging run warns at every step of every repeat
        timing = time_kernel(twin.reset, twin.advance, compiled.settings.steps, min_time)
    # MuJoCo's RK4 evaluates the dynamics 4 times a step, Euler once
    evals = compiled.settings.steps * (4 if method.order == 4 else 1)
    return _study_run(method.name, method.order, compiled, traj, times, ref, conserved, timing, force_evals=evals,
                      engine="mujoco")  # fmt: skip


def run_adaptive(
    compiled: CompiledScene, tolerance: float, *, trajectory: bool = True
) -> tuple[Trajectory | None, int, int]:
    """One adaptive (dopri5) run with error budget `tolerance` over the compiled scene's output grid
    (dt = the grid spacing, record_every as compiled), through the runner like `rbsim run --tolerance`.
    Returns the trajectory (None when not asked for) and the accepted and rejected step counts.
    """
    adaptive = _with_tolerance(compiled, tolerance)
    traj = _simulate(adaptive)
    summary = traj.summary
    assert summary is not None, "run() closes every sink with a summary when it returns"
    counts = int(summary.steps_accepted or 0), int(summary.steps_rejected or 0)
    return (traj if trajectory else None), *counts


def _with_tolerance(compiled: CompiledScene, tolerance: float) -> CompiledScene:
    return dataclasses.replace(compiled, settings=dataclasses.replace(compiled.settings, tolerance=tolerance))


def _measure_adaptive(
    spec: SceneSpec,
    info: IntegratorInfo,
    tolerance: float,
    grid: OutputGrid,
    ref: ReferencePath,
    conserved: tuple[str, ...],
    min_time: float,
) -> StudyRun:
    """Accuracy and cost of an adaptive method at one tolerance: `steps` counts accepted steps, force
    evaluations every attempt; the timing (`time_run`, the adaptive chunk over the output grid at the
    study's cadence) is per attempted step (the accuracy run compiled the kernel)."""
    compiled = compile_scene(
        spec, dt=grid.base, duration=grid.duration, integrator=info.name, record_every=grid.every_base
    )
    traj, accepted, rejected = run_adaptive(compiled, tolerance)
    assert traj is not None
    per_grid_step = time_run(_with_tolerance(compiled, tolerance), min_time)  # seconds per output-grid step
    attempts = max(accepted + rejected, 1)
    scale = grid.base_steps / attempts  # grid steps per attempted step
    nan = float("nan")
    ok = traj.status == "completed" and traj.t.size == grid.times.size
    errors = run_errors(traj, ref) if ok else (nan, nan, nan, nan)
    drifts = invariant_drifts(traj, conserved) if ok else (None, None, None)
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
        seconds_per_step=per_grid_step.median * scale,
        ns_per_body_step=per_grid_step.median * scale / compiled.model.body_count * 1e9,
        cost_per_sim_second=per_grid_step.median * grid.base_steps / grid.duration,
        seconds_per_step_min=per_grid_step.low * scale,
        seconds_per_step_max=per_grid_step.high * scale,
        wall_seconds_per_step=per_grid_step.wall * scale,
        timing_samples=per_grid_step.samples,
        timed_runs=per_grid_step.runs,
        nominal_order=info.order,
        rejected_steps=rejected,
    )


def _fit(name: str, order: int, symplectic: bool, runs: list[StudyRun], length_scale: float) -> IntegratorFit:
    """Fitted orders of the rotation and position errors over the asymptotic range."""
    dt = np.array([r.dt for r in runs])
    steps = np.array([r.steps for r in runs])
    rot = np.array([r.rotation_error_max for r in runs])
    pos = np.array([r.position_error_max for r in runs])
    return IntegratorFit(
        name,
        order,
        symplectic,
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
    "seconds_per_step_min",
    "seconds_per_step_max",
    "wall_seconds_per_step",
    "cost_spread",
    "timing_samples",
    "timed_runs",
    "engine",
    "fitted_order",
    "nominal_order",
)


def csv_text(result: StudyResult) -> str:
    """One row per run, every number at full precision (repr), empty where not applicable."""
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(CSV_COLUMNS)
    for run in result.runs:
        row = dataclasses.asdict(run) | {"fitted_order": result.run_fitted_order(run), "cost_spread": run.cost_spread}
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
