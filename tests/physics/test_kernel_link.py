"""Each kernel compiled once (physics/kernel_link.py): a second kind of scene reuses the first's compiled
stages instead of compiling copies of them into its own loop, in the same process and from the cache.

Scene A is a hinge pendulum in joint coordinates (reduced-euler); scene B is the same pendulum with a drag
force: another kind of scene, so another signature of the chunk loop (its force tables hold a drag
table), whose tree stages (forward kinematics, the articulated-body accelerations) take the same types as
A's. The maximal joint stages of split2 take the same types whatever else the scene holds too: the loop
hands every stage the model's body arrays alone (physics/step.py model_bodies); checked without compiling
on the split2 pendulum with a drag force, and with a ground (a contact table) and a kinematic body. The
compile test runs on the trees because their first compile is cheap (~20 CPU-s for both scenes against
~160 s for the split2 pendulum's RATTLE stack: the suite's costliest test then) and the mechanism is one
(kernel_link.separately_compiled, used by both families' stages). Checked with numba's compile events
(they fire only for real compilations) and with the machine code of B's loop: it must not define the
stages' functions (numba's own linking puts a copy of every callee's code into each caller, so the loop
would define them all)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import numba
import pytest

from rbcli.physics import kernel_link
from rbcli.physics.kernel_cache import VERIFIED_NUMBA

ROOT = Path(__file__).resolve().parents[2]

PENDULUM = """\
name: {name}
simulation: {{dt: 0.001, duration: 0.1, integrator: {integrator}}}
gravity: [0, 0, -9.81]
bodies:
  - name: rod
    particles: {{positions: [[0, 0, -0.2], [0.05, 0, -0.6], [0, 0.03, -1.0]], masses: 0.2, radius: 0.02}}
    position: [-0.1, 0.0, 0.41]
    angular_momentum: [0.001, 0.002, 0.0005]
{bodies}joints:
  - {{name: pivot, type: hinge, bodies: [rod, world], anchor: [0, 0, 1], axis: [0, 1, 0]}}
{forces}"""

SCENE_A = PENDULUM.format(name="pendulum", integrator="split2", bodies="", forces="")
DRAG = "forces:\n  - {type: drag, bodies: all, linear: 0.3}\n"
SCENE_B = PENDULUM.format(name="pendulum-drag", integrator="split2", bodies="", forces=DRAG)
# the compile test's pair: the same two scenes in joint coordinates
TREE_A = PENDULUM.format(name="pendulum", integrator="reduced-euler", bodies="", forces="")
TREE_B = PENDULUM.format(name="pendulum-drag", integrator="reduced-euler", bodies="", forces=DRAG)
# the pendulum again, its model holding a contact and a kinematic table as well as the joint table
SCENE_C = PENDULUM.format(
    name="pendulum-ground-conveyor",
    integrator="split2",
    bodies="  - {name: conveyor, shape: {type: box, size: [0.2, 0.2, 0.1]}, spacing: 0.05, density: 1000,\n"
    "     position: [0, 2, -4], kinematic: {velocity: [0.1, 0, 0]}}\n",
    forces="contact: {ground: -5}\n",
)

# the tree stages the reduced loop calls by symbol (physics/tree/aba.py), by module-qualified name
TREE_STAGES = ("aba.forward_kinematics", "aba.tree_accelerations")

SCRIPT = """
import json, sys
import numba.core.event as ev

compiled = []

class Recorder(ev.Listener):
    def on_start(self, event):
        f = event.data["dispatcher"].py_func
        compiled.append([f"{f.__module__}.{f.__qualname__}", str(event.data["args"])])

    def on_end(self, event):
        pass

ev.register("numba:compile", Recorder())

from rbcli.physics import kernel_link
from rbcli.physics.integrators import get_integrator
from rbcli.runner.simulation import Simulation

run_chunk = get_integrator(sys.argv[1]).chunk().run_chunk
out = {"runs": [], "separate": None}
for path in sys.argv[2:]:
    start = len(compiled)
    sim = Simulation(path)
    sim.step(50)
    state = sim.data.state
    out["runs"].append({"compiled": compiled[start:],
                        "bits": [a.tobytes().hex() for a in (state.x, state.q, state.P, state.L)]})
out["separate"] = kernel_link.active()
# the functions the machine code of each freshly compiled loop defines (a cache load cannot be inspected)
out["loop_functions"] = [[f.name for f in cres.library.get_defined_functions()]
                         for cres in run_chunk.overloads.values() if cres.metadata is not None]
