"""Articulated chains in joint coordinates: forward kinematics + ABA (physics/tree/) against MuJoCo's mj_step.

    python benchmarks/bench_aba.py [--quick] [--link-steps N] [--repeats N]

The chains of bench_joints.py (issue 27 and 48): hinge or ball chains of 10, 100, 400, 1,000 and 10,000 capsule
links 0.1 m long, radius 0.01 m, density 1000 kg/m^3, hinge axes world y, released horizontal along world x
from the origin under gravity -9.81 m/s^2 z, dt 1e-3, no contact. MuJoCo's model is bench_joints.py's
(imported: `MujocoRun`, Euler, `mj_step(m, d, nstep)` from the released pose in segments of 1,000 steps),
timed in the same run when `mujoco` is importable, at 10, 100 and 400 links (nested MJCF bodies: 1,000
levels exceed its XML parser's depth).

rbsim, one thread, in a compiled loop:
- "FK+ABA": `forward_kinematics` + `tree_accelerations` at one state (a sagging chain with random rates),
  repeated: the slice's kernels alone;
- "step": the same plus a semi-implicit Euler update in joint coordinates written here (rate += dt qdd,
  then angle += dt rate or u <- u exp(dt omega / 2) normalised), from the released pose in segments of
  1,000 steps as MuJoCo's: the nearest thing to mj_step until the tree integrators exist. Gravity enters
  as each link's external force m g.

"fell" is how far below the start the lowest link is at the end of the last segment [m]: a sanity check (a
ball chain released in a plane falls as the hinge chain does).

Costs are CPU ns per link-step of this process (time.process_time: the 2-core machine is shared, and CPU
time is what load changes least), best of `--repeats`, rbsim and MuJoCo interleaved; "spread" is median /
best - 1 and the load average is printed at the start and the end.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from pathlib import Path

import numba
import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from benchmarks.bench_joints import DT, LINK_LENGTH, MujocoRun, capsule_mass_properties, have_mujoco  # noqa: E402
from rbcli.physics.joints.tables import JOINT_BALL, JOINT_HINGE  # noqa: E402
from rbcli.physics.tree.aba import forward_kinematics, tree_accelerations  # noqa: E402
from rbcli.physics.tree.table import TreeTable, make_tree_work, tree_table, zero_coords  # noqa: E402

SIZES = (10, 100, 400, 1_000, 10_000)
MUJOCO_SIZES = (10, 100, 400)  # MJCF nests bodies: its XML parser refuses 1,000 levels
# Pinocchio's model of a chain takes memory superlinear in its degrees of freedom (4 GB at 400 hinge links,
# 15 GB at 600, pin 4.1.0: a 400-link ball chain's 1,200 do not fit), and below 100 links a Python call per
# ABA hides its rate: it runs at 100 links and up to 400 degrees of freedom
PINOCCHIO_LINKS, PINOCCHIO_DOFS = 100, 400
SEGMENT = 1000  # steps from the released pose, as bench_joints.MujocoRun
GRAVITY = np.array([0.0, 0.0, -9.81])
# the targets (rbsim / MuJoCo) at 10 / 100 / 400 links; per link, 10,000 over 10 links at most 1.5
TARGET_RATIO = {"hinge": {10: 2.0, 100: 5.0, 400: 50.0}, "ball": {10: 2.0, 100: 20.0, 400: 200.0}}


def chain_tree(links: int, joint: str) -> TreeTable:
    """The chain as a tree: link i (principal frame = capsule axis x) joined to link i - 1 at its far end
    (+l/2 x), link 0 to the world at the origin; hinge axes y; at coordinate 0 the chain lies along x."""
    mass, axial, transverse = capsule_mass_properties()
    half = 0.5 * LINK_LENGTH
    anchor_parent = np.tile([half, 0.0, 0.0], (links, 1))
    anchor_parent[0] = 0.0
    return tree_table(
        parent=np.arange(-1, links - 1),
        kind=np.full(links, JOINT_HINGE if joint == "hinge" else JOINT_BALL),
        anchor_parent=anchor_parent,
        anchor_child=np.tile([-half, 0.0, 0.0], (links, 1)),
        axis=np.tile([0.0, 1.0, 0.0], (links, 1)),
        rest_q=np.tile([1.0, 0.0, 0.0, 0.0], (links, 1)),
        mass=np.full(links, mass),
        inertia=np.tile([axial, transverse, transverse], (links, 1)),
    )


@numba.njit(cache=True)
def _kernel_steps(steps, tree, work, coord, rate, x, q, P, L, force, torque, joint_force, qdd):  # noqa: ANN001, ANN202
    """`steps` rounds of forward kinematics + ABA at one state."""
    for _ in range(steps):
        forward_kinematics(tree, coord, rate, work, x, q, P, L)
        tree_accelerations(tree, work, force, torque, joint_force, qdd)


@numba.njit(cache=True)
def _euler_steps(steps, dt, tree, work, coord0, coord, rate, x, q, P, L, force, torque, joint_force, qdd):  # noqa: ANN001, ANN202
    """`steps` semi-implicit Euler steps in joint coordinates, restarting from coord0 at rest every SEGMENT."""
    for step in range(steps):
        if step % SEGMENT == 0:
            coord[:] = coord0
            rate[:] = 0.0
        forward_kinematics(tree, coord, rate, work, x, q, P, L)
        tree_accelerations(tree, work, force, torque, joint_force, qdd)
        for d in range(rate.shape[0]):
            rate[d] += dt * qdd[d]
        for i in range(tree.parent.shape[0]):
            c0, d0 = tree.coord_start[i], tree.dof_start[i]
            if tree.kind[i] == JOINT_HINGE:
                coord[c0] += dt * rate[d0]
            elif tree.kind[i] == JOINT_BALL:  # u <- u (cos(h |w| / 2), sin(h |w| / 2) w / |w|)
                wx, wy, wz = rate[d0], rate[d0 + 1], rate[d0 + 2]
                norm = math.sqrt(wx * wx + wy * wy + wz * wz)
                cw = math.cos(0.5 * dt * norm)
                sw = 0.5 * dt if norm == 0.0 else math.sin(0.5 * dt * norm) / norm
                bx, by, bz = sw * wx, sw * wy, sw * wz
                aw, ax, ay, az = coord[c0], coord[c0 + 1], coord[c0 + 2], coord[c0 + 3]
                uw = aw * cw - ax * bx - ay * by - az * bz
                ux = aw * bx + ax * cw + ay * bz - az * by
                uy = aw * by - ax * bz + ay * cw + az * bx
                uz = aw * bz + ax * by - ay * bx + az * cw
                inv = 1.0 / math.sqrt(uw * uw + ux * ux + uy * uy + uz * uz)
                coord[c0], coord[c0 + 1], coord[c0 + 2], coord[c0 + 3] = uw * inv, ux * inv, uy * inv, uz * inv


class TreeRun:
    """A chain's tree, work and state, timed as FK+ABA at a fixed state and as Euler steps."""

    def __init__(self, links: int, joint: str) -> None:
        self.tree = chain_tree(links, joint)
        rng = np.random.default_rng(links)
        self.coord0 = zero_coords(self.tree)
        self.coord = self.coord0.copy()
        if joint == "hinge":  # a sagging pose: link i turned by 0.3 sin(pi i / n) about y, relative angles
            self.coord[:] = np.diff(0.3 * np.sin(np.pi * np.arange(links) / links), prepend=0.0)
        self.rate = rng.normal(size=int(self.tree.dof_start[-1]))
        self.work = make_tree_work(self.tree)
        self.state = [np.zeros((links, 3)), np.zeros((links, 4)), np.zeros((links, 3)), np.zeros((links, 3))]
        self.force = np.ascontiguousarray(self.tree.mass[:, None] * GRAVITY)
        self.torque = np.zeros((links, 3))
        self.joint_force = np.zeros_like(self.rate)
        self.qdd = np.zeros_like(self.rate)
        self.kernels(1)
        self.steps(1)

    def kernels(self, steps: int) -> float:
        started = time.process_time()
        _kernel_steps(steps, self.tree, self.work, self.coord, self.rate, *self.state, self.force, self.torque,
                      self.joint_force, self.qdd)  # fmt: skip
        return time.process_time() - started

    def steps(self, steps: int) -> float:
        coord, rate = self.coord0.copy(), np.zeros_like(self.rate)
        started = time.process_time()
        _euler_steps(steps, DT, self.tree, self.work, self.coord0, coord, rate, *self.state, self.force, self.torque,
                     self.joint_force, self.qdd)  # fmt: skip
        elapsed = time.process_time() - started
        self.sag = float(-self.state[0][:, 2].min())  # how far the chain fell in its last segment [m]
        return elapsed


