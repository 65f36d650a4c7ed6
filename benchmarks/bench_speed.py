"""Speed of rbsim's compiled step kernels against MuJoCo (and PyBullet), measured in the same run.

    python benchmarks/bench_speed.py [--quick] [--write-docs] [--integrators split2,rk4]

Body-steps per second (bodies x steps / wall second) for, all in one process, one after another:
  free bodies N = 1, 100, 10,000 under gravity, no contact, 1,000 steps (fewer where one run would take
    longer than the time budget: the steps used are listed), for every registered integrator with a
    `run_chunk`: (a) the compiled chunk alone (`kernel.run_chunk`, record_every = steps: one frame
    copied at the end) and (b) the runner path (`rbcli.runner.simulation.run` into a SinkMemory plus
    `trajectory()`, record_every = steps: frame 0 and the final frame, as `rbcli.simulate` does after
    compiling the scene; on the threads a run gets, RBSIM_THREADS else every core: split2's threaded
    loop from 256 bodies, benchmarks/bench_threads.py); the numpy vectorised tutorial step
    (`euler_matrix.step_numpy`) as baseline;
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
  start-up: `rbsim --help`, `rbsim validate`, a second `rbsim run` (warm numba cache), median of 5;
  contact: the collisions issue's 1,000-ball pile against MuJoCo CG (benchmarks/bench_contact.py).
Each measurement is warmed up first (kernels compiled or loaded from numba's cache, the time reported),
then repeated; runs of one scene size are interleaved across engines so a change of machine load hits
them alike; the best repeat is reported and the median/best spread printed (a shared machine is noisy).
MuJoCo's compiler is quadratic in the body count (~40 s for 10,000 bodies), so compiled models of 1,000
or more bodies are cached as .mjb under ~/.cache/rbsim-bench (keyed by the XML and MuJoCo's version).
`--write-docs` replaces the results block of docs/performance.md (between its two markers) with this
run's report; the prose around it (why the time goes where it does, suggestions) is written by hand.
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

from rbcli.physics.data import make_data  # noqa: E402
from rbcli.physics.integrators import INTEGRATORS, get_integrator  # noqa: E402
from rbcli.physics.integrators.euler_matrix import step_numpy  # noqa: E402
from rbcli.physics.rotation import quat_rotate, quat_rotate_inverse  # noqa: E402
from rbcli.physics.step import STATUS_OK, empty_buffers  # noqa: E402
from rbcli.record.memory_sink import SinkMemory  # noqa: E402
from rbcli.runner.simulation import run as runner_run  # noqa: E402
from rbcli.runner.simulation import warm_up  # noqa: E402
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
    """The generated `run_chunk` alone, from the initial state, record_every = steps (one frame copied at the end)."""
    chunk = get_integrator(integrator).chunk()
    km, forces = compiled.model.kernel(), compiled.forces.kernel()  # as runs pass them (Simulation)
    n = compiled.model.body_count
    frames = empty_buffers(2, n)

    def make(steps: int) -> Callable[[], float]:
        def run() -> float:
            data = make_data(compiled.initial_state, compiled.model, chunk.SCRATCH_WIDTH, forces=forces).kernel()
            started = time.perf_counter()
            done, _, status = chunk.run_chunk(km, forces, data, DT, 0, steps, steps, frames, 0)
            elapsed = time.perf_counter() - started
            if done != steps or status != STATUS_OK:
                raise RuntimeError(f"{integrator} stopped at step {done} with status {status} (diverged)")
            return elapsed

        return run

    return make


def dispatch_seconds(compiled: CompiledScene, integrator: str, calls: int = 200) -> float:
    """Seconds of one Python call of `run_chunk` for 0 steps: unboxing the arguments, the chunk's fixed cost."""
    chunk = get_integrator(integrator).chunk()
    km, forces, n = compiled.model.kernel(), compiled.forces.kernel(), compiled.model.body_count
    data = make_data(compiled.initial_state, compiled.model, chunk.SCRATCH_WIDTH, forces=compiled.forces).kernel()
    frames = empty_buffers(2, n)
    best = float("inf")
    for _ in range(5):
        started = time.perf_counter()
        for _ in range(calls):
            chunk.run_chunk(km, forces, data, DT, 0, 0, 1, frames, 0)
        best = min(best, (time.perf_counter() - started) / calls)
    return best


