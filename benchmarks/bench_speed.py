"""Speed of rbsim's compiled step kernels against MuJoCo (and PyBullet), measured in the same run.

    python benchmarks/bench_speed.py [--quick] [--write-docs] [--integrators split2,rk4]

Body-steps per second (bodies x steps / wall second) for, all in one process, one after another:
  free bodies N = 1, 100, 10,000 under gravity, no contact, 1,000 steps (fewer where one run would take
    longer than the time budget: the steps used are listed), for every registered integrator with a
    `run_chunk`: (a) the compiled chunk alone (`kernel.run_chunk`, record_every = steps: one frame
    copied at the end) and (b) the runner path (`rbcli.runner.loop.run` into a SinkMemory plus
    `trajectory()`, record_every = steps: frame 0 and the final frame, as `rbcli.simulate` does after
    compiling the scene); the numpy vectorised tutorial step (`euler_matrix.step_numpy`) as baseline;
  MuJoCo on the same bodies (same mass, principal inertia, initial state; a sphere geom with contype=0
    conaffinity=0; Euler; same dt), timed as `mj_step(m, d, nstep=steps)` (the loop in C) and as a
    Python loop of `mj_step`; the faster is the reference of every ratio. `mujoco.rollout` is not used:
    it stores the full state every step (a recording-on run, ~1 GB for N = 10,000 x 1,000 steps);
  PyBullet (if installed) on the same bodies with no collision shape, a Python loop of stepSimulation;
  a chain of 1,000 bodies joined by springs-dampers (ForceSpring between consecutive bodies, the first
    tied to a world anchor), against MuJoCo spatial tendons with the same stiffness, rest length,
    damping and attachment points;
  recording 1,000 bodies x 1,000 steps every step to each sink (memory, .mcap, .rrd) against none;
  peak traced memory of a recorded run at two lengths (flat = nothing grows with steps);
  start-up: `rbsim --help`, `rbsim validate`, a second `rbsim run` (warm numba cache), median of 5.
Each measurement is warmed up first (kernels compiled or loaded from numba's cache, the time reported),
then repeated; runs of one scene size are interleaved across engines so a change of machine load hits
them alike; the best repeat is reported and the median/best spread printed (a shared machine is noisy).
MuJoCo's compiler is quadratic in the body count (~40 s for 10,000 bodies), so compiled models of 1,000
or more bodies are cached as .mjb under ~/.cache/rbsim-bench (keyed by the XML and MuJoCo's version).
`--write-docs` writes docs/performance.md from this run.
"""

from __future__ import annotations

import argparse
import datetime
import hashlib
import importlib.metadata
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
import tracemalloc
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rbcli.physics.integrators import INTEGRATORS, get_integrator  # noqa: E402
from rbcli.physics.integrators.euler_matrix import step_numpy  # noqa: E402
from rbcli.physics.rotation import quat_rotate, quat_rotate_inverse  # noqa: E402
from rbcli.physics.step import STATUS_OK, empty_buffers  # noqa: E402
from rbcli.record.memory_sink import SinkMemory  # noqa: E402
from rbcli.runner.loop import run as runner_run  # noqa: E402
from rbcli.runner.loop import warm_up  # noqa: E402
from rbcli.scene.compile import CompiledScene, compile_scene  # noqa: E402
from rbcli.scene.force_specs import BodyPoint, ForceSpring  # noqa: E402
from rbcli.scene.spec import BodySpec, RecordSpec, SceneSpec, SimulationSpec  # noqa: E402

SIZES = (1, 100, 10_000)
STEPS = 1000
DT = 1e-3
GRAVITY = np.array([0.0, 0.0, -9.81])
MAIN_INTEGRATORS = ("euler-matrix", "split2", "rk4")
CHAIN_BODIES = 1000
RECORD_BODIES = 1000
# the issue's targets: split2 steps/s at N = 1, body-steps/s at N = 100 and 10,000; rk4 cost vs split2
TARGET_RATE = {1: 1e6, 100: 1e7, 10_000: 1e7}
TARGET_RK4_COST = 2.5
TARGET_RECORDING_OVERHEAD = 0.5
TARGET_STARTUP = {"rbsim --help": 0.3, "rbsim validate": 0.5, "rbsim run (warm cache)": 1.0}
# the issue's anchors (2-core machine, free bodies, no contact, 1,000 steps), body-steps/s; not measured here
ISSUE_ANCHORS = {
    "numpy vectorised tutorial step": ("1.0e4", "1.3e6", "3.1e6"),
    "MuJoCo 4.0 (Euler)": ("3.8e5", "3.6e6", "2.9e6"),
    "PyBullet": ("5e5-8e5", "1.5e6-9e6", "0.7e6-2.3e6"),
    "Newton (Warp CPU)": ("1e4", "5.9e5", "9.2e6"),
}
CACHE = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "rbsim-bench"

# ---- machine and scenes -----------------------------------------------------------------------------------


def machine() -> dict[str, str]:
    """CPU model, cores, load and library versions, for the report header."""
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    versions = {"python": platform.python_version()}
    for name in ("numpy", "numba", "mujoco", "pybullet"):
        try:
            versions[name] = importlib.metadata.version(name)
        except importlib.metadata.PackageNotFoundError:
            versions[name] = "not installed"
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    return {
        "date": datetime.datetime.now().strftime("%Y-%m-%d %H:%M"),
        "cpu": f"{cpu}, {os.cpu_count()} logical cores, {platform.system()} {platform.release()}",
        "load": "load average {:.2f} {:.2f} {:.2f} (1, 5, 15 min)".format(*load),
        "versions": ", ".join(f"{k} {v}" for k, v in versions.items()),
    }


