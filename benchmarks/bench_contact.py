"""The sphere pile of the collisions issue (18): rbsim's contact against MuJoCo, in one process.

    python benchmarks/bench_contact.py [--quick] [--no-mujoco] [--big] [--sections pile,far,idle,scenes,primitives]

Rows without a thread count run on rbsim's default (auto: the governor of runner/governor.py chooses one
thread or every core as the run goes, by measured speed); "all cores" rows run the contact search on every
core throughout (physics/contact/threaded.py: issue 45's "pile on 2 threads" on a 2-core machine); "1
thread" rows are the serial search.
1,000 spheres (radius 0.05 m, density 1000 kg/m^3) on a jittered 10 x 10 x 10 lattice (spacing 0.12 m,
lowest centres at z = 0.3 m, jitter +-0.01 m in x and y, numpy seed 0) dropped into a box (ground z = 0,
walls at |x|, |y| = 0.7 m), gravity -9.81, dt = 2e-3, 1,000 steps. Rows:
  rbsim, each sphere one particle (one contact sphere), split2 and semi-implicit, through the public
    `rbcli.Simulation.step` (what a user calls; no recording);
  rbsim, each sphere a 13-particle cloud (a centre sphere and 12 at the vertices of an icosahedron);
  MuJoCo (the installed version): Euler, CG solver with its default iterations, tolerance and cone,
    one sphere geom per free body, the floor a plane and the walls box geoms;
  --big: the same lattice 47 x 47 x 46 (101,614 spheres, walls moved out to fit), 200 steps: the
    per-sphere rate against the 1,000-sphere rate (a grid walk out of cache would show here).
Stability checks of each rbsim row (the issue's): finite states; total energy (kinetic + gravity + the
contact springs') never more than 1 % above its start; no sphere below z = -r or outside the box; at
the end, the deepest overlap under 5 % of the radius and the kinetic energy under 1 % of its peak.
Sphere-steps per second = spheres x steps / wall seconds of the stepping alone (compile excluded);
contact pairs per second counts the contacts evaluated. `bench_speed.py --sections contact` runs this.
far: two bricks 5 m apart with a `contact:` section (nothing touches) against the same scene without
  one, ns per step, best of 5 interleaved blocks (target <= 1.2x).
idle: issue 47 item 6's far-apart scenes (two tumbling 0.2 m boxes 5 m apart, no gravity, a ground
  100 m below) and variants (per-step calls or one call after reset(), no reset, not spinning, the
  plane near or far, nearer boxes, balls, other integrators), CPU ns per step with and without
  `contact:` measured in the same run (target <= 1.2x each).
scenes: steps/s of dominoes.yaml and container_mix.yaml (broad-phase work: sphere pairs tested).
primitives: a box and a capsule resting and sliding on the ground as their primitive (issue 47 slice 2)
  and as their lattice spheres (`contact.primitives: false`), CPU us per step in the same run.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import rbcli  # noqa: E402
from rbcli.physics.contact.tables import COUNT_CONTACTS, STAT_ENERGY, STAT_MAX_PENETRATION  # noqa: E402
from rbcli.scene.compile import compile_scene  # noqa: E402
from rbcli.scene.spec import BodySpec, ContactSpec, PlaneSpec, RecordSpec, SceneSpec, SimulationSpec  # noqa: E402

RADIUS = 0.05
DENSITY = 1000.0
MASS = DENSITY * 4.0 / 3.0 * math.pi * RADIUS**3
SPACING = 0.12
DT = 2e-3
GRAVITY = np.array([0.0, 0.0, -9.81])
TARGET_RATIO = 30.0  # x MuJoCo CG, sphere-steps/s
TARGET_THREADS_RATIO = 45.0  # issue 45: the pile on 2 threads, idle
TARGET_CLOUD_RATE = 1.5e5  # body-steps/s of the 13-particle row
TARGET_SCALING = 1.5  # the 10^3-sphere rate / the 10^5-sphere rate, per sphere


def lattice(shape: tuple[int, int, int], seed: int = 0) -> np.ndarray:
    """Jittered lattice centres [m], x fastest, centred in x and y, lowest layer at z = 0.3."""
    nx, ny, nz = shape
    rng = np.random.default_rng(seed)
    k, j, i = np.meshgrid(np.arange(nz), np.arange(ny), np.arange(nx), indexing="ij")
    x = (i.ravel() - (nx - 1) / 2) * SPACING + rng.uniform(-0.01, 0.01, i.size)
    y = (j.ravel() - (ny - 1) / 2) * SPACING + rng.uniform(-0.01, 0.01, i.size)
    z = 0.3 + k.ravel() * SPACING
    return np.stack([x, y, z], axis=1)


def icosahedron() -> np.ndarray:
    phi = (1 + 5**0.5) / 2
    v = np.array([(0, s1, s2 * phi) for s1 in (-1, 1) for s2 in (-1, 1)], dtype=float)
    v = np.concatenate([v, v[:, [1, 2, 0]], v[:, [2, 0, 1]]])
    return v / np.linalg.norm(v[0])


def pile(shape: tuple[int, int, int] = (10, 10, 10), *, cloud: bool = False, integrator: str = "split2",
         steps: int = 1000) -> tuple[SceneSpec, float]:  # fmt: skip
    """The pile scene and its wall half-width [m]."""
    centres = lattice(shape)
    half = max(0.7, max(shape[0], shape[1]) * SPACING / 2 + 0.1)
    if cloud:  # 13 spheres inside the 5 cm ball: a 3 cm centre and 12 of 2 cm at 3 cm from it
        points = np.concatenate([np.zeros((1, 3)), 0.03 * icosahedron()])
        radii = np.array([0.03] + [0.02] * 12)
    else:
        points, radii = np.zeros((1, 3)), np.array([RADIUS])
    masses = np.full(len(points), MASS / len(points))
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    bodies = tuple(
        BodySpec(
            name=f"s{n}",
            particle_position=points,
            particle_mass=masses,
            particle_radius=radii,
            position=centres[n],
            orientation_wxyz=identity,
        )  # fmt: skip
        for n in range(len(centres))
    )
    walls = [((0, 0, 0), (0, 0, 1)), ((-half, 0, 0), (1, 0, 0)), ((half, 0, 0), (-1, 0, 0)),
             ((0, -half, 0), (0, 1, 0)), ((0, half, 0), (0, -1, 0))]  # fmt: skip
    contact = ContactSpec(planes=tuple(PlaneSpec(np.array(p, float), np.array(n, float)) for p, n in walls))
    sim = SimulationSpec(dt=DT, duration=steps * DT, integrator=integrator, record=RecordSpec(steps))
    spec = SceneSpec(name="pile", simulation=sim, bodies=bodies, gravity=GRAVITY, contact=contact)
    return spec, half


@dataclass
class PileResult:
    label: str
    spheres: int
    steps: int
    seconds: float
    contacts: int
    checks: dict[str, tuple[float, bool]]

    @property
    def rate(self) -> float:
        return self.spheres * self.steps / self.seconds


def run_pile(
    label: str, spec: SceneSpec, half: float, steps: int, check_every: int = 50, threads: int | str | None = None
) -> PileResult:
    """Step the pile through rbcli.Simulation (on `threads`; None: rbsim's default, auto), timing
    only the stepping, checking stability between blocks."""
    sim = rbcli.Simulation(compile_scene(spec), threads=threads)
    sim.step(1)  # compile or load the kernels
    sim.reset()
    m = sim.model.body_mass
    r = RADIUS  # the ball's radius, also for the 13-sphere cloud (whose spheres are smaller)

    def energies() -> tuple[float, float]:
        s = sim.data.state
        v = s.P / m[:, None]
        kinetic = 0.5 * float((m[:, None] * v * v).sum()) + 0.5 * float((sim.state.omega * s.L).sum())
        total = kinetic + float((m * -GRAVITY[2] * s.x[:, 2]).sum()) + float(sim.data.force.contact.stats[STAT_ENERGY])
        return kinetic, total

    _, start = energies()
    peak_kinetic, worst_energy, lowest, outside = 0.0, -np.inf, np.inf, 0.0
    seconds = 0.0
    done = 0
    while done < steps:
        block = min(check_every, steps - done)
        began = time.perf_counter()
        sim.step(block)
        seconds += time.perf_counter() - began
        done += block
        kinetic, total = energies()
        peak_kinetic = max(peak_kinetic, kinetic)
        worst_energy = max(worst_energy, total)
        x = sim.data.state.x
        lowest = min(lowest, float(x[:, 2].min()))
        outside = max(outside, float(np.abs(x[:, :2]).max()) - half)
    s = sim.data.state
    finite = bool(np.isfinite(s.x).all() and np.isfinite(s.P).all() and np.isfinite(s.L).all())
    penetration = float(sim.data.force.contact.stats[STAT_MAX_PENETRATION]) / r
    gain = (worst_energy - start) / abs(start)
    checks = {
        "finite": (float(finite), finite),
        "energy gain": (gain, gain <= 0.01),
        "lowest z / r": (lowest / r, lowest > -r),
        "outside the walls [m]": (outside, outside <= 0.0),
        "overlap at end / r": (penetration, penetration < 0.05),
        "KE end / peak": (kinetic / peak_kinetic, kinetic < 0.01 * peak_kinetic),
    }
    contacts = int(sim.data.force.contact.counters[COUNT_CONTACTS])
    return PileResult(label, sim.model.body_count, steps, seconds, contacts, checks)


def mujoco_pile(steps: int, shape: tuple[int, int, int] = (10, 10, 10)) -> tuple[float, str]:
    """Sphere-steps/s of MuJoCo on the same pile (Euler, CG, its defaults) and its version."""
    import mujoco

    centres = lattice(shape)
    half = 0.7
    bodies = "".join(
        f'<body pos="{float(c[0])!r} {float(c[1])!r} {float(c[2])!r}"><freejoint/><geom type="sphere" size="{RADIUS}" '
        f'density="{DENSITY}"/></body>'
        for c in centres
    )
    walls = (
        f'<geom type="plane" size="0 0 1"/>'
        f'<geom type="box" pos="{half + 0.1} 0 1" size="0.1 {half + 0.2} 1"/>'
        f'<geom type="box" pos="{-half - 0.1} 0 1" size="0.1 {half + 0.2} 1"/>'
        f'<geom type="box" pos="0 {half + 0.1} 1" size="{half + 0.2} 0.1 1"/>'
        f'<geom type="box" pos="0 {-half - 0.1} 1" size="{half + 0.2} 0.1 1"/>'
    )
    xml = (
        f'<mujoco><option timestep="{DT}" integrator="Euler" solver="CG" gravity="0 0 -9.81"/>'
        f'<size memory="256M"/><worldbody>{walls}{bodies}</worldbody></mujoco>'
    )
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    mujoco.mj_step(model, data, nstep=5)
    mujoco.mj_resetData(model, data)
    began = time.perf_counter()
    mujoco.mj_step(model, data, nstep=steps)
    seconds = time.perf_counter() - began
    return len(centres) * steps / seconds, mujoco.__version__


def report(
    results: list[PileResult], mujoco_rate: float | None, mujoco_version: str, big: PileResult | None
) -> list[str]:
    lines = ["### Contact: the 1,000-sphere pile (collisions issue)", ""]
    if mujoco_rate is not None:
        lines.append(f"- MuJoCo {mujoco_version} (Euler, CG, defaults): {mujoco_rate:.3g} sphere-steps/s")
    lines += [
        "",
        "| row | spheres | sphere-steps/s | x MuJoCo CG | contact pairs/s | checks |",
        "|---|---:|---:|---:|---:|---|",
    ]
    for r in results:
        ratio = f"{r.rate / mujoco_rate:.1f}x" if mujoco_rate else "n/a"
        failed = [name for name, (_, passed) in r.checks.items() if not passed]
        summary = "all met" if not failed else "**missed: " + ", ".join(failed) + "**"
        lines.append(
            f"| {r.label} | {r.spheres:,} | {r.rate:.3g} | {ratio} | {r.contacts / r.seconds:.3g} | {summary} |"
        )
    lines.append("")
    for r in results:
        values = ", ".join(f"{name} {value:.3g}" for name, (value, _) in r.checks.items())
        lines.append(f"- {r.label}: {values}")
    if big is not None:
        small = results[0]
        per_small, per_big = small.rate, big.rate
        lines.append(f"- {big.spheres:,} spheres, {big.steps} steps: {per_big:.3g} sphere-steps/s, "
                     f"{per_small / per_big:.2f}x slower per sphere than 1,000 "
                     f"(target <= {TARGET_SCALING})")  # fmt: skip
    if mujoco_rate is not None:
        best = results[0].rate / mujoco_rate
        lines.append(
            f"- target >= {TARGET_RATIO:g}x MuJoCo CG: {'met' if best >= TARGET_RATIO else '**missed**'} ({best:.1f}x)"
        )
        for r in results:
            if r.label.endswith("all cores") and "cloud" not in r.label:
                ratio = r.rate / mujoco_rate
                verdict = "met" if ratio >= TARGET_THREADS_RATIO else "**missed**"
                machine = f"{os.cpu_count()} cores, load {os.getloadavg()[0]:.1f}"
                lines.append(f"- issue 45: the pile on every core >= {TARGET_THREADS_RATIO:g}x MuJoCo CG "
                             f"(idle machine): {verdict} ({ratio:.1f}x; {machine})")  # fmt: skip
    clouds = [r for r in results if "cloud" in r.label]
    if clouds:
        rate = clouds[0].rate
        lines.append(f"- 13-particle row >= {TARGET_CLOUD_RATE:.2g} body-steps/s: "
                     f"{'met' if rate >= TARGET_CLOUD_RATE else '**missed**'} ({rate:.3g})")  # fmt: skip
    return lines


def pile_section(quick: bool, with_mujoco: bool, big: bool) -> list[str]:
    steps = 200 if quick else 1000
    results = []
    rows = (
        ("1 particle, split2", False, "split2", None),
        ("1 particle, split2, all cores", False, "split2", "all"),
        ("1 particle, split2, 1 thread", False, "split2", 1),
        ("1 particle, semi-implicit", False, "semi-implicit", None),
        ("13-particle cloud, split2", True, "split2", None),
        ("13-particle cloud, split2, 1 thread", True, "split2", 1),
    )
    for label, cloud, integrator, threads in rows:
        print(f"pile: {label} ...", flush=True)
        spec, half = pile(cloud=cloud, integrator=integrator, steps=steps)
        results.append(run_pile(label, spec, half, steps, threads=threads))
    mujoco_rate, version = None, ""
    if with_mujoco:
        try:
            print("pile: MuJoCo ...", flush=True)
            mujoco_rate, version = mujoco_pile(steps)
        except ImportError:
            print("MuJoCo is not installed: no ratio", flush=True)
    big_result = None
    if big:
        print("pile: 101,614 spheres ...", flush=True)
        spec, half = pile((47, 47, 46), steps=200)
        big_result = run_pile("1 particle, split2, 10^5", spec, half, 200)
    return report(results, mujoco_rate, version, big_result)


FAR_BRICK = (
    "{{name: {name}, shape: {{type: box, size: [0.2, 0.1, 0.05]}}, spacing: 0.0125, density: 600, "
    "position: [{x}, 0, 1], velocity: [{v}, 0, 0], angular_velocity: [1, 2, 3]}}"
)
TARGET_FAR = 1.2  # a scene with contact and nothing touching / the same without a `contact:` section


def far_scene(contact: bool) -> str:
    """Two of box_drop's bricks (344 contact spheres each) 5 m apart, drifting apart and tumbling, and a
    ground 1,000 km below: with `contact:` nothing ever touches."""
    bricks = "".join("  - " + FAR_BRICK.format(name=f"b{i}", x=5.0 * i, v=0.1 * (2 * i - 1)) + "\n" for i in range(2))
    return ("simulation: {dt: 0.001, steps: 100000, integrator: split2}\ngravity: [0, 0, -9.81]\n"
            + ("contact: {ground: -1.0e6}\n" if contact else "") + "bodies:\n" + bricks)  # fmt: skip


def far_section(quick: bool) -> list[str]:
    """ns per step of the far-apart scene with and without contact: the best of 5 interleaved blocks, and
    each block's ratio. The bricks fall freely (1,000 km above the ground), so each block is faster than
    the last: a quiet skin that could not keep up with the speed shows in the later blocks
    (docs/contact.md)."""
    from rbcli.scene.load import load_scene_text

    steps = 5_000 if quick else 20_000
    sims = {c: rbcli.Simulation(load_scene_text(far_scene(c))) for c in (False, True)}
    blocks: dict[bool, list[float]] = {c: [] for c in sims}
    for sim in sims.values():
        sim.step(100)  # compile or load the kernels
    for _ in range(5):
        for c, sim in sims.items():
            began = time.perf_counter()
            sim.step(steps)
            blocks[c].append((time.perf_counter() - began) / steps)
    best = {c: min(times) for c, times in blocks.items()}
    ratio = best[True] / best[False]
    per_block = [b / a for a, b in zip(blocks[False], blocks[True], strict=True)]
    speed = abs(float(sims[True].state.v[0, 2]))
    return [
        "### Contact when nothing touches: two bricks 5 m apart",
        "",
        f"- without `contact:` {best[False] * 1e9:.0f} ns/step, with it {best[True] * 1e9:.0f} ns/step: "
        f"{ratio:.2f}x (target <= {TARGET_FAR}: {'met' if ratio <= TARGET_FAR else '**missed**'})",
        "- per block with / without: "
        + ", ".join(f"{r:.2f}x" for r in per_block)
        + f" (worst {max(per_block):.2f}x; falling at {speed:.0f} m/s at the end)",
    ]


IDLE_BOX = (
    "{{name: {name}, shape: {shape}, spacing: 0.02, density: 500, position: [{x}, 0, 0], "
    "velocity: [{v}, 0, 0], angular_velocity: {w}}}"
)
IDLE_CUBE = "{type: box, size: [0.2, 0.2, 0.2]}"


def idle_scene(contact: bool, *, integrator: str = "split2", gap: float = 5.0, ground: float = -100.0,
               spin: bool = True, shape: str = IDLE_CUBE) -> str:  # fmt: skip
    """Issue 47 item 6's scene: two tumbling 0.2 m boxes (spacing 0.02) `gap` m apart drifting apart at
    0.1 m/s each, no gravity, and with `contact:` a ground `ground` m below their centres."""
    w = "[1, 2, 3]" if spin else "[0, 0, 0]"
    bodies = "".join(
        "  - " + IDLE_BOX.format(name=f"b{i}", shape=shape, x=gap * i, v=0.1 * (2 * i - 1), w=w) + "\n"
        for i in range(2)
    )
    return (f"simulation: {{dt: 0.001, steps: 3000, integrator: {integrator}}}\n"
            + (f"contact: {{ground: {ground}}}\n" if contact else "") + "bodies:\n" + bodies)  # fmt: skip


IDLE_ROWS = (  # label, idle_scene keywords, how it is stepped after each reset (or without one)
    ("issue 47's scene: 3,000 calls of step() after reset()", {}, "calls"),
    ("the same, one call of step(3000) after reset()", {}, "chunk"),
    ("one call, no reset (the state runs on)", {}, "no-reset"),
    ("one call, not spinning", {"spin": False}, "chunk"),
    ("one call, ground 1 m below (0.83 m under the lowest corner)", {"ground": -1.0}, "chunk"),
    ("one call, ground 10^6 m below", {"ground": -1.0e6}, "chunk"),
    ("one call, boxes 0.5 m apart", {"gap": 0.5}, "chunk"),
    ("one call, balls (shape: sphere, radius 0.1)", {"shape": "{type: sphere, radius: 0.1}"}, "chunk"),
    ("3,000 calls of step(), balls", {"shape": "{type: sphere, radius: 0.1}"}, "calls"),
) + tuple(
    (f"one call, {name}", {"integrator": name}, "chunk")
    for name in ("euler-matrix", "euler-quat", "semi-implicit", "semi-implicit-gyro", "rk4", "split4")
)


def idle_section(quick: bool) -> list[str]:
    """Issue 47 item 6: far-apart scenes with and without `contact:`, CPU ns per step (process time),
    the best of `blocks` blocks, with and without interleaved; each block resets (but 'no reset') and
    steps 3,000 steps, ten times over for the one-call rows (0.5 ms is too short to time alone)."""
    from rbcli.scene.load import load_scene_text

    rows = IDLE_ROWS[:3] if quick else IDLE_ROWS
    blocks, steps = 5, 3000
    lines = ["### Contact when nothing touches: issue 47 item 6's scenes (CPU ns per step, best of 5)", "",
             "| scene | without `contact:` | with it | ratio |", "|---|---:|---:|---:|"]  # fmt: skip
    worst = 0.0
    for label, keywords, how in rows:
        print(f"idle: {label} ...", flush=True)
        sims = {c: rbcli.Simulation(load_scene_text(idle_scene(c, **keywords))) for c in (False, True)}
        for sim in sims.values():
            sim.step(10)  # compile or load the kernels
        best = {c: math.inf for c in sims}
        for _ in range(blocks):
            for c, sim in sims.items():
                repeats = 1 if how == "calls" else 10
                began = time.process_time()
                for _ in range(repeats):
                    if how != "no-reset":
                        sim.reset()
                    if how == "calls":
                        for _ in range(steps):
                            sim.step()
                    else:
                        sim.step(steps)
                best[c] = min(best[c], (time.process_time() - began) / (repeats * steps))
        ratio = best[True] / best[False]
        worst = max(worst, ratio)
        lines.append(f"| {label} | {best[False] * 1e9:,.0f} | {best[True] * 1e9:,.0f} | {ratio:.2f}x |")
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    lines += ["", f"- worst {worst:.2f}x (target <= {TARGET_FAR}: {'met' if worst <= TARGET_FAR else '**missed**'}); "
              f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (1, 5, 15 min)"]  # fmt: skip
    return lines


def scenes_section(quick: bool) -> list[str]:
    """Steps/s of scenes/contact/dominoes.yaml and container_mix.yaml (their dt; sub-steps as main chose
    them, 2 and 1, so the broad phase is compared at the same work; and at `substeps: auto`)."""
    from rbcli.scene.load import load_scene_text

    lines = ["### Contact scenes", "", "| scene | sub-steps | steps | steps/s | sphere pairs tested per step |",
             "|---|---:|---:|---:|---:|"]  # fmt: skip
    for name, pinned, steps in (("dominoes", 2, 1500), ("container_mix", 1, 1500)):
        path = ROOT / "scenes" / "contact" / f"{name}.yaml"
        for substeps in (pinned, "auto"):
            text = path.read_text().replace("substeps: auto", f"substeps: {substeps}")
            sim = rbcli.Simulation(load_scene_text(text, file=str(path), base_dir=path.parent))
            sim.step(10)
            count = steps // 3 if quick else steps
            before = int(sim.data.force.contact.counters[0])
            began = time.perf_counter()
            sim.step(count)
            seconds = time.perf_counter() - began
            tested = (int(sim.data.force.contact.counters[0]) - before) / count
            lines.append(f"| {name} | {sim.settings.substeps} ({substeps}) | {count} | {count / seconds:.3g} | "
                         f"{tested:.3g} |")  # fmt: skip
    return lines


PRIMITIVE_BODIES = {
    "box": "shape: {type: box, size: [0.2, 0.1, 0.05]}, spacing: 0.0125, density: 600",  # 128 face spheres
    "capsule": "shape: {type: capsule, radius: 0.03, height: 0.12, axis: y}, spacing: 0.01, density: 800",
}


def primitive_scene(body: str, primitives: bool, sliding: bool) -> str:
    """One shape body on the ground, resting (set down still) or sliding (2 m/s along y, friction 0.1: the
    capsule along its axis, so it slides, not rolls), as its primitive or its lattice spheres
    (`contact.primitives`)."""
    height = 0.025 if body == "box" else 0.03
    v = ", velocity: [0, 2, 0]" if sliding else ""
    return (
        "simulation: {dt: 0.001, steps: 3000, integrator: split2}\ngravity: [0, 0, -9.81]\n"
        f"contact: {{ground: 0, primitives: {str(primitives).lower()}, material: {{friction: 0.1}}}}\n"
        f"bodies:\n  - {{name: b, {PRIMITIVE_BODIES[body]}, position: [0, 0, {height}]{v}}}\n"
    )


def primitives_section(quick: bool) -> list[str]:
    """Issue 47 slice 2: a box and a capsule resting and sliding on the ground, touching it as their
    primitive (4 / 2 points) and as their lattice spheres, CPU us per step (process time), best of 5
    interleaved blocks of 500 steps after reset(), and the contacts per step."""
    from rbcli.physics.contact.tables import STAT_CONTACTS
    from rbcli.scene.load import load_scene_text

    steps = 200 if quick else 500
    lines = ["### Shape bodies on the ground: primitive against lattice spheres (CPU us per step, best of 5)", "",
             "| body | motion | spheres: us/step (contacts) | primitive: us/step (contacts) | speed-up |",
             "|---|---|---:|---:|---:|"]  # fmt: skip
    for body in PRIMITIVE_BODIES:
        for sliding in (False, True):
            sims = {p: rbcli.Simulation(load_scene_text(primitive_scene(body, p, sliding))) for p in (False, True)}
            for sim in sims.values():
                sim.step(10)  # compile or load the kernels
            best = {p: math.inf for p in sims}
            contacts = {p: 0.0 for p in sims}
            for _ in range(5):
                for p, sim in sims.items():
                    sim.reset()
                    began = time.process_time()
                    sim.step(steps)
                    best[p] = min(best[p], (time.process_time() - began) / steps)
                    contacts[p] = float(sim.data.force.contact.stats[STAT_CONTACTS])
            motion = "sliding 2 m/s" if sliding else "resting"
            lines.append(
                f"| {body} | {motion} | {best[False] * 1e6:.2f} ({contacts[False]:.0f}) "
                f"| {best[True] * 1e6:.2f} ({contacts[True]:.0f}) | {best[False] / best[True]:.1f}x |"
            )
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    lines += ["", f"- load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} (1, 5, 15 min)"]
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--quick",
        action="store_true",
        help="200 steps instead of 1,000 (stability checks then see a pile still falling)",
    )
    parser.add_argument("--no-mujoco", action="store_true")
    parser.add_argument("--big", action="store_true", help="also the 10^5-sphere pile (200 steps)")
    parser.add_argument("--sections", default="pile,far,idle,scenes,primitives",
                        help="comma-separated: pile, far, idle, scenes, primitives")  # fmt: skip
    args = parser.parse_args()
    sections = args.sections.split(",")
    lines = []
    if "far" in sections:
        lines += far_section(args.quick) + [""]
    if "idle" in sections:
        lines += idle_section(args.quick) + [""]
    if "scenes" in sections:
        lines += scenes_section(args.quick) + [""]
    if "primitives" in sections:
        lines += primitives_section(args.quick) + [""]
    if "pile" in sections:
        lines += pile_section(args.quick, not args.no_mujoco, args.big)
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    lines.append("- load average {:.2f} {:.2f} {:.2f} (1, 5, 15 min) at the end".format(*load))
    for line in lines:
        print(line)


if __name__ == "__main__":
    main()