def runner_runner(compiled: CompiledScene, integrator: str) -> Runner:
    """`rbcli.runner.simulation.run` into a SinkMemory plus `trajectory()`: `rbcli.simulate` minus compile_scene."""

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
    """The runner with no recording (frame 0 and the last) and recording every step into each sink, with
    the recording thread (the default) and inline (`threaded=False`)."""
    from rbcli.record.mcap_sink import SinkMcap
    from rbcli.record.rerun_sink import SinkRerun

    sinks: dict[str, tuple[Callable[[], object] | None, bool]] = {"off (frame 0 and last)": (None, True)}
    for threaded, how in ((True, "thread"), (False, "inline")):
        sinks[f"memory (SinkMemory + trajectory()), {how}"] = (SinkMemory, threaded)
        sinks[f".mcap (SinkMcap, zstd), {how}"] = (lambda: SinkMcap(out / "bench.mcap"), threaded)
        sinks[f".mcap (SinkMcap, uncompressed), {how}"] = (
            lambda: SinkMcap(out / "bench-raw.mcap", compression="none"),
            threaded,
        )
        sinks[f".rrd (SinkRerun), {how}"] = (lambda: SinkRerun(out / "bench.rrd"), threaded)
    runs: dict[str, Runner] = {}
    for label, (make_sink, threaded) in sinks.items():

        def make(steps: int, make_sink=make_sink, threaded=threaded) -> Callable[[], float]:  # noqa: ANN001
            case = with_settings(compiled, steps=steps, record_every=steps if make_sink is None else 1)
            warm_up(case)

            def run() -> float:
                sink = make_sink() if make_sink is not None else SinkMemory()
                # start every run from a clean page cache: the dirty pages of the last 200 MB file would
                # otherwise be written back during this run and charged to whichever sink runs next
                path = getattr(sink, "path", None)
                if path is not None:
                    path.unlink(missing_ok=True)
                os.sync()
                started = time.perf_counter()
                runner_run(case, [sink], threaded=threaded)
                if isinstance(sink, SinkMemory):
                    sink.trajectory()
                return time.perf_counter() - started

            return run

        runs[label] = make
    return runs


