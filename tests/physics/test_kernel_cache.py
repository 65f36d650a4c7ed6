"""numba's cache cannot serve a stale kernel (physics/kernel_cache.py, issue 30).

numba keys a cached function on its own source file only; a chunk loop links its callees from other
files, so an edit of a callee used to leave the cached loop running the old code. The cache indexes of
rbcli's kernels now carry a hash of every physics source: an edit anywhere in rbcli/physics recompiles,
and an unchanged package loads without compiling.
"""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
PHYSICS = ROOT / "rbcli" / "physics"

# one free body falling under gravity, semi-implicit Euler: the cheapest loop to compile (~7 s cold on
# the 2-core machine; a contact scene's split2 loop takes ~55 s there, too long for the suite). The chunk
# loop (chunk_loop.py, compiled for semi-implicit) reaches the gravity kernel through two other files
# (forces/wrench.py, forces/gravity.py): the edited file is neither the loop's nor its direct callee's.
DT, STEPS, G = 1e-3, 100, 9.81
SCENE = f"""\
name: stale-cache
simulation: {{dt: {DT}, steps: {STEPS}, integrator: semi-implicit}}
gravity: [0, 0, -{G}]
bodies:
  - name: ball
    particles: {{positions: [[0, 0, 0]], masses: 1.0, radius: 0.05}}
    position: [0, 0, 1]
"""
CHILD = """
import json, sys
from rbcli.physics import kernel_cache
from rbcli.physics import chunk_loop
from rbcli.physics.integrators import get_integrator
from rbcli.runner.simulation import Simulation

sim = Simulation(sys.argv[1])
sim.step(sim.settings.steps)
stats = get_integrator("semi-implicit").chunk().run_chunk.stats
print(json.dumps({"vz": float(sim.state.v[0, 2]), "loaded": sum(stats.cache_hits.values()),
                  "compiled": sum(stats.cache_misses.values()), "guarded": kernel_cache.guarded(),
                  "module": chunk_loop.__file__}))
"""
GRAVITY_LINE = "            F[b, k] += body_mass[b] * gravity[k]\n"
DOUBLED_LINE = "            F[b, k] += 2.0 * body_mass[b] * gravity[k]\n"


def _run(copy: Path, scene: Path) -> dict:
    env = {**os.environ, "PYTHONPATH": str(copy), "NUMBA_CACHE_DIR": str(copy / "numba_cache")}
    out = subprocess.run([sys.executable, "-c", CHILD, str(scene)], env=env, cwd=copy,
                         capture_output=True, text=True, timeout=300)  # fmt: skip
    assert out.returncode == 0, out.stderr
    result = json.loads(out.stdout.strip().splitlines()[-1])
    assert Path(result["module"]).is_relative_to(copy), result  # the copy ran, not this checkout
    return result


