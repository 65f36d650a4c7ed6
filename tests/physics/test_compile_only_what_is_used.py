"""A first run compiles only what the scene needs (tracker issue 16, item 5): the kernels take
`ForceTables.kernel()` and `Model.kernel()`, whose tables of what the scene lacks (force terms beyond
gravity, contact, joints, kinematic bodies) are None, and every optional stage is called through a
dispatcher (physics/stages.py, physics/forces/stages.py) that compiles to nothing for None. The force
types go together (issue 44): a scene with any force term compiles the stages of all six, once, and every
other mix of force types then compiles nothing. Checked by numba's
own compile events in a fresh process with an empty cache (a warm cache compiles nothing at all, so it
could not tell), then that a second process loads every kernel from that cache without compiling."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numba
import numpy as np
from conftest import make_body, make_scene, random_bodies

from rbcli.api import prepare
from rbcli.physics.contact import force as contact_force
from rbcli.physics.data import make_data
from rbcli.physics.forces import drag, field, impulse, point_force, spring, torque
from rbcli.physics.forces.gravity import accumulate_gravity
from rbcli.physics.forces.tables import KernelForceTables, make_force_data
from rbcli.physics.integrators import get_integrator
from rbcli.physics.model import KernelModel
from rbcli.physics.step import empty_buffers
from rbcli.scene.force_specs import BodyPoint, ForceDrag, ForceField, ForceImpulse, ForceSpring

ROOT = Path(__file__).resolve().parents[2]
INTEGRATOR = "semi-implicit"  # the cheapest step to compile: the test is about the stages around it
G = np.array([0.0, 0.0, -9.81])


def _name(dispatcher) -> str:  # noqa: ANN001
    return f"{dispatcher.py_func.__module__}.{dispatcher.py_func.__qualname__}"


# the kernels of the force types a gravity-only scene does not have
FORCE_TYPES = {
    _name(k)
    for k in (
        field.accumulate_field,
        point_force.accumulate_point_force,
        torque.accumulate_torque,
        spring.accumulate_spring,
        drag.accumulate_drag,
        impulse.apply_impulses,
    )
}
# ...and of the contact stages, which no scene without contact has
CONTACT_STAGES = {
    _name(k)
    for k in (
        contact_force.accumulate_contact,
        contact_force.hold_static_bodies,
        contact_force.begin_contact_step,
        contact_force.commit_contacts,
    )
}
UNUSED_BY_GRAVITY = FORCE_TYPES | CONTACT_STAGES
CHUNK = f"rbcli.physics.chunk_loop.run_chunk[{INTEGRATOR.replace('-', '_')}]"  # its loop: chunk_loop.py

# Run in a fresh process: prints the qualified names of the functions numba compiled (not loaded from
# its cache) while stepping a gravity-only scene and, with --forces, then a scene with a spring and an
# impulse and a scene with drag and a field; `numba:compile` events fire only for real compilations.
SCRIPT = """
import json, sys
from dataclasses import replace
import numpy as np
import numba.core.event as ev

compiled = []

class Recorder(ev.Listener):
    def on_start(self, event):
        f = event.data["dispatcher"].py_func
        compiled.append(f"{f.__module__}.{f.__qualname__}")

    def on_end(self, event):
        pass

ev.register("numba:compile", Recorder())

from conftest import make_body, make_scene
from rbcli.runner.simulation import Simulation
from rbcli.scene.force_specs import BodyPoint, ForceDrag, ForceField, ForceImpulse, ForceSpring

def run(forces):
    body = make_body("h", velocity=np.array([0.5, 0.0, 4.0]), angular_momentum=np.array([0.01, 0.02, 0.03]))
    scene = make_scene([body], integrator=sys.argv[1], gravity=np.array([0.0, 0.0, -9.81]))
    start = len(compiled)
    sim = Simulation(replace(scene, forces=tuple(forces)))
    sim.step(3)
    states.append([a.tobytes().hex() for a in (sim.data.state.x, sim.data.state.q, sim.data.state.P, sim.data.state.L)])
    return compiled[start:]