def have_pinocchio() -> bool:
    try:
        import pinocchio  # noqa: F401
    except ImportError:
        return False
    return True


class PinocchioRun:
    """The same chain as a Pinocchio model (`pip install pin`: not a dependency of rbsim, a reference
    point): revolute-y or spherical joints at each link's near end, the capsule's mass, centre (+l/2 x)
    and principal moments; `pinocchio.aba(model, data, q, v, tau)` at the state TreeRun's FK+ABA uses (its
    angles, random rates, gravity -9.81 z as Pinocchio's default), the same work as FK+ABA: Pinocchio's
    ABA computes its kinematics itself. Called from Python (~1 us a call), so its rate per link is
    measured from 100 links up to 400 degrees of freedom (PINOCCHIO_LINKS, PINOCCHIO_DOFS)."""

    def __init__(self, links: int, joint: str, coord: np.ndarray, rate: np.ndarray) -> None:
        import pinocchio as pin

        self.pin = pin
        mass, axial, transverse = capsule_mass_properties()
        model = pin.Model()
        parent = 0
        for i in range(links):
            at = pin.SE3(np.eye(3), np.array([LINK_LENGTH if i else 0.0, 0.0, 0.0]))
            kind = pin.JointModelRY() if joint == "hinge" else pin.JointModelSpherical()
            parent = model.addJoint(parent, kind, at, f"j{i}")
            inertia = pin.Inertia(
                mass, np.array([0.5 * LINK_LENGTH, 0.0, 0.0]), np.diag([axial, transverse, transverse])
            )
            model.appendBodyToJoint(parent, inertia, pin.SE3.Identity())
        self.model, self.data = model, model.createData()
        self.q = coord.copy() if joint == "hinge" else pin.neutral(model)
        self.v = rate.copy()
        self.tau = np.zeros(model.nv)

    def run(self, calls: int) -> float:
        aba, model, data, q, v, tau = self.pin.aba, self.model, self.data, self.q, self.v, self.tau
        started = time.process_time()
        for _ in range(calls):
            aba(model, data, q, v, tau)
        return time.process_time() - started


