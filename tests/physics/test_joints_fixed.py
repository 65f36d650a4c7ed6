"""Welded = union (issue 46 item 2): bodies joined by `fixed` joints are merged at compile time into one
rigid body of all their particles (scene/welds.py), so they move exactly as a body of those particles
written by hand, whatever the integrator; each part keeps its name and its pose (scene/parts.py), and
each weld reports the force and torque that keep its parts on the body's motion (runner/weld_reactions.py).

Tolerances: the welded body's model is the hand-written union's bit for bit (the same particles in the
same order), and the parts' initial momenta are summed where the union's are given as velocities (1e-16
apart), so the two runs differ by round-off only: 1e-12 after 2 s (measured ~1e-15). A weld's reaction
is the part's momentum change less its other forces over the step, so each part's momentum balances to
round-off: 1e-10 of the forces (measured ~1e-14)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import rbcli
from rbcli.physics.integrators import INTEGRATORS
from rbcli.physics.rotation import quat_conjugate, quat_multiply, quat_to_matrix
from rbcli.runner.simulation import Simulation
from rbcli.scene.compile import compile_model
from rbcli.scene.load import load_scene_text

G = np.array([0.0, 0.0, -9.81])


def _vector(v) -> str:  # noqa: ANN001
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def _points(a) -> str:  # noqa: ANN001
    return "[" + ", ".join(_vector(row) for row in a) + "]"


def _centre(p: np.ndarray, m: np.ndarray) -> np.ndarray:
    return (m[:, None] * p).sum(axis=0) / m.sum()


class Welded:
    """Bodies given by particles in the world frame at t = 0 (orientation 1, position their centre of
    mass), welded by `welds` (pairs of names or a name and world), as a scene of the parts and as a scene
    of their union written by hand. Every part moves with the rigid motion v0 at the union's centre of mass
    and angular velocity w, plus `relative` [m/s] of its own (a velocity the welds take: the union starts
    with the parts' total momentum)."""

    def __init__(self, parts: dict, welds, v0, w, dt: float, steps: int, integrator: str = "split2",  # noqa: ANN001
                 relative: dict | None = None, joints: str = "", streams: str = "[bodies]") -> None:  # fmt: skip
        self.parts = {name: (np.asarray(p, dtype=float), np.asarray(m, dtype=float)) for name, (p, m) in parts.items()}
        self.centres = {name: _centre(p, m) for name, (p, m) in self.parts.items()}
        points = np.vstack([p for p, _ in self.parts.values()])
        masses = np.concatenate([m for _, m in self.parts.values()])
        self.union_centre = _centre(points, masses)
        relative = relative or {}
        head = (f"simulation: {{dt: {dt!r}, steps: {steps}, integrator: {integrator}, record: {{every: 1, "
                f"streams: {streams}}}}}\ngravity: {_vector(G)}\nbodies:\n")  # fmt: skip

        def body(name: str, p: np.ndarray, m: np.ndarray, c: np.ndarray, dv) -> str:  # noqa: ANN001
            v = np.asarray(v0) + np.cross(w, c - self.union_centre) + dv
            return (f"  - {{name: {name}, particles: {{positions: {_points(p)}, masses: {_vector(m)}}}, "
                    f"position: {_vector(c)}, velocity: {_vector(v)}, angular_velocity: {_vector(w)}}}\n")  # fmt: skip

        welds_text = "".join(
            f"  - {{name: {a}_{b}, type: fixed, bodies: [{a}, {b}], anchor: {_vector(self.union_centre)}}}\n"
            for a, b in welds
        )
        bodies = "".join(body(n, p, m, self.centres[n], relative.get(n, 0.0)) for n, (p, m) in self.parts.items())
        self.scene = head + bodies + "joints:\n" + welds_text + joints
        shared = sum(self.parts[n][1].sum() * np.asarray(dv, dtype=float) for n, dv in relative.items()) / masses.sum()
        union_joints = f"joints:\n{joints}" if joints else ""
        self.union = head + body("u", points, masses, self.union_centre, shared) + union_joints
        self.steps = steps
        self.frames: dict[str, np.ndarray] = {}  # a part written in its own frame: world-from-that-frame at t = 0

    def poses(self, sim: Simulation) -> tuple[np.ndarray, np.ndarray]:
        """Every particle's world position and each part's orientation (world-from-world-at-t=0), from the
        parts' recorded poses (a scene of parts) or the union's (the hand-written body)."""
        s = sim.state  # q: world-from-user frame; the user frames here are the world frame at t = 0 ...
        if len(s.x) == len(self.parts):  # ... but for a part written in a turned frame (`frames`)
            turn = np.array([self.frames.get(n, [1.0, 0.0, 0.0, 0.0]) for n in self.parts])
            s = replace(s, q=quat_multiply(s.q, quat_conjugate(turn)))
        R = quat_to_matrix(s.q)
        if len(s.x) == len(self.parts):
            points = [s.x[i] + (p - self.centres[n]) @ R[i].T for i, (n, (p, _)) in enumerate(self.parts.items())]
            return np.vstack(points), s.q
        points = [s.x[0] + (p - self.union_centre) @ R[0].T for p, _ in self.parts.values()]
        return np.vstack(points), np.repeat(s.q, len(self.parts), axis=0)

    def differences(self) -> tuple[float, float]:
        """The largest distance [m] between a particle of the parts and the same particle of the union, and
        the largest angle [rad] between a part's orientation and the union's, after `steps`."""
        parts, union = Simulation(load_scene_text(self.scene)), Simulation(load_scene_text(self.union))
        parts.step(self.steps)
        union.step(self.steps)
        (a, qa), (b, qb) = self.poses(parts), self.poses(union)
        turn = quat_multiply(qa, quat_conjugate(qb))
        angle = 2.0 * np.arctan2(np.linalg.norm(turn[:, 1:], axis=1), np.abs(turn[:, 0]))
        return float(np.abs(a - b).max()), float(angle.max())


BOX = np.array([[x, y, z] for x in (-0.2, 0.2) for y in (-0.1, 0.1) for z in (-0.05, 0.05)]) + [0.1, 0.0, 0.0]
BOX_MASSES = [0.3, 0.2, 0.25, 0.25, 0.2, 0.3, 0.25, 0.25]
ROD = [[0.3, 0, 0], [0.6, 0.05, 0], [0.9, 0.0, 0.1]]
ROD_MASSES = [0.4, 0.3, 0.2]


def tumbling_pair(integrator: str = "split2", dt: float = 1e-3, steps: int = 2000, **keys) -> Welded:  # noqa: ANN003
    """The issue's scene: two clouds welded, spinning at (1, 2, 3) rad/s under gravity."""
    parts = {"a": (BOX, BOX_MASSES), "b": (ROD, ROD_MASSES)}
    return Welded(parts, [("a", "b")], v0=[0.3, 0, 1.0], w=[1.0, 2.0, 3.0], dt=dt, steps=steps,
                  integrator=integrator, **keys)  # fmt: skip


@pytest.mark.parametrize("integrator", [*sorted(INTEGRATORS), "dopri5, tolerance: 1.0e-9"])
def test_welded_clouds_move_as_their_union_body_for_every_integrator(integrator):
    """After 2 s of tumbling under gravity (dt = 1e-3; adaptive dopri5 too) the parts' particles and
    orientations are the union's to 1e-12 (before the merge: 1.4e-6 m and 1.05e-5 rad with split2, the
    only method that ran)."""
    distance, angle = tumbling_pair(integrator).differences()
    assert distance <= 1e-12 and angle <= 1e-12, (distance, angle)


def test_a_weld_takes_a_relative_velocity_as_an_inelastic_weld_and_warns():
    """b starts 1 m/s faster than the rigid motion: the welded body starts with the total momentum (and
    angular momentum about its centre of mass), as the union written with them; a warning says how much
    kinetic energy the weld takes (1/2 mu |dv|^2, mu = m_a m_b / M, the relative velocity along the line
    of the centres of mass here, so no rotation takes a share)."""
    rod = [[0.8, 0, 0], [1.2, 0, 0], [1.0, 0.05, 0], [1.0, -0.05, 0]]
    pair = Welded({"a": (BOX - [0.1, 0, 0], [0.25] * 8), "b": (rod, [0.3] * 4)}, [("a", "b")], v0=[0.1, 0.2, 0.3],
                  w=[0, 0, 0], dt=1e-3, steps=1000, relative={"b": [1.0, 0.0, 0.0]})  # fmt: skip
    assert max(pair.differences()) <= 1e-12
    (warning,) = [w for w in rbcli.prepare(load_scene_text(pair.scene)).warnings if "inelastic" in w.message]
    mu = 2.0 * 1.2 / 3.2
    assert f"{0.5 * mu:.4g} J of kinetic energy lost" in warning.message, warning.message
    assert warning.severity == "warning" and warning.location.line == 4  # body 'a'


@pytest.mark.parametrize("integrator", ["split2", "rk4"])
def test_each_parts_momentum_changes_by_gravity_and_its_welds_reaction(integrator):
    """Every step recorded: part i's momentum changes by (m_i g + F_i) dt, F_i the weld's recorded force
    on it. For b that is how its weld's reaction is defined; for a, the root of the weld tree, whose row is
    b's reversed (Newton's third law), it holds only because the body's momentum changes by M g dt and the
    parts' momenta add up to it: measured 2e-14 of the forces. Angular momentum about each part's centre of
    mass changes by the recorded torque dt: for b to round-off, for a to O(dt^2) (over a finite step the
    parts' moments of momentum about moving centres do not add up exactly: measured 3.1e-6 of the torque
    with split2 at dt = 1e-3, 7.8e-7 at 5e-4; 6.0e-7 with rk4). The stream is Simulation.joint_reactions."""
    pair = tumbling_pair(integrator, steps=200, streams="[bodies, joint_forces]")
    scene = load_scene_text(pair.scene)
    trajectory = rbcli.simulate(scene)
    assert trajectory.body_names == ("a", "b") and trajectory.joint_names == ("a_b",)
    reaction = trajectory.joint_reactions["a_b"]  # (T, 2, 6): rows for a and b
    assert np.isnan(reaction[0]).all() and np.isfinite(reaction[1:]).all()
    dt = 1e-3
    masses = np.array([np.sum(BOX_MASSES), np.sum(ROD_MASSES)])
    force = reaction[1:, :, 0:3]
    expected = masses[None, :, None] * G + force
    dP = np.diff(trajectory.P, axis=0) / dt
    assert np.abs(dP - expected).max() <= 1e-10 * np.abs(expected).max()
    torque = reaction[1:, :, 3:6]
    dL = np.diff(trajectory.L, axis=0) / dt
    assert np.abs(dL[:, 1] - torque[:, 1]).max() <= 1e-10 * np.abs(torque).max()
    assert np.abs(dL[:, 0] - torque[:, 0]).max() <= 1e-5 * np.abs(torque).max()
    sim = Simulation(scene)
    sim.step(200)
    assert np.allclose(sim.joint_reactions["a_b"], reaction[-1], rtol=0, atol=1e-12 * np.abs(reaction[-1]).max())


def test_a_loop_of_welds_moves_as_its_union_and_a_body_welded_to_the_world_is_static():
    """Three clouds welded in a loop (a-b, b-c, c-a) tumble as their union to 1e-12; the loop's last weld
    carries nothing (a loop of welds is statically indeterminate: the spanning tree's welds carry it all)
    and each part's momentum still balances its weight and its welds' forces. A fourth body welded to the
    world, without a contact section, stays where it is, its weld holding its weight (F = -m g)."""
    third = np.array([[0.1, 0.3, 0.0], [0.2, 0.5, 0.1], [0.0, 0.6, -0.1]])
    parts = {"a": (BOX, BOX_MASSES), "b": (ROD, ROD_MASSES), "c": (third, [0.2, 0.2, 0.3])}
    loop = Welded(parts, [("a", "b"), ("b", "c"), ("c", "a")], v0=[0.3, 0, 1.0], w=[1.0, 2.0, 3.0], dt=1e-3,
                  steps=2000)  # fmt: skip
    assert max(loop.differences()) <= 1e-12
    post = [[2.0, 0.0, 0.0], [2.0, 0.0, 0.5], [2.1, 0.0, 0.25]]
    text = loop.scene.replace("joints:\n", f"  - {{name: post, particles: {{positions: {_points(post)}, masses: 1.0}}, "
                              "position: [2.0333333333333333, 0.0, 0.25]}\njoints:\n")  # fmt: skip
    text = text.replace("streams: [bodies]", "streams: [bodies, joint_forces]").replace("steps: 2000", "steps: 50")
    text += "  - {name: ground, type: fixed, bodies: [world, post], anchor: [2, 0, 0]}\n"
    trajectory = rbcli.simulate(load_scene_text(text))
    assert trajectory.body_names == ("a", "b", "c", "post")
    assert np.array_equal(trajectory.x[:, 3], np.repeat(trajectory.x[:1, 3], len(trajectory.step), axis=0))
    ground = trajectory.joint_reactions["ground"][1:]  # row 0: the post (the world is never row 0)
    assert np.abs(ground[:, 0, 0:3] - 3.0 * -G).max() <= 1e-12 and not ground[:, 1].any()
    assert not trajectory.joint_reactions["c_a"][1:].any()
    masses = np.array([np.sum(BOX_MASSES), np.sum(ROD_MASSES), 0.7])
    force = np.zeros((len(trajectory.step) - 1, 3, 3))
    for name in ("a_b", "b_c", "c_a"):
        a, b = name.split("_")
        rows = trajectory.joint_reactions[name][1:]
        force[:, "abc".index(a)] += rows[:, 0, 0:3]
        force[:, "abc".index(b)] += rows[:, 1, 0:3]
    expected = masses[None, :, None] * G + force
    dP = np.diff(trajectory.P[:, :3], axis=0) / 1e-3
    assert np.abs(dP - expected).max() <= 1e-10 * np.abs(expected).max()


def test_a_hinge_on_a_welded_part_holds_the_union_as_a_hinge_on_the_union():
    """A rod of two welded halves hinged to the world at one half's end swings as the one rod on the same
    hinge (the hinge's anchor and axis re-expressed on the welded body, split2's joint stages): to 1e-12
    after 0.5 s, with the same reaction force on the hinged half; its torque is about that half's centre
    of mass, the rod's reaction moved there."""
    top = [[0.1, 0.0, 0.8], [0.2, 0.05, 0.6], [0.15, -0.05, 0.7]]
    bottom = [[0.3, 0.0, 0.4], [0.4, 0.05, 0.2], [0.5, -0.05, 0.05]]
    hinge = "  - {name: pivot, type: hinge, bodies: [HINGED, world], anchor: [0, 0, 1], axis: [0, 1, 0]}\n"
    parts = {"top": (top, [0.2, 0.2, 0.1]), "bottom": (bottom, [0.2, 0.2, 0.2])}
    rod = Welded(parts, [("top", "bottom")], v0=[0, 0, 0], w=[0, 0, 0], dt=1e-3, steps=500, joints=hinge,
                 streams="[bodies, joint_forces]")  # fmt: skip
    rod.scene, rod.union = rod.scene.replace("HINGED", "top"), rod.union.replace("HINGED", "u")
    assert max(rod.differences()) <= 1e-12
    parts, union = Simulation(load_scene_text(rod.scene)), Simulation(load_scene_text(rod.union))
    parts.step(500)
    union.step(500)
    mine, theirs = parts.joint_reactions["pivot"], union.joint_reactions["pivot"]
    assert np.abs(mine[0, 0:3] - theirs[0, 0:3]).max() <= 1e-10 * np.abs(theirs[0, 0:3]).max()
    lever = parts.state.x[0] - union.state.x[0]
    moved = theirs[0, 3:6] - np.cross(lever, theirs[0, 0:3])
    assert np.abs(mine[0, 3:6] - moved).max() <= 1e-10 * np.abs(theirs[0, 0:6]).max()


def test_every_recording_shows_the_parts_under_their_names(tmp_path):
    """MCAP, Rerun and memory: the scene's bodies with their own names and poses (the particles stream
    too), read back by rbcli.record.read as the Simulation shows them (bit for bit from .mcap, to float32
    from .rrd)."""
    from rbcli.record.read import read_trajectory

    pair = tumbling_pair(steps=20, streams="[bodies, particles, joint_forces]")
    compiled = rbcli.prepare(load_scene_text(pair.scene))
    memory = rbcli.simulate(compiled)
    sim = Simulation(compiled)
    sim.step(20)
    assert np.array_equal(memory.x[-1], sim.state.x) and np.array_equal(memory.q[-1], sim.state.q)
    for suffix, tolerance in ((".mcap", 0.0), (".rrd", 1e-7)):  # Rerun keeps poses in float32
        rbcli.run_to_file(compiled, tmp_path / f"pair{suffix}")
        read = read_trajectory(tmp_path / f"pair{suffix}")
        assert read.body_names == ("a", "b"), suffix
        assert np.abs(read.x - memory.x).max() <= tolerance and np.abs(read.q - memory.q).max() <= tolerance
    assert memory.particle_position.shape == (21, 11, 3)
    start = np.vstack([BOX, ROD])
    assert np.abs(memory.particle_position[0] - start).max() <= 1e-15


def test_set_state_moves_each_welded_body_with_its_first_part():
    """set_state in the scene's bodies: a welded body follows its first part; the others read back on it."""
    sim = Simulation(load_scene_text(tumbling_pair(steps=1).scene))
    before = sim.state
    sim.set_state(x=before.x + [1.0, 2.0, 3.0], omega=np.zeros((2, 3)), v=np.zeros((2, 3)))
    after = sim.state
    assert np.abs(after.x - before.x - [1.0, 2.0, 3.0]).max() <= 1e-14
    assert np.abs(after.v).max() <= 1e-15 and np.abs(after.omega).max() <= 1e-15


def test_the_constraint_form_of_a_weld_is_still_compiled_on_request():
    """compile_model(merge_welds=False) keeps a weld as 6 constraint rows (the joint kernels' tests)."""
    spec = load_scene_text(tumbling_pair(steps=1).scene)
    assert spec.compiled_model.model.joint is None and spec.compiled_model.model.body_count == 1
    rows = compile_model(replace(spec, compiled_model=None), merge_welds=False)
    assert rows.model.joint.row_count.tolist() == [6] and rows.model.body_count == 2


def test_force_terms_on_welded_parts_act_on_the_union_as_written_there():
    """Points, particles and body-frame vectors given in a part's own frame (here a part turned 30 degrees
    in its frame) act on the welded body exactly as the same terms written on the union at the same world
    points: a body-frame force at b's point, a spring from a's particle to the world, a body-frame torque
    on b, a uniform field on a alone (a force at a's centre of mass); rk4, 1 s, to 1e-12."""
    angle = 0.5235987755982988
    R = np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0], [0.0, 0.0, 1.0]])
    local = np.array([[0.0, 0.0, 0.0], [0.4, 0.0, 0.0], [0.2, 0.1, 0.05]])  # b's particles in its own frame
    b_mass = np.array([0.4, 0.3, 0.2])
    b_centre_local = _centre(local, b_mass)
    b_world_centre = np.array([0.5, 0.2, 0.0])
    b_world = b_world_centre + (local - b_centre_local) @ R.T
    pair = Welded({"a": (BOX, BOX_MASSES), "b": (b_world, b_mass)}, [("a", "b")], v0=[0.1, 0, 0.2], w=[0.5, -1, 2],
                  dt=1e-3, steps=1000, integrator="rk4")  # fmt: skip
    # b written in its own frame, turned by R
    b_line = next(line for line in pair.scene.splitlines() if line.startswith("  - {name: b,"))
    mine = b_line.replace(_points(b_world), _points(local)).replace(
        "position:", f"orientation: {{axis_angle: {{axis: [0, 0, 1], angle: {angle!r}}}}}, position:"
    )
    text = pair.scene.replace(b_line, mine)
    pair.frames["b"] = np.array([np.cos(angle / 2), 0.0, 0.0, np.sin(angle / 2)])
    point_b, vector_b, torque_b = np.array([0.3, 0.05, 0.0]), np.array([0.0, 2.0, 1.0]), np.array([0.2, 0.0, 0.1])
    a_particle = 5
    forces = ("forces:\n"
              f"  - {{type: force, body: b, point: {_vector(point_b)}, vector: {_vector(vector_b)}, frame: body}}\n"
              f"  - {{type: spring, body: a, particle: {a_particle}, anchor: [0, 0, 2], stiffness: 30}}\n"
              f"  - {{type: torque, body: b, vector: {_vector(torque_b)}, frame: body}}\n"
              "  - {type: field, bodies: [a], value: [0.5, 0, 0]}\n")  # fmt: skip
    world_point = b_world_centre + R @ (point_b - b_centre_local)
    union_forces = ("forces:\n"
                    f"  - {{type: force, body: u, point: {_vector(world_point)}, vector: {_vector(R @ vector_b)}, "
                    "frame: body}\n"
                    f"  - {{type: spring, body: u, particle: {a_particle}, anchor: [0, 0, 2], stiffness: 30}}\n"
                    f"  - {{type: torque, body: u, vector: {_vector(R @ torque_b)}, frame: body}}\n"
                    f"  - {{type: force, body: u, point: {_vector(_centre(BOX, np.array(BOX_MASSES)))}, "
                    f"vector: [{float(0.5 * np.sum(BOX_MASSES))!r}, 0, 0]}}\n")  # fmt: skip
    pair.scene = text.replace("joints:\n", forces + "joints:\n")
    pair.union = pair.union + union_forces
    assert max(pair.differences()) <= 1e-12