def free_bodies(count: int, seed: int = 0, spacing: float = 0.0) -> list[BodySpec]:
    """Bodies of 5 random particles with random orientation, velocity and angular momentum; spacing > 0
    puts them on a line along x instead of random positions."""
    rng = np.random.default_rng(seed)
    bodies = []
    for i in range(count):
        q = rng.normal(size=4)
        bodies.append(
            BodySpec(
                name=f"b{i}",
                particle_position=rng.normal(size=(5, 3)) * 0.1,
                particle_mass=rng.uniform(0.5, 2.0, size=5),
                position=np.array([i * spacing, 0.0, 0.0]) if spacing else rng.normal(size=3) * 10.0,
                orientation_wxyz=q / np.linalg.norm(q),
                velocity=rng.normal(size=3),
                angular_momentum=rng.normal(size=3) * 0.01,
            )
        )
    return bodies


def scene(bodies: list[BodySpec], forces: tuple = (), integrator: str = "split2") -> SceneSpec:
    sim = SimulationSpec(dt=DT, duration=STEPS * DT, integrator=integrator, record=RecordSpec(STEPS))
    return SceneSpec(name="bench-speed", simulation=sim, bodies=tuple(bodies), gravity=GRAVITY, forces=forces)


def spring_chain(count: int) -> SceneSpec:
    """count bodies 0.5 m apart along x, each joined to the next by a spring-damper between body points,
    body 0 tied to a world anchor; gravity on."""
    bodies = free_bodies(count, seed=1, spacing=0.5)
    springs = [ForceSpring(end_a=BodyPoint(body="b0", point=np.zeros(3)), anchor=np.array([-0.5, 0.0, 0.0]),
                           stiffness=100.0, rest_length=0.3, damping=0.1)]  # fmt: skip
    for i in range(count - 1):
        springs.append(
            ForceSpring(end_a=BodyPoint(body=f"b{i}", point=np.array([0.1, 0.0, 0.0])),
                        end_b=BodyPoint(body=f"b{i + 1}", point=np.array([-0.1, 0.0, 0.0])),
                        stiffness=100.0, rest_length=0.3, damping=0.1)
        )  # fmt: skip
    return scene(bodies, tuple(springs))


def with_settings(compiled: CompiledScene, **settings: object) -> CompiledScene:
    """The same compiled scene with other run settings (integrator, steps, record_every)."""
    return replace(compiled, settings=replace(compiled.settings, **settings))


# ---- timing -------------------------------------------------------------------------------------------------

# a factory: steps -> a function that runs that many steps once and returns the wall seconds it took
Runner = Callable[[int], Callable[[], float]]


@dataclass
class Timing:
    """Best and median seconds per step over the repeats; steps per repeat; warm-up seconds."""

    best: float
    median: float
    steps: int
    warm: float = 0.0
    note: str = ""

    def rate(self, bodies: int) -> float:
        return bodies / self.best


def measure(runners: dict[str, Runner], repeats: int, budget: float, max_steps: int = STEPS) -> dict[str, Timing]:
    """Warm each runner up (1 step), size its steps to the budget (<= max_steps, >= 20), then run all of
    them `repeats` times interleaved. A runner whose probe raises is reported with the error as note."""
    timed: dict[str, tuple[Callable[[], float], int, float]] = {}
    out: dict[str, Timing] = {}
    for label, make in runners.items():
        try:
            started = time.perf_counter()
            make(1)()
            warm = time.perf_counter() - started
            probe_steps = min(20, max_steps)
            per_step = make(probe_steps)() / probe_steps
            steps = int(np.clip(budget / max(per_step, 1e-12), min(20, max_steps), max_steps))
            timed[label] = (make(steps), steps, warm)
        except Exception as exc:  # noqa: BLE001 - a failing engine is reported, not fatal
            out[label] = Timing(float("nan"), float("nan"), 0, note=f"{type(exc).__name__}: {exc}"[:120])
    samples: dict[str, list[float]] = {label: [] for label in timed}
    for _ in range(repeats):
        for label, (run, steps, _) in list(timed.items()):
            try:
                samples[label].append(run() / steps)
            except Exception as exc:  # noqa: BLE001 - e.g. a divergence after the probe's steps
                out[label] = Timing(float("nan"), float("nan"), 0, note=f"{type(exc).__name__}: {exc}"[:120])
                del timed[label]
    for label, (_, steps, warm) in timed.items():
        out[label] = Timing(min(samples[label]), statistics.median(samples[label]), steps, warm)
    return {label: out[label] for label in runners}


def chunk_runner(compiled: CompiledScene, integrator: str) -> Runner:
    """`kernel.run_chunk` alone, from the initial state, record_every = steps (one frame copied at the end)."""
    kernel = get_integrator(integrator).load()
    km, forces = compiled.model.kernel(), compiled.forces
    n = compiled.model.body_count
    F, tau, scratch = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, kernel.SCRATCH_WIDTH))
    frames = empty_buffers(2, n)

    def make(steps: int) -> Callable[[], float]:
        def run() -> float:
            s = compiled.initial_state.copy()
            started = time.perf_counter()
            done, _, status = kernel.run_chunk(km, forces, DT, 0, steps, steps, s.x, s.q, s.P, s.L, F, tau, scratch,
                                               frames, 0)  # fmt: skip
            elapsed = time.perf_counter() - started
            if done != steps or status != STATUS_OK:
                raise RuntimeError(f"{integrator} stopped at step {done} with status {status} (diverged)")
            return elapsed

        return run

    return make


