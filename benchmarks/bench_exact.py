"""Cost of `exact` against split2, measured in the same run on the same 10,000 free bodies under gravity.

    python benchmarks/bench_exact.py [--bodies 10000] [--repeats 7] [--pieces] [--clock cpu|wall]

Rows, each the median over repeats (spread = max / min printed) in ns per body and per unit of work:
  split2 step                 sim.step(100): ns per body-step (the reference of every ratio)
  exact evaluation            sim.step(1) 10 s after the anchors: one deferred step, then the state of
                              every body evaluated from its anchor (the chunk's end): ns per body per
                              evaluation, what a recorded frame costs (the issue's target: <= 4x split2)
  exact, recorded every 100   sim.step(100): 100 deferred steps and one evaluation, ns per body-step
  exact, every step written   a drag of 1e-300 N s/m makes the forces non-constant, so every step
                              is written (the orientation at the force evaluation and at the step's end:
                              two evaluations) and the wrench evaluated: ns per body-step
  one-shot flow               free_rotation_exact_batch from the initial state over the evaluation's
                              horizon, what each evaluation cost before the anchor's constants were
                              kept (ns per body)
The machine's load moves every row alike; the ratios are what to read.

--pieces adds the profile of one evaluation, each piece timed alone in a compiled loop over the same
bodies' anchor constants (a compact table, as in the scratch rows): the Jacobi functions from the kept
AGM, psi by the Fourier series (the bodies that have one), psi by the closed form (Pi = R_F + R_J, the
arctangent; every elliptic body), the quaternion composition, and the whole evaluation.
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numba
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_speed import free_bodies, scene  # noqa: E402

from rbcli.api import prepare
from rbcli.physics import free_rotation_anchored as fa
from rbcli.physics.elliptic import JACOBI_WORK_SIZE, ellipj_kept, ellippi_sc
from rbcli.physics.free_rotation_exact import _quat_mul, _scatter, free_rotation_exact_batch
from rbcli.runner.simulation import Simulation
from rbcli.scene.force_specs import ForceDrag

# the clock of `timed`: this process's CPU time by default (on a shared machine the wall time also counts
# the other processes' time slices; the runs here are single-threaded), or the wall clock (--clock wall)
CLOCK = {"cpu": time.process_time, "wall": time.perf_counter}
clock = CLOCK["cpu"]


def timed(run: Callable[[], None], repeats: int) -> tuple[float, float]:
    """(median seconds, max / min) over repeats, after one warm-up call."""
    run()
    times = []
    for _ in range(repeats):
        start = clock()
        run()
        times.append(clock() - start)
    return statistics.median(times), max(times) / min(times)


@numba.njit(cache=True)
def _jacobi(c: np.ndarray, h: float) -> float:
    total = 0.0
    for b in range(c.shape[0]):
        sn, cn, dn = ellipj_kept(c[b, fa._U0] + c[b, fa._LAM] * h, c[b, fa._MC], c[b, fa._JACOBI :])
        total += sn + cn + dn
    return total


@numba.njit(cache=True)
def _fourier(c: np.ndarray, h: float) -> float:
    total = 0.0
    for b in range(c.shape[0]):
        if c[b, fa._TERMS] > 0.0:
            total += h * c[b, fa._RATE_MEAN] + fa._fourier_sum(c[b], c[b, fa._U0] + c[b, fa._LAM] * h)
    return total


@numba.njit(cache=True)
def _closed_form(c: np.ndarray, h: float) -> float:
    """The Pi branch of anchor_evaluate from (sn, cn) = (sin, cos) of a fixed-rate angle (the Jacobi
    functions are timed on their own)."""
    total = 0.0
    for b in range(c.shape[0]):
        row = c[b]
        u1 = row[fa._U0] + row[fa._LAM] * h
        s1, c1 = math.sin(0.1 * b), abs(math.cos(0.1 * b))
        j = round(u1 / row[fa._PERIOD])
        pi1 = ellippi_sc(-row[fa._NN], s1, c1, row[fa._MC]) + 2.0 * j * row[fa._PIC]
        th1 = math.atan2(row[fa._SQ] * s1, c1) + j * math.pi
        total += row[fa._G] * (pi1 - row[fa._PI0]) - row[fa._A3] * (th1 - row[fa._TH0]) / row[fa._SQ]
    return total


@numba.njit(cache=True)
def _composition(c: np.ndarray, h: float, out: np.ndarray) -> None:
    for b in range(c.shape[0]):
        row = c[b]
        m1, m2, m3 = row[fa._A1] * 0.6, row[fa._A2] * 0.8, row[fa._A3]
        pw, px, py, pz = fa._quat_e3_to_norm(m1, m2, m3, row[fa._G])
        half = 0.5 * h * row[fa._RATE]
        dw, dx, dy, dz = _quat_mul(math.cos(half), 0.0, 0.0, math.sin(half), pw, -px, -py, -pz)
        w1, w2, w3 = int(row[fa._AXIS]), int(row[fa._AXIS + 1]), int(row[fa._AXIS + 2])
        ex, ey, ez = row[fa._SIGN] * dx, row[fa._SIGN + 1] * dy, row[fa._SIGN + 2] * dz
        o = _quat_mul(row[fa._A], row[fa._A + 1], row[fa._A + 2], row[fa._A + 3], dw,
                      _scatter(ex, ey, ez, w1, w2, w3, 0), _scatter(ex, ey, ez, w1, w2, w3, 1),
                      _scatter(ex, ey, ez, w1, w2, w3, 2))  # fmt: skip
        inverse = 1.0 / math.sqrt(o[0] * o[0] + o[1] * o[1] + o[2] * o[2] + o[3] * o[3])
        for k in range(4):
            out[b, k] = o[k] * inverse


@numba.njit(cache=True)
def _evaluations(c: np.ndarray, h: float, out: np.ndarray) -> None:
    for b in range(c.shape[0]):
        fa.anchor_evaluate(c[b], h, out[b])


def pieces(sim: Simulation, repeats: int, reference: float) -> None:
    """The profile of one evaluation (module docstring), ns per body, at the horizon of the evaluation row."""
    n = sim.model.body_count
    s, h = sim.compiled.initial_state, sim.time
    constants = np.zeros((n, fa.ANCHOR_CONSTANTS))
    for b in range(n):
        fa.anchor_prepare(sim.model.body_inertia[b], s.q[b], s.L[b], constants[b])
    elliptic = constants[constants[:, fa._KIND] == fa.KIND_ELLIPTIC]
    series = int(np.count_nonzero(elliptic[:, fa._TERMS] > 0.0))
    out = np.empty((n, 4))
    rows = {
        "sn, cn, dn (kept AGM)": (lambda: _jacobi(elliptic, h), elliptic.shape[0]),
        "psi by Fourier series": (lambda: _fourier(elliptic, h), series),
        "psi by Pi (R_F + R_J)": (lambda: _closed_form(elliptic, h), elliptic.shape[0]),
        "quaternion composition": (lambda: _composition(constants, h, out), n),
        "whole evaluation": (lambda: _evaluations(constants, h, out), n),
    }
    print(f"  one evaluation in pieces ({elliptic.shape[0]} elliptic bodies, {series} with a Fourier series)")
    for name, (run, count) in rows.items():
        seconds, spread = timed(run, repeats)
        per = seconds / max(count, 1)
        print(f"    {name:26s} {per * 1e9:8.1f} ns  {per / reference:6.2f}x split2  (spread {spread:.2f})")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--bodies", type=int, default=10_000)
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--pieces", action="store_true", help="also time the pieces of one evaluation")
    parser.add_argument("--clock", choices=sorted(CLOCK), default="cpu", help="what `timed` measures")
    args = parser.parse_args()
    global clock
    clock = CLOCK[args.clock]
    n, repeats = args.bodies, args.repeats
    bodies = free_bodies(n)
    rows: dict[str, tuple[float, float]] = {}

    split2 = Simulation(prepare(scene(bodies, integrator="split2")))
    seconds, spread = timed(lambda: split2.step(100), repeats)
    rows["split2 step"] = (seconds / (100 * n), spread)

    exact = Simulation(prepare(scene(bodies, integrator="exact")))
    # the anchors, then 100 s on (deferred steps): each evaluation below is at a horizon of several periods,
    # the closed form's case (short arcs, lambda h < dist / 2, integrate psi' by Gauss-Legendre instead)
    exact.step(round(100.0 / exact.dt))
    seconds, spread = timed(lambda: exact.step(1), repeats)
    rows["exact evaluation"] = (seconds / n, spread)
    seconds, spread = timed(lambda: exact.step(100), repeats)
    rows["exact, recorded every 100"] = (seconds / (100 * n), spread)

    zero_drag = (ForceDrag(linear=1e-300),)  # a drag row that changes nothing: the forces are no longer constant
    eager = Simulation(prepare(scene(bodies, forces=zero_drag, integrator="exact")))
    seconds, spread = timed(lambda: eager.step(10), repeats)
    rows["exact, every step written"] = (seconds / (10 * n), spread)

    s, horizon = exact.compiled.initial_state, exact.time  # the same bodies and horizon as the evaluation
    inertia, out, work = exact.model.body_inertia, np.empty_like(s.q), np.empty(JACOBI_WORK_SIZE)
    seconds, spread = timed(lambda: free_rotation_exact_batch(inertia, s.q, s.L, horizon, out, work), repeats)
    rows["one-shot flow"] = (seconds / n, spread)

    reference = rows["split2 step"][0]
    print(f"{n} free bodies under gravity, median of {repeats} (spread max/min), {args.clock} time")
    for name, (seconds, spread) in rows.items():
        print(f"  {name:28s} {seconds * 1e9:8.1f} ns  {seconds / reference:6.2f}x split2  (spread {spread:.2f})")
    if args.pieces:
        pieces(exact, repeats, reference)


if __name__ == "__main__":
    main()
