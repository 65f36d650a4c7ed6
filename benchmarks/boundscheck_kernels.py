"""Every integrator under numba's bounds checking, at the edges of the runner's frame buffers.

    python benchmarks/boundscheck_kernels.py            # the whole matrix (see "Measured" below)
    python benchmarks/boundscheck_kernels.py --quick    # split2 and adaptive dopri5, capacity 1 and 2 (CI)
    python benchmarks/boundscheck_kernels.py --integrators rk4,dopri5-adaptive --capacities 1 --no-large

Why: compiled kernels do not check indices. At 40,330 bodies the frame buffer held one frame and a
chunk kernel wrote the next frame past its end, corrupting the heap silently. With NUMBA_BOUNDSCHECK=1
numba checks every array index and raises IndexError instead, so a run that completes here wrote
nothing out of bounds. The setting is read when numba is imported, and numba's on-disk cache would hand
back kernels compiled without the checks, so the script re-executes itself in a subprocess with
NUMBA_BOUNDSCHECK=1 and NUMBA_CACHE_DIR set to a fresh empty directory (every kernel is compiled anew,
checked; the directory is removed afterwards). The child refuses to run if either did not take effect.

Cases (public entry points only: `rbcli.api.simulate`, `prepare`, `run_to_file`, the readers in
`rbcli.record.read`, and `rbcli.runner.loop.frame_capacity`, patched to choose the buffer size):

  edge   every integrator (INTEGRATORS, plus dopri5 with a tolerance) on a 3-body scene with every force
         type (gravity, field, springs to the world and between bodies, drag, an impulse, a scheduled
         torque and a scheduled force), frame capacity c = 1, 2, 3, runs whose recorded frame count is
         c-1, c, c+1 and 2c (the initial and the final state are always recorded, so a run has at least
         2 frames: c = 1 gives 2 only, c = 2 gives 2, 3, 4), with record_every 1 and 3 (for 3 also with
         the final state off the recording grid, which the runner records after the last chunk); to
         memory, .mcap and .rrd (written by run_to_file, read back).
  scene  every scenes/forces/*.yaml (at most 2,000 steps of each) with every integrator, capacity 1 and 2.
  large  a grid of 40,329 and of 40,330 bodies (4 particles each; frame_capacity gives 2 and 1 frames,
         the edge of the reported bug), 10 steps of split2 under gravity and drag, to memory, .mcap and
         .rrd, read back.

Pass: no exception (an out-of-bounds index is an IndexError here), the recorded frame count is the
intended one, and the trajectory equals the one recorded with the default capacity (for `large`: a
capacity holding every frame) bit for bit: step, t, x, q, v, omega, P, L and the invariants from memory
and .mcap (exact float64); step, x, q (float32 in Rerun: equal to the reference rounded to float32) and
the invariants from .rrd. A table of cases is printed as they run. Exit status: 0 all passed, 1 a case
failed, 2 a usage error or bounds checks not in effect.

Measured on a 2-core machine shared with other work (numba 0.68.1, rerun-sdk 0.41.0, cold cache, so
every kernel compiled with bounds checks): the whole matrix, 930 cases (792 edge, 132 scene, 6 large),
101 s and 1.6 GB peak memory (the 40,330-body runs); --quick, 72 cases, 23-25 s.
"""

from __future__ import annotations

import argparse
import contextlib
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # the rbcli next to this script, whichever is installed

CHILD_FLAG = "--child"
ADAPTIVE_SUFFIX = "-adaptive"  # "dopri5-adaptive": the adaptive integrator run with TOLERANCE
# The adaptive runs' error budget. Loose on purpose: the edge scene switches a torque on and off (a
# jump in the force), and with the error-per-unit-step control of physics/adaptive.py a jump's error
# shrinks no faster than the allowed error as the step shrinks, so at 1e-6 the step falls below 1e-12 t
# at the first switch and the run stops (measured); 1e-3 takes the jump in one step.
TOLERANCE = 1e-3
DT = 0.01
QUICK_INTEGRATORS = ("split2", "dopri5-adaptive")
LARGE_BODY_COUNTS = (40_329, 40_330)  # frame_capacity: 2 and 1 frames
LARGE_STEPS = 10
SCENE_STEPS_MAX = 2_000