print(json.dumps(out))
"""


def _run(cache: Path, integrator: str, *scenes: Path) -> dict:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    done = subprocess.run([sys.executable, "-c", SCRIPT, integrator, *map(str, scenes)], env=env, cwd=ROOT,
                          capture_output=True, text=True, timeout=900)  # fmt: skip
    assert done.returncode == 0, done.stderr[-3000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


def _verified() -> bool:
    return tuple(int(p) for p in numba.__version__.split(".")[:2]) in VERIFIED_NUMBA


@pytest.mark.slow
@pytest.mark.skipif(not _verified(), reason="kernel_link is installed only on the numba versions it was verified on")
def test_a_second_kind_of_scene_compiles_none_of_the_first_ones_functions_and_links_no_copies(tmp_path):
    scene_a, scene_b = tmp_path / "a.yaml", tmp_path / "b.yaml"
    scene_a.write_text(TREE_A)
    scene_b.write_text(TREE_B)
    cache = tmp_path / "numba_cache"

    first = _run(cache, "reduced-euler", scene_a, scene_b)
    assert first["separate"]
    run_a, run_b = first["runs"]
    compiled_a = {tuple(item) for item in run_a["compiled"]}
    compiled_b = {tuple(item) for item in run_b["compiled"]}
    names_a = {name for name, _ in compiled_a}
    stages = {f"rbcli.physics.tree.{stage}" for stage in TREE_STAGES}
    # the empty cache really compiled A's loop and tree stages, and B compiled a loop of its own types...
    assert stages <= names_a, sorted(names_a)
    assert any(name == "rbcli.physics.chunk_loop.run_chunk[reduced_euler]" for name, _ in compiled_a)
    assert any(name == "rbcli.physics.chunk_loop.run_chunk[reduced_euler]" for name, _ in compiled_b)
    # ...but none of rbcli's functions with the types A already compiled it for (its stages are reused, not
    # recompiled; numba's own overload implementations, builtins min and max, are compiled again for each
    # calling function's options), and no tree stage at all
    again_a = {(name, args) for name, args in compiled_a & compiled_b if name.startswith("rbcli.")}
    assert not again_a, sorted(again_a)
    assert not {name for name, _ in compiled_b} & stages
    # and neither loop carries a copy of the stages' code: they are called by symbol
    assert len(first["loop_functions"]) == 2
    for functions in first["loop_functions"]:
        names = [stage.split(".")[1] for stage in TREE_STAGES]
        copies = [name for name in functions if any(f"{len(stage)}{stage}" in name for stage in names)]
        assert not copies, copies
        assert functions  # the machine code was inspected, not an empty list

    # a new process on the same cache compiles nothing, loading each loop's callees before the loop
    again = _run(cache, "reduced-euler", scene_b, scene_a)
    assert [run["compiled"] for run in again["runs"]] == [[], []]
    assert [run["bits"] for run in again["runs"]] == [run_b["bits"], run_a["bits"]]


def test_the_joint_stages_take_the_same_types_whatever_else_the_scene_holds(tmp_path):
    """What lets B (and any other kind of scene) reuse A's compiled joint stages: the arguments the loop
    passes them (the body arrays alone, the joint table, the joint work) have the same numba types with
    or without a contact table, a kinematic table or force tables beside them. Compiles nothing."""
    from rbcli.physics.step import model_bodies
    from rbcli.runner.simulation import Simulation

    types = []
    for name, text in (("a", SCENE_A), ("b", SCENE_B), ("c", SCENE_C)):
        path = tmp_path / f"{name}.yaml"
        path.write_text(text)
        sim = Simulation(path)
        model = sim.model.kernel()
        stage_arguments = (model_bodies.py_func(model), model.joint, sim.data.kernel().joint)
        types.append(tuple(numba.typeof(v) for v in stage_arguments))
        if name == "c":  # the scene really holds the other tables
            assert model.contact is not None and model.kinematic is not None
    assert types[0] == types[1] == types[2]


def test_stage_kernels_are_called_by_symbol_and_small_kernels_stay_linked():
    """Stage-sized kernels (a joint stage, the solver's factor) are separate; kernels called per body stay
    linked so LLVM can inline them into their loops, and numba-inlined ones are never linked at all."""
    from rbcli.physics.contact import search
    from rbcli.physics.integrators import kinematics
    from rbcli.physics.joints import rattle, solver, stages

    for kernel in (rattle.joint_update, rattle.joint_position, stages.joint_velocity, solver.factor_rows,
                   solver.solve_rows, search.find_contacts):  # fmt: skip
        assert kernel_link.is_separate_kernel(kernel), kernel
    assert not kernel_link.is_separate_kernel(kinematics.turn)
    inlined = [kernel for kernel in vars(solver).values()
               if getattr(kernel, "targetoptions", {}).get("inline") == "always"]  # fmt: skip
    assert inlined and not any(kernel_link.is_separate_kernel(kernel) for kernel in inlined)


CONTACT_SCENE = """\
name: two-balls
simulation: {dt: 0.001, duration: 0.01}
gravity: [0, 0, -9.81]
contact:
  planes: [{point: [0, 0, 0], normal: [0, 0, 1]}]
bodies:
  - {name: a, particles: {positions: [[0, 0, 0]], masses: 1.0, radius: 0.1}, position: [0, 0, 0.09]}
  - {name: b, particles: {positions: [[0, 0, 0]], masses: 1.0, radius: 0.1}, position: [0.19, 0, 0.09]}
"""

# A function of another module, cached, calling contact.points.contact_points: a kernel that is not
# separate but calls one (find_contacts); numba links contact_points' module into it.
PROBE = """
import numba
from rbcli.physics.contact.points import contact_points

@numba.njit(cache=True)
def probe(model, table, work, x, q, P, L, point, force):
    return contact_points(model, table, work, x, q, P, L, point, force)
"""

PROBE_SCRIPT = """
import sys
import numpy as np
from rbcli.api import prepare
from rbcli.physics.contact.tables import make_contact_work

compiled = prepare(sys.argv[2])
table = compiled.model.contact
work = make_contact_work(table, compiled.model.body_count, history=False)
s = compiled.initial_state
point, force = np.zeros((16, 3)), np.zeros(16)
args = (compiled.model.kernel_bodies(), table, work, s.x, s.q, s.P, s.L, point, force)
if sys.argv[1] == "direct":
    from rbcli.physics.contact.points import contact_points
    print(contact_points(*args))
else:
    sys.path.insert(0, sys.argv[3])
    from probe import probe
    print(probe(*args))
"""


@pytest.mark.skipif(not _verified(), reason="kernel_link is installed only on the numba versions it was verified on")
def test_a_caller_compiled_over_a_cached_kernel_loads_the_separate_kernels_that_kernel_calls(tmp_path):
    """Process 1 compiles contact_points (which calls find_contacts by symbol) and caches it; process 2
    compiles a new function calling it, contact_points loaded from the cache; process 3 calls only that
    new function. numba does not keep a cached function's loaders on its library, so without kernel_link
    giving them back, the new function's cache entry lacked find_contacts' loader and process 3 called an
    unresolved symbol (a segmentation fault, seen in the suite's workers)."""
    scene = tmp_path / "two_balls.yaml"
    scene.write_text(CONTACT_SCENE)
    (tmp_path / "probe.py").write_text(PROBE)
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "numba_cache")}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))

    def run(mode: str) -> int:
        done = subprocess.run([sys.executable, "-c", PROBE_SCRIPT, mode, str(scene), str(tmp_path)], env=env,
                              cwd=ROOT, capture_output=True, text=True, timeout=600)  # fmt: skip
        assert done.returncode == 0, (mode, done.returncode, done.stderr[-2000:])
        return int(done.stdout.strip().splitlines()[-1])

    # two balls touching each other and the plane: 3 contacts
    assert run("direct") == 3
    assert run("probe") == 3  # compiles probe over the cached contact_points
    assert run("probe") == 3  # loads probe alone: its callees' separate kernels must come with it


