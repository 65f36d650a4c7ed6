"""Jointed chains: rbsim's multiplier solver against MuJoCo 4.0 (Euler), measured in the same run.

    python benchmarks/bench_joints.py [--quick] [--link-steps N] [--repeats N] [--full-step]
                                      [--integrators split2,reduced-euler,reduced-rk4]

The issue's chains (issue 27): hinge or ball chains of 10, 100, 400 (and, for rbsim, 10,000) capsule
links, 0.1 m long (the segment between the two joint anchors), radius 0.01 m, density 1000 kg/m^3, hinge
axes parallel (world y), released horizontal (along world x, the first link hinged to the world at the
origin) under gravity -9.81 m/s^2 z, dt 1e-3, no contact.

MuJoCo: the chain as nested bodies in an MJCF generated here (capsule geoms with contype = conaffinity
= 0, one hinge or ball joint per link), integrator Euler, timed as `mj_step(m, d, nstep)` from the
released pose in segments of 1,000 steps (longer Euler runs of long chains go unstable). Its coordinates
are the joint angles, so its constraint error is 0 by construction.

rbsim: the solver alone, as the RATTLE-type step uses it: per step one `factor_rows` and three
`solve_rows` (the simplified Newton of the position projection and the velocity projection) on the rows of
the chain in a sagging pose (link i turned by 0.3 sin(pi i / n) about y, so the rows are not axis-aligned),
in a compiled loop, rhs = G v for random body velocities v. The error beside each rate is what one
velocity projection leaves, |G v'| / |G v| with v' = v - W G^T lambda (computed in numpy from the rows,
not from the factor). `--full-step` adds the whole split2 step (`full_step_chain`: the chain written as
an rbsim scene, its rate, the anchor gap and hinge-axis misalignment after the run, and its ratio to
MuJoCo); it needs the joints integration (scene format, stages) and says why it did not run on a
checkout without it.

Rates are link-steps per CPU second of this process (links x steps / time.process_time: the machine is
shared, and CPU time is what load changes least), best of `--repeats`, rbsim and MuJoCo interleaved; the
median/best spread and the load average are printed beside them.
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

from rbcli.physics.joints.solver import factor_rows, joint_graph, make_solver_work, solve_rows  # noqa: E402

LINK_LENGTH = 0.1  # [m]
LINK_RADIUS = 0.01  # [m]
DENSITY = 1000.0  # [kg/m^3]
DT = 1e-3  # [s]
SIZES = (10, 100, 400)
RBSIM_SIZES = (10, 100, 400, 10_000)
# MuJoCo 4.0 Euler as the issue measured it (link-steps/s), and the issue's targets (split2 / MuJoCo)
ISSUE_MUJOCO = {("hinge", 10): 2.3e6, ("hinge", 100): 1.3e6, ("hinge", 400): 1.3e5,
                ("ball", 10): 1.1e6, ("ball", 100): 9.0e4, ("ball", 400): 5.1e3}  # fmt: skip
TARGET_RATIO = {10: 2.0, 100: 5.0, 400: 20.0}
TARGET_FLAT = 1.5  # cost per link from 10 to 10,000 links, at most this ratio
MUJOCO_SECONDS = 0.5  # CPU seconds per timed MuJoCo run
MUJOCO_SEGMENT = 1000  # steps from the released pose per segment: 1 s, well before Euler's instability (4.4 s
# for the 100-link hinge chain, measured)


def capsule_mass_properties() -> tuple[float, float, float]:
    """(mass [kg], axial moment, transverse moment about the centre [kg m^2]) of a capsule: a cylinder of
    length l and radius r plus two hemispheres (each of mass m_h = 2/3 pi r^3 rho, axial 2/5 m_h r^2,
    transverse 2/5 m_h r^2 + m_h (l^2 / 4 + 3 l r / 8) about the centre: the parallel-axis theorem from the
    hemisphere's centre of mass 3 r / 8 from its flat face)."""
    r, l = LINK_RADIUS, LINK_LENGTH
    m_c, m_h = DENSITY * math.pi * r * r * l, DENSITY * 2.0 / 3.0 * math.pi * r**3
    axial = m_c * r * r / 2 + 2 * (0.4 * m_h * r * r)
    transverse = m_c * (3 * r * r + l * l) / 12 + 2 * (0.4 * m_h * r * r - m_h * (3 * r / 8) ** 2)
    transverse += 2 * m_h * (l / 2 + 3 * r / 8) ** 2
    return m_c + 2 * m_h, axial, transverse


def chain_rows(links: int, joint: str, sag: float = 0.3) -> dict[str, np.ndarray]:
    """The chain's bodies, joints and rows in a sagging pose: anchors p_i, link i from p_i to p_i+1 turned by
    theta_i = sag sin(pi i / n) about y; joint i connects link i - 1 (the world for i = 0) and link i at p_i.
    Rows as tests/physics/test_joint_solver.py's hinge_rows (anchor velocities equal; a hinge adds w_a - w_b
    normal to the axis)."""
    theta = sag * np.sin(np.pi * np.arange(links) / links)
    direction = np.stack([np.cos(theta), np.zeros(links), -np.sin(theta)], axis=1)
    anchor = np.concatenate([np.zeros((1, 3)), np.cumsum(LINK_LENGTH * direction, axis=0)])
    center = anchor[:-1] + 0.5 * LINK_LENGTH * direction
    mass, axial, transverse = capsule_mass_properties()
    c, s = np.cos(theta), np.sin(theta)
    rotation = np.zeros((links, 3, 3))  # world from body (body x = the link's axis), about y by theta
    rotation[:, 0, 0], rotation[:, 0, 2], rotation[:, 1, 1], rotation[:, 2, 0], rotation[:, 2, 2] = c, s, 1, -s, c
    inv_inertia = rotation @ np.diag([1 / axial, 1 / transverse, 1 / transverse]) @ rotation.transpose(0, 2, 1)
    per_joint = 5 if joint == "hinge" else 3
    r_a = anchor[:-1] - np.concatenate([np.zeros((1, 3)), center[:-1]])  # anchor from body a (unused at the world)
    r_b = anchor[:-1] - center
    eye = np.eye(3)
    jac_a, jac_b = np.zeros((links, per_joint, 6)), np.zeros((links, per_joint, 6))
    jac_a[:, :3, :3], jac_b[:, :3, :3] = eye, -eye
    jac_a[:, :3, 3:] = np.cross(r_a[:, None, :], eye[None, :, :])  # row e_k: (e_k, r x e_k)
    jac_b[:, :3, 3:] = -np.cross(r_b[:, None, :], eye[None, :, :])
    if joint == "hinge":  # axis y: w_a - w_b has no x or z component
        jac_a[:, 3, 3], jac_a[:, 4, 5], jac_b[:, 3, 3], jac_b[:, 4, 5] = 1.0, 1.0, -1.0, -1.0
    return {
        "body_a": np.arange(-1, links - 1, dtype=np.int64),
        "body_b": np.arange(links, dtype=np.int64),
        "ground": np.zeros(links, dtype=bool),
        "row_count": np.full(links, per_joint, dtype=np.int64),
        "row_start": per_joint * np.arange(links, dtype=np.int64),
        "jac_a": np.ascontiguousarray(jac_a.reshape(-1, 6)),
        "jac_b": np.ascontiguousarray(jac_b.reshape(-1, 6)),
        "inv_mass": np.full(links, 1.0 / mass),
        "inv_inertia": np.ascontiguousarray(inv_inertia),
    }


@numba.njit(cache=True)
def _solver_steps(
    steps, graph, work, row_start, row_count, body_a, body_b, jac_a, jac_b, inv_mass, inv_inertia, rhs, out
):  # noqa: ANN001, ANN202, E501
    """`steps` rounds of one factor and three solves (the step's use of the solver), in compiled code."""
    redundant = 0
    for _ in range(steps):
        redundant += factor_rows(graph, work, row_start, row_count, body_a, body_b, jac_a, jac_b, inv_mass, inv_inertia)
        for _ in range(3):
            solve_rows(graph, work, row_start, row_count, body_a, body_b, rhs, out)
    return redundant


@numba.njit(cache=True)
def _factor_steps(steps, graph, work, row_start, row_count, body_a, body_b, jac_a, jac_b, inv_mass, inv_inertia):  # noqa: ANN001, ANN202, E501
    """`steps` factors alone: the factor's share of a step."""
    redundant = 0
    for _ in range(steps):
        redundant += factor_rows(graph, work, row_start, row_count, body_a, body_b, jac_a, jac_b, inv_mass, inv_inertia)
    return redundant


def velocity_rows(s: dict[str, np.ndarray], velocity: np.ndarray) -> np.ndarray:
    """G v: each row's velocity error for body velocities (v, omega) `velocity` (bodies, 6), world frame."""
    rows = np.repeat(np.arange(s["body_a"].shape[0]), s["row_count"])
    out = np.zeros(s["jac_a"].shape[0])
    for body, jac in ((s["body_a"][rows], s["jac_a"]), (s["body_b"][rows], s["jac_b"])):
        moving = body >= 0
        out[moving] += np.einsum("ri,ri->r", jac[moving], velocity[body[moving]])
    return out


class SolverRun:
    """The chain's rows, graph and work, and `steps` rounds of factor + 3 solves as one timed call."""

    def __init__(self, links: int, joint: str) -> None:
        self.rows = chain_rows(links, joint)
        s = self.rows
        graph = joint_graph(s["body_a"], s["body_b"], s["ground"], s["row_count"])
        # rhs = G v for random body velocities: the velocity projection's system (v' = v - W G^T lambda)
        self.velocity = np.random.default_rng(links).normal(size=(links, 6))
        self.rhs = velocity_rows(s, self.velocity)
        self.out = np.zeros_like(self.rhs)
        self.args = (graph, make_solver_work(graph), s["row_start"], s["row_count"], s["body_a"], s["body_b"])
        self.args = (*self.args, s["jac_a"], s["jac_b"], s["inv_mass"], s["inv_inertia"])
        assert _solver_steps(1, *self.args, self.rhs, self.out) == 0 and _factor_steps(1, *self.args) == 0

    def run(self, steps: int) -> float:
        started = time.process_time()
        _solver_steps(steps, *self.args, self.rhs, self.out)
        return time.process_time() - started

    def run_factor(self, steps: int) -> float:
        started = time.process_time()
        _factor_steps(steps, *self.args)
        return time.process_time() - started

    def constraint_error(self) -> float:
        """|G v'| / |G v| after one velocity projection v' = v - W G^T lambda, A lambda = G v."""
        s, lam = self.rows, self.out
        rows = np.repeat(np.arange(s["body_a"].shape[0]), s["row_count"])
        impulse = np.zeros_like(self.velocity)
        for body, jac in ((s["body_a"][rows], s["jac_a"]), (s["body_b"][rows], s["jac_b"])):
            moving = body >= 0
            np.add.at(impulse, body[moving], jac[moving] * lam[moving, None])
        change = np.concatenate(
            [impulse[:, :3] * s["inv_mass"][:, None], np.einsum("bij,bj->bi", s["inv_inertia"], impulse[:, 3:])], axis=1
        )
        return float(np.linalg.norm(velocity_rows(s, self.velocity - change)) / np.linalg.norm(self.rhs))


def mujoco_xml(links: int, joint: str) -> str:
    """The chain as MJCF: nested bodies, a capsule from the joint to the next anchor, no contact."""
    body = ""
    for _ in range(links):
        body = (
            f'<body pos="{LINK_LENGTH} 0 0">'
            f'<joint type="{joint}" pos="0 0 0" axis="0 1 0" damping="0"/>'
            f'<geom type="capsule" fromto="0 0 0 {LINK_LENGTH} 0 0" size="{LINK_RADIUS}" density="{DENSITY}"'
            f' contype="0" conaffinity="0"/>'
            f"{body}</body>"
        )
    body = body.replace(f'<body pos="{LINK_LENGTH} 0 0">', '<body pos="0 0 0">', 1)  # the first link at the origin
    return (
        f'<mujoco><option timestep="{DT}" integrator="Euler" gravity="0 0 -9.81"/>'
        f"<worldbody>{body}</worldbody></mujoco>"
    )


class MujocoRun:
    """The chain in MuJoCo; `mj_step(m, d, nstep=steps)` from the released pose as one timed call."""

    def __init__(self, links: int, joint: str) -> None:
        import mujoco

        self.mujoco = mujoco
        self.model = mujoco.MjModel.from_xml_string(mujoco_xml(links, joint))
        self.data = mujoco.MjData(self.model)
        mujoco.mj_step(self.model, self.data, nstep=10)  # warm: first-call allocations

    def steps_for(self, seconds: float) -> int:
        """Steps that take about `seconds` (its cost per link grows with the chain: a dense mass matrix)."""
        return max(10, int(10 * seconds / max(self.run(10), 1e-6)))

    def run(self, steps: int) -> float:
        """CPU seconds of `steps` steps, in segments of at most MUJOCO_SEGMENT from the released pose (a long
        Euler run of a long chain goes unstable: MuJoCo then warns and resets itself, which would be timed)."""
        elapsed = 0.0
        while steps > 0:
            segment = min(steps, MUJOCO_SEGMENT)
            self.mujoco.mj_resetData(self.model, self.data)
            started = time.process_time()
            self.mujoco.mj_step(self.model, self.data, nstep=segment)
            elapsed += time.process_time() - started
            steps -= segment
        return elapsed


def chain_scene_yaml(links: int, joint: str, duration: float, integrator: str = "split2") -> str:
    """The chain as an rbsim scene (the joints format of docs/joints.md): capsule links filled with ~30
    particles each (mass set to the capsule's: the lattice only shapes the inertia), released horizontal."""
    mass = capsule_mass_properties()[0]
    axis = ", axis: [0, 1, 0]" if joint == "hinge" else ""
    lines = [
        f"name: {joint}_chain_{links}",
        f"simulation: {{dt: {DT}, duration: {duration}, integrator: {integrator}, record: {{every: 1000000}}}}",
        "gravity: [0, 0, -9.81]",
        "bodies:",
    ]
    for i in range(links):
        shape = f"{{type: capsule, radius: {LINK_RADIUS}, height: {LINK_LENGTH}, axis: x}}"
        x = (i + 0.5) * LINK_LENGTH
        lines.append(f"  - {{name: link{i}, shape: {shape}, count: 30, mass: {mass!r}, position: [{x!r}, 0, 0]}}")
    lines.append("joints:")
    for i in range(links):
        parent = "world" if i == 0 else f"link{i - 1}"
        anchor = f"[{i * LINK_LENGTH!r}, 0, 0]"
        lines.append(f"  - {{name: j{i}, type: {joint}, bodies: [{parent}, link{i}], anchor: {anchor}{axis}}}")
    return "\n".join(lines) + "\n"


def _rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate v (3,) by each unit quaternion q (n, 4), (w, x, y, z)."""
    w, u = q[:, :1], q[:, 1:]
    t = 2.0 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


FULL_STEP_REFUSED: list[str] = []  # why the scene loader refused the chain (printed once)


def full_step_chain(links: int, joint: str, steps: int, integrator: str = "split2") -> tuple[float, float] | None:
    """The chain as an rbsim scene run by `integrator` (split2 with its joint stages, or one in joint
    coordinates: reduced-euler, reduced-rk4): (link-steps per CPU second, the
    largest anchor gap [m] after the run, or the hinge axes' misalignment [rad] if larger). None when this
    checkout's scene format has no joints yet (the hook waits for the joints integration to merge)."""
    import tempfile

    import rbcli

    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "chain.yaml"
        path.write_text(chain_scene_yaml(links, joint, duration=(steps + 1) * DT, integrator=integrator))
        try:
            simulation = rbcli.Simulation(path)
        except Exception as error:  # noqa: BLE001 - a loader without joints refuses the section
            if not FULL_STEP_REFUSED:
                FULL_STEP_REFUSED.append(f"{type(error).__name__}: {str(error).splitlines()[0][:120]}")
                print(f"  full step not run: {FULL_STEP_REFUSED[0]}")
            return None
    simulation.step(1)  # compiles (or loads the kernels)
    started = time.process_time()
    simulation.step(steps)
    elapsed = time.process_time() - started
    state = simulation.state
    half = np.array([0.5 * LINK_LENGTH, 0.0, 0.0])
    near, far = state.x - _rotate(state.q, half), state.x + _rotate(state.q, half)
    gap = max(float(np.linalg.norm(near[0])), float(np.max(np.linalg.norm(near[1:] - far[:-1], axis=1), initial=0.0)))
    if joint == "hinge":
        axes = _rotate(state.q, np.array([0.0, 1.0, 0.0]))
        gap = max(gap, float(np.max(np.linalg.norm(np.cross(axes[1:], axes[:-1]), axis=1), initial=0.0)))
        gap = max(gap, float(np.linalg.norm(np.cross(axes[0], [0.0, 1.0, 0.0]))))
    return links * steps / elapsed, gap


def spread(times: list[float]) -> float:
    return statistics.median(times) / min(times) - 1.0


def have_mujoco() -> bool:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer steps and repeats (a smoke run)")
    parser.add_argument("--link-steps", type=float, default=1e6, help="rbsim link-steps per timed run")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument(
        "--full-step", action="store_true", help="also run the chains as rbsim scenes (split2 + joint stages)"
    )
    parser.add_argument(
        "--integrators",
        default="split2",
        help="comma list of the whole steps --full-step runs [default: split2; "
        "reduced-euler, reduced-rk4: the chain in joint coordinates, docs/trees.md]",
    )
    options = parser.parse_args()
    whole_steps = [name for name in options.integrators.split(",") if name]
    budget, repeats = (2e5, 3) if options.quick else (options.link_steps, options.repeats)
    mujoco_present = have_mujoco()
    print(f"load average {os.getloadavg()[0]:.2f} at the start, {os.cpu_count()} cores; CPU time of this process")
    print("link-steps per CPU second; rbsim = factor_rows + 3 solve_rows per step (the solver alone);")
    print("error = |G v'| / |G v| after one velocity projection; spread = median / best - 1 of the repeats")
    print(
        f"{'chain':>6} {'links':>6} {'MuJoCo':>9} {'(issue)':>9} {'rbsim':>9} {'ratio':>6} {'target':>6}"
        f" {'ns/link':>8} {'factor':>7} {'error':>8} {'spread':>11}"
        + "".join(f" {name:>13} {'gap':>8} {'ratio':>6}" for name in whole_steps if options.full_step)
    )
    for joint in ("hinge", "ball"):
        cost = {}
        whole_cost: dict[str, dict[int, float]] = {}
        for links in RBSIM_SIZES:
            steps = max(10, int(budget / links))
            solver = SolverRun(links, joint)
            mj = MujocoRun(links, joint) if mujoco_present and links in TARGET_RATIO else None
            mj_steps = mj.steps_for(MUJOCO_SECONDS / (4 if options.quick else 1)) if mj is not None else 0
            times, factor_times, mj_times = [], [], []
            for _ in range(repeats):  # interleaved, so a change of load hits both engines alike
                times.append(solver.run(steps))
                factor_times.append(solver.run_factor(steps))
                if mj is not None:
                    mj_times.append(mj.run(mj_steps))
            rate = links * steps / min(times)
            cost[links] = 1e9 / rate
            mj_rate = links * mj_steps / min(mj_times) if mj_times else float("nan")
            ratio = rate / mj_rate
            spreads = f"{spread(times):4.0%}" + (f" / {spread(mj_times):4.0%}" if mj_times else "")
            # the whole steps at the sizes MuJoCo runs; the reduced ones (O(n) per step) at 10,000 links too
            fulls = [
                full_step_chain(links, joint, steps, name)
                if links in TARGET_RATIO or name.startswith("reduced")
                else None
                for name in whole_steps
                if options.full_step
            ]
            for name, full in zip(whole_steps, fulls, strict=False):
                if full is not None:
                    whole_cost.setdefault(name, {})[links] = 1e9 / full[0]
            print(
                f"{joint:>6} {links:>6} {mj_rate:9.3g} {ISSUE_MUJOCO.get((joint, links), float('nan')):9.2g}"
                f" {rate:9.3g} {ratio:6.2f} {TARGET_RATIO.get(links, float('nan')):6.1f} {cost[links]:8.0f}"
                f" {min(factor_times) / min(times):7.0%} {solver.constraint_error():8.1e} {spreads:>11}"
                + "".join(
                    f" {full[0]:13.3g} {full[1]:8.1e} {full[0] / mj_rate:6.2f}" if full else f" {'':>29}"
                    for full in fulls
                )  # fmt: skip
            )
        flat = cost[RBSIM_SIZES[-1]] / cost[RBSIM_SIZES[0]]
        print(
            f"{joint}: cost per link at {RBSIM_SIZES[-1]:,} / at {RBSIM_SIZES[0]} links = {flat:.2f}"
            f" (target <= {TARGET_FLAT})"
        )
        for name, costs in whole_cost.items():
            if RBSIM_SIZES[-1] in costs:
                print(
                    f"{joint}: {name} whole step, ns per link-step {costs[RBSIM_SIZES[0]]:.0f} at {RBSIM_SIZES[0]}"
                    f" links, {costs[RBSIM_SIZES[-1]]:.0f} at {RBSIM_SIZES[-1]:,}: ratio"
                    f" {costs[RBSIM_SIZES[-1]] / costs[RBSIM_SIZES[0]]:.2f} (target <= {TARGET_FLAT})"
                )
    print(f"load average {os.getloadavg()[0]:.2f} at the end")


if __name__ == "__main__":
    main()