def spread(times: list[float]) -> float:
    return statistics.median(times) / min(times) - 1.0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer link-steps and repeats (a smoke run)")
    parser.add_argument("--link-steps", type=float, default=4e6, help="rbsim link-steps per timed run")
    parser.add_argument("--repeats", type=int, default=5)
    options = parser.parse_args()
    budget, repeats = (4e5, 3) if options.quick else (options.link_steps, options.repeats)
    mujoco_present, pinocchio_present = have_mujoco(), have_pinocchio()
    print(f"load average {os.getloadavg()[0]:.2f} at the start, {os.cpu_count()} cores; CPU ns per link-step")
    print("FK+ABA: the kernels at one state; step: + semi-implicit Euler; MuJoCo: mj_step (Euler);")
    print("ratio = MuJoCo / step; spread = median / best - 1 of the repeats (FK+ABA / step / MuJoCo)")
    print(
        "Pinocchio: pinocchio.aba at FK+ABA's state (100 links to 400 rates: a Python call each), / FK+ABA its ratio"
        if pinocchio_present
        else "Pinocchio: not installed (pip install pin), no ratio"
    )
    print(
        f"{'chain':>6} {'links':>6} {'FK+ABA':>7} {'step':>7} {'MuJoCo':>8} {'ratio':>7} {'target':>6}"
        f" {'fell':>7} {'spread':>16}"
    )
    for joint in ("hinge", "ball"):
        cost = {}
        for links in SIZES:
            steps = max(SEGMENT, int(budget / links))
            run = TreeRun(links, joint)
            mj = MujocoRun(links, joint) if mujoco_present and links in MUJOCO_SIZES else None
            mj_steps = mj.steps_for(0.5 / (4 if options.quick else 1)) if mj is not None else 0
            fits = PINOCCHIO_LINKS <= links and run.rate.shape[0] <= PINOCCHIO_DOFS
            pin = PinocchioRun(links, joint, run.coord, run.rate) if pinocchio_present and fits else None
            kernel_times, step_times, mj_times, pin_times = [], [], [], []
            for _ in range(repeats):  # interleaved, so a change of load hits both engines alike
                kernel_times.append(run.kernels(steps))
                step_times.append(run.steps(steps))
                if mj is not None:
                    mj_times.append(mj.run(mj_steps))
                if pin is not None:
                    pin_times.append(pin.run(steps))
            per = 1e9 / (links * steps)
            kernel_ns, step_ns = min(kernel_times) * per, min(step_times) * per
            cost[links] = step_ns
            mj_ns = 1e9 * min(mj_times) / (links * mj_steps) if mj_times else float("nan")
            target = TARGET_RATIO[joint].get(links, float("nan"))
            spreads = f"{spread(kernel_times):3.0%}/{spread(step_times):3.0%}" + (
                f"/{spread(mj_times):3.0%}" if mj_times else ""
            )
            pinocchio = ""
            if pin_times:
                pin_ns = 1e9 * min(pin_times) / (links * steps)
                pinocchio = f"  Pinocchio {pin_ns:6.1f} ns, / FK+ABA {pin_ns / kernel_ns:5.2f}"
            print(
                f"{joint:>6} {links:>6} {kernel_ns:7.1f} {step_ns:7.1f} {mj_ns:8.1f} {mj_ns / step_ns:7.2f}"
                f" {target:6.1f} {run.sag:7.3f} {spreads:>16}{pinocchio}"
            )
        flat = cost[SIZES[-1]] / cost[SIZES[0]]
        print(f"{joint}: step cost per link at {SIZES[-1]:,} / at {SIZES[0]} links = {flat:.2f} (target <= 1.5)")
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
