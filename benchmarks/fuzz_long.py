"""The long fuzz run (issue 17, item 7): the properties of the suite's fuzz tests with fresh random
examples, >= 10^4 in all by default, every integrator, force type and contact, huge arrays included.

    python benchmarks/fuzz_long.py                      # 10,000 examples over the targets below
    python benchmarks/fuzz_long.py --examples 2000 --minutes 10 --only load-broken run-options

Targets (tests/fuzz_cases.py has the strategies and the checks):
  load-valid     valid generated scenes through rbcli's loader: a SceneSpec
  load-broken    broken generated scenes through rbcli.load_scene: SceneSpec or located SceneError
  validate       `rbsim validate` in-process on valid and broken scenes: exit 0/1, located error lines
  run-valid      `rbsim run` in-process on valid scenes (every integrator, forces, contact): exit 0 or 3
  run-broken     `rbsim run` on broken scenes: exit 0, 1 (located errors) or 3
  run-options    `rbsim run` with generated options: a documented exit code, a message, no traceback
  mcap-damaged   damaged .mcap through info, replay --save and rbcli.read_recording
  rrd-truncated  truncated .rrd (a killed run) through info, replay --save and rbcli.read_recording
  rrd-damaged    .rrd with flipped bits, overwritten or cut slices through `rbsim info`, in child
                 processes (rerun's reader can abort the process: each abort is counted, the child
                 restarted, and the file kept)
  mesh-damaged   damaged OBJ / STL / PLY meshes through the loader: read or a located error, and no
                 traceback logged to stderr
A failing example is recorded (the first one of each distinct message, its input saved under
outputs/fuzz/), not shrunk, and the run goes on. Prints a table of examples and findings per target.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import random
import re
import subprocess
import sys
import tempfile
import time
import traceback
import warnings
from collections import Counter
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))

from fuzz_cases import (  # noqa: E402
    LOCATED,
    TINY,
    analyse_mesh_file,
    broken_scene,
    check_analysis,
    check_command,
    damaged,
    dump,
    load_scene_file,
    planned_steps,
    run_arguments,
    valid_scene,
    write_mesh_files,
)
from hypothesis import HealthCheck, Phase, assume, given, settings  # noqa: E402
from hypothesis import seed as seed_examples  # noqa: E402
from hypothesis import strategies as st  # noqa: E402
from hypothesis.errors import UnsatisfiedAssumption  # noqa: E402

WEIGHTS = {
    "load-valid": 0.12,
    "load-broken": 0.25,
    "validate": 0.08,
    "run-valid": 0.08,
    "run-broken": 0.08,
    "run-options": 0.12,
    "mcap-damaged": 0.10,
    "rrd-truncated": 0.04,
    "rrd-damaged": 0.03,
    "mesh-damaged": 0.10,
}
RECORDED = TINY.replace("split2}", "split2, record: {streams: [bodies, invariants, particles]}}")


class TimeUp(Exception):
    """A target's share of the time is spent."""