def test_welded_clouds_collide_on_their_own_particles_as_their_union():
    """With contact, the welded body's contact spheres are its parts' (their particles, in part order): it
    lands on the ground as the union does, to 1e-12 after 0.4 s; its weld's reaction is NaN (the contact
    force on each part is not known from the states) and says so nowhere else."""
    radius = "radius: 0.02"
    pair = Welded({"a": (BOX, BOX_MASSES), "b": (ROD, ROD_MASSES)}, [("a", "b")], v0=[0.2, 0, -1.0], w=[0, 1, 2],
                  dt=5e-4, steps=800, integrator="split2", streams="[bodies, joint_forces]")  # fmt: skip
    contact = "contact: {planes: [{point: [0, 0, -0.3], normal: [0, 0, 1]}]}\n"
    pair.scene = contact + pair.scene.replace("masses: [", f"{radius}, masses: [")
    pair.union = contact + pair.union.replace("masses: [", f"{radius}, masses: [")
    assert max(pair.differences()) <= 1e-12
    trajectory = rbcli.simulate(load_scene_text(pair.scene))
    assert trajectory.x[:, :, 2].min() < trajectory.x[0, :, 2].min() - 0.1  # it fell and hit the ground
    assert np.isnan(trajectory.joint_reactions["a_b"]).all()