# Three bodies, every force type; the impulse, the torque window and the force ramp fall inside the
# shortest runs (t = 0.02 s is step 2), so the impulse's chunk split lands on buffer edges too.
EDGE_SCENE = """\
name: boundscheck-edge
simulation: {dt: 0.01, duration: 0.1, integrator: split2}
gravity: [0, 0, -9.81]
bodies:
  - name: a
    particles: {positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]], masses: [1.0, 0.5, 0.5, 0.25]}
    position: [0, 0, 1]
    angular_momentum: [0.01, 0.02, 0.03]
  - name: b
    particles: {positions: [[-0.2, 0, 0], [0.2, 0, 0], [0, 0.05, 0], [0, 0, 0.1]], masses: 0.3}
    position: [0.5, 0, 1]
    velocity: [0, 0.1, 0]
    angular_velocity: {body: [0, 0, 2]}
  - name: c
    particles: {positions: [[0, 0, 0], [0.3, 0, 0], [0, 0.1, 0], [0, 0, 0.1], [0.1, 0.1, 0.1]], masses: 0.2}
    position: [1, 0, 1]
forces:
  - {type: spring, body: a, point: [0, 0, 0.3], anchor: [0, 0, 2], stiffness: 50, rest_length: 0.5, damping: 0.1}
  - {type: spring, bodies: [a, b], points: [[0.1, 0, 0], [-0.2, 0, 0]], stiffness: 80, damping: 0.2}
  - {type: drag, bodies: all, linear: 0.05, quadratic: 0.01, angular_linear: 0.001}
  - {type: field, per: particle, bodies: [c], value: [0.1, 0, 0], schedule: {kind: sine, amplitude: 1, frequency: 3}}
  - {type: impulse, body: c, time: 0.02, point: [0.3, 0, 0], vector: [0, 0.5, 0], frame: world}
  - {type: torque, body: b, vector: [0, 0, 0.2], frame: body, schedule: {start: 0.01, stop: 0.06}}
  - type: force
    body: a
    point: [0.1, 0, 0]
    vector: [0, 1, 0]
    frame: world
    schedule: {kind: piecewise_linear, times: [0, 0.03, 0.07], values: [0, 1, 0]}
"""

LARGE_SCENE = """\
name: boundscheck-large-{count}
simulation: {{dt: 0.01, duration: 0.1, integrator: split2}}
gravity: [0, 0, -9.81]
bodies:
  - grid:
      name: g
      count: [{count}, 1, 1]
      spacing: 0.5
      template:
        particles: {{positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]], masses: [1.0, 0.5, 0.5, 0.25]}}
        angular_momentum: [0.0, 0.01, 0.02]
forces:
  - {{type: drag, bodies: all, linear: 0.01}}
"""


@dataclass(frozen=True)
class Run:
    """One simulation: scene file, integrator (tolerance for adaptive), steps, record_every."""

    scene: Path
    integrator: str
    tolerance: float | None
    steps: int
    every: int
    dt: float | None = DT  # None: the scene's own

    def overrides(self, scene_dt: float) -> dict:
        dt = self.dt if self.dt is not None else scene_dt
        return dict(
            integrator=self.integrator,
            tolerance=self.tolerance,
            dt=dt,
            duration=self.steps * dt,
            record_every=self.every,
        )


@dataclass
class Outcome:
    label: str
    ok: bool
    detail: str = ""
    seconds: float = 0.0
    frames: int = 0


@dataclass
class Report:
    outcomes: list[Outcome] = field(default_factory=list)

    def add(self, outcome: Outcome) -> None:
        self.outcomes.append(outcome)
        mark = "pass" if outcome.ok else "FAIL"
        print(f"{len(self.outcomes):5d}  {outcome.label:<62} {outcome.frames:6d}  {mark}  "
              f"{1e3 * outcome.seconds:8.0f}  {outcome.detail}", flush=True)  # fmt: skip


# --- comparisons -----------------------------------------------------------------------------------


