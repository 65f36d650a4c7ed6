"""A fixed joint makes two bodies move as the single rigid body of their union, simulated alone: to
round-off where split2 is exact for both (a relative velocity along the line of the centres of mass,
absorbed by the weld), and converging at second order in a general tumble (the pair's splitting and the union's
are different second-order maps of the same exact flow)."""

from __future__ import annotations

import numpy as np

from rbcli.physics.rotation import quat_to_matrix
from rbcli.runner.simulation import Simulation
from rbcli.scene.load import load_scene_text


def _vector(v) -> str:  # noqa: ANN001
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def _points(a) -> str:  # noqa: ANN001
    return "[" + ", ".join(_vector(row) for row in a) + "]"


def _centre(p: np.ndarray, m: np.ndarray) -> np.ndarray:
    return (m[:, None] * p).sum(axis=0) / m.sum()


class Pair:
    """Bodies a and b given by particles in one world-aligned frame at t = 0, as a fixed pair and as their
    union. The union moves rigidly (v0 at its centre of mass, angular velocity w); the pair's bodies move
    with that rigid motion plus `relative` [m/s] for b (a velocity the weld must absorb: the union starts
    with the pair's total momentum, v0 + m_b relative / M)."""

    def __init__(self, pa, ma, pb, mb, v0, w, dt: float, steps: int, relative=(0.0, 0.0, 0.0)) -> None:  # noqa: ANN001
        self.pa, self.ma, self.pb, self.mb = (np.asarray(v, dtype=float) for v in (pa, ma, pb, mb))
        self.ca, self.cb = _centre(self.pa, self.ma), _centre(self.pb, self.mb)
        self.cu = _centre(np.vstack([self.pa, self.pb]), np.concatenate([self.ma, self.mb]))
        head = f"simulation: {{dt: {dt!r}, steps: {steps}, integrator: split2}}\ngravity: [0, 0, -9.81]\nbodies:\n"

        def body(name: str, p: np.ndarray, m: np.ndarray, c: np.ndarray, dv=(0.0, 0.0, 0.0)) -> str:  # noqa: ANN001
            v = np.asarray(v0) + np.cross(w, c - self.cu) + dv
            return (f"  - {{name: {name}, particles: {{positions: {_points(p)}, masses: {_vector(m)}}}, "
                    f"position: {_vector(c)}, velocity: {_vector(v)}, angular_velocity: {_vector(w)}}}\n")  # fmt: skip

        self.pair = (head + body("a", self.pa, self.ma, self.ca) + body("b", self.pb, self.mb, self.cb, relative)
                     + f"joints:\n  - {{type: fixed, bodies: [a, b], anchor: {_vector(self.cu)}}}\n")  # fmt: skip
        shared = self.mb.sum() / (self.ma.sum() + self.mb.sum()) * np.asarray(relative, dtype=float)
        self.union = head + body(
            "u", np.vstack([self.pa, self.pb]), np.concatenate([self.ma, self.mb]), self.cu, shared
        )
        self.steps = steps

    def difference(self) -> float:
        """The largest distance [m] between a particle of the pair and the same particle of the union."""
        pair, union = Simulation(load_scene_text(self.pair)), Simulation(load_scene_text(self.union))
        pair.step(self.steps)
        union.step(self.steps)

        def world(sim: Simulation, groups: list[tuple[np.ndarray, np.ndarray]]) -> np.ndarray:
            s = sim.state  # q: world-from-user frame
            R = quat_to_matrix(s.q)
            return np.vstack([s.x[i] + (p - c) @ R[i].T for i, (p, c) in enumerate(groups)])

        a = world(pair, [(self.pa, self.ca), (self.pb, self.cb)])
        b = world(union, [(np.vstack([self.pa, self.pb]), self.cu)])
        return float(np.abs(a - b).max())


BOX = [[x, y, z] for x in (-0.2, 0.2) for y in (-0.1, 0.1) for z in (-0.05, 0.05)]


def test_a_weld_absorbs_a_relative_velocity_and_then_moves_as_the_union_to_round_off():
    """b starts at 1 m/s along the line through both centres of mass, a at rest: the first step's
    stages weld them (an inelastic push carried by the joint alone), and from then on the pair is the
    union moving at the total momentum over the total mass under gravity. split2 is exact for both
    forms of this motion, so they agree to round-off: 1e-10 m after 1 s (measured 7e-14)."""
    rod = [[0.8, 0, 0], [1.2, 0, 0], [1.0, 0.05, 0], [1.0, -0.05, 0]]
    pair = Pair(BOX, [0.25] * 8, rod, [0.3] * 4, v0=[0.1, 0.2, 0.3], w=[0, 0, 0], dt=1e-3, steps=1000,
                relative=[1.0, 0.0, 0.0])  # fmt: skip
    assert pair.difference() <= 1e-10
    # the weld really acted: without it b would have run 1 m ahead of the union
    free = Simulation(load_scene_text(pair.pair.split("joints:")[0]))
    free.step(1000)
    assert abs(free.state.x[1, 0] - (pair.cb[0] + 1.1)) < 1e-12


def test_a_tumbling_pair_converges_to_its_union_at_second_order():
    """Spinning about (1, 2, 3) rad/s under gravity: the particles of the welded pair and of the union
    differ by O(dt^2) (measured 1.5e-6 m at dt = 1e-3 after 0.5 s; 4.0x less per halving). The two are
    different second-order maps: the pair's step is RATTLE (its drift between two half kicks), the
    union's split2's drift-kick-drift."""
    box = np.array(BOX) + [0.1, 0.0, 0.0]
    rod = [[0.3, 0, 0], [0.6, 0.05, 0], [0.9, 0.0, 0.1]]
    masses = [0.3, 0.2, 0.25, 0.25, 0.2, 0.3, 0.25, 0.25]
    errors = [
        Pair(box, masses, rod, [0.4, 0.3, 0.2], v0=[0.3, 0, 1.0], w=[1.0, 2.0, 3.0], dt=dt, steps=round(0.5 / dt))
        .difference()
        for dt in (2e-3, 1e-3)
    ]  # fmt: skip
    assert 3.5 < errors[0] / errors[1] < 4.5, errors
    assert errors[1] < 3e-6, errors