def test_an_edited_callee_in_another_file_is_recompiled_and_an_unchanged_one_is_loaded(tmp_path):
    """Semi-implicit Euler under constant gravity: v_z after n steps is exactly the sum of n kicks,
    -n g dt (to round-off of the sum: 1e-12 relative); doubling gravity in forces/gravity.py must double
    it in the next process. Without the physics hash in the cache key the third process loaded the
    cached loop with the old gravity kernel linked in and gave -n g dt again (checked on the old
    kernel_cache.py)."""
    copy = tmp_path / "copy"
    ignore = shutil.ignore_patterns("__pycache__", "*.nbi", "*.nbc")
    shutil.copytree(ROOT / "rbcli", copy / "rbcli", ignore=ignore)
    shutil.copytree(ROOT / "schemas", copy / "schemas")
    scene = tmp_path / "fall.yaml"
    scene.write_text(SCENE)
    expected = -STEPS * G * DT

    cold = _run(copy, scene)
    assert cold["guarded"] and (cold["compiled"], cold["loaded"]) == (1, 0), cold
    assert np.isclose(cold["vz"], expected, rtol=1e-12, atol=0.0), cold

    warm = _run(copy, scene)  # nothing changed: loaded, not compiled, the same bits
    assert (warm["compiled"], warm["loaded"]) == (0, 1) and warm["vz"] == cold["vz"], warm

    gravity = copy / "rbcli" / "physics" / "forces" / "gravity.py"
    source = gravity.read_text()
    assert source.count(GRAVITY_LINE) == 1
    gravity.write_text(source.replace(GRAVITY_LINE, DOUBLED_LINE))
    edited = _run(copy, scene)
    assert (edited["compiled"], edited["loaded"]) == (1, 0), edited
    assert np.isclose(edited["vz"], 2.0 * expected, rtol=1e-12, atol=0.0), edited

    again = _run(copy, scene)  # the new key is stable: the edited package loads from the cache
    assert (again["compiled"], again["loaded"]) == (0, 1) and again["vz"] == edited["vz"], again


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def test_every_kernel_module_installs_the_cache_guard_before_its_kernels_can_run():
    """A kernel loaded before `kernel_cache.install()` ran would be looked up under numba's own key (the
    stale one): every rbcli.physics module that imports numba must call `kernel_cache.install()` at
    module level or import, at module level, an rbcli.physics module that does (checked on the import
    graph: an import or call in a function body does not count)."""
    imports: dict[str, set[str]] = {}
    uses_numba: set[str] = set()
    calls_install: set[str] = set()
    for path in PHYSICS.rglob("*.py"):
        name = _module_name(path)
        found = imports.setdefault(name, set())
        for node in ast.parse(path.read_text()).body:
            if isinstance(node, ast.Expr) and ast.unparse(node.value) == "kernel_cache.install()":
                calls_install.add(name)
            if isinstance(node, ast.Import):
                targets = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                targets = [node.module, *(f"{node.module}.{alias.name}" for alias in node.names)]
            else:
                continue
            if any(target.split(".")[0] == "numba" for target in targets):
                uses_numba.add(name)
            found.update(target for target in targets if target.startswith("rbcli."))

    def installs(name: str, seen: set[str]) -> bool:
        if name in calls_install:
            return True
        seen.add(name)
        return any(installs(other, seen) for other in imports.get(name, ()) if other not in seen)

    assert "rbcli.physics.kernel_cache" not in uses_numba  # it imports numba inside install() only
    missing = sorted(name for name in uses_numba if not installs(name, set()))
    assert not missing, f"these modules import numba but never kernel_cache: {missing}"
    assert len(uses_numba) > 40  # the walk found the kernel modules


# a cached function whose signature names a NamedTuple of its module (as rbcli's kernels name their tables
# and sinks); version 2 of the module has removed that class
HOLDER_V1 = """
from typing import NamedTuple
import numba
import numpy as np

class Gone(NamedTuple):
    values: np.ndarray

@numba.njit(cache=True)
def total(table):
    return table[0].sum()
"""
HOLDER_V2 = HOLDER_V1.replace("Gone", "Kept").replace("table[0].sum()", "table[0].sum() + 1.0")
HOLDER_CALL = """
import sys
from rbcli.physics import kernel_cache
kernel_cache.install()
import numpy as np
import holder
print(holder.total(getattr(holder, sys.argv[1])(np.ones(3))))
"""


def test_an_index_naming_a_class_that_is_gone_is_a_cache_miss_not_a_crash(tmp_path):
    """numba unpickles a cache index before it checks its source stamp: an index written by a version
    of the code whose argument type is gone raised AttributeError at every later load (seen when a sink
    class of contact/ was merged away: a suite run on the old cache failed). kernel_cache reads such an
    index as empty: the function compiles and its index is written anew."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}
    env["PYTHONPATH"] = os.pathsep.join([str(tmp_path), str(ROOT)])

    def call(version: str, type_name: str) -> subprocess.CompletedProcess:
        (tmp_path / "holder.py").write_text(version)
        return subprocess.run([sys.executable, "-c", HOLDER_CALL, type_name], env=env, cwd=tmp_path,
                              capture_output=True, text=True, timeout=120)  # fmt: skip

    first = call(HOLDER_V1, "Gone")
    assert first.returncode == 0 and first.stdout.split() == ["3.0"], first.stderr[-2000:]
    assert any((tmp_path / "numba_cache").rglob("holder.total-*.nbi"))  # the index naming holder.Gone
    second = call(HOLDER_V2, "Kept")
    assert second.returncode == 0, second.stderr[-2000:]
    assert second.stdout.split() == ["4.0"]  # version 2's code, compiled anew
    again = call(HOLDER_V2, "Kept")  # and its index, written anew, serves the next process
    assert again.returncode == 0 and again.stdout.split() == ["4.0"], again.stderr[-2000:]
