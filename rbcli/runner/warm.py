"""`rbsim warm`: compile, before any first run, the kernels of a small scene of each kind (free bodies,
forces, contact, joints, joints with contact) or of given scenes, several processes at once, into numba's
cache, so that first runs load them instead of compiling (issue 44).

A kind's scene is short (a few hundred steps): only its kernels matter. A later scene of the same kind,
integrator and threads loads the same chunk loop, and a scene of another kind still reuses every stage
kernel it shares (physics/kernel_link.py: the joint solver, the contact search), compiling only its own
loop (~4-9 s) instead of the whole stack (docs/performance.md, "Start-up"). Processes compiling on one
cache at the same time are safe (kernel_link's symbol check); two compiling the same stage both pay for
it, so the kind that reuses the others' stages (joints with contact) starts last (KIND_ORDER).
"""

from __future__ import annotations

# Short scenes of each kind; `{integrator}` is the `integrator:` entry of `simulation:` (", integrator:
# NAME", or "" for the scene format's default: euler-matrix, split2 with contact, reduced-rk4 with joints
# that form trees, as both jointed kinds' do, reduced-implicit where such a tree has few contacts)
KIND_SCENES: dict[str, str] = {
    "free": """\
name: free-cloud
simulation: {{dt: 0.001, duration: 0.2{integrator}}}
bodies:
  - name: handle
    particles: {{positions: [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.3]], masses: [1.0, 0.5, 0.5, 0.25]}}
    position: [0, 0, 1]
    angular_momentum: [0.02, 0.05, 0.01]
""",
    "forces": """\
name: forces
simulation: {{dt: 0.001, duration: 0.2{integrator}}}
gravity: [0, 0, -9.81]
bodies:
  - {{name: a, shape: {{type: box, size: [0.2, 0.1, 0.05]}}, spacing: 0.05, density: 500, position: [0, 0, 1]}}
  - {{name: b, shape: {{type: sphere, radius: 0.1}}, spacing: 0.05, density: 500, position: [0.5, 0, 1]}}
forces:
  - {{type: spring, bodies: [a, b], points: [[0.1, 0, 0], [0, 0, 0]], stiffness: 200, damping: 1}}
  - {{type: drag, bodies: all, linear: 0.05}}
""",
    "contact": """\
name: poured
simulation: {{dt: 0.0005, duration: 0.1{integrator}}}
gravity: [0, 0, -9.81]
contact:
  container: {{min: [-0.3, -0.3, 0], max: [0.3, 0.3, 2]}}
  material: {{restitution: 0.3, friction: 0.5}}
bodies:
  - grid:
      name: ball
      count: [5, 4, 3]
      spacing: [0.1, 0.1, 0.1]
      origin: [-0.2, -0.15, 0.2]
      template: {{particles: {{positions: [[0, 0, 0]], masses: 0.1, radius: 0.04}}}}
""",
    "joints": """\
name: hinge-chain
simulation: {{dt: 0.001, duration: 0.2{integrator}}}
gravity: [0, 0, -9.81]
defaults:
  particles: {{positions: [[-0.1, 0, 0], [0.1, 0, 0]], masses: 0.2, radius: 0.02}}
bodies:
  - {{name: l1, position: [0.1, 0, 1]}}
  - {{name: l2, position: [0.3, 0, 1]}}
  - {{name: l3, position: [0.5, 0, 1]}}
  - {{name: l4, position: [0.7, 0, 1]}}
  - {{name: l5, position: [0.9, 0, 1]}}
  - {{name: l6, position: [1.1, 0, 1]}}
joints:
  - {{name: j1, type: hinge, bodies: [l1, world], anchor: [0, 0, 1], axis: [0, 1, 0]}}
  - {{name: j2, type: hinge, bodies: [l2, l1], anchor: [0.2, 0, 1], axis: [0, 1, 0]}}
  - {{name: j3, type: hinge, bodies: [l3, l2], anchor: [0.4, 0, 1], axis: [0, 1, 0]}}
  - {{name: j4, type: hinge, bodies: [l4, l3], anchor: [0.6, 0, 1], axis: [0, 1, 0]}}
  - {{name: j5, type: hinge, bodies: [l5, l4], anchor: [0.8, 0, 1], axis: [0, 1, 0]}}
  - {{name: j6, type: hinge, bodies: [l6, l5], anchor: [1.0, 0, 1], axis: [0, 1, 0]}}
""",
    "joints+contact": """\
name: capsule-chain
simulation: {{dt: 0.0005, duration: 0.1{integrator}}}
gravity: [0, 0, -9.81]
contact:
  planes: [{{point: [0, 0, 0], normal: [0, 0, 1]}}]
  material: {{restitution: 0.2, friction: 0.6}}
defaults:
  shape: {{type: capsule, radius: 0.03, height: 0.14, axis: x}}
  spacing: 0.03
  density: 900
bodies:
  - {{name: c1, position: [0.1, 0, 0.2]}}
  - {{name: c2, position: [0.3, 0, 0.2]}}
  - {{name: c3, position: [0.5, 0, 0.2]}}
  - {{name: c4, position: [0.7, 0, 0.2]}}
joints:
  - {{name: b1, type: ball, bodies: [c2, c1], anchor: [0.2, 0, 0.2]}}
  - {{name: b2, type: ball, bodies: [c3, c2], anchor: [0.4, 0, 0.2]}}
  - {{name: b3, type: ball, bodies: [c4, c3], anchor: [0.6, 0, 0.2]}}
""",
}

# the order `rbsim warm` starts them in: the stacks others reuse first
KIND_ORDER = ("contact", "joints", "free", "forces", "joints+contact")


def kind_scene(kind: str, integrator: str | None = None) -> str:
    """The scene text of `kind` (KIND_SCENES) with `integrator`, or the scene format's default."""
    return KIND_SCENES[kind].format(integrator=f", integrator: {integrator}" if integrator else "")


def warm_scene(path: str) -> dict[str, float]:
    """In this process: load the scene at `path` and load or compile every kernel its run calls (a
    Simulation with the default threads, as `rbsim run` makes it); a stop signal (SIGINT, SIGTERM) ends
    the compile at its next safe point (runner/compile_progress.py: what finished stays cached). Returns
    {"functions": compiled, "seconds": wall}; 0 functions: all of them came from the cache."""
    import signal
    import time

    from rbcli.runner.compile_progress import watch_compiles
    from rbcli.runner.simulation import Simulation
    from rbcli.scene.compile import compile_scene
    from rbcli.scene.load import load_scene

    stops: list[int] = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, lambda received, frame: stops.append(received))
    started = time.perf_counter()
    sim = Simulation(compile_scene(load_scene(path)))
    with watch_compiles(stop_requested=lambda: bool(stops)) as progress:
        sim.load_kernels()
    return {"functions": progress().functions, "seconds": time.perf_counter() - started}


if __name__ == "__main__":  # `rbsim warm`'s worker: python -m rbcli.runner.warm SCENE
    import json
    import sys

    from rbcli.runner.compile_progress import CompileInterrupted

    try:
        print(json.dumps(warm_scene(sys.argv[1])), flush=True)
    except CompileInterrupted:
        sys.exit(130)
