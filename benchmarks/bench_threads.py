"""The threaded step (issues 28 and 45) against the serial one and MuJoCo, idle and under a load.

    python benchmarks/bench_threads.py [--quick] [--repeats N] [--load | --one-thread]

`Simulation.step` of split2 on 1 thread (`threads=1`: the serial loop), on every core (`threads="all"`:
the threaded loop, fixed) and on the default (auto: runner/governor.py chooses 1 or every core per slice
by measured speed), body-steps per wall second, median of the repeats, interleaved so a change of
machine load hits each alike. Each row says whether the runs ended bitwise equal (they must), and the
header the machine's load average (other jobs on the machine count: say it beside the numbers).
Idle table: free bodies under gravity (bench_speed's bodies) at N = 100, 300, 1,000, 10,000, beside
  MuJoCo Euler (bench_speed's model, `mj_step(nstep)`, on one core, only if mujoco is installed);
  bench_speed's spring chain of 1,000 bodies; scenes/contact/sphere_pile.yaml (1,000 balls, contact).
--load adds the loaded table: 10,000 free bodies, the pile and a 400-link hinge chain (bench_joints'
  capsule chain) under a load this benchmark makes on the same cores: "twin", a second process
  stepping the same scene with the default threads (a second `rbsim run`), and "busy", two Python
  busy loops. Target (issue 45): the default >= 0.8x of one thread under any load.
--one-thread: each scene's threaded variant run on one thread (as the governor's one-thread slices run
  it) against the serial loop, CPU time per step.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_joints  # noqa: E402
import bench_speed  # noqa: E402

from rbcli.runner.simulation import Simulation  # noqa: E402
from rbcli.runner.threads import PARALLEL_MIN_BODIES, available_cores  # noqa: E402
from rbcli.scene.compile import CompiledScene, compile_scene  # noqa: E402
from rbcli.scene.load import load_scene  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LOADED_SCENES = ("free bodies N = 10,000", "sphere pile N = 1,000", "hinge chain N = 400")
VARIANTS = ("1 thread", "auto", "all")  # threads=1, the default, threads="all"


def scene_named(name: str) -> tuple[CompiledScene, int]:
    """(compiled scene, bodies) of a row's scene."""
    if name.startswith("free bodies"):
        n = int(name.split("=")[1].replace(",", ""))
        return compile_scene(bench_speed.scene(bench_speed.free_bodies(n))), n
    if name.startswith("spring chain"):
        return compile_scene(bench_speed.spring_chain(1_000)), 1_000
    if name.startswith("sphere pile"):
        return compile_scene(load_scene(ROOT / "scenes" / "contact" / "sphere_pile.yaml")), 1_000
    if name.startswith("hinge chain"):
        path = Path(tempfile.mkdtemp()) / "chain.yaml"
        path.write_text(bench_joints.chain_scene_yaml(400, "hinge", duration=1e4 * bench_joints.DT))
        return compile_scene(load_scene(path)), 400
    raise KeyError(name)


def load_average() -> str:
    return " ".join(f"{v:.2f}" for v in os.getloadavg())


def measure(compiled: CompiledScene, seconds: float, repeats: int) -> dict[str, object]:
    """Wall seconds per step of each variant (medians of interleaved rounds), whether they ended bitwise
    equal, and the auto run's report."""
    sims = {"1 thread": Simulation(compiled, threads=1), "auto": Simulation(compiled),
            "all": Simulation(compiled, threads="all")}  # fmt: skip
    for sim in sims.values():
        sim.step(2)  # kernels loaded, threads launched
    started = time.perf_counter()
    sims["1 thread"].step(5)
    steps = max(5, int(seconds * 5 / max(time.perf_counter() - started, 1e-9)))
    for name in ("auto", "all"):
        sims[name].step(5)
    per_step: dict[str, list[float]] = {name: [] for name in VARIANTS}
    for _ in range(repeats):
        for name in VARIANTS:
            started = time.perf_counter()
            sims[name].step(steps)
            per_step[name].append((time.perf_counter() - started) / steps)
    first = sims["1 thread"].data.state
    same = all(np.array_equal(getattr(first, k), getattr(sim.data.state, k)) for sim in sims.values() for k in "xqPL")
    return {
        "median": {name: statistics.median(v) for name, v in per_step.items()},
        "same": same,
        "report": sims["auto"].threads_report(),
        "most": max(sims["all"].threads, sims["all"].contact_threads),
    }


def choice(result: dict[str, object]) -> str:
    """The auto run's report without its reason: '2 threads for 93 % of 12,000 steps, 3 switches'."""
    return str(result["report"]).removeprefix("threads: ").split(" (")[0]


def idle_table(quick: bool, repeats: int) -> None:
    try:
        import mujoco  # noqa: F401

        have_mujoco = True
    except ImportError:
        have_mujoco = False
    print(f"\nIdle (no load made by the benchmark): body-steps/s, median of {repeats}; load average {load_average()}")
    print("| scene | 1 thread | auto (default) | all cores | auto / 1 | all / 1 | bitwise | auto's choice | MuJoCo |")
    print("|---|---|---|---|---|---|---|---|---|")
    rows = [f"free bodies N = {n:,}" for n in (100, 300, 1_000, 10_000)]
    rows += ["spring chain N = 1,000", "sphere pile N = 1,000"]
    for name in rows:
        compiled, bodies = scene_named(name)
        r = measure(compiled, 0.2 if quick else 0.5, repeats)
        rate = {k: bodies / v for k, v in r["median"].items()}  # type: ignore[attr-defined]
        mj = ""
        if have_mujoco and name.startswith("free"):
            runners, _ = bench_speed.mujoco_runners(compiled)
            run = runners["MuJoCo mj_step(nstep)"](1000)
            run()
            mj_rate = bodies * 1000 / min(run() for _ in range(repeats))
            mj = f"{mj_rate:.3g} (rbsim auto {rate['auto'] / mj_rate:.1f}x)"
        print(
            f"| {name} | {rate['1 thread']:.3g} | {rate['auto']:.3g} | {rate['all']:.3g} | "
            f"{rate['auto'] / rate['1 thread']:.2f}x | {rate['all'] / rate['1 thread']:.2f}x | "
            f"{'yes' if r['same'] else 'NO'} | {choice(r)} | {mj} |",
            flush=True,
        )