def dispatch_seconds(compiled: CompiledScene, integrator: str, calls: int = 200) -> float:
    """Seconds of one Python call of `run_chunk` for 0 steps: unboxing the arguments, the chunk's fixed cost."""
    kernel = get_integrator(integrator).load()
    km, n = compiled.model.kernel(), compiled.model.body_count
    s = compiled.initial_state.copy()
    args = (np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, kernel.SCRATCH_WIDTH)), empty_buffers(2, n), 0)
    best = float("inf")
    for _ in range(5):
        started = time.perf_counter()
        for _ in range(calls):
            kernel.run_chunk(km, compiled.forces, DT, 0, 0, 1, s.x, s.q, s.P, s.L, *args)
        best = min(best, (time.perf_counter() - started) / calls)
    return best


def runner_runner(compiled: CompiledScene, integrator: str) -> Runner:
    """`rbcli.runner.loop.run` into a SinkMemory plus `trajectory()`: `rbcli.simulate` minus compile_scene."""

    def make(steps: int) -> Callable[[], float]:
        case = with_settings(compiled, integrator=integrator, steps=steps, record_every=steps)
        warm_up(case)

        def run() -> float:
            sink = SinkMemory()
            started = time.perf_counter()
            summary = runner_run(case, [sink])
            sink.trajectory()
            elapsed = time.perf_counter() - started
            if summary.status != "completed":
                raise RuntimeError(f"{integrator}: {summary.message}")
            return elapsed

        return run

    return make


def numpy_runner(compiled: CompiledScene) -> Runner:
    """The tutorial's step vectorised over bodies with numpy, a Python loop over steps."""
    km, forces = compiled.model.kernel(), compiled.forces

    def make(steps: int) -> Callable[[], float]:
        def run() -> float:
            s = compiled.initial_state.copy()
            started = time.perf_counter()
            for k in range(steps):
                step_numpy(km, forces, k * DT, DT, s.x, s.q, s.P, s.L)
            return time.perf_counter() - started

        return run

    return make


# ---- MuJoCo and PyBullet on the same bodies ------------------------------------------------------------------


def xml_numbers(values: object) -> str:
    """Numbers for an XML attribute, exactly (repr of float64 round-trips)."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def mujoco_xml(compiled: CompiledScene) -> str:
    """MJCF of the compiled bodies: free joint, explicit inertial (mass, principal moments; body frame =
    principal frame), a sphere geom that collides with nothing; spring rows as spatial tendons."""
    model, state, springs = compiled.model, compiled.initial_state, compiled.forces.spring
    sites: dict[int, list[str]] = {}
    world_sites, tendons = [], []
    for row in range(springs.body_a.shape[0]):
        ends = []
        for end, (body, point) in enumerate(((springs.body_a[row], springs.point_a[row]),
                                             (springs.body_b[row], springs.point_b[row]))):  # fmt: skip
            name = f"s{row}_{end}"
            site = f'<site name="{name}" pos="{xml_numbers(point)}"/>'
            (world_sites if body < 0 else sites.setdefault(int(body), [])).append(site)
            ends.append(f'<site site="{name}"/>')
        k, l0, c = (xml_numbers(v[row]) for v in (springs.stiffness, springs.rest_length, springs.damping))
        tendons.append(f'<spatial stiffness="{k}" springlength="{l0}" damping="{c}">{"".join(ends)}</spatial>')
    bodies = []
    for b in range(model.body_count):
        x, q, inertia = state.x[b], state.q[b], model.body_inertia[b]
        bodies.append(
            f'<body pos="{xml_numbers(x)}" quat="{xml_numbers(q)}"><freejoint/>'
            f'<inertial pos="0 0 0" mass="{xml_numbers(model.body_mass[b])}" '
            f'diaginertia="{xml_numbers(inertia)}"/>'
            f'<geom type="sphere" size="0.05" contype="0" conaffinity="0"/>{"".join(sites.get(b, []))}</body>'
        )
    g = compiled.forces.gravity
    return (
        f'<mujoco model="rbsim-bench"><size memory="{max(64, model.body_count // 20)}M"/>'
        f'<option timestep="{xml_numbers(compiled.settings.dt)}" integrator="Euler" gravity="{xml_numbers(g)}"/>'
        f"<worldbody>{''.join(world_sites)}{''.join(bodies)}</worldbody>"
        f"<tendon>{''.join(tendons)}</tendon></mujoco>"
    )


def mujoco_model(compiled: CompiledScene):  # noqa: ANN201 - mujoco.MjModel
    """Compile (or load from the .mjb cache) the MuJoCo twin of the scene; returns (model, build seconds)."""
    import mujoco

    xml = mujoco_xml(compiled)
    key = hashlib.sha256((mujoco.__version__ + xml).encode()).hexdigest()[:16]
    path = CACHE / f"bodies-{compiled.model.body_count}-{key}.mjb"
    started = time.perf_counter()
    if path.exists():
        return mujoco.MjModel.from_binary_path(str(path)), time.perf_counter() - started, "cached .mjb"
    if compiled.model.body_count >= 1000:
        print(f"  compiling the MuJoCo model of {compiled.model.body_count} bodies (once; cached in {CACHE}) ...",
              flush=True)  # fmt: skip
    model = mujoco.MjModel.from_xml_string(xml)
    built = time.perf_counter() - started
    if compiled.model.body_count >= 1000:
        CACHE.mkdir(parents=True, exist_ok=True)
        mujoco.mj_saveModel(model, str(path), None)
    return model, built, "compiled"


def mujoco_runners(compiled: CompiledScene) -> tuple[dict[str, Runner], str]:
    """`mj_step(nstep)` and a Python loop of `mj_step`, from the scene's initial state each run."""
    import mujoco

    m, built, how = mujoco_model(compiled)
    d = mujoco.MjData(m)
    state, model = compiled.initial_state, compiled.model
    qvel0 = np.zeros(m.nv)
    qvel0.reshape(-1, 6)[:, :3] = state.P / model.body_mass[:, None]  # world linear velocity of the centre of mass
    # free joint angular velocity is in the body (principal) frame: omega_b = I^-1 R^T L
    qvel0.reshape(-1, 6)[:, 3:] = quat_rotate_inverse(state.q, state.L) / model.body_inertia
    qpos0 = m.qpos0.copy()

    def reset() -> None:
        d.qpos[:], d.qvel[:], d.time = qpos0, qvel0, 0.0

    def nstep(steps: int) -> Callable[[], float]:
        def run() -> float:
            reset()
            started = time.perf_counter()
            mujoco.mj_step(m, d, nstep=steps)
            return time.perf_counter() - started

        return run

    def loop(steps: int) -> Callable[[], float]:
        def run() -> float:
            reset()
            step = mujoco.mj_step
            started = time.perf_counter()
            for _ in range(steps):
                step(m, d)
            return time.perf_counter() - started

        return run

    return {"MuJoCo mj_step(nstep)": nstep, "MuJoCo Python loop of mj_step": loop}, f"{how} in {built:.2f} s"