states = []
out = {"gravity": run([])}
if "--forces" in sys.argv:
    spring = ForceSpring(end_a=BodyPoint(body="h", point=np.array([0.1, 0.0, 0.0])), anchor=np.zeros(3), stiffness=1.0)
    kick = ForceImpulse(at=BodyPoint(body="h"), time=0.001, vector=np.array([0.0, 1.0, 0.0]))
    out["spring_impulse"] = run([spring, kick])
    drag = ForceDrag(bodies=("h",), linear=0.1)
    field = ForceField(value=np.array([0.0, 0.3, 0.0]))
    out["drag_field"] = run([drag, field])
out["states"] = states
out["integrators"] = sorted(m for m in sys.modules if m.startswith("rbcli.physics.integrators."))
out["joint_stages"] = "rbcli.physics.joints.stages" in sys.modules
# physics/kernel_cache.py: loading rbcli's kernels does not build numba's compiler tables (which import
# numba.np.arraymath); compiling does
out["arraymath"] = "numba.np.arraymath" in sys.modules
from rbcli.physics import kernel_cache
out["fast_loads"] = kernel_cache.active()
print(json.dumps(out))
"""


def _compiled_in_fresh_process(cache: Path, *extra: str) -> dict[str, list[str]]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    env["PYTHONPATH"] = os.pathsep.join([str(ROOT), str(ROOT / "tests"), *filter(None, [env.get("PYTHONPATH")])])
    out = subprocess.run([sys.executable, "-c", SCRIPT, INTEGRATOR, *extra], env=env, cwd=ROOT,
                         capture_output=True, text=True, timeout=600)  # fmt: skip
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_first_run_compiles_only_the_stages_the_scene_has_and_the_second_loads_them(tmp_path):
    cache = tmp_path / "numba_cache"
    first = _compiled_in_fresh_process(cache, "--forces")

    gravity = set(first["gravity"])
    # the empty cache really compiled the scene's kernels (so the events are seen; the force pass
    # wrench.accumulate_wrench is inlined into the chunk loop, physics/step.py STEP_ENTRY)...
    assert {CHUNK, _name(accumulate_gravity)} <= gravity, sorted(gravity)
    # ...and none of the kinds of force and stage the scene does not have
    assert not gravity & UNUSED_BY_GRAVITY, sorted(gravity & UNUSED_BY_GRAVITY)
    # ...nor anything of another integrator (the one loop is compiled per integrator with its own step,
    # physics/chunk_loop.py; the others' modules are not even imported) or the joint stages (its loop has
    # none: only split2's runs them)
    own = INTEGRATOR.replace("-", "_")
    assert first["integrators"] == [f"rbcli.physics.integrators.{m}" for m in sorted(("kinematics", own))]
    assert not [name for name in gravity if name.startswith("rbcli.physics.joints.")], sorted(gravity)
    assert not first["joint_stages"]  # not even imported (~20 ms of a warm start: chunk_loop.py)
    # record_if_due copies with element loops: no array-assignment shape-error message (~2.5 s) compiled
    assert not [name for name in gravity if "shape_context" in name], sorted(gravity)

    # a scene with a spring and an impulse compiles the loop of scenes with forces and every force type's
    # stage (one numba type for every mix of force types: forces/tables.py), still nothing of contact...
    forces = set(first["spring_impulse"])
    assert {CHUNK} | FORCE_TYPES <= forces, sorted(FORCE_TYPES - forces)
    assert not forces & CONTACT_STAGES, sorted(forces & CONTACT_STAGES)
    # ...so a scene with another mix of force types compiles nothing at all
    assert first["drag_field"] == [], first["drag_field"]

    # numba's cache serves the loops that call the dispatchers: a second process compiles nothing...
    second = _compiled_in_fresh_process(cache, "--forces")
    assert (second["gravity"], second["spring_impulse"], second["drag_field"]) == ([], [], []), second
    # ...loads them without numba's compiler tables (physics/kernel_cache.py), which compiling built...
    # (on the numba versions it was verified on: kernel_cache.VERIFIED_NUMBA)
    assert first["arraymath"] and second["arraymath"] != second["fast_loads"]
    import numba

    from rbcli.physics.kernel_cache import VERIFIED_NUMBA

    assert second["fast_loads"] == (tuple(int(p) for p in numba.__version__.split(".")[:2]) in VERIFIED_NUMBA)
    # ...and the loaded kernels give the compiled ones' bits
    assert second["states"] == first["states"]


def test_kernel_tables_are_none_without_forces_and_all_present_with_any():
    body = make_body("h")
    alone = prepare(make_scene([body], gravity=G))
    kernel_alone = alone.forces.kernel()
    for name in ("field", "point_force", "torque", "spring", "drag", "impulse"):
        assert getattr(kernel_alone, name) is None, name  # gravity only: no force stage compiles
    kick = ForceImpulse(at=BodyPoint(body="h"), time=0.5, vector=np.ones(3))
    compiled = prepare(replace(make_scene([body], gravity=G), forces=(kick,)))
    forces, model = compiled.forces, compiled.model
    kernel = forces.kernel()
    assert isinstance(kernel, KernelForceTables) and kernel._fields == forces._fields
    assert kernel.impulse is forces.impulse and kernel.schedule is forces.schedule
    for name in ("field", "point_force", "torque", "spring", "drag"):  # present, with 0 rows
        assert getattr(kernel, name) is getattr(forces, name) and getattr(kernel, name)[0].shape[0] == 0, name
    kernel_model = model.kernel()  # the model's tables: None where the scene lacks them
    assert isinstance(kernel_model, KernelModel)
    assert (kernel_model.contact, kernel_model.joint, kernel_model.kinematic) == (None, None, None)
    assert make_force_data(model).contact is None and make_force_data(kernel_model).contact is None
    # one numba type for every scene with forces, whatever its force types
    drag = ForceDrag(bodies=("h",), linear=0.5)
    other = prepare(replace(make_scene([body], gravity=G), forces=(drag,)))
    assert numba.typeof(other.forces.kernel()) == numba.typeof(kernel) != numba.typeof(kernel_alone)
    again = prepare(replace(make_scene([body], gravity=G), forces=(kick,)))
    assert numba.typeof(again.model.kernel()) == numba.typeof(kernel_model)


def test_a_chunk_gives_the_same_bits_with_kernel_tables_as_with_full_tables():
    """Kernels also take a plain ForceTables (tests and benchmarks call them with `compiled.forces`):
    every stage is then compiled and the empty ones skipped at run time, bitwise as the kernel form."""
    bodies = random_bodies(3, seed=4)
    specs = (
        ForceSpring(end_a=BodyPoint(body="b0", point=np.array([0.1, 0.0, 0.0])), anchor=np.zeros(3), stiffness=2.0),
        ForceField(value=np.array([0.0, 0.3, 0.0]), gradient=0.1 * np.eye(3)),
        ForceImpulse(at=BodyPoint(body="b1", point=np.array([0.0, 0.1, 0.0])), time=0.004, vector=np.ones(3)),
    )
    compiled = prepare(replace(make_scene(bodies, integrator=INTEGRATOR, gravity=G), forces=specs))
    chunk = get_integrator(INTEGRATOR).chunk()
    results = []
    for forces in (compiled.forces, compiled.forces.kernel()):
        data = make_data(compiled.initial_state, compiled.model, chunk.SCRATCH_WIDTH, forces=compiled.forces)
        frames = empty_buffers(4, 3)
        status = chunk.run_chunk(compiled.model.kernel(), forces, data.kernel(), 1e-3, 0, 20, 5, frames, 0)
        results.append((status, data.state.x, data.state.q, data.state.P, data.state.L, frames.x,
                        data.force.term_evaluations))  # fmt: skip
    full, kernel = results
    assert full[0] == kernel[0] == (20, 4, 2)  # the 4th frame fills the buffers
    for a, b in zip(full[1:], kernel[1:], strict=True):
        assert np.array_equal(a, b)
