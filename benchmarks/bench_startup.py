"""Start-up of `rbsim run`: whole-process wall time against a MuJoCo script, and the first run.

    python benchmarks/bench_startup.py [--repeats 7] [--steps 100000] [--integrator NAME] [--no-cold]
    python benchmarks/bench_startup.py --cold [--integrators all|NAME,...] [--top 8] [--json FILE]

`--cold` measures first runs per kind of scene instead (benchmarks/startup_kinds.py: free bodies,
forces, contact, joints, joints with contact, each integrator; every compiled function with its types
and compile time from numba's event API; warm; the kinds one after another in one cache).

Every number is a whole process, from before the fork to after the exit: interpreter start, imports,
numba's cache (or compiler), the steps and the output file. In a temporary folder:
  (a) warm cache: `rbsim run one.yaml -o out.mcap -q` of one free body (one particle, gravity) for
      `--steps` steps of dt = 1 ms, recording only the first and the last state (`record.every` =
      steps, streams [bodies], uncompressed .mcap: the least output the CLI allows), against a Python
      script that builds the same body in MuJoCo (free joint, sphere of the same mass, Euler, same dt)
      and calls `mj_step` `--steps` times in a Python loop; `python -c pass` is the floor. One
      unmeasured run of each first (numba's cache filled, the OS file cache warm), then `--repeats`
      rounds, the commands interleaved and their order alternated between rounds so that a change of
      machine load hits them alike; medians, and the ratio of the medians. Skipped rows for MuJoCo
      when it is not installed (`pip install -e .[bench]`). Two floors beside them: `import numpy,
      numba`, and `one kernel`: that import plus one small cached rbcli kernel loaded from numba's
      cache and called (what any run through the cache pays before it does anything).
  (b) first run: the same command with NUMBA_CACHE_DIR a new empty folder (a new machine, as far as
      numba is concerned: every kernel the scene needs is compiled), `--cold-repeats` times.
  (c) where the time goes: the same run in a driver that wraps the CLI's phases (import, parse,
      prepare, kernel load, run, exit) with wall-clock marks, warm (median of 3) and with an empty
      cache; and `python -X importtime` of the warm run summed per top-level package (the modules
      numba imports when it loads its first kernel count as imports there).
The machine is shared and small (2 cores): look at the spread printed beside each median.
NUMBA_CACHE_DIR, when set, is the warm cache used for (a) and (c).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DT = 1e-3
TARGET_RATIO = 1.3  # tracker issue 16, item 5: warm whole process <= 1.3x the MuJoCo script
TARGET_FIRST_RUN = 8.0  # seconds, empty numba cache, 2-core machine

SCENE = """\
name: startup
simulation:
  dt: {dt}
  steps: {steps}
{integrator}  record: {{every: {steps}, streams: [bodies], compression: none}}
gravity: [0, 0, -9.81]
bodies:
  - name: ball
    particles: {{positions: [[0, 0, 0]], masses: 1.0, radius: 0.05}}
    position: [0, 0, 1]
    velocity: [0.5, 0, 4.0]
    angular_momentum: [0.0002, 0.0005, 0.0001]
"""

MUJOCO_SCRIPT = """\
import sys
import mujoco
steps, dt = int(sys.argv[1]), float(sys.argv[2])
xml = f'''<mujoco><option timestep="{dt}" integrator="Euler" gravity="0 0 -9.81"/>
<worldbody><body pos="0 0 1"><freejoint/>
<geom type="sphere" size="0.05" mass="1" contype="0" conaffinity="0"/></body></worldbody></mujoco>'''
m = mujoco.MjModel.from_xml_string(xml)
d = mujoco.MjData(m)
d.qvel[:3] = (0.5, 0.0, 4.0)
step = mujoco.mj_step
for _ in range(steps):
    step(m, d)
print(d.time, *d.qpos[:3])
"""

# The floor of any run through numba's cache: the interpreter, numpy and numba, and one small cached rbcli
# kernel (the divergence check) loaded and called on one body's state, then the same exit as `rbsim run`.
ONE_KERNEL = """\
import os
import numpy as np
from rbcli.physics.step import state_is_sane
assert state_is_sane(np.zeros((1, 3)), np.ones((1, 4)), np.zeros((1, 3)), np.zeros((1, 3)))
os._exit(0)
"""

# Runs the real CLI (`rbcli.cli.app.main`, which may end the process itself) with wall-clock marks at
# the entry and exit of the functions it calls (rbcli.api.prepare, rbcli.runner.simulation.warm_up,
# rbcli.api.run_to_file); its first atexit handler, so the last to run, prints the marks as JSON on
# stdout. It imports rbcli.api and rbcli.runner.loop itself before the CLI runs, to wrap them.
DRIVER = """\
import atexit, json, sys, time
marks = [["interpreter start (fork, exec, site)", time.time()]]
def mark(label):
    marks.append([label, time.time()])
