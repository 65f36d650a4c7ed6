"""numba's fork/join under a competing load: why a threaded step can lose to one thread (issue 45).

    python benchmarks/bench_forkjoin.py [--quick] [--configs omp,omp-passive,...] [--loads none,busy,twin]

A compiled loop of `reps` rounds, each round one parallel region (a `prange` over `n` elements of a
few flops each: the fork and the join) followed by `serial` elements of serial work (the stages a
threaded step runs between its passes), is timed on 1 and on 2 threads, interleaved, median of the
repeats, in a child process per configuration, because the threading layer and libgomp's wait policy
are fixed when the layer loads:
  omp               numba's default here (GNU OpenMP): idle threads spin GOMP_SPINCOUNT = 300,000
                    rounds before they sleep (libgomp's default when OMP_WAIT_POLICY is unset)
  omp-spin<N>       the same with GOMP_SPINCOUNT=N (set before libgomp loads)
  omp-passive       OMP_WAIT_POLICY=PASSIVE: idle threads sleep at once (a futex wake per fork)
  workqueue         numba's own layer: threads sleep on semaphores, no spinning
  tbb               only if numba can load its tbb layer here (libtbb.so.12: the `tbb` pip package,
                    or a copy on LD_LIBRARY_PATH)
under each load, started by this benchmark on the same cores:
  none   nothing
  busy   two Python busy loops (one per core of a 2-core machine)
  twin   a second process running the same rounds on 2 threads with the same configuration
Columns: us per round on 1 and 2 threads, their ratio (> 1: threads win) and the process's CPU
seconds per wall second on 2 threads (2.0 with one thread spinning while the other works serially).
Patterns: "join" (n = 2,000: fork/join cost; serial 2,000), "step" (n = 200,000: a pass over 10,000
bodies' worth of work, serial 20,000).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time

CONFIGS = {
    "omp": {"NUMBA_THREADING_LAYER": "omp"},
    "omp-spin10000": {"NUMBA_THREADING_LAYER": "omp", "GOMP_SPINCOUNT": "10000"},
    "omp-spin1000": {"NUMBA_THREADING_LAYER": "omp", "GOMP_SPINCOUNT": "1000"},
    "omp-passive": {"NUMBA_THREADING_LAYER": "omp", "OMP_WAIT_POLICY": "PASSIVE"},
    "workqueue": {"NUMBA_THREADING_LAYER": "workqueue"},
    "tbb": {"NUMBA_THREADING_LAYER": "tbb"},
}
PATTERNS = {"join": (2_000, 2_000), "step": (200_000, 20_000)}  # (parallel elements, serial elements)
WAIT_VARIABLES = ("NUMBA_THREADING_LAYER", "OMP_WAIT_POLICY", "GOMP_SPINCOUNT")


def _kernel():  # noqa: ANN202
    import numba
    import numpy as np

    @numba.njit(parallel=True, cache=False)
    def rounds(a, b, reps, n, serial):  # noqa: ANN001, ANN202
        for _ in range(reps):
            for i in numba.prange(n):  # one fork and one join
                a[i] = a[i] * 0.999 + 1e-3 * np.sqrt(a[i] + 1.0)
            for i in range(serial):  # the serial stages between passes
                b[i] = b[i] * 0.999 + 1e-3 * np.sqrt(b[i] + 1.0)
        return a[0] + b[0]

    return rounds


def child(pattern: str, seconds: float, repeats: int, forever: bool) -> None:
    """Measure (or, as a twin, run until killed) in this process's configuration; prints JSON."""
    import numba
    import numpy as np

    n, serial = PATTERNS[pattern]
    rounds = _kernel()
    a, b = np.ones(n), np.ones(serial)
    numba.set_num_threads(2)
    rounds(a, b, 1, n, serial)
    layer = numba.threading_layer()
    if forever:
        print("ready", flush=True)
        while True:
            rounds(a, b, 1000, n, serial)
    # rounds per timed run: about `seconds` on each thread count (a loaded 2-thread round can cost 100x)
    reps = {}
    for threads in (1, 2):
        numba.set_num_threads(threads)
        started = time.perf_counter()
        rounds(a, b, 20, n, serial)
        reps[threads] = max(5, int(20 * seconds / max(time.perf_counter() - started, 1e-9)))
    per = {1: [], 2: []}
    cpu = []
    for _ in range(repeats):
        for threads in (1, 2):
            numba.set_num_threads(threads)
            wall, process = time.perf_counter(), time.process_time()
            rounds(a, b, reps[threads], n, serial)
            wall, process = time.perf_counter() - wall, time.process_time() - process
            per[threads].append(wall / reps[threads])
            if threads == 2:
                cpu.append(process / wall)
    print(json.dumps({
        "layer": layer, "one": statistics.median(per[1]), "two": statistics.median(per[2]),
        "cpu": statistics.median(cpu),
    }), flush=True)  # fmt: skip