def write_floor(frames: int, frame_bytes: int, out: Path) -> float:
    """Seconds to only write `frames` x `frame_bytes` of ready bytes to a file (no encoding, no
    compression): the least any recording of that content can cost on this disk. Best of 3."""
    payload = np.random.default_rng(0).random(frame_bytes // 8).tobytes()
    best = float("inf")
    for _ in range(3):
        os.sync()
        started = time.perf_counter()
        with open(out / "floor.bin", "wb") as f:
            for _ in range(frames):
                f.write(payload)
        best = min(best, time.perf_counter() - started)
    (out / "floor.bin").unlink()
    return best


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


class Report:
    """Lines printed as they come and kept for docs/performance.md (Markdown)."""

    def __init__(self) -> None:
        self.lines: list[str] = []

    def say(self, text: str = "") -> None:
        print(text, flush=True)
        self.lines.append(text)

    def table(self, title: str, head: list[str], rows: list[list[str]]) -> None:
        self.say(f"### {title}")
        self.say()
        self.say("| " + " | ".join(head) + " |")
        self.say("|---|" + "---:|" * (len(head) - 1))
        for row in rows:
            self.say("| " + " | ".join(row) + " |")
        self.say()


def cell(timing: Timing, bodies: int, reference: float = float("nan")) -> str:
    """Body-steps/s with the ratio to the reference rate, or why there is no number."""
    if timing.note:
        return "failed"
    rate = timing.rate(bodies)
    return f"{rate:.2e}" + (f" ({rate / reference:.2g}x)" if np.isfinite(reference) else "")


def ok(passed: bool) -> str:
    return "met" if passed else "**missed**"


def mujoco_reference(timings: dict[str, Timing], bodies: int) -> tuple[float, str]:
    """The faster MuJoCo timing: (body-steps/s, its label); nan when MuJoCo was not run."""
    runs = {k: v for k, v in timings.items() if k.startswith("MuJoCo") and not v.note}
    if not runs:
        return float("nan"), "n/a"
    label = min(runs, key=lambda k: runs[k].best)
    return runs[label].rate(bodies), label


def free_body_section(rep: Report, names: list[str], repeats: int, budget: float, engines: set[str]) -> dict:
    """Free bodies at every size: measure, print the table, the notes and the cost model; returns the
    timings by size and the facts the reading needs."""
    results: dict[int, dict[str, Timing]] = {}
    scenes: dict[int, CompiledScene] = {}
    notes, compile_ms = [], {}
    for n in SIZES:
        print(f"free bodies N = {n:,} ...", flush=True)
        started = time.perf_counter()
        scenes[n] = compiled = compile_scene(scene(free_bodies(n)))
        compile_ms[n] = (time.perf_counter() - started) * 1e3
        runners: dict[str, Runner] = {"numpy tutorial step": numpy_runner(compiled)}
        for name in names:
            runners[f"{name}: chunk"] = chunk_runner(compiled, name)
            runners[f"{name}: runner"] = runner_runner(compiled, name)
        if "mujoco" in engines:
            mj, how = mujoco_runners(compiled)
            runners.update(mj)
            notes.append(f"MuJoCo model of N = {n:,} {how}")
        if "pybullet" in engines:
            make, how = pybullet_runner(compiled)
            runners["PyBullet stepSimulation loop"] = make
            notes.append(f"PyBullet N = {n:,} {how}")
        results[n] = measure(runners, repeats, budget)
    reference = {n: mujoco_reference(results[n], n) for n in SIZES}
    rows = [[label] + [cell(results[n][label], n, reference[n][0]) for n in SIZES] for label in results[SIZES[0]]]
    rep.table("Free bodies under gravity, no contact: body-steps/s (ratio to the faster MuJoCo timing)",
              ["engine / path"] + [f"N = {n:,}" for n in SIZES], rows)  # fmt: skip
    for n in SIZES:
        rep.say(f"- N = {n:,}: MuJoCo reference = {reference[n][1]}; the scene compile that `rbcli.simulate` adds "
                f"to the runner row: {compile_ms[n]:.0f} ms")  # fmt: skip
    everything = [(n, label, t) for n in SIZES for label, t in results[n].items()]
    short = [f"{label} at N = {n:,}: {t.steps}" for n, label, t in everything if 0 < t.steps < STEPS]
    if short:
        rep.say("- steps per run where fewer than 1,000: " + "; ".join(short))
    for n, label, t in everything:
        if t.note:
            rep.say(f"- failed: {label} at N = {n:,}: {t.note}")
    spread = max((t.median / t.best for _, _, t in everything if not t.note), default=1.0)
    rep.say(f"- noise: the largest median/best ratio of any row is {spread:.2f}")
    warm = [f"{name} {results[1][f'{name}: chunk'].warm:.2f} s" for name in names]
    rep.say("- first call (compile, or load from numba's cache): " + ", ".join(warm))
    if notes:
        rep.say("- set-up: " + "; ".join(notes))
    rep.say("- issue anchors (2-core machine, not measured here), N = 1 / 100 / 10,000: "
            + "; ".join(f"{k} {' / '.join(v)}" for k, v in ISSUE_ANCHORS.items()))  # fmt: skip
    rep.say()

    rows, facts = [], {"compile_us_per_body": compile_ms[10_000] / 10_000 * 1e3}
    split = {n: results[n].get("split2: chunk") for n in SIZES}
    for name in names:
        t = {n: results[n][f"{name}: chunk"] for n in SIZES}
        if any(v.note for v in t.values()):
            continue
        per_body = (t[10_000].best - t[1].best) / (10_000 - 1)
        rel = " / ".join(f"{t[n].best / split[n].best:.2f}" if split[n] and not split[n].note else "n/a" for n in SIZES)
        dispatch = dispatch_seconds(scenes[1], name)
        rows.append([name, f"{t[1].best * 1e9:.0f} ns", f"{per_body * 1e9:.1f} ns", rel, f"{dispatch * 1e6:.1f} us"])
        if name == "split2":
            runner = results[1]["split2: runner"]
            facts.update(fixed_ns=t[1].best * 1e9, per_body_ns=per_body * 1e9, dispatch_us=dispatch * 1e6,
                         runner_fixed_ms=(runner.best - t[1].best) * runner.steps * 1e3)  # fmt: skip
    rep.table("Cost of the compiled chunk: time per step = fixed + per-body x N",
              ["integrator", "fixed per step (N = 1)", "per body-step (N = 10,000)", "x split2 (N = 1 / 100 / 10,000)",
               "Python call of run_chunk (0 steps)"], rows)  # fmt: skip
    return {"results": results, "reference": {n: r[0] for n, r in reference.items()}, "facts": facts}


def chain_section(rep: Report, names: list[str], repeats: int, budget: float, engines: set[str]) -> None:
    print(f"spring chain of {CHAIN_BODIES:,} bodies ...", flush=True)
    chain = compile_scene(spring_chain(CHAIN_BODIES))
    runners = {f"{name}: chunk": chunk_runner(chain, name) for name in names}
    if "mujoco" in engines:
        runners["MuJoCo mj_step(nstep), spatial tendons"] = mujoco_runners(chain)[0]["MuJoCo mj_step(nstep)"]
    timings = measure(runners, repeats, budget)
    reference = mujoco_reference(timings, CHAIN_BODIES)[0]
    rows = [[label, cell(t, CHAIN_BODIES, reference), f"{t.best * 1e6:.0f} us"] for label, t in timings.items()]
    rep.table(f"Spring chain: {CHAIN_BODIES:,} bodies, {CHAIN_BODIES - 1:,} springs-dampers + 1 anchor, gravity",
              ["engine / path", "body-steps/s (ratio to MuJoCo)", "time per step"], rows)  # fmt: skip


def recording_section(rep: Report, quick: bool, out: Path) -> dict[str, float]:
    """Recording every step against none; memory at two run lengths. Returns the overheads and memory."""
    print(f"recording {RECORD_BODIES:,} bodies ...", flush=True)
    compiled = compile_scene(scene(free_bodies(RECORD_BODIES, seed=2)))
    steps = 200 if quick else STEPS
    timings = measure(recording_runs(compiled, out), 1 if quick else 3, float("inf"), max_steps=steps)
    off = timings["off (frame 0 and last)"]
    files = {"zstd": out / "bench.mcap", "uncompressed": out / "bench-raw.mcap", ".rrd": out / "bench.rrd"}
    rows, overhead = [], {}
    for label, t in timings.items():
        if t.note:
            rows.append([label, f"failed: {t.note}", "", "", ""])
            continue
        overhead[label] = t.best / off.best - 1.0
        path = next((p for key, p in files.items() if key in label), None)
        size = f"{path.stat().st_size / 1e6:.1f} MB" if path is not None and path.exists() else ""
        rows.append([label, f"{t.best * t.steps * 1e3:.0f} ms", f"+{overhead[label]:.0%}",
                     f"{(t.best - off.best) * 1e6:.0f} us", size])  # fmt: skip
    # the exact state record alone: 19 float64 per body per frame (position, quaternion, v, omega, P, L)
    state_bytes = 19 * 8 * RECORD_BODIES
    floor = write_floor(steps, state_bytes, out) / steps
    rows.append([f"floor: write {state_bytes / 1e3:.0f} kB of ready bytes per frame (the float64 state alone)",
                 f"{floor * steps * 1e3:.0f} ms", f"+{floor / off.best:.0%}", f"{floor * 1e6:.0f} us", ""])  # fmt: skip
    rep.table(f"Recording: {RECORD_BODIES:,} bodies x {steps:,} steps, split2, runner path, every step",
              ["sink", "wall time", "vs off", "cost per frame", "file"], rows)  # fmt: skip
    rep.say(f"- one step costs {off.best * 1e6:.0f} us here; +{TARGET_RECORDING_OVERHEAD:.0%} leaves "
            f"{TARGET_RECORDING_OVERHEAD * off.best * 1e6:.0f} us per frame for a recording that must carry at least "
            f"{state_bytes / 1e3:.0f} kB (MCAP: also /tf, ~100 kB); `thread` rows overlap it with the integration "
            f"on a second core ({os.cpu_count()} here).")  # fmt: skip
    lengths = (100, 400) if quick else (500, 2000)
    try:
        memory = [peak_memory(compiled, s, out) for s in lengths]
    except Exception as exc:  # noqa: BLE001 - a failing sink is reported, not fatal
        memory = [float("nan")] * 2
        rep.say(f"- memory: failed: {type(exc).__name__}: {exc}")
    rep.say(f"- memory: peak traced allocations recording {RECORD_BODIES:,} bodies to .mcap every step: "
            f"{memory[0]:.1f} MB over {lengths[0]:,} steps, {memory[1]:.1f} MB over {lengths[1]:,} steps")  # fmt: skip
    rep.say()
    return {"overhead": overhead, "memory": memory}


def targets_section(rep: Report, names: list[str], free: dict, recording: dict, startup: dict[str, float]) -> None:
    results, reference = free["results"], free["reference"]
    rows = []
    for path in ("chunk", "runner"):
        t = {n: results[n].get(f"split2: {path}") for n in SIZES}
        if any(v is None or v.note for v in t.values()):
            continue
        for n in SIZES:
            unit, rate = ("steps/s" if n == 1 else "body-steps/s"), t[n].rate(n)
            rows.append([f"split2 {path}, N = {n:,}: >= {TARGET_RATE[n]:.0e} {unit}", f"{rate:.2e}",
                         ok(rate >= TARGET_RATE[n])])  # fmt: skip
        if all(np.isfinite(reference[n]) for n in SIZES):
            ratios = [t[n].rate(n) / reference[n] for n in SIZES]
            rows.append([f"split2 {path} faster than MuJoCo at N = 1 / 100 / 10,000",
                         " / ".join(f"{r:.2f}x" for r in ratios), ok(min(ratios) > 1.0)])  # fmt: skip
    if {"rk4", "split2"} <= set(names) and not any(results[n]["rk4: chunk"].note for n in SIZES):
        costs = [results[n]["rk4: chunk"].best / results[n]["split2: chunk"].best for n in SIZES]
        rows.append([f"rk4 cost per step <= {TARGET_RK4_COST}x split2 (chunk, N = 1 / 100 / 10,000)",
                     " / ".join(f"{c:.2f}x" for c in costs), ok(max(costs) <= TARGET_RK4_COST)])  # fmt: skip
    for fmt in (".mcap (SinkMcap, zstd), thread", ".rrd (SinkRerun), thread"):
        if fmt in recording["overhead"]:
            extra = recording["overhead"][fmt]
            rows.append([f"recording every step adds <= {TARGET_RECORDING_OVERHEAD:.0%} ({RECORD_BODIES:,} bodies, "
                         f"{fmt.split(' ')[0]})", f"+{extra:.0%}", ok(extra <= TARGET_RECORDING_OVERHEAD)])  # fmt: skip
    short, long = recording["memory"]
    rows.append(["memory flat in the number of steps (peak traced, short / 4x longer run)",
                 f"{short:.1f} / {long:.1f} MB", ok(long <= 1.1 * short + 1.0)])  # fmt: skip
    for label, seconds in startup.items():
        rows.append(
            [f"`{label}` < {TARGET_STARTUP[label]:g} s", f"{seconds:.2f} s", ok(seconds < TARGET_STARTUP[label])]
        )
    rep.table("Targets of the issue", ["target", "measured", "status"], rows)
    facts = free["facts"]
    if {"fixed_ns", "per_body_ns"} <= facts.keys():
        rep.say(f"- reading: split2 costs {facts['fixed_ns']:.0f} ns per step at N = 1 and {facts['per_body_ns']:.0f} "
                f"ns per body-step at N = 10,000; a Python call of `run_chunk` {facts['dispatch_us']:.0f} us (once "
                f"per runner chunk of ~0.2 s); the runner adds {facts['runner_fixed_ms']:.1f} ms per run at N = 1; "
                f"compiling a scene costs {facts['compile_us_per_body']:.0f} us per body. Why, and what to change: "
                "below.")  # fmt: skip


def write_docs(lines: list[str]) -> Path:
    """Replace the results block of docs/performance.md (between the markers) with this run's report;
    the prose around it is kept. A missing file or marker gets a minimal file."""
    path = ROOT / "docs" / "performance.md"
    block = f"{DOCS_BEGIN}\n" + "\n".join(lines) + f"\n{DOCS_END}"
    text = path.read_text() if path.exists() else ""
    if DOCS_BEGIN in text and DOCS_END in text:
        text = text[: text.index(DOCS_BEGIN)] + block + text[text.index(DOCS_END) + len(DOCS_END) :]
    else:
        text = "# Performance\n\nRegenerated by `python benchmarks/bench_speed.py --write-docs`.\n\n" + block + "\n"
    path.write_text(text)
    return path


DOCS_BEGIN = "<!-- bench_speed results: begin (regenerated by --write-docs; edit around, not inside) -->"
DOCS_END = "<!-- bench_speed results: end -->"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repeats, shorter runs (under ~60 s)")
    parser.add_argument("--write-docs", action="store_true", help="write the results into docs/performance.md")
    parser.add_argument("--integrators", default="", help="comma list [default: quick: " + ",".join(MAIN_INTEGRATORS)
                        + "; full: every registered integrator with a run_chunk]")  # fmt: skip
    parser.add_argument("--no-pybullet", action="store_true")
    parser.add_argument("--sections", default="free,chain,recording,startup,contact",
                        help="comma list of sections to run [default: all]; --write-docs needs all")  # fmt: skip
    args = parser.parse_args()
    sections = set(args.sections.split(","))
    if args.write_docs and sections != {"free", "chain", "recording", "startup", "contact"}:
        parser.error("--write-docs needs every section")

    repeats, budget = (3, 0.15) if args.quick else (7, 1.0)
    every = list(INTEGRATORS)
    names = [n for n in args.integrators.split(",") if n] or (list(MAIN_INTEGRATORS) if args.quick else every)
    info, rep = machine(), Report()
    rep.say(f"- date: {info['date']}; mode: {'--quick' if args.quick else 'full'}")
    rep.say(f"- machine: {info['cpu']}; {info['load']} at start")
    rep.say(f"- {info['versions']}")
    rep.say(f"- timing: best of {repeats} interleaved repeats, {STEPS:,} steps (fewer where one run would pass "
            f"{budget:g} s, listed below), dt = {DT:g} s, after a warm-up run")  # fmt: skip
    engines = set()
    for engine, missing in (("mujoco", "**MuJoCo is not installed** (`pip install -e .[bench]`): no MuJoCo rows "
                                       "or ratios"),
                            ("pybullet", "PyBullet is not installed (optional): no PyBullet row")):  # fmt: skip
        try:
            __import__(engine)
            engines.add(engine)
        except ImportError:
            rep.say(f"- {missing}")
    if args.no_pybullet:
        engines.discard("pybullet")
    rep.say()

    free = free_body_section(rep, names, repeats, budget, engines) if "free" in sections else None
    if "chain" in sections:
        chain_section(rep, names, repeats, budget, engines)
    if "contact" in sections:  # the collisions issue's 1,000-ball pile (benchmarks/bench_contact.py)
        from bench_contact import pile_section

        for line in pile_section(args.quick, "mujoco" in engines, big=False):
            rep.say(line)
    out = Path(tempfile.mkdtemp(prefix="rbsim-bench-speed-"))
    try:
        recording = recording_section(rep, args.quick, out) if "recording" in sections else None
        startup = None
        if "startup" in sections:
            print("start-up ...", flush=True)
            startup = startup_times(out)
    finally:
        shutil.rmtree(out, ignore_errors=True)
    if free is not None and recording is not None and startup is not None:
        targets_section(rep, names, free, recording, startup)
    rep.say(f"- {machine()['load']} at the end")
    if args.write_docs:
        print(f"wrote {write_docs(rep.lines)}")


if __name__ == "__main__":
    main()