def report():
    mark("the rest of the command, its threads and atexit handlers")
    print(json.dumps(marks), flush=True)
atexit.register(report)
import rbcli.cli.app
mark("import rbcli.cli.app (typer, the command modules)")
import rbcli.api, rbcli.runner.loop, rbcli.runner.simulation
mark("import rbcli.api, rbcli.runner.loop (numpy, numba, scene, record, runner)")
def wrap(module, name, before, during):
    inner = getattr(module, name)
    def wrapped(*args, **kwargs):
        mark(before)
        try:
            return inner(*args, **kwargs)
        finally:
            mark(during)
    setattr(module, name, wrapped)
wrap(rbcli.api, "prepare", "typer: parse the command line, rich", "prepare: read, validate, compile the scene")
wrap(rbcli.runner.simulation, "warm_up", "check the output", "warm_up: load (or compile) the kernels, first step")
wrap(rbcli.api, "run_to_file", "between", "run_to_file: the steps, the sink's imports, the .mcap")
sys.argv = ["rbsim", "run", *sys.argv[1:]]
rbcli.cli.app.main()
"""


def rbsim_command() -> list[str]:
    """The console script beside this interpreter (as a user runs it), else `python -m rbcli`."""
    script = Path(sys.executable).with_name("rbsim")
    return [str(script)] if script.exists() else [sys.executable, "-m", "rbcli"]


def environment(cache: str | None = None) -> dict[str, str]:
    """This checkout first on the path (whatever is installed); NUMBA_CACHE_DIR = cache when given.
    Python writes and reuses its bytecode caches (.pyc), as on a user's machine (pip writes them for an
    installed package): with PYTHONDONTWRITEBYTECODE set, as in some shells, every run would compile
    rbcli's ~90 modules from source (~0.1-0.3 s) while the MuJoCo script's packages have theirs."""
    env = dict(os.environ)
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), *filter(None, [env.get("PYTHONPATH")])])
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = cache
    return env


def timed(cmd: list[str], cwd: Path, env: dict[str, str]) -> tuple[float, subprocess.CompletedProcess]:
    """Wall seconds of one process, fork to exit."""
    started = time.perf_counter()
    out = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - started
    if out.returncode != 0:
        raise SystemExit(f"failed ({out.returncode}): {' '.join(cmd)}\n{out.stdout}\n{out.stderr}")
    return elapsed, out


def spread(samples: list[float]) -> str:
    middle = statistics.median(samples)
    return f"median {middle:.3f} s (min {min(samples):.3f}, max {max(samples):.3f}, n = {len(samples)})"


def phases(args: list[str], cwd: Path, env: dict[str, str]) -> list[tuple[str, float]]:
    """(phase, seconds) of one driver run, the last phase being the interpreter's exit."""
    started = time.time()
    _, out = timed([sys.executable, "-c", DRIVER, *args], cwd, env)
    ended = time.time()
    marks = json.loads(out.stdout.strip().splitlines()[-1])
    times = [started] + [t for _, t in marks] + [ended]
    labels = [label for label, _ in marks] + ["exit: the interpreter's teardown (when not skipped)"]
    return [(label, times[i + 1] - times[i]) for i, label in enumerate(labels)]


def print_phases(runs: list[list[tuple[str, float]]]) -> None:
    labels = [label for label, _ in runs[0]]
    medians = [statistics.median(run[i][1] for run in runs) for i in range(len(labels))]
    total = sum(medians)
    for label, seconds in zip(labels, medians, strict=True):
        print(f"  {seconds:7.3f} s  {100 * seconds / total:4.0f}%  {label}")
    print(f"  {total:7.3f} s        total (sum of the medians)")


