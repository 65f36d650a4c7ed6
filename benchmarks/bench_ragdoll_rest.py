"""When does the shipped ragdoll come to rest? The spread of its settling time over round-off-sized changes.

    python benchmarks/bench_ragdoll_rest.py [--runs N] [--seconds S] [--integrator NAME]

scenes/joints/ragdoll.yaml dropped as it ships (run 0), and with one body's centre moved by
1e-13 m x run (runs 1 .. N-1: a different body and axis each; in joint coordinates, `--integrator
reduced-rk4`, a hinge angle moved by 1e-13 rad x run instead). Prints for each run the last time any
part's fastest particle moved at 1 cm/s or more, checked every 20 steps up to S seconds.

Why: the fall is chaotic (the ragdoll topples over its limits and rolls on its contacts), so a change
far below any tolerance (a body moved by 1e-13 m, or the joints' Newton stopping one round-off step
elsewhere) changes which way it rolls and when it settles. A test of "at rest from time T" must leave a
margin over this spread (tests/physics/test_joints_contact_scenes.py). Measured (issue 46, 16 runs on
split2 with the rest rule's stiffness: 8 before the Newton's extrapolated first iterate, 8 after):
3.1-4.5 s; as shipped since 2026-12-06 (reduced-implicit, landing stiffness, shoulder dampers 0.3), 40
runs: 2.8-7.8 s, the late ones an arm rocking on its one contact.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from rbcli import Simulation  # noqa: E402
from rbcli.analysis.contact_depth import fastest_particle_speeds  # noqa: E402

REST_SPEED = 0.01  # [m/s]


def last_motion(run: int, seconds: float, integrator: str | None = None) -> float:
    """The last time [s] (on the 20-step grid) any part moved at REST_SPEED or more (the scene's integrator,
    or `integrator`)."""
    sim = Simulation(ROOT / "scenes" / "joints" / "ragdoll.yaml", integrator=integrator)
    if run and sim.model.tree is not None:  # joint coordinates: the state is the joints', not x
        joints = sim.joint_state()
        hinges = sorted(name for name, joint in joints.items() if joint.position.shape == (1,))
        name = hinges[run % len(hinges)]
        sim.set_joint_state(name, position=joints[name].position + 1e-13 * run)  # [rad]
    elif run:
        x = sim.data.state.x
        x[run % x.shape[0], run % 3] += 1e-13 * run
    last = 0.0
    while sim.time < seconds - 1e-9:
        sim.step(20)
        view = sim.state
        if fastest_particle_speeds(sim.model, sim.data.state.q, view.v, view.omega).max() >= REST_SPEED:
            last = sim.time
    return last


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=8)
    parser.add_argument("--seconds", type=float, default=6.0)
    parser.add_argument("--integrator", default=None, help="instead of the scene's (e.g. reduced-rk4)")
    options = parser.parse_args()
    times = [last_motion(run, options.seconds, options.integrator) for run in range(options.runs)]
    print("last time any part moved at >= 1 cm/s [s]:", ", ".join(f"{t:.2f}" for t in times))
    print(f"spread {min(times):.2f} - {max(times):.2f} s over {len(times)} runs")


if __name__ == "__main__":
    main()