class Findings:
    """Examples run and distinct failures per target; each failure's input saved under `folder`."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        self.examples: Counter[str] = Counter()
        self.outcomes: dict[str, Counter[str]] = {}
        self.failures: dict[str, dict[str, str]] = {}

    def outcome(self, target: str, what: object) -> None:
        self.outcomes.setdefault(target, Counter())[str(what)] += 1

    def fail(self, target: str, error: BaseException | str, data: str | bytes, suffix: str = ".txt") -> None:
        message = error if isinstance(error, str) else "".join(traceback.format_exception(error))[-3000:]
        key = re.sub(r"0x[0-9a-f]+|\d+", "N", (message.strip().splitlines() or ["?"])[-1])[:160]
        found = self.failures.setdefault(target, {})
        if key in found:
            return
        self.folder.mkdir(parents=True, exist_ok=True)
        path = self.folder / f"{target}-{len(found)}{suffix}"
        path.write_bytes(data if isinstance(data, bytes) else data.encode("utf-8", "surrogatepass"))
        found[key] = f"{path}: {message}"


def runner_app():
    from typer.testing import CliRunner

    from rbcli.cli.app import app

    return CliRunner(), app


def property_for(target: str, findings: Findings, stop_at: float):  # noqa: C901 - one branch per target
    """The hypothesis test of one target; it records failures instead of raising them."""
    import rbcli
    from rbcli.scene.load import analyse_scene_text

    runner, app = runner_app()

    def guarded(body):
        def run(value) -> None:  # noqa: ANN001
            if time.monotonic() > stop_at:
                raise TimeUp  # ends the target (no shrinking phase: see main)
            findings.examples[target] += 1
            data = value if isinstance(value, str | bytes) else repr(value)
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("error", RuntimeWarning)
                    body(value)
            except AssertionError as exc:
                findings.fail(target, exc, data)
            except UnsatisfiedAssumption:
                findings.examples[target] -= 1  # hypothesis draws another example instead
                raise
            except Exception as exc:  # an exception that escaped rbsim: the finding
                findings.fail(target, exc, data)

        return run

    if target == "load-valid":

        @given(valid_scene())
        @guarded
        def test(scene):
            text = dump(scene)
            spec, issues = analyse_scene_text(text, "valid.yaml")
            assert spec is not None, "valid scene refused: " + "; ".join(map(str, issues))
            check_analysis(spec, issues, text)

    elif target == "load-broken":

        @given(broken_scene(huge_sizes=(1000, 20_000)))
        @guarded
        def test(text):
            with tempfile.TemporaryDirectory() as folder:
                spec, issues, _ = load_scene_file(text, Path(folder))
                findings.outcome(target, "loaded" if spec else "refused")
                check_analysis(spec, issues, text)

    elif target == "validate":

        @given(st.one_of(valid_scene().map(dump), broken_scene()))
        @guarded
        def test(text):
            with tempfile.TemporaryDirectory() as folder:
                path = Path(folder) / "scene.yaml"
                path.write_text(text, encoding="utf-8", errors="surrogatepass")
                result = runner.invoke(app, ["validate", str(path)])
                findings.outcome(target, result.exit_code)
                check_command(result, codes={0, 1}, message_on="stdout")
                for line in result.stdout.splitlines():
                    if ": error: " in line:
                        assert LOCATED.match(line), line

    elif target in ("run-valid", "run-broken"):
        strategy = valid_scene().map(dump) if target == "run-valid" else broken_scene()

        @given(strategy)
        @guarded
        def test(text):
            with tempfile.TemporaryDirectory() as folder:
                path = Path(folder) / "scene.yaml"
                path.write_text(text, encoding="utf-8", errors="surrogatepass")
                result = runner.invoke(app, ["run", str(path), "-o", str(Path(folder) / "out.mcap"), "-q"])
                findings.outcome(target, result.exit_code)
                check_command(result, codes={0, 3} if target == "run-valid" else {0, 1, 3})
                if result.exit_code == 1:
                    for line in result.stderr.splitlines():
                        if "error:" in line:
                            assert LOCATED.match(line), line

    elif target == "run-options":

        @given(run_arguments())
        @guarded
        def test(args):
            assume(not 2e4 < planned_steps(args, 1e-3, 1e-2) <= 1e10)
            with tempfile.TemporaryDirectory() as name:
                folder = Path(name)
                (folder / "scene.yaml").write_text(TINY)
                (folder / "file.txt").write_text("not a folder")
                (folder / "existing_dir").mkdir()
                at = args.index("-o") + 1
                if args[at] and not args[at].startswith("/"):
                    args[at] = str(folder / args[at])
                result = runner.invoke(app, ["run", str(folder / "scene.yaml"), *args, "-q"])
                findings.outcome(target, result.exit_code)
                check_command(result)

    elif target in ("mcap-damaged", "rrd-truncated"):
        fmt = "mcap" if target == "mcap-damaged" else "rrd"
        raw = recording_bytes(fmt)
        strategy = damaged(raw) if fmt == "mcap" else st.integers(0, len(raw) - 1).map(lambda n: raw[:n])

        @given(strategy)
        @guarded
        def test(data):
            with tempfile.TemporaryDirectory() as name:
                path = Path(name) / f"run.{fmt}"
                path.write_bytes(data)
                info = runner.invoke(app, ["info", str(path)])
                findings.outcome(target, f"info {info.exit_code}")
                check_command(info, codes={0, 1})
                check_command(runner.invoke(app, ["replay", str(path), "--save", f"{name}/s.rrd"]), codes={0, 1})
                try:
                    rbcli.read_recording(path)
                except (ValueError, OSError) as exc:
                    assert str(exc)

    elif target == "mesh-damaged":
        meshes = write_mesh_files()

        @given(st.sampled_from(sorted(meshes)).flatmap(lambda n: st.tuples(st.just(n), damaged(meshes[n]))))
        @guarded
        def test(case):
            name, data = case
            with tempfile.TemporaryDirectory() as folder:
                spec, issues, text, stderr = analyse_mesh_file(name, data, Path(folder))
                findings.outcome(target, "read" if spec else "refused")
                if "Traceback" in stderr:
                    findings.fail(target, f"{name}: a traceback logged to stderr:\n{stderr[-1500:]}", data)
                check_analysis(spec, issues, text)

    else:
        raise ValueError(target)
    return test


def recording_bytes(fmt: str) -> bytes:
    import rbcli

    with tempfile.TemporaryDirectory() as folder:
        scene = Path(folder) / "rec.yaml"
        scene.write_text(RECORDED)
        output = Path(folder) / f"rec.{fmt}"
        rbcli.run_to_file(rbcli.prepare(scene), output)
        return output.read_bytes()


def rrd_damaged(count: int, findings: Findings, stop_at: float, seed: int) -> None:
    """`rbsim info` on damaged .rrd files in child processes: one child reads many files and reports each
    result; when rerun's reader aborts it, the file it was reading is a finding and a new child goes on."""
    raw = recording_bytes("rrd")
    rng = random.Random(seed)
    with tempfile.TemporaryDirectory() as name:
        folder = Path(name)
        paths = []
        for i in range(count):
            data = damage_at_random(raw, rng)
            path = folder / f"d{i}.rrd"
            path.write_bytes(data)
            paths.append(path)
        done = 0
        while done < len(paths) and time.monotonic() < stop_at:
            listing = folder / "todo.json"
            listing.write_text(json.dumps([str(p) for p in paths[done:]]))
            child = subprocess.run(
                [sys.executable, __file__, "--rrd-worker", str(listing), str(stop_at - time.monotonic())],
                capture_output=True,
                text=True,
            )
            results = [json.loads(line) for line in child.stdout.splitlines() if line.startswith("{")]
            for result in results:
                findings.examples["rrd-damaged"] += 1
                findings.outcome("rrd-damaged", f"info {result['code']}")
                if result["code"] not in (0, 1) or result["traceback"]:
                    findings.fail("rrd-damaged", f"exit {result['code']}: {result['tail']}", paths[done].read_bytes())
                done += 1
            if child.returncode == 0:
                break
            # the child died on paths[done]: rerun's reader aborted the process
            findings.examples["rrd-damaged"] += 1
            findings.outcome("rrd-damaged", f"process died ({child.returncode})")
            panic = re.search(r"panicked at [^\n]*\n[^\n]*", child.stderr)
            why = panic.group(0) if panic else child.stderr[-500:]
            message = f"rbsim info: process died, exit {child.returncode}: {why}"
            findings.fail("rrd-damaged", message, paths[done].read_bytes(), ".rrd")
            done += 1