def pybullet_runner(compiled: CompiledScene) -> tuple[Runner, str]:
    """PyBullet (DIRECT) with the same bodies, no collision shape, a Python loop of stepSimulation."""
    import pybullet as pb

    client = pb.connect(pb.DIRECT)
    started = time.perf_counter()
    pb.setGravity(*compiled.forces.gravity, physicsClientId=client)
    pb.setTimeStep(DT, physicsClientId=client)
    model, state = compiled.model, compiled.initial_state
    xyzw = state.q[:, [1, 2, 3, 0]]
    # PyBullet takes the world angular velocity: omega = R I^-1 R^T L
    omega_world = quat_rotate(state.q, quat_rotate_inverse(state.q, state.L) / model.body_inertia)
    ids = []
    for b in range(model.body_count):  # set-up only
        body = pb.createMultiBody(baseMass=float(model.body_mass[b]), baseCollisionShapeIndex=-1,
                                  basePosition=state.x[b].tolist(), baseOrientation=xyzw[b].tolist(),
                                  physicsClientId=client)  # fmt: skip
        pb.changeDynamics(body, -1, localInertiaDiagonal=model.body_inertia[b].tolist(), linearDamping=0.0,
                          angularDamping=0.0, physicsClientId=client)  # fmt: skip
        ids.append(body)
    built = time.perf_counter() - started

    def make(steps: int) -> Callable[[], float]:
        def run() -> float:
            for b, body in enumerate(ids):
                pb.resetBasePositionAndOrientation(body, state.x[b].tolist(), xyzw[b].tolist(), physicsClientId=client)
                pb.resetBaseVelocity(body, (state.P[b] / model.body_mass[b]).tolist(), omega_world[b].tolist(),
                                     physicsClientId=client)  # fmt: skip
            step = pb.stepSimulation
            started = time.perf_counter()
            for _ in range(steps):
                step(physicsClientId=client)
            return time.perf_counter() - started

        return run

    return make, f"built in {built:.2f} s"


# ---- recording, memory, start-up --------------------------------------------------------------------------


def recording_runs(compiled: CompiledScene, out: Path) -> dict[str, Runner]:
    """The runner with no recording (frame 0 and the last) and recording every step into each sink."""
    from rbcli.record.mcap_sink import SinkMcap
    from rbcli.record.rerun_sink import SinkRerun

    sinks: dict[str, Callable[[], object] | None] = {
        "off (frame 0 and last)": None,
        "memory (SinkMemory + trajectory())": SinkMemory,
        ".mcap (SinkMcap, zstd)": lambda: SinkMcap(out / "bench.mcap"),
        ".rrd (SinkRerun)": lambda: SinkRerun(out / "bench.rrd"),
    }
    runs: dict[str, Runner] = {}
    for label, make_sink in sinks.items():

        def make(steps: int, make_sink=make_sink) -> Callable[[], float]:  # noqa: ANN001
            case = with_settings(compiled, steps=steps, record_every=steps if make_sink is None else 1)
            warm_up(case)

            def run() -> float:
                sink = make_sink() if make_sink is not None else SinkMemory()
                started = time.perf_counter()
                runner_run(case, [sink])
                if isinstance(sink, SinkMemory):
                    sink.trajectory()
                return time.perf_counter() - started

            return run

        runs[label] = make
    return runs