def one_thread_table(quick: bool, repeats: int) -> None:
    """The threaded variant of each scene's step run on one thread (as the governor's one-thread slices
    run it) against the serial loop: CPU us per step, best of the interleaved rounds, the two runs stepping
    the same states in lockstep (bitwise equal: checked)."""
    import numba

    print(f"\nThreaded variants on one thread: CPU us per step, best of {repeats}; load average {load_average()}")
    print("| scene | serial loop | threaded variant on 1 thread | threaded / serial | bitwise |")
    print("|---|---|---|---|---|")
    for name in ("free bodies N = 10,000", "spring chain N = 1,000", "sphere pile N = 1,000"):
        compiled, _ = scene_named(name)
        serial, threaded = Simulation(compiled, threads=1), Simulation(compiled, threads="all")
        steps = 20 if quick else 60

        def chunk(sim: Simulation, n: int) -> float:
            started = time.process_time()
            sim._run_chunk(sim.data.state.step, n, 2**62, sim._no_frames, 0)  # no governor: as given
            sim.data.state.step += n
            return (time.process_time() - started) / n

        best = {"serial": float("inf"), "threaded": float("inf")}
        numba.set_num_threads(1)
        try:
            chunk(serial, 2), chunk(threaded, 2)  # loaded, the pool started
            for _ in range(repeats):
                best["serial"] = min(best["serial"], chunk(serial, steps))
                best["threaded"] = min(best["threaded"], chunk(threaded, steps))
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        same = all(np.array_equal(getattr(serial.data.state, k), getattr(threaded.data.state, k)) for k in "xqPL")
        print(f"| {name} | {best['serial'] * 1e6:.1f} | {best['threaded'] * 1e6:.1f} | "
              f"{best['threaded'] / best['serial']:.3f} | {'yes' if same else 'NO'} |", flush=True)  # fmt: skip


def start_load(load: str, scene: str) -> list[subprocess.Popen]:
    if load == "none":
        return []
    if load == "busy":
        return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    twin = subprocess.Popen([sys.executable, __file__, "--twin", scene], stdout=subprocess.PIPE, text=True)
    assert twin.stdout is not None
    twin.stdout.readline()  # "ready": its kernels loaded and stepping
    return [twin]


def twin(scene: str) -> None:
    """A second run on the same cores: the same scene stepped with the default threads until killed."""
    compiled, _ = scene_named(scene)
    sim = Simulation(compiled)
    sim.step(2)
    print("ready", flush=True)
    while True:
        sim.step(100)


def loaded_table(quick: bool, repeats: int) -> None:
    print(f"\nLoaded (the load made by the benchmark on the same {available_cores()} cores): "
          f"rates relative to 1 thread, median of {repeats} interleaved rounds")  # fmt: skip
    print("| scene | load | 1 thread (body-steps/s) | auto / 1 | all / 1 | bitwise | auto's choice | load average |")
    print("|---|---|---|---|---|---|---|---|")
    for name in LOADED_SCENES:
        compiled, bodies = scene_named(name)
        for load in ("none", "twin", "busy"):
            others = start_load(load, name)
            try:
                r = measure(compiled, 0.25 if quick else 0.5, repeats)
            finally:
                for process in others:
                    process.kill()
                    process.wait()
            m = r["median"]  # type: ignore[index]
            print(
                f"| {name} | {load} | {bodies / m['1 thread']:.3g} | {m['1 thread'] / m['auto']:.2f}x | "
                f"{m['1 thread'] / m['all']:.2f}x | {'yes' if r['same'] else 'NO'} | "
                f"{choice(r)} | {load_average()} |",
                flush=True,
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter rounds, fewer repeats")
    parser.add_argument("--repeats", type=int, default=None)
    parser.add_argument("--load", action="store_true", help="also the table under a load the benchmark makes")
    parser.add_argument("--only-load", action="store_true", help="only the loaded table")
    parser.add_argument("--one-thread", action="store_true",
                        help="only the threaded variants on one thread against the serial loop")  # fmt: skip
    parser.add_argument("--twin", help=argparse.SUPPRESS)
    options = parser.parse_args()
    if options.twin:
        twin(options.twin)
        return
    repeats = options.repeats or (3 if options.quick else 5)
    print(f"threads: {available_cores()} cores; threaded loop from {PARALLEL_MIN_BODIES} bodies; "
          f"GOMP_SPINCOUNT={os.environ.get('GOMP_SPINCOUNT', '(rbsim sets it at the first threaded run)')}; "
          f"load average {load_average()}")  # fmt: skip
    if options.one_thread:
        one_thread_table(options.quick, repeats)
        return
    if not options.only_load:
        idle_table(options.quick, repeats)
    if options.load or options.only_load:
        loaded_table(options.quick, repeats)


if __name__ == "__main__":
    main()