def _same_bits(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal shape, dtype and bytes (so NaN equals the same NaN and -0.0 differs from 0.0)."""
    a, b = np.ascontiguousarray(a), np.ascontiguousarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _as_float32(a: np.ndarray) -> np.ndarray:
    """What an .rrd holds for a float64 array, read back as float64 (overflow to inf is what Rerun gets)."""
    with np.errstate(over="ignore"):
        return np.asarray(a).astype(np.float32).astype(np.float64)


def compare(got, reference, fields: tuple[str, ...], *, float32: tuple[str, ...] = ()) -> list[str]:  # noqa: ANN001
    """Names of the fields (and invariants) where `got` and the reference Trajectory differ."""
    bad = []
    for name in fields:
        want = getattr(reference, name)
        if name in float32:
            want = _as_float32(want)
        if not _same_bits(np.asarray(getattr(got, name)), np.asarray(want)):
            bad.append(name)
    for name, series in reference.invariants.items():
        if name not in got.invariants or not _same_bits(got.invariants[name], series):
            bad.append(f"invariants[{name}]")
    return bad


MEMORY_FIELDS = ("step", "t", "x", "q", "v", "omega", "P", "L")
RRD_FIELDS = ("step", "x", "q")


# --- running ---------------------------------------------------------------------------------------


@contextlib.contextmanager
def frame_capacity(capacity: int | None) -> Iterator[None]:
    """Patch `rbcli.runner.loop.frame_capacity` (the one place buffer sizes come from); None: leave it."""
    from rbcli.runner import loop

    original = loop.frame_capacity
    if capacity is not None:
        loop.frame_capacity = lambda body_count: capacity
    try:
        yield
    finally:
        loop.frame_capacity = original


def simulate_run(run: Run, capacity: int | None, dt: float):  # noqa: ANN201
    from rbcli.api import simulate

    with frame_capacity(capacity):
        return simulate(run.scene, on_diverge="return", **run.overrides(dt))


def file_run(run: Run, capacity: int | None, dt: float, path: Path):  # noqa: ANN201
    """Write the run with run_to_file and read it back with rbcli.record.read."""
    from rbcli.api import prepare, run_to_file
    from rbcli.record.read import read_recording

    with frame_capacity(capacity):
        compiled = prepare(run.scene, **run.overrides(dt))
        run_to_file(compiled, path)
    recorded = read_recording(path)
    path.unlink()
    return recorded


def check(report: Report, label: str, frames_expected: int | None, fn) -> None:  # noqa: ANN001
    """Run fn() -> (differing fields, frame count, how the run ended); record pass or fail. Any exception
    fails the case; a run that diverged passes when it equals the default-capacity run (which then
    diverged the same way), and the table says so."""
    started = time.perf_counter()
    try:
        bad, frames, status = fn()
    except Exception as exc:  # noqa: BLE001 - an IndexError from a bounds check is the point
        report.add(Outcome(label, False, f"{type(exc).__name__}: {exc}", time.perf_counter() - started))
        return
    if frames_expected is not None and frames != frames_expected:
        bad = [f"{frames} frames, meant {frames_expected}", *bad]
    detail = "" if not bad else "differs: " + ", ".join(bad)
    if status != "completed":
        detail = f"({status}) {detail}".rstrip()
    report.add(Outcome(label, not bad, detail, time.perf_counter() - started, frames))


def integrator_variants(names: list[str]) -> list[tuple[str, str, float | None]]:
    """(label, integrator, tolerance) for each requested name; NAME-adaptive runs NAME with TOLERANCE.
    ValueError for a name that is neither."""
    from rbcli.physics.integrators import INTEGRATORS

    out = []
    for name in names:
        base = name.removesuffix(ADAPTIVE_SUFFIX)
        adaptive = name.endswith(ADAPTIVE_SUFFIX)
        if base not in INTEGRATORS or (adaptive and not INTEGRATORS[base].adaptive):
            raise ValueError(f"unknown integrator {name!r}; known: {', '.join(all_integrator_names())}")
        out.append((name, base, TOLERANCE if adaptive else None))
    return out


def all_integrator_names() -> list[str]:
    from rbcli.physics.integrators import INTEGRATORS

    return [*INTEGRATORS, *(f"{n}{ADAPTIVE_SUFFIX}" for n, info in INTEGRATORS.items() if info.adaptive)]


def edge_runs(capacity: int, every: int) -> Iterator[tuple[int, int]]:
    """(steps, recorded frames) whose frame count is capacity-1, capacity, capacity+1 and 2 capacity.

    Frames are 1 (the initial state) + steps // every, + 1 when the last step is off the grid (the
    final state is always recorded); so F frames are (F - 1) every steps, or (F - 2) every + 1. A run
    has at least one step, so F >= 2."""
    for frames in sorted({capacity - 1, capacity, capacity + 1, 2 * capacity}):
        if frames < 2:
            continue
        yield (frames - 1) * every, frames
        if every > 1 and frames >= 2:
            yield (frames - 2) * every + 1, frames


def run_edge(report: Report, work: Path, variants, capacities: list[int], files: bool) -> None:  # noqa: ANN001
    scene = work / "edge.yaml"
    scene.write_text(EDGE_SCENE)
    for label, integrator, tolerance in variants:
        for every in (1, 3):
            for capacity in capacities:
                for steps, frames in edge_runs(capacity, every):
                    run = Run(scene, integrator, tolerance, steps, every)
                    reference = simulate_run(run, None, DT)
                    name = f"edge {label} cap={capacity} every={every} steps={steps}"

                    def memory(run=run, capacity=capacity, reference=reference):  # noqa: ANN001, ANN202
                        traj = simulate_run(run, capacity, DT)
                        return compare(traj, reference, MEMORY_FIELDS), len(traj.t), traj.status

                    check(report, f"{name} memory", frames, memory)
                    if not files:
                        continue
                    for ext, fields, float32 in ((".mcap", MEMORY_FIELDS, ()), (".rrd", RRD_FIELDS, ("x", "q"))):

                        def to_file(run=run, capacity=capacity, reference=reference, ext=ext, f=fields, f32=float32):  # noqa: ANN001, ANN202
                            got = file_run(run, capacity, DT, work / f"edge{ext}")
                            return compare(got, reference, f, float32=f32), got.frames, got.summary.get("status")

                        check(report, f"{name} {ext}", frames, to_file)


def run_scenes(report: Report, variants, capacities: list[int]) -> None:  # noqa: ANN001
    from rbcli.api import load_scene

    for path in sorted((REPO / "scenes" / "forces").glob("*.yaml")):
        sim = load_scene(path).simulation
        dt = float(sim.dt)
        steps = min(SCENE_STEPS_MAX, int(round(sim.duration / dt)))
        for label, integrator, tolerance in variants:
            run = Run(path, integrator, tolerance, steps, sim.record.every, dt=None)
            reference = simulate_run(run, None, dt)
            for capacity in capacities:

                def memory(run=run, capacity=capacity, reference=reference, dt=dt):  # noqa: ANN001, ANN202
                    traj = simulate_run(run, capacity, dt)
                    return compare(traj, reference, MEMORY_FIELDS), len(traj.t), traj.status

                check(report, f"scene {path.stem} {label} cap={capacity} steps={steps}", len(reference.t), memory)


def run_large(report: Report, work: Path) -> None:
    from rbcli.runner.loop import frame_capacity as natural_capacity

    for count in LARGE_BODY_COUNTS:
        scene = work / f"large-{count}.yaml"
        scene.write_text(LARGE_SCENE.format(count=count))
        run = Run(scene, "split2", None, LARGE_STEPS, 1)
        natural = natural_capacity(count)
        # the reference: one buffer holds every frame, so no hand-over happens at all
        reference = simulate_run(run, LARGE_STEPS + 1, DT)
        name = f"large {count:,} bodies split2 cap={natural} (natural) steps={LARGE_STEPS}"

        def memory(run=run, reference=reference):  # noqa: ANN001, ANN202
            traj = simulate_run(run, None, DT)
            return compare(traj, reference, MEMORY_FIELDS), len(traj.t), traj.status

        check(report, f"{name} memory", LARGE_STEPS + 1, memory)
        for ext, fields, float32 in ((".mcap", MEMORY_FIELDS, ()), (".rrd", RRD_FIELDS, ("x", "q"))):

            def to_file(run=run, reference=reference, ext=ext, f=fields, f32=float32):  # noqa: ANN001, ANN202
                got = file_run(run, None, DT, work / f"large{ext}")
                return compare(got, reference, f, float32=f32), got.frames, got.summary.get("status")

            check(report, f"{name} {ext}", LARGE_STEPS + 1, to_file)


# --- the two processes -----------------------------------------------------------------------------


def child(args: argparse.Namespace) -> int:
    """Runs the cases; only in the re-executed process, with bounds checks on and an empty cache."""
    import numba

    cache = os.environ.get("NUMBA_CACHE_DIR", "")
    if numba.config.BOUNDSCHECK != 1 or not cache or Path(numba.config.CACHE_DIR) != Path(cache):
        print(f"error: bounds checks not in effect (BOUNDSCHECK={numba.config.BOUNDSCHECK!r}, CACHE_DIR="
              f"{numba.config.CACHE_DIR!r}); run this script directly", file=sys.stderr)  # fmt: skip
        return 2
    if any(Path(cache).iterdir()):
        print(f"error: NUMBA_CACHE_DIR {cache} is not empty: cached kernels may lack bounds checks", file=sys.stderr)
        return 2
    variants = integrator_variants(args.integrators)  # checked in parse()
    report = Report()
    print(f"bounds-checked kernels (NUMBA_BOUNDSCHECK=1, fresh cache {cache})", flush=True)
    print(f"{'#':>5}  {'case':<62} {'frames':>6}  {'':4}  {'ms':>8}", flush=True)
    with tempfile.TemporaryDirectory(prefix="rbsim-boundscheck-") as tmp:
        work = Path(tmp)
        run_edge(report, work, variants, args.capacities, files=not args.memory_only)
        if args.scenes:
            run_scenes(report, variants, [c for c in args.capacities if c <= 2] or args.capacities[:1])
        if args.large:
            run_large(report, work)
    failed = [o for o in report.outcomes if not o.ok]
    print(f"{len(report.outcomes) - len(failed)} of {len(report.outcomes)} cases passed", flush=True)
    for outcome in failed:
        print(f"FAIL  {outcome.label}: {outcome.detail}", flush=True)
    return 1 if failed else 0


def parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="split2 and dopri5-adaptive, capacity 1 and 2 (CI)")
    parser.add_argument("--integrators", help="comma-separated; NAME-adaptive runs NAME with a tolerance")
    parser.add_argument("--capacities", help="comma-separated frame capacities (default 1,2,3; quick 1,2)")
    parser.add_argument("--large", action=argparse.BooleanOptionalAction, default=None, help="40,329/40,330 bodies")
    parser.add_argument("--scenes", action=argparse.BooleanOptionalAction, default=None, help="scenes/forces/*.yaml")
    parser.add_argument("--memory-only", action="store_true", help="no .mcap/.rrd in the edge cases")
    parser.add_argument(CHILD_FLAG, action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.integrators:
        args.integrators = [s.strip() for s in args.integrators.split(",") if s.strip()]
    else:
        args.integrators = list(QUICK_INTEGRATORS) if args.quick else all_integrator_names()
    try:
        integrator_variants(args.integrators)
    except ValueError as exc:
        parser.error(str(exc))
    capacities = args.capacities or ("1,2" if args.quick else "1,2,3")
    args.capacities = sorted({int(c) for c in capacities.split(",")})
    if min(args.capacities) < 1:
        parser.error("capacities are at least 1")
    if args.large is None:
        args.large = not args.quick
    if args.scenes is None:
        args.scenes = not args.quick
    return args


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    args = parse(argv)
    if args.child:
        return child(args)
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="rbsim-numba-cache-") as cache:
        env = {**os.environ, "NUMBA_BOUNDSCHECK": "1", "NUMBA_CACHE_DIR": cache}
        code = subprocess.run([sys.executable, str(Path(__file__).resolve()), CHILD_FLAG, *argv], env=env).returncode
    print(f"boundscheck_kernels: {'passed' if code == 0 else 'FAILED'} in {time.perf_counter() - started:.0f} s")
    return code


if __name__ == "__main__":
    sys.exit(main())