def peak_memory(compiled: CompiledScene, steps: int, out: Path) -> float:
    """Peak traced allocations [MB] of a run recording every step to .mcap (numpy and Python objects)."""
    from rbcli.record.mcap_sink import SinkMcap

    case = with_settings(compiled, steps=steps, record_every=1)
    warm_up(case)
    tracemalloc.start()
    runner_run(case, [SinkMcap(out / "memory.mcap")])
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    return peak / 1e6


def startup_times(out: Path, repeats: int = 5) -> dict[str, float]:
    """Median wall seconds of each command in a fresh process, after one unmeasured run of each."""
    rbsim = Path(sys.executable).with_name("rbsim")
    exe = str(rbsim) if rbsim.exists() else shutil.which("rbsim") or "rbsim"
    tutorial = str(ROOT / "scenes" / "tutorial.yaml")
    commands = {
        "rbsim --help": [exe, "--help"],
        "rbsim validate": [exe, "validate", tutorial],
        "rbsim run (warm cache)": [exe, "run", tutorial, "-o", str(out / "x.mcap"), "--duration", "0.01"],
    }
    times = {}
    for label, cmd in commands.items():
        samples = []
        for i in range(repeats + 1):
            started = time.perf_counter()
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, cwd=ROOT)
            if i:  # the first run warms the OS file cache and numba's cache
                samples.append(time.perf_counter() - started)
        times[label] = statistics.median(samples)
    return times


# ---- report -----------------------------------------------------------------------------------------------


def cell(rate: float, reference: float | None, timing: Timing | None = None) -> str:
    if timing is not None and timing.note:
        return "failed"
    if not np.isfinite(rate):
        return "n/a"
    ratio = f" ({rate / reference:.2g}x)" if reference and np.isfinite(reference) else ""
    return f"{rate:.2e}{ratio}"