# a separate kernel and its caller in a module of their own (cheap to compile: each process here costs
# its imports and a second or two)
PAIR = """\
import numba
from rbcli.physics import kernel_cache
from rbcli.physics.kernel_link import separately_compiled

kernel_cache.install()


@separately_compiled
@numba.njit(cache=True)
def callee(x):
    total = 0.0
    for i in range(x.shape[0]):
        total += x[i] * x[i]
    return total


@numba.njit(cache=True)
def caller(x):
    return callee(x) + 1.0
"""

PAIR_SCRIPT = """\
import sys
import numba
import numpy as np

for i in range(int(sys.argv[1])):  # functions compiled first: this process's symbols get other numbers
    numba.njit(lambda x, i=i: x + i)(1.0)
import pair

print(pair.caller(np.arange(3.0)))
"""


@pytest.mark.skipif(not _verified(), reason="kernel_link is installed only on the numba versions it was verified on")
def test_a_cached_caller_whose_callee_this_process_compiled_anew_is_compiled_again_not_run(tmp_path):
    """numba's symbol for a function holds a number given by the process that compiled it. Process 1
    compiles `caller` and its separate kernel `callee` and caches both; the callee's cache entry is then
    lost (as when a second process compiling at the same time overwrites it: two test workers on one empty
    cache). Process 2, having compiled other functions first, loads `caller` from the cache; its loader
    compiles `callee` anew, under another symbol than the one the cached caller calls: mapped, the caller
    would call an unresolved symbol (a segmentation fault, seen in the suite's workers). The loader
    refuses it and the caller is compiled again: the right answer, exit 0."""
    (tmp_path / "pair.py").write_text(PAIR)
    cache = tmp_path / "numba_cache"
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(tmp_path), str(ROOT), env.get("PYTHONPATH")]))

    def run(shift: int) -> str:
        done = subprocess.run([sys.executable, "-c", PAIR_SCRIPT, str(shift)], env=env, cwd=tmp_path,
                              capture_output=True, text=True, timeout=300)  # fmt: skip
        assert done.returncode == 0, (shift, done.returncode, done.stderr[-2000:])
        return done.stdout.strip().splitlines()[-1]

    assert run(0) == "6.0"
    callee_entries = [path for path in cache.rglob("pair.callee-*") if path.suffix in (".nbi", ".nbc")]
    assert callee_entries and any(cache.rglob("pair.caller-*.nbi"))
    for path in callee_entries:
        path.unlink()
    assert run(7) == "6.0"
    assert run(3) == "6.0"  # and the caller compiled again in process 2 loads with its callee