def _env(config: str) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k not in WAIT_VARIABLES}
    env.update(CONFIGS[config])
    env["NUMBA_NUM_THREADS"] = "2"
    return env


def _start_load(load: str, config: str, pattern: str) -> list[subprocess.Popen]:
    if load == "none":
        return []
    if load == "busy":
        return [subprocess.Popen([sys.executable, "-c", "while True: pass"]) for _ in range(2)]
    twin = subprocess.Popen(
        [sys.executable, __file__, "--child", "--pattern", pattern, "--forever"],
        env=_env(config), stdout=subprocess.PIPE, text=True,
    )  # fmt: skip
    assert twin.stdout is not None
    twin.stdout.readline()  # "ready": compiled and running
    return [twin]


def _stop(processes: list[subprocess.Popen]) -> None:
    for process in processes:
        process.kill()
        process.wait()


def tbb_loadable() -> bool:
    """Whether numba's tbb layer loads in a child process (the `tbb` package has no Python module)."""
    probe = "from numba.np.ufunc import tbbpool"
    return subprocess.run([sys.executable, "-c", probe], capture_output=True).returncode == 0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--forever", action="store_true", help=argparse.SUPPRESS)
    parser.add_argument("--pattern", default="join", choices=sorted(PATTERNS))
    parser.add_argument("--quick", action="store_true", help="shorter runs, fewer repeats")
    parser.add_argument("--configs", default=",".join(CONFIGS))
    parser.add_argument("--loads", default="none,busy,twin")
    parser.add_argument("--patterns", default="join,step")
    options = parser.parse_args()
    seconds, repeats = (0.1, 5) if options.quick else (0.3, 9)
    if options.child:
        child(options.pattern, seconds, repeats, options.forever)
        return
    configs = [c for c in options.configs.split(",") if c != "tbb" or tbb_loadable()]
    if "tbb" in options.configs.split(",") and "tbb" not in configs:
        print("tbb: numba cannot load its tbb layer here (no libtbb.so.12): skipped")
    print(f"{os.cpu_count()} cores; us per round, median of {repeats}, 1 and 2 threads interleaved")
    print(f"{'pattern':7s} {'config':14s} {'layer':9s} {'load':5s} {'1 thread':>9s} {'2 threads':>9s} "
          f"{'2 vs 1':>7s} {'CPU/wall':>8s}  load average")  # fmt: skip
    for pattern in options.patterns.split(","):
        for config in configs:
            for load in options.loads.split(","):
                others = _start_load(load, config, pattern)
                try:
                    out = subprocess.run(
                        [sys.executable, __file__, "--child", "--pattern", pattern]
                        + (["--quick"] if options.quick else []),
                        env=_env(config), capture_output=True, text=True, timeout=600,
                    )  # fmt: skip
                finally:
                    _stop(others)
                if out.returncode:
                    print(f"{pattern:7s} {config:14s} failed: {out.stderr.strip().splitlines()[-1:]}")
                    continue
                r = json.loads(out.stdout.strip().splitlines()[-1])
                avg = os.getloadavg()
                print(f"{pattern:7s} {config:14s} {r['layer']:9s} {load:5s} {1e6 * r['one']:9.1f} "
                      f"{1e6 * r['two']:9.1f} {r['one'] / r['two']:6.2f}x {r['cpu']:8.2f}  "
                      f"{avg[0]:.2f} {avg[1]:.2f} {avg[2]:.2f}", flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