def importtime_summary(cmd: list[str], cwd: Path, env: dict[str, str], top: int = 12) -> None:
    """`python -X importtime` of the command: self time summed per top-level package."""
    out = subprocess.run([sys.executable, "-X", "importtime", *cmd], cwd=cwd, env=env, capture_output=True, text=True)
    per_package: dict[str, float] = defaultdict(float)
    for line in out.stderr.splitlines():
        if not line.startswith("import time:") or "self [us]" in line:
            continue
        self_us, _, name = (part.strip() for part in line[len("import time:") :].split("|"))
        per_package[name.split(".")[0]] += int(self_us) / 1e6
    total = sum(per_package.values())
    print(f"  imports: {total:.3f} s in all (under -X importtime, which adds its own overhead); the largest:")
    for name, seconds in sorted(per_package.items(), key=lambda kv: -kv[1])[:top]:
        print(f"  {seconds:7.3f} s  {name}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeats", type=int, default=7, help="interleaved rounds of the warm runs")
    parser.add_argument("--steps", type=int, default=100_000)
    parser.add_argument("--integrator", default=None, help="default: the scene format's default (euler-matrix)")
    parser.add_argument("--cold-repeats", type=int, default=1, help="first runs, each with a new empty cache")
    parser.add_argument("--no-cold", action="store_true", help="skip the first-run measurements")
    parser.add_argument("--cold", action="store_true", help="first runs per kind of scene (startup_kinds.py)")
    parser.add_argument("--integrators", default="all", help="with --cold: free-body rows per integrator")
    parser.add_argument("--top", type=int, default=8, help="with --cold: functions listed per kind")
    parser.add_argument("--json", type=Path, default=None, help="with --cold: every record, as JSON")
    parser.add_argument("--only", default="", help="with --cold: the kinds whose label contains this")
    args = parser.parse_args()
    if args.cold:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import startup_kinds

        from rbcli.physics.integrators import INTEGRATORS

        names = list(INTEGRATORS) if args.integrators == "all" else [n for n in args.integrators.split(",") if n]
        startup_kinds.measure(names, args.top, args.json, args.only)
        return

    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    print(f"python {platform.python_version()}, {os.cpu_count()} logical cores, load average "
          f"{load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; tree {ROOT}")  # fmt: skip
    have_mujoco = importlib.util.find_spec("mujoco") is not None
    with tempfile.TemporaryDirectory(prefix="rbsim-startup-") as tmp:
        work = Path(tmp)
        integrator = f"  integrator: {args.integrator}\n" if args.integrator else ""
        (work / "one.yaml").write_text(SCENE.format(dt=DT, steps=args.steps, integrator=integrator))
        (work / "mujoco_one.py").write_text(MUJOCO_SCRIPT)
        run_args = ["one.yaml", "-o", "out.mcap", "-q"]
        env = environment()
        commands = {
            "rbsim run": [*rbsim_command(), "run", *run_args],
            "python -c pass": [sys.executable, "-c", "pass"],
            "import numba": [sys.executable, "-c", "import numpy, numba"],
            "one kernel": [sys.executable, "-c", ONE_KERNEL],
        }
        if have_mujoco:
            commands["MuJoCo script"] = [sys.executable, "mujoco_one.py", str(args.steps), str(DT)]
        else:
            print("MuJoCo row skipped: mujoco is not importable (pip install -e .[bench])")

        print(f"\n(a) warm cache, whole process, {args.steps:,} steps of one body, dt = {DT:g} s "
              f"({args.repeats} interleaved rounds after one unmeasured run of each)")  # fmt: skip
        for cmd in commands.values():
            timed(cmd, work, env)
        samples: dict[str, list[float]] = {label: [] for label in commands}
        for round_ in range(args.repeats):
            order = list(commands) if round_ % 2 == 0 else list(reversed(commands))
            for label in order:
                samples[label].append(timed(commands[label], work, env)[0])
        for label, values in samples.items():
            print(f"  {label:16s} {spread(values)}")
        if have_mujoco:
            ratio = statistics.median(samples["rbsim run"]) / statistics.median(samples["MuJoCo script"])
            verdict = "met" if ratio <= TARGET_RATIO else "missed"
            print(f"  ratio rbsim / MuJoCo (medians): {ratio:.2f}x (target <= {TARGET_RATIO:g}x: {verdict})")
            floor = statistics.median(samples["one kernel"]) / statistics.median(samples["MuJoCo script"])
            print(f"  ratio one kernel / MuJoCo (the floor of any run through numba's cache): {floor:.2f}x")

        print("\n(c) warm run, by phase (driver around the CLI, median of 3):")
        print_phases([phases(run_args, work, env) for _ in range(3)])
        importtime_summary(["-m", "rbcli", "run", *run_args], work, env)

        if not args.no_cold:
            print(f"\n(b) first run: empty NUMBA_CACHE_DIR, whole process ({args.cold_repeats} run(s))")
            cold = []
            for _ in range(args.cold_repeats):
                with tempfile.TemporaryDirectory(prefix="rbsim-numba-") as cache:
                    cold.append(timed(commands["rbsim run"], work, environment(cache))[0])
            verdict = "met" if statistics.median(cold) < TARGET_FIRST_RUN else "missed"
            print(f"  rbsim run        {spread(cold)} (target < {TARGET_FIRST_RUN:g} s: {verdict})")
            print("  by phase (driver, its own empty cache):")
            with tempfile.TemporaryDirectory(prefix="rbsim-numba-") as cache:
                print_phases([phases(run_args, work, environment(cache))])


if __name__ == "__main__":
    main()