def test_a_resumed_welded_run_records_what_the_run_never_stopped_records(tmp_path, monkeypatch):
    """The checkpoint carries the state before its step, so the first resumed frame's weld reaction is the
    uninterrupted run's, bit for bit, as are the parts' poses."""
    import os
    import signal

    import rbcli.runner.loop as loop
    from rbcli.record.mcap_sink import SinkMcap
    from rbcli.record.read import read_mcap
    from rbcli.runner.resume import plan_resume, resume_run

    monkeypatch.setattr(loop, "CHUNK_SECONDS", 0.002)  # many chunks, so the stop falls mid-run
    path = tmp_path / "pair.yaml"
    path.write_text(tumbling_pair(steps=600, streams="[bodies, joint_forces]").scene.replace("every: 1", "every: 7"))
    Simulation(path).run(sinks=[SinkMcap(tmp_path / "whole.mcap")])

    def interrupted_run(name: str):  # noqa: ANN202 - the resume plan of a run stopped after its second chunk
        calls = []

        def progress(done: int, total: int) -> None:
            calls.append(done)
            if len(calls) == 2:
                os.kill(os.getpid(), signal.SIGINT)

        assert Simulation(path).run(sinks=[SinkMcap(tmp_path / name)], progress=progress).status == "interrupted"
        return plan_resume(tmp_path / name)

    # where the stop falls depends on the chunks' timing: a stop on a recording step (1 in 7) would not
    # test a checkpoint between frames, so stop again until one falls between them
    for attempt in range(6):
        plan = interrupted_run(f"cut{attempt}.mcap")
        if plan.checkpoint.step % 7:
            break
    assert 0 < plan.checkpoint.step < plan.total_steps and plan.checkpoint.step % 7
    resume_run(plan, [SinkMcap(tmp_path / "resumed.mcap")])
    a, b = read_mcap(tmp_path / "resumed.mcap"), read_mcap(tmp_path / "whole.mcap")
    assert a.body_names == ("a", "b") and a.step.tolist() == b.step.tolist()
    assert a.x.tobytes() == b.x.tobytes() and a.joint_force.tobytes() == b.joint_force.tobytes()


