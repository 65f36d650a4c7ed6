"""Issue 47's capsule ragdoll target: rbsim's scenes/joints/capsule_ragdoll.yaml beside MuJoCo's own ragdoll of
the same capsules, measured in the same run.

    python benchmarks/bench_capsule_ragdoll.py [--repeats N]

rbsim: the shipped scene as it is (no stiffness given, `substeps: auto`), its kernels compiled or loaded
first, then 3 s of motion from its initial state, CPU time of this process (time.process_time), best of
`--repeats`; beside it the deepest any part's lowest point went below the tilted plane, as a fraction of
its radius (every 10 steps), and the largest joint row residual.

MuJoCo (4.x, when installed): the same bodies as an MJCF tree (a free torso; the head and arms on ball
joints, the thighs and shins on hinges about x, the hinge limits as `range`, each ball joint's cone as its
largest swing angle: MuJoCo's ball `range` is one cone angle, no twist limit), capsule and sphere geoms
of the same sizes and masses (inertia from the geoms: MuJoCo's own), the same 10-degree plane, friction
0.6, its default contact softness, integrator and step (Euler, 2 ms), 3 s, best of `--repeats`; beside it
its deepest contact penetration (-min dist over the contacts, every 5 steps) over each part's radius.
The targets (issue 47): rbsim <= 5 CPU-s warm on one core, no part deeper than 10 % of its radius,
joints held to 1e-12.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rbcli import Simulation  # noqa: E402
from rbcli.analysis.contact_depth import depth_below_plane  # noqa: E402
from rbcli.physics.joints.reference import joint_rows_numpy  # noqa: E402

SCENE = ROOT / "scenes" / "joints" / "capsule_ragdoll.yaml"
SECONDS = 3.0
TILT = math.radians(10.0)


def run_rbsim(repeats: int, integrator: str = "reduced-implicit") -> tuple[float, float, float, int]:
    """(best CPU s for SECONDS, deepest sink / radius, largest joint residual [m], sub-steps a step), the
    scene run by `integrator` (reduced-implicit as shipped, reduced-rk4, reduced-euler: in joint coordinates;
    split2: maximal)."""
    sim = Simulation(SCENE, threads=1, integrator=integrator)
    sim.step(1)  # compiles (or loads) the kernels
    steps = round(SECONDS / sim.dt)
    best = math.inf
    for _ in range(repeats):
        sim.reset()
        started = time.process_time()
        sim.step(steps)
        best = min(best, time.process_time() - started)
    sim.reset()
    sink = gap = 0.0
    for _ in range(steps // 10):
        sim.step(10)
        sink = max(sink, float(depth_below_plane(sim.model.contact, sim.data.state.x, sim.data.state.q).max()))
        s = sim.data.state
        gap = max(gap, float(np.abs(joint_rows_numpy(sim.model.joint, s.x, s.q)[0]).max()))
    return best, sink, gap, sim.settings.substeps


def mujoco_xml() -> str:
    """The capsule ragdoll as an MJCF tree (positions relative to each parent; the scene's world poses)."""
    n = f"{math.sin(TILT)!r} 0 {math.cos(TILT)!r}"

    def capsule(name: str, radius: float, half: float, axis: str, mass: float) -> str:
        a = {"x": (half, 0, 0), "z": (0, 0, half)}[axis]
        return (f'<geom name="{name}" type="capsule" size="{radius}" fromto="{-a[0]} {-a[1]} {-a[2]} {a[0]} {a[1]} '
                f'{a[2]}" mass="{mass}"/>')  # fmt: skip

    return f"""<mujoco model="capsule_ragdoll">
  <option gravity="0 0 -9.81"/>
  <default><geom friction="0.6 0.005 0.0001" condim="3"/></default>
  <worldbody>
    <geom name="plane" type="plane" size="10 10 0.1" zaxis="{n}"/>
    <body name="torso" pos="0 0 2.25">
      <freejoint/>
      {capsule("torso", 0.12, 0.15, "z", 20.0)}
      <body name="head" pos="0 0 0.47">
        <joint name="neck" type="ball" pos="0 0 -0.12" range="0 34.4" damping="0.3"/>
        <geom name="head" type="sphere" size="0.1" mass="5"/>
      </body>
      <body name="arm_l" pos="0.4 0 0.15">
        <joint name="shoulder_l" type="ball" pos="-0.25 0 0" range="0 74.5" damping="0.1"/>
        {capsule("arm_l", 0.05, 0.2, "x", 2.5)}
      </body>
      <body name="arm_r" pos="-0.4 0 0.15">
        <joint name="shoulder_r" type="ball" pos="0.25 0 0" range="0 74.5" damping="0.1"/>
        {capsule("arm_r", 0.05, 0.2, "x", 2.5)}
      </body>
      <body name="thigh_l" pos="0.1 0 -0.5">
        <joint name="hip_l" type="hinge" axis="1 0 0" pos="0 0 0.2" range="-85.9 17.2"/>
        {capsule("thigh_l", 0.07, 0.15, "z", 6.0)}
        <body name="shin_l" pos="0 0 -0.45">
          <joint name="knee_l" type="hinge" axis="1 0 0" pos="0 0 0.2" range="0 126"/>
          {capsule("shin_l", 0.06, 0.15, "z", 4.0)}
        </body>
      </body>
      <body name="thigh_r" pos="-0.1 0 -0.5">
        <joint name="hip_r" type="hinge" axis="1 0 0" pos="0 0 0.2" range="-85.9 17.2"/>
        {capsule("thigh_r", 0.07, 0.15, "z", 6.0)}
        <body name="shin_r" pos="0 0 -0.45">
          <joint name="knee_r" type="hinge" axis="1 0 0" pos="0 0 0.2" range="0 126"/>
          {capsule("shin_r", 0.06, 0.15, "z", 4.0)}
        </body>
      </body>
    </body>
  </worldbody>
  <contact>
    <exclude body1="torso" body2="head"/><exclude body1="torso" body2="arm_l"/>
    <exclude body1="torso" body2="arm_r"/><exclude body1="torso" body2="thigh_l"/>
    <exclude body1="torso" body2="thigh_r"/><exclude body1="thigh_l" body2="shin_l"/>
    <exclude body1="thigh_r" body2="shin_r"/>
  </contact>
</mujoco>"""


def run_mujoco(repeats: int) -> tuple[float, float, float] | None:
    """(best CPU s for SECONDS, deepest penetration / the part's radius, its step [s]); None without MuJoCo."""
    try:
        import mujoco
    except ImportError:
        return None
    model = mujoco.MjModel.from_xml_string(mujoco_xml())
    data = mujoco.MjData(model)
    steps = round(SECONDS / model.opt.timestep)
    radius = {model.geom(g).id: float(model.geom_size[g][0]) for g in range(model.ngeom)}
    best = math.inf
    for _ in range(repeats):
        mujoco.mj_resetData(model, data)
        started = time.process_time()
        mujoco.mj_step(model, data, steps)
        best = min(best, time.process_time() - started)
    mujoco.mj_resetData(model, data)
    deepest = 0.0
    for _ in range(steps // 5):
        mujoco.mj_step(model, data, 5)
        for c in data.contact[: data.ncon]:
            part = c.geom2 if c.geom1 == 0 else c.geom1
            deepest = max(deepest, -float(c.dist) / radius[part])
    return best, deepest, float(model.opt.timestep)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    choices = "comma list: reduced-implicit (as shipped), reduced-rk4, split2, reduced-euler"
    parser.add_argument("--integrators", default="reduced-implicit,reduced-rk4,split2,reduced-euler", help=choices)
    options = parser.parse_args()
    cost = {}
    for integrator in options.integrators.split(","):
        seconds, sink, gap, substeps = run_rbsim(options.repeats, integrator)
        cost[integrator] = seconds
        print(
            f"rbsim {integrator:13s}: {SECONDS:g} s of motion in {seconds:.2f} CPU-s (dt 1 ms x {substeps} sub-steps), "
            f"deepest part {100 * sink:.1f} % of its radius, joint rows <= {gap:.1e} m"
        )
    print("         targets: <= 5 CPU-s, <= 10 %, <= 1e-12 m")
    found = run_mujoco(options.repeats)
    if found is None:
        print("MuJoCo : not installed (pip install mujoco)")
    else:
        seconds_mj, deepest, step = found
        print(
            f"MuJoCo : {SECONDS:g} s of motion in {seconds_mj:.3f} CPU-s (Euler, dt {step:g} s), deepest contact "
            f"{100 * deepest:.1f} % of its part's radius"
        )
        for integrator, seconds in cost.items():
            print(f"         rbsim ({integrator}) / MuJoCo CPU time {seconds / seconds_mj:.1f}x")
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
