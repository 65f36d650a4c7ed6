"""`rbsim warm`: the kernels of the given scenes (or of a small scene of each kind) compiled into numba's
cache by processes of their own, so that a first run afterwards loads instead of compiling."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from rbcli.runner.warm import KIND_ORDER, KIND_SCENES, kind_scene
from rbcli.scene.load import load_scene_text

ROOT = Path(__file__).resolve().parents[2]
FREE = """\
simulation: {{dt: 0.001, duration: 0.05, integrator: {integrator}}}
bodies:
  - name: handle
    particles: {{positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0]], masses: [1.0, 0.5, 0.5]}}
    angular_momentum: [0.01, 0.02, 0.0]
"""


def rbsim(cache: Path, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    return subprocess.run([sys.executable, "-m", "rbcli", *args], env=env, cwd=ROOT, capture_output=True, text=True,
                          timeout=600)  # fmt: skip


def test_warmed_scenes_first_runs_compile_nothing(tmp_path):
    """Two scenes warmed two at a time in an empty cache: each compiled its kernels in a process of its
    own; a run of one of them then compiles nothing (no compile line), and warming it again finds
    everything in the cache."""
    a, b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    a.write_text(FREE.format(integrator="euler-quat"))
    b.write_text(FREE.format(integrator="semi-implicit"))
    cache = tmp_path / "cache"
    done = rbsim(cache, "warm", str(a), str(b), "--jobs", "2")
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    for path in (a, b):
        line = next(line for line in lines if line.startswith(f"warm {path}:"))
        assert "compiled" in line and "nothing" not in line, done.stderr
    assert lines[-1].startswith("warm: 2 of 2 ready") and "(2 at a time)" in lines[-1], done.stderr
    run = rbsim(cache, "run", str(a), "-o", str(tmp_path / "a.mcap"))
    assert run.returncode == 0 and "compiling" not in run.stderr, run.stderr
    again = rbsim(cache, "warm", str(b))
    assert again.returncode == 0 and f"warm {b}: nothing to compile (in the cache)" in again.stderr, again.stderr


def test_an_invalid_scene_is_refused_before_anything_compiles(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(FREE.format(integrator="euler-matrix").replace("dt: 0.001", "dt: -1"))
    cache = tmp_path / "cache"
    done = rbsim(cache, "warm", str(bad), str(tmp_path / "missing.yaml"))
    assert done.returncode == 1, done.stderr
    assert f"{bad}:1:" in done.stderr and "missing.yaml" in done.stderr, done.stderr
    assert not any(cache.rglob("*.nbi")), "nothing may be compiled for a refused scene"


def test_the_kinds_are_scenes_of_those_kinds():
    """What `rbsim warm` without a scene prepares: each kind loads, with the scene format's default
    integrator (euler-matrix, split2 with contact, reduced-rk4 with joints: the kinds' chains are trees;
    reduced-implicit with joints and contact: its chain of capsules has few contacts), and is the kind it
    is named after."""
    assert sorted(KIND_ORDER) == sorted(KIND_SCENES) and KIND_ORDER[-1] == "joints+contact"
    for kind in KIND_ORDER:
        spec = load_scene_text(kind_scene(kind))
        has = {"contact": spec.contact is not None, "joints": bool(spec.joints), "forces": bool(spec.forces)}
        assert has["contact"] == ("contact" in kind) and has["joints"] == ("joints" in kind), kind
        assert has["forces"] == (kind == "forces"), kind
        default = "reduced-rk4" if has["joints"] else ("split2" if has["contact"] else "euler-matrix")
        default = "reduced-implicit" if has["joints"] and has["contact"] else default
        assert spec.simulation.integrator == default, kind
    assert load_scene_text(kind_scene("free", "rk4")).simulation.integrator == "rk4"
