"""First runs per kind of scene (`bench_startup.py --cold`): where a new user's minutes go.

For each kind of scene (free bodies, forces, contact, joints, joints with contact, and a free body under
each integrator), `rbsim run` of a short scene in a fresh process:
  cold: with NUMBA_CACHE_DIR a new empty folder, the process's CPU time (user + system, from the
        child's rusage) and every function numba compiled, from numba's event API ("numba:compile"
        fires only for real compilations, never for cache loads): its inclusive time (with the callees
        it compiled while typing it) and exclusive time (without them), its argument types, and the
        time spent holding numba's LLVM lock ("numba:llvm_lock": LLVM's optimiser and code generation,
        and printing the IR it parses);
  warm: the same command again on that cache;
  in one cache: every kind one after another, each a new process, in one shared empty cache (the
        second kind pays only for what the first did not compile).
CPU seconds, not wall: the machine is shared and small, and CPU time is what load changes least; the
machine's load average is printed beside the table.
"""

from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

from rbcli.runner.warm import KIND_SCENES, kind_scene

ROOT = Path(__file__).resolve().parents[1]

# Short scenes of each kind; `{integrator}` is filled per row. Durations are a few hundred steps: the
# first run's cost is compiling, and a warm run of each stays well under a second of stepping.
# Short scenes of each kind: the ones `rbsim warm` prepares (rbcli/runner/warm.py)
SCENES = KIND_SCENES

# The child: `rbsim run` in this process with numba's compile and LLVM-lock events recorded; the record
# is written by an atexit hook (`rbsim run` ends the process with os._exit after the atexit handlers).
CHILD = r"""
import atexit, json, os, resource, sys, time
import numba.core.event as ev

stack, compiled, llvm = [], [], [0.0]

class Compiles(ev.Listener):
    def on_start(self, event):
        f = event.data["dispatcher"].py_func
        stack.append([f"{f.__module__}.{f.__qualname__}", str(event.data.get("args")), time.process_time(), 0.0])

    def on_end(self, event):
        name, args, start, nested = stack.pop()
        inclusive = time.process_time() - start
        if stack:
            stack[-1][3] += inclusive
        compiled.append([name, args, inclusive, inclusive - nested])

class LlvmLock(ev.Listener):
    def on_start(self, event):
        self.start = time.process_time()

    def on_end(self, event):
        llvm[0] += time.process_time() - self.start

ev.register("numba:compile", Compiles())
ev.register("numba:llvm_lock", LlvmLock())

def dump():
    usage = resource.getrusage(resource.RUSAGE_SELF)
    with open(os.environ["RBSIM_STARTUP_RECORD"], "w") as out:
        json.dump({"cpu": usage.ru_utime + usage.ru_stime, "compiled": compiled, "llvm": llvm[0]}, out)

atexit.register(dump)
from rbcli.cli.app import main
sys.argv = ["rbsim", "run", *sys.argv[1:]]
main()
"""


@dataclass
class FirstRun:
    """One process's record: CPU seconds, the functions compiled (name, types, inclusive and exclusive
    seconds) and the seconds spent in LLVM."""

    cpu: float
    compiled: list[tuple[str, str, float, float]] = field(default_factory=list)
    llvm: float = 0.0
    returncode: int = 0

    @property
    def compile_seconds(self) -> float:
        return sum(item[3] for item in self.compiled)


def run_scene(scene: Path, cache: Path, workdir: Path) -> FirstRun:
    """`rbsim run scene` in a new process on `cache`; its CPU time and what it compiled."""
    record = workdir / f"{scene.stem}.record.json"
    output = workdir / f"{scene.stem}.mcap"
    output.unlink(missing_ok=True)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "RBSIM_STARTUP_RECORD": str(record)}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    done = subprocess.run([sys.executable, "-c", CHILD, str(scene), "-o", str(output), "-q"], env=env,
                          cwd=workdir, capture_output=True, text=True)  # fmt: skip
    if done.returncode != 0 or not record.exists():
        print(done.stderr[-2000:], file=sys.stderr)
        return FirstRun(cpu=float("nan"), returncode=done.returncode)
    data = json.loads(record.read_text())
    return FirstRun(cpu=data["cpu"], compiled=[tuple(c) for c in data["compiled"]], llvm=data["llvm"])


def kinds(integrators: list[str], only: str = "") -> list[tuple[str, str]]:
    """(label, scene text): the five kinds on split2, the jointed ones as the scene format runs them when
    they name no integrator (trees: reduced-rk4, docs/trees.md), then the free body under each other
    integrator; only: the rows whose label contains it."""
    rows = [(kind, kind_scene(kind, "split2")) for kind in SCENES]
    rows += [(f"{kind}, default", kind_scene(kind)) for kind in ("joints", "joints+contact")]
    rows += [(f"free, {name}", kind_scene("free", name)) for name in integrators if name != "split2"]
    return [row for row in rows if only in row[0]]


def short_types(args: str, width: int = 60) -> str:
    return args if len(args) <= width else args[: width - 3] + "..."


def measure(integrators: list[str], top: int, json_out: Path | None, only: str = "") -> None:
    load = os.getloadavg()[0]
    print(f"First runs per kind of scene (CPU s of the process; load average {load:.1f} on "
          f"{os.cpu_count()} cores)")  # fmt: skip
    results = {}
    with tempfile.TemporaryDirectory(prefix="rbsim-startup-") as folder:
        work = Path(folder)
        rows = kinds(integrators, only)
        scenes = []
        for index, (label, text) in enumerate(rows):
            scene = work / f"kind{index}.yaml"
            scene.write_text(text)
            scenes.append((label, scene))
        for label, scene in scenes:
            cache = work / f"cache-{scene.stem}"
            cold = run_scene(scene, cache, work)
            warm = run_scene(scene, cache, work)
            results[label] = {"cold": cold.__dict__, "warm": warm.__dict__}
            print(f"\n{label}: cold {cold.cpu:.1f} s (numba compiled {len(cold.compiled)} functions in "
                  f"{cold.compile_seconds:.1f} s, LLVM {cold.llvm:.1f} s), warm {warm.cpu:.2f} s, "
                  f"warm compiled {len(warm.compiled)}")  # fmt: skip
            for name, args, inclusive, exclusive in sorted(cold.compiled, key=lambda c: -c[3])[:top]:
                print(f"  {exclusive:6.2f} s own {inclusive:6.2f} s with callees  {name}  {short_types(args)}")
        print("\nIn one cache, one kind after another (each a new process):")
        shared = work / "cache-shared"
        total = 0.0
        for label, scene in scenes:
            run = run_scene(scene, shared, work)
            total += run.cpu
            results[label]["after_the_others"] = run.__dict__
            print(f"  {label:24s} {run.cpu:6.1f} s  compiled {len(run.compiled):3d} functions "
                  f"({run.compile_seconds:.1f} s)")  # fmt: skip
        print(f"  {'all kinds':24s} {total:6.1f} s")
    own = resource.getrusage(resource.RUSAGE_CHILDREN)
    print(f"\n(children's CPU in all: {own.ru_utime + own.ru_stime:.0f} s; load average now {os.getloadavg()[0]:.1f})")
    if json_out is not None:
        json_out.write_text(json.dumps(results, indent=1))
