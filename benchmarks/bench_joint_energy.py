"""Long runs of the joint step's conservation (issue 46): the energy error's trend of the 3-D double
pendulums and the tilted-hinge pendulum's period, swing after swing.

    python benchmarks/bench_joint_energy.py [--steps N] [--dt DT]

Scenes from tests/physics/joint_scenes.py (the suite runs each for 1e5 steps or less:
tests/physics/test_joints_rattle.py):

- hanging: the box and the four-sphere cloud on two ball joints, small swings, both turning slowly
  about axes off their principal axes (a regular motion);
- tumbling: the same bodies released high and spinning (3-6 rad/s): a chaotic motion;
- tilted: the box on a hinge about (1, 1, 0)/sqrt 2 through a pivot off every principal axis, from 170
  degrees.

For the double pendulums, E(t) - E(0) every 10 steps (E = |P|^2/2M + m.m/2I + M g z): the least-squares
line's rise over the run divided by the error's range (max - min) and, beside it, that rise's standard
error from batch means (20 blocks): a chaotic run's energy error wanders with its state, so its fitted
trend is noise of about range x sqrt(12 tau / T) (tau its correlation time) and cannot be told from zero
below that; a drifting step's trend grows with T. For the pendulum, the periods between every other
crossing of the bottom (cubic Hermite crossings): the change from the first to the last and the fitted
change per swing, relative. CPU seconds of this process per run, with the load average.

To measure another checkout's step (the one before RATTLE, say) with the same scenes, run this file with
PYTHONPATH pointing at that checkout and RBSIM_ROOT at this one (the scenes are read from RBSIM_ROOT).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(os.environ.get("RBSIM_ROOT", Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(ROOT / "tests" / "physics"))
if "PYTHONPATH" not in os.environ:
    sys.path.insert(0, str(ROOT))

from joint_scenes import (  # noqa: E402
    G,
    crossings,
    double_pendulum_3d_text,
    hanging_double_pendulum_3d_text,
    tilted_hinge_angle,
    tilted_hinge_text,
)

from rbcli.physics.rotation import quat_rotate_inverse  # noqa: E402
from rbcli.runner.simulation import Simulation  # noqa: E402
from rbcli.scene.load import load_scene_text  # noqa: E402

EVERY = 10  # steps between energy samples
BLOCKS = 20  # batch means for the trend's standard error


def energy_run(text: str, steps: int) -> tuple[np.ndarray, float]:
    """(E(t) - E(0) every EVERY steps, CPU seconds), E(0) after a first step that makes the given
    velocities consistent with the joints."""
    sim = Simulation(load_scene_text(text))
    sim.step(1)
    mass, inertia = sim.model.body_mass, sim.model.body_inertia

    def energy() -> float:
        s = sim.data.state
        m = quat_rotate_inverse(s.q, s.L)
        return float(np.sum(s.P**2 / (2 * mass[:, None])) + 0.5 * np.sum(m * m / inertia) + G * mass @ s.x[:, 2])

    start = energy()
    out = np.empty(steps // EVERY)
    began = time.process_time()
    for k in range(out.shape[0]):
        sim.step(EVERY)
        out[k] = energy() - start
    return out, time.process_time() - began


def trend(errors: np.ndarray) -> tuple[float, float, float]:
    """(fitted rise over the run / range, its standard error / range from BLOCKS batch means, range)."""
    t = np.arange(errors.shape[0], dtype=float)
    span, width = t[-1] - t[0], errors.max() - errors.min()
    slope = np.polyfit(t, errors, 1)[0]
    n = errors.shape[0] // BLOCKS * BLOCKS
    means, centres = errors[:n].reshape(BLOCKS, -1).mean(1), t[:n].reshape(BLOCKS, -1).mean(1)
    fit = np.polyfit(centres, means, 1)
    residual = means - np.polyval(fit, centres)
    error = math.sqrt(residual @ residual / (BLOCKS - 2) / np.sum((centres - centres.mean()) ** 2))
    return float(slope * span / width), float(error * span / width), float(width)


def period_run(dt: float, steps: int) -> tuple[np.ndarray, float]:
    """(the tilted pendulum's periods from 170 degrees, CPU seconds)."""
    sim = Simulation(load_scene_text(tilted_hinge_text(math.radians(170), dt)))
    s, mass = sim.data.state, float(sim.model.body_mass[0])
    theta, rate = np.empty(steps + 1), np.empty(steps + 1)
    theta[0], rate[0] = tilted_hinge_angle(s.x[0], s.P[0] / mass)
    began = time.process_time()
    for k in range(steps):
        sim.step(1)
        theta[k + 1], rate[k + 1] = tilted_hinge_angle(s.x[0], s.P[0] / mass)
    elapsed = time.process_time() - began
    found = crossings(np.arange(steps + 1) * dt, theta, rate)
    return found[2:] - found[:-2], elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000)
    parser.add_argument("--dt", type=float, default=1e-3)
    options = parser.parse_args()
    print(f"rbcli from {Path(sys.modules['rbcli'].__file__).parent}, load average {os.getloadavg()[0]:.1f}")
    print(f"{'scene':>9} {'steps':>9} {'trend/range':>12} {'+-':>9} {'range [J]':>10} {'CPU s':>7}")
    for name, text in (("hanging", hanging_double_pendulum_3d_text), ("tumbling", double_pendulum_3d_text)):
        errors, cpu = energy_run(text(options.dt), options.steps)
        rise, error, width = trend(errors)
        print(f"{name:>9} {options.steps:>9} {rise:>12.2e} {error:>9.1e} {width:>10.2e} {cpu:>7.1f}")
    periods, cpu = period_run(options.dt, options.steps)
    change = (periods[-1] - periods[0]) / periods[0]
    per_swing = 2.0 * np.polyfit(np.arange(periods.shape[0]), periods, 1)[0] / periods[0]  # entries: half swings
    print(f"tilted hinge, {periods.shape[0] // 2} swings: period {periods[0]:.12f} s, first to last {change:.2e}, "
          f"per swing {per_swing:.2e} (relative), {cpu:.1f} CPU s")  # fmt: skip
    print(f"load average at the end {os.getloadavg()[0]:.1f}")


if __name__ == "__main__":
    main()