def ok(passed: bool) -> str:
    return "met" if passed else "**missed**"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, shorter runs (under ~60 s)")
    parser.add_argument("--write-docs", action="store_true", help="write docs/performance.md from this run")
    parser.add_argument("--integrators", default="", help="comma list [default: quick: " + ",".join(MAIN_INTEGRATORS)
                        + "; full: every registered integrator]")  # fmt: skip
    parser.add_argument("--no-pybullet", action="store_true")
    args = parser.parse_args()

    repeats, budget = (3, 0.15) if args.quick else (7, 1.0)
    every = [n for n in INTEGRATORS if hasattr(INTEGRATORS[n].load(), "run_chunk")]
    names = [n for n in args.integrators.split(",") if n] or (list(MAIN_INTEGRATORS) if args.quick else every)
    info = machine()
    lines: list[str] = []

    def say(text: str = "") -> None:
        print(text, flush=True)
        lines.append(text)

    say(f"- date: {info['date']}; mode: {'--quick' if args.quick else 'full'}")
    say(f"- machine: {info['cpu']}; {info['load']} at start")
    say(f"- {info['versions']}")
    say(f"- timing: best of {repeats} interleaved repeats, {STEPS} steps (fewer where one run would pass "
        f"{budget:g} s, listed below), dt = {DT:g} s, after a warm-up run")  # fmt: skip
    try:
        import mujoco  # noqa: F401

        have_mujoco = True
    except ImportError:
        have_mujoco = False
        say("- **MuJoCo is not installed** (`pip install -e .[bench]`): its columns and ratios are left out")
    try:
        import pybullet  # noqa: F401

        have_pybullet = not args.no_pybullet
    except ImportError:
        have_pybullet = False
        say("- PyBullet is not installed (optional, `pip install pybullet`): its row is left out")
    say("- contact: the sphere-pile benchmark against MuJoCo waits for the collisions issue (no contact in rbsim yet)")
    say()

    # ---- free bodies -------------------------------------------------------------------------------------
    results: dict[int, dict[str, Timing]] = {}
    notes: list[str] = []
    compile_seconds: dict[int, float] = {}
    scenes: dict[int, CompiledScene] = {}
    for n in SIZES:
        print(f"free bodies N = {n} ...", flush=True)
        bodies = free_bodies(n)
        started = time.perf_counter()
        compiled = compile_scene(scene(bodies))
        compile_seconds[n] = time.perf_counter() - started
        scenes[n] = compiled
        runners: dict[str, Runner] = {"numpy tutorial step": numpy_runner(compiled)}
        for name in names:
            runners[f"{name}: chunk"] = chunk_runner(compiled, name)
            runners[f"{name}: runner"] = runner_runner(compiled, name)
        if have_mujoco:
            mj, how = mujoco_runners(compiled)
            runners.update(mj)
            notes.append(f"MuJoCo model of N = {n:,}: {how}")
        if have_pybullet:
            make, how = pybullet_runner(compiled)
            runners["PyBullet stepSimulation loop"] = make
            notes.append(f"PyBullet N = {n:,}: {how}")
        results[n] = measure(runners, repeats, budget)

    def mujoco_best(n: int) -> tuple[float, str]:
        candidates = {k: v for k, v in results[n].items() if k.startswith("MuJoCo") and not v.note}
        if not candidates:
            return float("nan"), ""
        label = min(candidates, key=lambda k: candidates[k].best)
        return candidates[label].rate(n), label

    reference = {n: mujoco_best(n)[0] for n in SIZES}
    say("### Free bodies under gravity, no contact: body-steps/s (ratio to the faster MuJoCo timing)")
    say()
    say("| engine / path | " + " | ".join(f"N = {n:,}" for n in SIZES) + " |")
    say("|---|" + "---:|" * len(SIZES))
    for label in results[SIZES[0]]:
        say(f"| {label} | " + " | ".join(cell(results[n][label].rate(n), reference[n], results[n][label])
                                         for n in SIZES) + " |")  # fmt: skip
    say()
    for n in SIZES:
        say(f"- N = {n:,}: MuJoCo reference = {mujoco_best(n)[1] or 'n/a'}; scene compile (Python) "
            f"{compile_seconds[n] * 1e3:.0f} ms, which `rbcli.simulate` adds to the runner row")  # fmt: skip
    short = sorted({f"{label} at N = {n:,}: {t.steps} steps" for n in SIZES for label, t in results[n].items()
                    if t.steps and t.steps < STEPS})  # fmt: skip
    if short:
        say("- shorter runs: " + "; ".join(short))
    failed = [f"{label} at N = {n:,}: {t.note}" for n in SIZES for label, t in results[n].items() if t.note]
    for note in failed:
        say(f"- failed: {note}")
    spread = max(t.median / t.best for n in SIZES for t in results[n].values() if not t.note)
    say(f"- noise: the largest median/best ratio of any row is {spread:.2f}")
    warm = {name: results[1][f"{name}: chunk"].warm for name in names if not results[1][f"{name}: chunk"].note}
    say("- first call (compile, or load from numba's cache): "
        + ", ".join(f"{k} {v:.2f} s" for k, v in warm.items()))  # fmt: skip
    if notes:
        say("- set-up: " + "; ".join(notes))
    say("- issue anchors (2-core machine, not measured here), N = 1 / 100 / 10,000: "
        + "; ".join(f"{k} {' / '.join(v)}" for k, v in ISSUE_ANCHORS.items()))  # fmt: skip
    say()

    # ---- where the time goes: t(N) = fixed + per-body * N from the chunk rows --------------------------
    say("### Cost model of the compiled chunk: time per step = fixed + per-body x N")
    say()
    say(
        "| integrator | fixed per step (N = 1) | per body-step (N = 10,000) | x split2 (N = 1 / 100 / 10,000) "
        "| Python call of run_chunk (0 steps) |"
    )
    say("|---|---:|---:|---:|---:|")
    facts: dict[str, float] = {}
    split = {n: results[n].get("split2: chunk") for n in SIZES}
    for name in names:
        t = {n: results[n][f"{name}: chunk"] for n in SIZES}
        if any(v.note for v in t.values()):
            continue
        per_body = (t[10_000].best - t[1].best) / (10_000 - 1)
        rel = " / ".join(f"{t[n].best / split[n].best:.2f}" if split[n] and not split[n].note else "n/a" for n in SIZES)
        dispatch = dispatch_seconds(scenes[1], name)
        say(f"| {name} | {t[1].best * 1e9:.0f} ns | {per_body * 1e9:.1f} ns | {rel} | {dispatch * 1e6:.1f} us |")
        if name == "split2":
            runner_fixed = (results[1]["split2: runner"].best - t[1].best) * results[1]["split2: runner"].steps
            facts.update(fixed_ns=t[1].best * 1e9, per_body_ns=per_body * 1e9, dispatch_us=dispatch * 1e6,
                         runner_fixed_ms=runner_fixed * 1e3)  # fmt: skip
    say()

    # ---- spring chain -------------------------------------------------------------------------------------
    print(f"spring chain of {CHAIN_BODIES} bodies ...", flush=True)
    chain = compile_scene(spring_chain(CHAIN_BODIES))
    runners = {f"{name}: chunk": chunk_runner(chain, name) for name in names}
    if have_mujoco:
        mj, how = mujoco_runners(chain)
        runners["MuJoCo mj_step(nstep), spatial tendons"] = mj["MuJoCo mj_step(nstep)"]
    chain_t = measure(runners, repeats, budget)
    mj_chain = chain_t.get("MuJoCo mj_step(nstep), spatial tendons")
    mj_rate = mj_chain.rate(CHAIN_BODIES) if mj_chain and not mj_chain.note else float("nan")
    say(f"### Spring chain: {CHAIN_BODIES:,} bodies, {CHAIN_BODIES - 1:,} springs-dampers + 1 anchor, gravity")
    say()
    say("| engine / path | body-steps/s (ratio to MuJoCo) | time per step |")
    say("|---|---:|---:|")
    for label, t in chain_t.items():
        say(f"| {label} | {cell(t.rate(CHAIN_BODIES), mj_rate, t)} | {t.best * 1e6:.0f} us |")
    say()

    # ---- recording ----------------------------------------------------------------------------------------
    print(f"recording {RECORD_BODIES} bodies ...", flush=True)
    out = Path(tempfile.mkdtemp(prefix="rbsim-bench-speed-"))
    rec_compiled = compile_scene(scene(free_bodies(RECORD_BODIES, seed=2)))
    rec_steps = 200 if args.quick else STEPS
    rec = measure(recording_runs(rec_compiled, out), 1 if args.quick else 3, 1e9, max_steps=rec_steps)
    off = rec["off (frame 0 and last)"]
    say(f"### Recording: {RECORD_BODIES:,} bodies x {rec_steps:,} steps, split2, runner path, every step")
    say()
    say("| sink | wall time | vs off | cost per frame | file |")
    say("|---|---:|---:|---:|---:|")
    sizes = {".mcap (SinkMcap, zstd)": out / "bench.mcap", ".rrd (SinkRerun)": out / "bench.rrd"}
    overhead = {}
    for label, t in rec.items():
        if t.note:
            say(f"| {label} | failed: {t.note} | | | |")
            continue
        overhead[label] = t.best / off.best - 1.0
        per_frame = (t.best - off.best) * 1e6
        size = f"{sizes[label].stat().st_size / 1e6:.1f} MB" if label in sizes and sizes[label].exists() else ""
        say(f"| {label} | {t.best * t.steps * 1e3:.0f} ms | +{overhead[label] * 100:.0f} % | "
            f"{per_frame:.0f} us | {size} |")  # fmt: skip
    say()
    short_steps, long_steps = (100, 400) if args.quick else (500, 2000)
    mem = {s: peak_memory(rec_compiled, s, out) for s in (short_steps, long_steps)}
    flat = mem[long_steps] <= 1.1 * mem[short_steps] + 1.0
    say(f"- memory: peak traced allocations recording {RECORD_BODIES:,} bodies to .mcap every step: "
        f"{mem[short_steps]:.1f} MB over {short_steps:,} steps, {mem[long_steps]:.1f} MB over {long_steps:,} "
        f"steps ({'flat' if flat else 'GROWS with steps'})")  # fmt: skip
    say()

    # ---- start-up -----------------------------------------------------------------------------------------
    print("start-up ...", flush=True)
    startup = startup_times(out)
    say("### Start-up (fresh process, median of 5 after one warm run)")
    say()
    say("| command | median | target |")
    say("|---|---:|---:|")
    for label, seconds in startup.items():
        say(f"| `{label}` | {seconds:.2f} s | < {TARGET_STARTUP[label]:g} s ({ok(seconds < TARGET_STARTUP[label])}) |")
    say()

    # ---- targets ------------------------------------------------------------------------------------------
    say("### Targets of the issue")
    say()
    say("| target | measured | status |")
    say("|---|---|---|")
    for path in ("chunk", "runner"):
        t = {n: results[n].get(f"split2: {path}") for n in SIZES}
        if any(v is None or v.note for v in t.values()):
            continue
        for n in SIZES:
            unit = "steps/s" if n == 1 else "body-steps/s"
            rate = t[n].rate(n)
            target = TARGET_RATE[n]
            say(f"| split2 {path}, N = {n:,}: >= {target:.0e} {unit} | {rate:.2e} | {ok(rate >= target)} |")
        if have_mujoco:
            ratios = [t[n].rate(n) / reference[n] for n in SIZES]
            say(f"| split2 {path} faster than MuJoCo at every size | "
                + " / ".join(f"{r:.2f}x" for r in ratios) + f" | {ok(min(ratios) > 1.0)} |")  # fmt: skip
    if "rk4" in names and "split2" in names and not any(results[n]["rk4: chunk"].note for n in SIZES):
        costs = [results[n]["rk4: chunk"].best / results[n]["split2: chunk"].best for n in SIZES]
        say(f"| rk4 cost per step <= {TARGET_RK4_COST}x split2 (chunk, N = 1 / 100 / 10,000) | "
            + " / ".join(f"{c:.2f}x" for c in costs) + f" | {ok(max(costs) <= TARGET_RK4_COST)} |")  # fmt: skip
    if overhead:
        worst = max(overhead, key=lambda k: overhead[k])
        say(f"| recording every step adds <= {TARGET_RECORDING_OVERHEAD:.0%} ({RECORD_BODIES:,} bodies) | worst "
            f"{worst}: +{overhead[worst]:.0%} | {ok(overhead[worst] <= TARGET_RECORDING_OVERHEAD)} |")  # fmt: skip
    say(f"| memory flat in the number of steps | {mem[short_steps]:.1f} / {mem[long_steps]:.1f} MB | {ok(flat)} |")
    say()
    say(f"- {machine()['load']} at the end")
    shutil.rmtree(out, ignore_errors=True)

    if args.write_docs:
        path = ROOT / "docs" / "performance.md"
        facts.setdefault("compile_us_per_body", compile_seconds[10_000] / 10_000 * 1e6)
        tail = DOCS_TAIL.format(**facts) if {"fixed_ns", "per_body_ns"} <= facts.keys() else ""
        path.write_text(DOCS_HEAD + "\n".join(lines) + "\n" + tail + DOCS_PROFILE)
        print(f"wrote {path}")