def damage_at_random(raw: bytes, rng: random.Random) -> bytes:
    """As fuzz_cases.damaged, drawn with `random` (a child process reads many files per start)."""
    data = bytearray(raw)
    kind = rng.choice(["flip", "flip", "overwrite", "splice"])
    if kind == "flip":
        for _ in range(rng.randint(1, 8)):
            data[rng.randrange(len(data))] ^= 1 << rng.randrange(8)
        return bytes(data)
    i = rng.randrange(len(data))
    if kind == "overwrite":
        return bytes(data[:i]) + rng.randbytes(rng.randint(1, 64)) + bytes(data[i + 64 :])
    return bytes(data[:i]) + bytes(data[rng.randint(i, len(data)) :])


def rrd_worker(listing: str, seconds: str) -> None:
    runner, app = runner_app()
    stop_at = time.monotonic() + float(seconds)
    for path in json.loads(Path(listing).read_text()):
        if time.monotonic() > stop_at:
            break
        result = runner.invoke(app, ["info", path])
        tail = (result.stderr + result.stdout)[-300:]
        escaped = result.exception is not None and not isinstance(result.exception, SystemExit)
        print(json.dumps({"code": result.exit_code, "traceback": escaped or "Traceback" in tail, "tail": tail}))
        sys.stdout.flush()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--examples", type=int, default=10_000, help="examples in all, split by WEIGHTS")
    parser.add_argument("--minutes", type=float, default=60.0, help="stop each target at its share of this")
    parser.add_argument("--only", nargs="*", default=None, help="run only these targets")
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--out", type=Path, default=REPO / "outputs" / "fuzz", help="where failing inputs go")
    parser.add_argument("--rrd-worker", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.rrd_worker:
        rrd_worker(*args.rrd_worker)
        return
    targets = args.only or list(WEIGHTS)
    total_weight = sum(WEIGHTS[t] for t in targets)
    findings = Findings(args.out)
    seed = args.seed if args.seed is not None else random.SystemRandom().randrange(2**32)
    started = time.monotonic()
    for target in targets:
        share = WEIGHTS[target] / total_weight
        examples = max(1, round(args.examples * share))
        stop_at = time.monotonic() + args.minutes * 60 * share
        t0 = time.monotonic()
        if target == "rrd-damaged":
            rrd_damaged(examples, findings, stop_at, seed)
        else:
            test = property_for(target, findings, stop_at)
            test = settings(
                max_examples=examples,
                deadline=None,
                database=None,
                derandomize=False,
                suppress_health_check=list(HealthCheck),
                phases=[Phase.generate],  # failures are recorded, not raised: nothing to shrink
                report_multiple_bugs=False,
            )(test)
            with contextlib.suppress(TimeUp):
                seed_examples(seed)(test)()
        print(
            f"{target:14s} {findings.examples[target]:6d} examples in {time.monotonic() - t0:6.1f} s; "
            f"{len(findings.failures.get(target, {}))} distinct failures; {dict(findings.outcomes.get(target, {}))}",
            flush=True,
        )
    total = sum(findings.examples.values())
    print(f"\n{total} examples in {time.monotonic() - started:.0f} s (seed {seed})")
    for target, found in findings.failures.items():
        for message in found.values():
            print(f"\n[{target}] {message}")
    os.makedirs(args.out, exist_ok=True)
    (args.out / "summary.json").write_text(
        json.dumps({"seed": seed, "examples": dict(findings.examples), "failures": findings.failures}, indent=1)
    )


if __name__ == "__main__":
    main()