def test_what_a_merge_cannot_keep_exactly_is_warned_or_refused():
    """Drag on a welded part becomes drag on its body (a warning: exact only while it translates); a spring
    or a joint between two welded parts holds nothing and is left out (a warning each); a field with a
    gradient on some parts of a welded body cannot be one, and is refused at its line."""
    from rbcli.scene.spec import SceneError

    base = tumbling_pair(steps=1).scene
    extra = ("  - {name: inside, type: ball, bodies: [a, b], anchor: [0, 0, 0]}\n"
             "forces:\n  - {type: drag, bodies: [a], linear: 0.1}\n"
             "  - {type: spring, bodies: [a, b], particles: [0, 1], stiffness: 10}\n")  # fmt: skip
    warnings = rbcli.prepare(load_scene_text(base + extra)).warnings
    messages = [w.message for w in warnings if w.severity == "warning"]
    assert any("drag acts at each simulated body's centre of mass" in m for m in messages), messages
    assert any("joint 'inside': both its bodies are welded" in m for m in messages), messages
    assert any("force 'spring': bodies 'a' and 'b' are welded" in m for m in messages), messages
    field = "forces:\n  - {type: field, bodies: [a], value: [0, 0, 1], gradient: [[1, 0, 0], [0, 0, 0], [0, 0, 0]]}\n"
    with pytest.raises(SceneError, match="a field with a gradient on 'a'") as error:
        load_scene_text(base + field)
    assert error.value.issues[0].location.line == base.count("\n") + 2