DOCS_HEAD = """# Performance

Regenerated by `python benchmarks/bench_speed.py --write-docs` (add `--quick` for a ~1 minute run); every
number below comes from that one run on the machine it names, MuJoCo and PyBullet included, so the
ratios compare like with like. Body-steps/s = bodies x steps / wall second. A shared machine is noisy:
compare rows of one run, not runs of different days.

## Results

"""

DOCS_TAIL = """
## Where the time goes (numbers from the run above)

- **Small scenes pay per call, not per body.** split2's fixed cost is {fixed_ns:.0f} ns per step at N = 1
  against {per_body_ns:.0f} ns of work per body. Most of the fixed cost is numba's reference counting:
  every call of a compiled function that is not inlined increfs and decrefs each array it receives
  (an atomic add each, ~10 ns per array per call), and `model` + `forces` hold ~55 arrays, handed down
  run_chunk -> step -> compose -> accumulate_wrench every step (measured: passing `forces` to a
  function that only zeroes F and adds gravity costs ~580 ns per call; the same work on 5 plain arrays
  ~50 ns). A Python call of `run_chunk` costs {dispatch_us:.0f} us (unboxing those arrays), paid once
  per runner chunk of ~0.2 s.
- **Large scenes pay per body.** split2 turns every body about its three principal axes: 5 sin/cos pairs
  per body per step, and glibc's `sincos` is about half of the per-body time (perf, N = 10,000). The
  state (x, q, P, L and 5 scratch columns: 18 float64 per body) is 1.4 MB at 10,000 bodies and stays
  in cache: the kernel is compute-bound, not bandwidth-bound.
- **The runner** adds ~{runner_fixed_ms:.1f} ms per run at N = 1 (header, frame 0 and the last frame
  through `make_block`, the sink) and one `run_chunk` call per chunk; `rbcli.simulate` also compiles the
  scene in Python, ~{compile_us_per_body:.0f} us per body (about 1 s for 10,000 bodies).
- **MuJoCo** runs its general pipeline per step (kinematics, composite inertia, mass matrix and its
  factorisation, the constraint stage) even for free bodies, ~0.3-0.4 us per body; PyBullet's per-step
  cost grows faster than linearly with the body count.
- **The numpy row** is rbsim's numpy reference of euler-matrix (`step_numpy`), not a bare tutorial step:
  its `wrench_numpy` evaluates the numpy reference of every force type, empty tables included (about
  two thirds of its ~0.6 ms per step at N = 1, cProfile), which is why it is below the issue's numpy
  anchor at small N.
- **Recording** every step costs far more than a step of 1,000 bodies: the table gives each sink's cost per
  frame, which sets the `record_every` a long run should use.
"""

