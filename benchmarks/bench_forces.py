"""Cost per step of the force pipeline: a scene pays only for the terms it names.

    python benchmarks/bench_forces.py [--bodies 10000] [--steps 200] [--integrator euler-matrix]

Scenes (all with gravity; bodies of 4 particles, the tutorial's handle):
  gravity        gravity only
  +1 spring      the same plus one off-centre spring on one body (the other bodies must not notice: only
                 that body can receive a torque, so only it takes the integrator's torque path)
  +field all     the same plus a per-particle force field on every body (every particle, every step)
  +drag all      the same plus linear + quadratic drag on every body
Timing: the integrator's compiled `run_chunk` over `--steps` steps (no frame due, so nothing is copied),
best of `--repeats` rounds that interleave the scenes, after a warm-up call that compiles the kernels.
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import replace

import numpy as np

from rbcli.physics.integrators import get_integrator
from rbcli.physics.step import empty_buffers
from rbcli.scene.compile import compile_scene
from rbcli.scene.force_specs import BodyPoint, ForceDrag, ForceField, ForceSpring
from rbcli.scene.spec import BodySpec, RecordSpec, SceneSpec, SimulationSpec

HANDLE_POSITIONS = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.0, 0.2, 0.0], [0.0, 0.0, 0.3]])
HANDLE_MASSES = np.array([1.0, 0.5, 0.5, 0.25])


def base_scene(bodies: int, integrator: str) -> SceneSpec:
    rng = np.random.default_rng(0)
    specs = []
    for i in range(bodies):
        q = rng.normal(size=4)
        specs.append(
            BodySpec(
                name=f"b{i}",
                particle_position=HANDLE_POSITIONS,
                particle_mass=HANDLE_MASSES,
                position=rng.normal(size=3) * 10.0,
                orientation_wxyz=q / np.linalg.norm(q),
                velocity=rng.normal(size=3),
                angular_momentum=rng.normal(size=3) * 0.01,
            )
        )
    sim = SimulationSpec(dt=1e-3, duration=1.0, integrator=integrator, record=RecordSpec(10**9, ("bodies",)))
    return SceneSpec(name="bench-forces", simulation=sim, bodies=tuple(specs), gravity=np.array([0.0, 0.0, -9.81]))


def chunk_runner(scene: SceneSpec, steps: int) -> Callable[[], float]:
    """Compile the scene and warm its kernels; returns a function timing one `run_chunk` of `steps`
    steps [s per step] (no frame is due, so nothing is copied; each call starts from the initial state)."""
    compiled = compile_scene(scene)
    from rbcli.physics.data import make_data

    chunk = get_integrator(scene.simulation.integrator).chunk()
    km, forces, dt = compiled.model.kernel(), compiled.forces, compiled.settings.dt
    n = compiled.model.body_count
    frames = empty_buffers(1, n)

    def run(count: int = steps) -> float:
        data = make_data(compiled.initial_state, compiled.model, chunk.SCRATCH_WIDTH, forces=compiled.forces).kernel()
        started = time.perf_counter()
        chunk.run_chunk(km, forces, data, dt, 0, count, 10**9, frames, 0)
        return (time.perf_counter() - started) / count

    run(1)  # compiles, or loads from the cache
    return run


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=10_000)
    parser.add_argument("--steps", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--integrator", default="euler-matrix")
    args = parser.parse_args()

    base = base_scene(args.bodies, args.integrator)
    scenes = {
        "gravity": base,
        "+1 spring": replace(base, forces=(
            ForceSpring(end_a=BodyPoint(body="b0", point=np.array([0.0, 0.0, 0.3])), anchor=np.zeros(3),
                        stiffness=100.0, rest_length=1.0, damping=0.1),
        )),
        "+field all": replace(base, forces=(ForceField(per="particle", value=np.array([0.1, 0.0, 0.0])),)),
        "+drag all": replace(base, forces=(ForceDrag(linear=0.1, quadratic=0.01),)),
    }  # fmt: skip
    print(f"{args.bodies} bodies x 4 particles, {args.integrator}, {args.steps} steps, best of {args.repeats}")
    runners = {name: chunk_runner(scene, args.steps) for name, scene in scenes.items()}
    best = dict.fromkeys(runners, np.inf)
    for _ in range(args.repeats):  # interleaved, so a change of machine load hits every scene alike
        for name, run in runners.items():
            best[name] = min(best[name], run())
    reference = best["gravity"]
    for name, seconds in best.items():
        print(f"  {name:<12} {seconds * 1e3:8.3f} ms/step  {seconds / args.bodies * 1e9:7.1f} ns/body/step  "
              f"x{seconds / reference:5.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
