"""The integrators issue's pass criteria as one markdown report (pasted into docs/integrators.md).

    python benchmarks/integrator_errors.py              # errors, slopes, adaptive, costs (~3 min)
    python benchmarks/integrator_errors.py --no-cost    # without the timing table

Every error is the max over the run of the geodesic angle [rad] between the simulated orientation and
the exact torque-free solution (rbcli.analysis.exact.torque_free, Jacobi elliptic functions), for a
particle cloud whose principal inertia is exactly the one asked for (6 point masses on the axes),
omega0 given in the body frame. Errors are deterministic; the costs depend on the machine (stated).
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import os
import platform
import sys

import numpy as np

from rbcli.analysis.exact import free_flight, quat_geodesic_angle, torque_free
from rbcli.api import prepare, simulate
from rbcli.physics.adaptive import STATUS_STEP_TOO_SMALL
from rbcli.physics.data import make_data
from rbcli.physics.forces import WORLD, build_force_tables, spring_table
from rbcli.physics.frames import user_orientation
from rbcli.physics.integrators import INTEGRATORS
from rbcli.physics.rotation import quat_to_matrix
from rbcli.physics.step import STATUS_DIVERGED, empty_buffers
from rbcli.record.memory_sink import SinkMemory
from rbcli.runner.simulation import run
from rbcli.scene.spec import BodySpec, RecordSpec, SceneSpec, SimulationSpec

FLIP, GENERIC, ROD, FAST, STEADY = (
    ((1.0, 2.0, 3.0), (0.01, 5.0, 0.0)),
    ((1.0, 2.0, 3.0), (1.0, 1.0, 2.0)),
    ((1.0, 1.0, 1e-3), (0.3, 0.0, 100.0)),
    ((1.0, 2.0, 3.0), (60.0, 40.0, 80.0)),
    ((1.0, 2.0, 3.0), (0.0, 3.0, 0.0)),
)
# dt decades over which each method's error is in its asymptotic regime and above round-off
SLOPE_DECADE = {1: (1e-4, 1e-3), 2: (1e-3, 1e-2), 4: (5e-3, 5e-2), 5: (1e-2, 1e-1)}
G = np.array([0.0, 0.0, -9.81])


def principal_cloud(inertia: tuple[float, float, float]) -> tuple[np.ndarray, np.ndarray]:
    """Point-mass pairs at +-e_k (unit distance) whose inertia is exactly diag(inertia).

    A pair of masses m/2 at +-e_k adds m to the two other moments, so with s_k = m_k:
    I_1 = s_2 + s_3, I_2 = s_1 + s_3, I_3 = s_1 + s_2, i.e. s_k = (I_i + I_j - I_k) / 2 (k's pair
    omitted when s_k = 0: a planar body such as diag(1, 2, 3)).
    """
    i1, i2, i3 = inertia
    s = 0.5 * np.array([i2 + i3 - i1, i1 + i3 - i2, i1 + i2 - i3])
    positions, masses = [], []
    for k in range(3):
        if s[k] > 0.0:
            e = np.eye(3)[k]
            positions += [e, -e]
            masses += [0.5 * s[k], 0.5 * s[k]]
    return np.array(positions), np.array(masses)


def scene(inertia, omega0, integrator, dt, duration, every=1, gravity=None, velocity=None) -> SceneSpec:  # noqa: ANN001
    positions, masses = principal_cloud(inertia)
    body = BodySpec(
        name="body",
        particle_position=positions,
        particle_mass=masses,
        position=np.zeros(3),
        orientation_wxyz=np.array([1.0, 0.0, 0.0, 0.0]),
        velocity=velocity,
        angular_velocity=np.asarray(omega0, dtype=float),
        angular_velocity_frame="body",
    )
    sim = SimulationSpec(
        dt=dt, duration=duration, integrator=integrator, record=RecordSpec(every, ("bodies", "invariants"))
    )
    return SceneSpec(name="integrator-errors", simulation=sim, bodies=(body,), gravity=gravity, source_text="")


def rotation_error(integrator, case, dt, duration, every=1) -> tuple[float, object]:  # noqa: ANN001
    """(max geodesic angle against the exact solution, trajectory); inf when the run diverged."""
    inertia, omega0 = case
    traj = simulate(scene(inertia, omega0, integrator, dt, duration, every), on_diverge="return")
    if traj.status != "completed":
        return float("inf"), traj
    exact = torque_free(np.array(inertia), np.eye(3), np.array(omega0), traj.t, frame="body")
    return float(quat_geodesic_angle(traj.q[:, 0], exact.q).max()), traj


def slope(errors: list[float], dts: list[float]) -> float:
    """Least-squares slope of log(error) against log(dt)."""
    return float(np.polyfit(np.log(dts), np.log(errors), 1)[0])


def measured_order(integrator: str, order: int) -> tuple[float, list[float]]:
    """Slope over the decade SLOPE_DECADE[order] on the generic case, 20 s."""
    lo, hi = SLOPE_DECADE[order]
    dts = list(np.geomspace(lo, hi, 4))
    errors = [rotation_error(integrator, GENERIC, dt, 20.0, every=max(1, round(0.1 / dt)))[0] for dt in dts]
    return slope(errors, dts), errors


def torque_scene(integrator: str, dt: float, duration: float):  # noqa: ANN201
    """The generic body hung from an off-centre spring under gravity: coupled translation and rotation."""
    compiled = prepare(scene(*GENERIC, integrator, dt, duration, every=max(1, round(0.05 / dt)), gravity=G))
    spring = spring_table(body_a=[0], point_a=[[0.4, 0.3, 0.2]], body_b=[WORLD], point_b=[[0.0, 0.0, 1.0]],
                          stiffness=[40.0], rest_length=[0.5], damping=[0.0])  # fmt: skip
    forces = build_force_tables(G, body_count=compiled.model.body_count, spring=spring)
    return dataclasses.replace(compiled, forces=forces)


def run_compiled(compiled):  # noqa: ANN001, ANN201
    memory = SinkMemory()
    run(compiled, [memory])
    return memory.trajectory()


def torque_order(integrator: str, order: int, reference_q: np.ndarray) -> float:
    """Slope of the final-orientation error over SLOPE_DECADE[order] (steps dividing the 5 s run)."""
    lo, hi = SLOPE_DECADE[order]
    dts = [5.0 / n for n in np.unique(np.round(5.0 / np.geomspace(lo, hi, 4)))]
    errors = []
    for dt in dts:
        traj = run_compiled(torque_scene(integrator, dt, 5.0))
        errors.append(float(quat_geodesic_angle(traj.q[-1, 0], reference_q)))
    return slope(errors, dts)


def adaptive_run(compiled, tolerance: float):  # noqa: ANN001, ANN201
    """Drive the adaptive loop as the runner would; returns (t, q_user (T, N, 4), x, counters)."""
    model, settings = compiled.model, compiled.settings
    n, total, dt = model.body_count, settings.steps, settings.dt
    data = make_data(compiled.initial_state, compiled.model, 0, adaptive=True, tolerance=tolerance, duration=total * dt)
    state, run_chunk = data.state, INTEGRATORS["dopri5"].adaptive_chunk().run_chunk
    frames = empty_buffers(total + 1, n)
    frames.step[0], frames.x[0], frames.q[0], frames.P[0], frames.L[0] = 0, state.x, state.q, state.P, state.L
    filled, index = 1, 0
    while index < total:
        done, filled, status = run_chunk(
            model.kernel(), compiled.forces, data.kernel(), dt, index, total - index, settings.record_every,
            frames, filled,
        )  # fmt: skip
        index += done
        if status in (STATUS_DIVERGED, STATUS_STEP_TOO_SMALL):
            raise RuntimeError(f"adaptive run stopped with status {status}")
    k = filled
    return (
        frames.step[:k] * dt,
        user_orientation(model, frames.q[:k]),
        frames.x[:k].copy(),
        data.adaptive_counters.copy(),
    )


def transient_scene(integrator: str, dt: float, duration: float):  # noqa: ANN201
    """Fast transient: the generic body on a stiff damped spring at its centre (30 rad/s, decays in ~1 s)."""
    compiled = prepare(scene(*GENERIC, integrator, dt, duration, velocity=np.array([0.0, 0.0, 0.0])))
    mass = compiled.model.body_mass[0]
    omega_n, zeta = 30.0, 0.15
    k, c = mass * omega_n**2, 2.0 * zeta * mass * omega_n
    spring = spring_table(body_a=[0], point_a=[[0.0, 0.0, 0.0]], body_b=[WORLD], point_b=[[0.0, 0.0, 0.0]],
                          stiffness=[k], rest_length=[0.0], damping=[c])  # fmt: skip
    state = compiled.initial_state
    state.x[0] = [0.5, 0.0, 0.0]
    forces = build_force_tables(None, body_count=compiled.model.body_count, spring=spring)
    return dataclasses.replace(compiled, forces=forces), omega_n, zeta


def transient_error(t, q, x, omega_n, zeta):  # noqa: ANN001, ANN201
    """max(|x - x_exact| / 0.5 m, rotation angle): the damped oscillator along x and the free body."""
    wd = omega_n * np.sqrt(1 - zeta**2)
    x_exact = 0.5 * np.exp(-zeta * omega_n * t) * (np.cos(wd * t) + zeta * omega_n / wd * np.sin(wd * t))
    rot = torque_free(np.array(GENERIC[0]), np.eye(3), np.array(GENERIC[1]), t, frame="body")
    return max(np.abs(x[:, 0, 0] - x_exact).max() / 0.5, quat_geodesic_angle(q[:, 0], rot.q).max())


def fmt(value: float) -> str:
    return "lost (inf)" if not np.isfinite(value) else f"{value:.2g}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--no-cost", action="store_true", help="skip the timing table")
    args = parser.parse_args()
    out = sys.stdout.write
    out(f"Generated {datetime.date.today()} by `python benchmarks/integrator_errors.py` on {platform.machine()} "
        f"{platform.processor() or ''} ({os.cpu_count()} CPUs), Python {platform.python_version()}.\n\n")  # fmt: skip

    out("### Errors at the issue's settings (max geodesic angle [rad] over the run, vs the exact solution)\n\n")
    out(
        "| integrator | order | slope (torque-free) | slope (spring torque) | flip dt=0.01 | rod dt=0.01 "
        "| fast spin dt=1/60 | fast: max d\\|L\\|/\\|L\\| | fast: max dE/E | steady (0,3,0) off-axis [rad/s] |\n"
    )
    out("|---|---|---|---|---|---|---|---|---|---|\n")
    reference = run_compiled(torque_scene("dopri5", 5.0 / 20_000, 5.0)).q[-1, 0]
    for name, info in INTEGRATORS.items():
        exact_like = name.startswith("exact")
        torque_free_slope = "exact" if exact_like else f"{measured_order(name, info.order)[0]:.2f}"
        torque_slope = f"{torque_order(name, info.order, reference):.2f}"
        flip, _ = rotation_error(name, FLIP, 0.01, 20.0)
        rod, _ = rotation_error(name, ROD, 0.01, 20.0)
        fast, traj = rotation_error(name, FAST, 1.0 / 60.0, 20.0)
        if np.isfinite(fast):
            norm = np.linalg.norm(traj.L[:, 0], axis=-1)
            energy = traj.invariants["energy_total"]
            dL, dE = fmt(np.abs(norm / norm[0] - 1).max()), fmt(np.abs(energy / energy[0] - 1).max())
        else:
            dL = dE = f"diverged at t = {traj.t[-1]:.2g} s"
        steady = simulate(scene(*STEADY, name, 0.01, 10.0, every=100))
        off_axis = np.abs(np.einsum("kji,kj->ki", quat_to_matrix(steady.q[:, 0]), steady.omega[:, 0])[:, [0, 2]]).max()
        out(f"| {name} | {info.order} | {torque_free_slope} | {torque_slope} | {fmt(flip)} | {fmt(rod)} | {fmt(fast)} "
            f"| {dL} | {dE} | {off_axis:.1g} |\n")  # fmt: skip
        sys.stdout.flush()

    out("\n### Long run, I = diag(1, 2, 3), omega0 = (1, 1, 2), dt = 0.05: max relative energy error up to t\n\n")
    out("| integrator | t = 20 s | t = 200 s | t = 2000 s |\n|---|---|---|---|\n")
    for name in ("split2", "split4", "rk4", "exact"):
        traj = simulate(scene(*GENERIC, name, 0.05, 2000.0, every=10))
        rel = np.abs(traj.invariants["energy_total"] / traj.invariants["energy_total"][0] - 1)
        cells = [fmt(rel[: np.searchsorted(traj.t, T) + 1].max()) for T in (20.0, 200.0, 2000.0)]
        out(f"| {name} | {' | '.join(cells)} |\n")

    out("\n### Free flight under gravity, 10 s at dt = 0.01: max |x - exact| / max |x|\n\n")
    out("| integrator | error |\n|---|---|\n")
    for name in ("split2", "split4", "rk4", "exact"):
        spec = scene(*GENERIC, name, 0.01, 10.0, gravity=G, velocity=np.array([1.0, 2.0, 30.0]))
        traj = simulate(spec)
        x_exact, _ = free_flight(np.zeros(3), np.array([1.0, 2.0, 30.0]), G, traj.t)
        out(f"| {name} | {fmt(np.abs(traj.x[:, 0] - x_exact).max() / np.abs(x_exact).max())} |\n")

    out("\n### Adaptive dopri5 (tolerance = error budget of the run), flip case, recorded every 0.5 s\n\n")
    out("| tolerance | max error [rad] | error / tolerance | accepted | rejected |\n|---|---|---|---|---|\n")
    for tolerance in (1e-4, 1e-6, 1e-8):
        compiled = prepare(scene(*FLIP, "dopri5", 0.5, 20.0))
        t, q, _, counters = adaptive_run(compiled, tolerance)
        err = quat_geodesic_angle(q[:, 0], torque_free(np.array(FLIP[0]), np.eye(3), np.array(FLIP[1]), t).q).max()
        out(f"| {tolerance:g} | {err:.2g} | {err / tolerance:.2g} | {counters[0]} | {counters[1]} |\n")
    out("\nFast transient (damped spring, 30 rad/s, decaying in ~1 s, on the slowly tumbling body; 10 s):\n\n")
    out("| run | steps | max error |\n|---|---|---|\n")
    compiled, omega_n, zeta = transient_scene("dopri5", 0.1, 10.0)
    t, q, x, counters = adaptive_run(compiled, 1e-6)
    adaptive_err = transient_error(t, q, x, omega_n, zeta)
    out(f"| adaptive, tolerance 1e-6 | {counters[0]} (+{counters[1]} rejected) | {adaptive_err:.2g} |\n")
    for dt in (0.01, 0.005, 0.0025):
        compiled, *_ = transient_scene("dopri5", dt, 10.0)
        traj = run_compiled(compiled)
        err = transient_error(traj.t, traj.q, traj.x, omega_n, zeta)
        out(f"| fixed dt = {dt:g} | {round(10.0 / dt)} | {err:.2g} |\n")

    if not args.no_cost:
        from rbcli.cli.integrators import measure_cost

        out("\n### Cost: body-steps per second of the compiled chunk loop (gravity on, nothing recorded)\n\n")
        out("| integrator | N = 1 | N = 100 | N = 10,000 | ns / body-step at N = 10,000 | vs split2 |\n")
        out("|---|---|---|---|---|---|\n")
        costs = {}
        for name in INTEGRATORS:
            costs[name] = [
                measure_cost(name, n, steps, repeats=5) for n, steps in ((1, 100_000), (100, 5_000), (10_000, 100))
            ]
        for name, (c1, c100, c10k) in costs.items():
            out(f"| {name} | {1e9 / c1:.3g} | {1e9 / c100:.3g} | {1e9 / c10k:.3g} | {c10k:.0f} "
                f"| {c10k / costs['split2'][2]:.2f} |\n")  # fmt: skip


if __name__ == "__main__":
    main()