DOCS_PROFILE = """
## Profile and measured suggestions (2026-11-25)

Prototypes are copies of the kernels of that date, so nothing in `rbcli/` changed; they were timed in one
process against the cached kernels, interleaved, best of 7, on the 2-core machine above while other jobs
held 1-2 cores. The prototypes are ns per step of `run_chunk`, split2 unless named.

| change | N = 1 | N = 100 | N = 10,000 |
|---|---:|---:|---:|
| split2 as it is | 2,310 | 9,590 | 728,700 |
| 1. `_nrt=False` on the per-step functions | 403 | 7,630 | 726,300 |
| 2. small-angle polynomial sin/cos | 2,280 | 7,550 | 533,000 |
| 1 + 2 | 385 | 5,670 | 532,500 |
| 1 + 2 + 3. call `record_if_due` only on recording steps | **282** | **5,540** | **533,600** |
| rk4 as it is / with 1 | 3,875 / 710 | 10,920 / 7,790 | 864,900 / 870,300 |

1. **Compile the per-step functions without reference counting**: `@numba.njit(cache=True, _nrt=False)` on
   `step`, `compose`, `_drift_to_first_kick`, `_kick_and_drift` (split2), `step` and `_stage` (rk4), and
   `accumulate_wrench` (forces/wrench.py); none of them allocates. Keep `run_chunk` with NRT (it calls
   `record_if_due`, whose `frames.x[filled] = x` copies need NRT). The final states are bit-identical.
   `_nrt` is numba's private option (in its jit options for years; caching works with it, checked);
   pin it with a test that the chunk's result equals the numpy reference (as now) and the benchmark.
   `inline="always"` on the same functions was tried: it removes the calls, not the increfs (N = 1:
   2.3 -> 1.4 us).
2. **sin/cos of split2's half-angles by a Taylor polynomial** (kinematics.half_turn): the half-angles are
   omega h / 2, tiny at any usable dt, so for |a| <= 1/16 use sin to a^9 and cos to a^10 (truncation
   below 1e-20 relative) and libm above. Checked against libm on 210,000 points of [-1/16, 1/16]: at
   most 1 ulp apart, 0.05 % of values differ in the last bit; the benchmark's final states were
   unchanged. 1.37x at N = 10,000.
3. **Call `record_if_due` only when a frame is due** (`if (step0 + k + 1) % record_every == 0:` in each
   `run_chunk`): the call passes 9 arrays every step even when nothing is recorded. 1.4x at N = 1 on top
   of 1 + 2.
4. **Not recommended: `numba.prange` over bodies.** With `parallel=True` on split2's two body loops (on top
   of 1-3) N = 10,000 went from 0.53 to 1.33 ms per step and N = 100,000 from 6.2 to 15.7 ms, because
   another process held one of the 2 cores and the threads wait for each other at every loop's end; with
   one thread it equals the serial loop. On an idle 2-core machine it could at best halve the per-body
   time; offer it only as an opt-in (a thread count setting), never by default on a shared machine.
5. Start-up (`python -X importtime`, one warm `rbsim run`, ~0.9 s in all): importing numba ~0.20 s,
   `numba.np.arraymath` ~0.25 s of which ~0.21 s is scipy.linalg (its BLAS bindings, pulled in by
   numba), typer/rich/pydantic ~0.15 s, the MCAP writer ~0.06 s; the kernels load from numba's cache
   in ~0.02 s each. The big items are numba's own import, outside rbsim's control short of not
   importing numba for commands that do not step.
"""


if __name__ == "__main__":
    main()
