"""The object API: compile a scene once, then step, read and change the state, reset, and run.

    import rbcli
    sim = rbcli.Simulation("scenes/tumbling_plate.yaml", integrator="split2", dt=1e-3)
    sim.step(1000)                 # compiled chunk, no recording
    sim.state.omega                # (N, 3) [rad/s], world frame
    sim.set_state(omega=...)       # in the user's frames; the internal principal-frame state follows
    sim.reset()
    saved = sim.checkpoint()       # everything carried between steps; sim.restore(saved) continues bitwise
    sim.joint_reactions["hinge"]   # (2, 6): the last step's force [N] and torque [N m] of a joint on its bodies
    summary = sim.run(2.0, sinks=[...])   # the CLI's run: chunks, recording, interrupts

A Simulation owns the compiled scene (constant Model and force tables, runner settings) and one Data
(every mutable array, physics/data.py). The user's frames (the particle frame given in the scene) are
converted to the internal principal frame only here and in the recording blocks; so are the scene's
bodies welded into one simulated body (scene/welds.py): `state`, `set_state` and `joint_reactions` show
the scene's bodies (scene/parts.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Unpack

import numpy as np

from rbcli.physics.data import make_data
from rbcli.physics.frames import body_angular_velocity, internal_orientation, user_orientation
from rbcli.physics.integrators import get_integrator
from rbcli.physics.joints.tables import JOINT_KINDS
from rbcli.physics.rotation import quat_conjugate, quat_multiply, quat_rotate, quat_rotate_inverse
from rbcli.physics.state import State
from rbcli.runner.governor import ThreadGovernor
from rbcli.runner.threads import (
    chunk_threads,
    contact_threads,
    plan_threads,
    prepare_pool,
    serial_reason,
    use_threads,
)
from rbcli.scene.compile import CompiledScene, RunOptions, RunOverrides
from rbcli.scene.parts import merged_state, part_states

if TYPE_CHECKING:
    from rbcli.physics.kernel_handle import KernelHandle
    from rbcli.record.frame import Checkpoint, RunSummary, Sink
    from rbcli.runner.loop import ProgressCallback
    from rbcli.scene.spec import SceneSpec

# record_every for steps that record nothing: no grid index below 2^62 is a multiple of it but 0
NEVER = 2**62
# a checkpoint's array of the simulated state before its step, in scenes with welds (their reactions)
WELD_PREVIOUS = "weld.previous"
# joints/tables.py's kind codes, as JointCoordinates names them
_KIND_NAMES = {code: name for name, code in JOINT_KINDS.items()}


class SimulationDiverged(RuntimeError):
    """The state became non-finite or blew up; `trajectory` holds every frame up to that point (when the
    run recorded one; `Simulation.step` records nothing)."""

    def __init__(self, message: str, trajectory=None) -> None:  # noqa: ANN001 - Trajectory | None
        super().__init__(message)
        self.trajectory = trajectory


@dataclass(frozen=True)
class BodyState:
    """A snapshot of every body, in the user's frames. SI units; arrays (body_count, ...).

    x: centre of mass [m], world. q: (w, x, y, z) world-from-user-body-frame. v [m/s], omega [rad/s]:
    world. P [kg m/s], L [kg m^2/s]: world, L about the centre of mass. t = step * dt [s].
    """

    step: int
    t: float
    x: np.ndarray
    q: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    P: np.ndarray
    L: np.ndarray


@dataclass(frozen=True)
class JointCoordinates:
    """One joint's coordinate and rate in joint coordinates (a reduced integrator: docs/trees.md).

    kind: "hinge", "slider" or "ball". child: the body the joint moves, the end farther from its tree's
    root; parent: the other end ("world" for the world or a static body). position: a hinge's angle [rad]
    or a slider's travel [m], the child's relative to its parent measured from the initial pose, shape
    (1,); a ball's unit quaternion (w, x, y, z), the child's turn relative to its parent since the
    initial pose, in the child's own (user) body frame, shape (4,). rate: d position / dt [rad/s, m/s],
    or a ball's relative angular velocity [rad/s] in the child's body frame, shape (1,) or (3,).
    """

    kind: str
    child: str
    parent: str
    position: np.ndarray
    rate: np.ndarray


class Simulation:
    """A scene compiled once, with its state: step, read, write, reset, run (see the module docstring)."""

    def __init__(
        self,
        scene: SceneSpec | CompiledScene | str | Path,
        options: RunOptions | None = None,
        *,
        threads: int | str | None = None,
        **overrides: Unpack[RunOverrides],
    ) -> None:
        """scene: a path, a loaded scene or a CompiledScene; run options (RunOptions: dt, duration,
        integrator, record_every, tolerance, compression) as one object, keywords or both (keywords win),
        only with a scene (a CompiledScene has its settings). threads: runner/threads.py."""
        if isinstance(scene, CompiledScene):
            if (options is not None and options.given()) or any(v is not None for v in overrides.values()):
                raise ValueError("overrides apply when compiling: pass a scene or a path, not a CompiledScene")
            compiled = scene
        else:
            from rbcli.scene.compile import compile_scene
            from rbcli.scene.load import load_scene
            from rbcli.scene.spec import SceneSpec

            spec = scene if isinstance(scene, SceneSpec) else load_scene(scene)
            compiled = compile_scene(spec, options, **overrides)
        self.compiled = compiled
        self.model = compiled.model
        self.forces = compiled.forces
        self.settings = compiled.settings
        info = get_integrator(self.settings.integrator)
        tolerance = self.settings.tolerance
        self.adaptive = tolerance is not None
        self.threads = 1  # the threads the chunk loop runs on (1: the serial loop)
        self.contact_threads = 1  # the threads of the contact stage's pair search (1: the serial search)
        # with the default thread count: chooses 1 or all of them per slice of a chunk (runner/governor.py)
        self.governor: ThreadGovernor | None = None
        self.threads_why = "adaptive steps run on one thread" if tolerance is not None else ""
        # whether the joints' last (sub-)step impulses describe the step that led to the current state:
        # not before a step, nor after set_state or reset (restore: when the checkpoint carries them)
        self.reactions_known = False
        if tolerance is not None:  # the error-controlled loop (physics/adaptive_loop.py, the method: adaptive.py)
            self._chunk = info.adaptive_chunk().run_chunk
            self.data = make_data(
                compiled.initial_state, self.model, 0, adaptive=True, tolerance=tolerance,
                duration=self.settings.steps * self.settings.dt, forces=self.forces,
            )  # fmt: skip
        else:
            # threads (runner/threads.py): the loop whose passes over the bodies run on threads, for a
            # scene large enough to gain; bitwise the serial loop's results at any thread count
            plan = plan_threads(threads)
            contact, joints = compiled.contact is not None, compiled.model.joint is not None
            self.threads = chunk_threads(plan.count, info.parallel, compiled.model.body_count, contact, joints)
            if contact:
                from rbcli.physics.contact.tables import touching_spheres

                # the spheres the search walks: a shape body's lattice is its mass only (a stack of boxes
                # has thousands and walks none: no threaded search to compile for it)
                self.contact_threads = contact_threads(plan.count, touching_spheres(compiled.model.contact))
                if info.implicit_contact:  # it keeps the contacts in the search's order (implicit_rows.py)
                    self.contact_threads = 1
            self.threads_why = plan.why
            if max(self.threads, self.contact_threads) > 1:  # numba launches at most NUMBA_NUM_THREADS
                import numba  # (sweep workers: 1)

                cap = numba.config.NUMBA_NUM_THREADS  # type: ignore[attr-defined]
                self.threads, self.contact_threads = min(self.threads, cap), min(self.contact_threads, cap)
            most = max(self.threads, self.contact_threads)
            if most > 1:
                prepare_pool()  # before the threaded kernels load numba's threading layer
                if plan.auto:
                    self.governor = ThreadGovernor(most)
            elif plan.count > 1:
                self.threads_why = serial_reason(info.parallel, compiled.model.body_count, contact, joints)
            chunk = info.parallel_chunk() if self.threads > 1 else info.chunk()
            self._chunk = chunk.run_chunk
            self.data = make_data(
                compiled.initial_state, self.model, chunk.SCRATCH_WIDTH, substeps=self.settings.substeps,
                contact_threads=self.contact_threads, tree_reactions="joint_forces" in self.settings.streams,
                implicit_contact=info.implicit_contact, forces=self.forces,
            )  # fmt: skip
        # welds (scene/welds.py): the scene's bodies on the simulated ones, and the simulated state before the
        # last step, (body_count, 13) x, q, P, L, from which the welds' reactions are read (runner/weld_reactions.py)
        self.parts = compiled.parts
        self._previous: np.ndarray | None = None
        self._kmodel = self.model.kernel()  # None for the tables the scene lacks: their stages compile away
        self._kforces = self.forces.kernel()  # None for unused force types, likewise
        self._kdata = self.data.kernel()
        from rbcli.physics.step import empty_buffers

        self._no_frames = empty_buffers(1, self.model.body_count)  # never written: nothing is due
        self._handles: list[KernelHandle | None] = [None] * 4  # model, forces, data, frames (_run_chunk)

    # ---- time -------------------------------------------------------------------------------------

    @property
    def dt(self) -> float:
        """The step [s] (with a tolerance: the spacing of output times)."""
        return self.settings.dt

    @property
    def step_index(self) -> int:
        """Grid steps taken since the initial state (or the last reset)."""
        return self.data.state.step

    @property
    def time(self) -> float:
        """t = step_index * dt [s] (never accumulated)."""
        return self.data.state.step * self.settings.dt

    def step(self, n: int = 1) -> None:
        """Advance n grid steps in compiled code, recording nothing; raises SimulationDiverged when the
        state at the end of the call is non-finite or exceeds 1e100 (checked once per call, not per step:
        `run` checks every recorded frame)."""
        from rbcli.physics.step import STATUS_OK

        if n < 0:
            raise ValueError(f"steps must be >= 0, got {n}")
        done, _, status = self.advance(n)
        self.data.state.step += int(done)
        if status != STATUS_OK:  # nothing is recorded, so a full buffer cannot be the reason
            from rbcli.physics.adaptive import STATUS_STEP_TOO_SMALL

            why = (
                "the adaptive step fell below 1e-12 t"
                if status == STATUS_STEP_TOO_SMALL
                else "the state became non-finite or exceeded 1e100"
            )
            raise SimulationDiverged(
                f"diverged by step {self.data.state.step} (t = {self.time:.6g} s): {why} with integrator "
                f"{self.settings.integrator!r} at dt = {self.settings.dt:g} s"
            )

    def advance(
        self,
        n_steps: int,
        record_every: int = NEVER,
        frames=None,  # noqa: ANN001 - FrameBuffers
        filled: int = 0,
        previous: np.ndarray | None = None,
    ) -> tuple[int, int, int]:
        """At most n_steps grid steps from the current one, recording due frames into `frames` (from
        `filled` on; None: record nothing); returns (steps done, frames filled, status) and raises nothing.
        The caller adds the steps done to `data.state.step` (the runner does, between chunks). previous:
        scenes with welds recording the joint_forces stream, (K, body_count, 13), where the state one step
        before each recorded frame goes (x, q, P, L: the welds' reactions are read off that step)."""
        if frames is None:
            frames, record_every = self._no_frames, NEVER
        if self.governor is None and max(self.threads, self.contact_threads) > 1:  # per calling thread in numba;
            use_threads(max(self.threads, self.contact_threads))  # launches its pool on the first call (with a
            # governor: per slice, _run_governed)
        # adaptive runs land their steps on the chunk's ends: a stop one step early would change them (runs
        # must not depend on chunking), so their welds' reactions stay unknown (NaN)
        if self.parts is not None and n_steps and not self.adaptive:
            done, filled, status = self._advance_welded(n_steps, record_every, frames, filled, previous)
        else:
            done, filled, status = self._run_chunk(self.data.state.step, n_steps, record_every, frames, filled)
        if done:
            self.reactions_known = True
        return done, filled, status

    def _run_chunk(self, step0: int, n_steps: int, record_every: int, frames, filled: int) -> tuple[int, int, int]:  # noqa: ANN001
        if self.governor is not None and n_steps > 0:
            return self._run_governed(self.governor, step0, n_steps, record_every, frames, filled)
        model, forces, data, frames = self._handles_of(frames)
        return self._chunk(model, forces, data, self.settings.dt, step0, n_steps, record_every, frames, filled)

    def _handles_of(self, frames):  # noqa: ANN001, ANN202 - FrameBuffers -> four KernelHandles
        """The model, force tables, data and `frames` as KernelHandles (physics/kernel_handle.py): each
        table converted once, not at every call of the chunk loop (~120 arrays in a contact scene)."""
        return (self._handle(0, self._kmodel), self._handle(1, self._kforces), self._handle(2, self._kdata),
                self._handle(3, frames))  # fmt: skip

    def _handle(self, slot: int, value: Any) -> KernelHandle:  # noqa: ANN401 - a kernel table
        """The KernelHandle of `value` kept in `slot`, made anew when the slot held another object (the
        frame buffers of another block; a table a test replaced)."""
        handle = self._handles[slot]
        if handle is None or handle.value is not value:
            from rbcli.physics.kernel_handle import KernelHandle  # numba: not at import

            handle = self._handles[slot] = KernelHandle(value)
        return handle

    def _run_governed(
        self,
        governor: ThreadGovernor,
        step0: int,
        n_steps: int,
        record_every: int,
        frames,  # noqa: ANN001 - FrameBuffers
        filled: int,
    ) -> tuple[int, int, int]:
        """`_run_chunk` in the governor's slices, each on the threads it chose (the threaded loop on one
        thread is the serial loop's arithmetic: the same bits, ~the serial loop's speed)."""
        import time

        from rbcli.physics.step import STATUS_OK

        done, status = 0, STATUS_OK
        model, forces, data, frame_handle = self._handles_of(frames)
        while done < n_steps:
            threads, steps = governor.plan(n_steps - done)
            use_threads(threads)
            started = time.perf_counter()
            ran, filled, status = self._chunk(
                model, forces, data, self.settings.dt, step0 + done, steps, record_every, frame_handle, filled
            )
            governor.record(threads, ran, time.perf_counter() - started)
            done += ran
            if status != STATUS_OK or ran < steps:
                break
        return done, filled, status

    def _advance_welded(
        self,
        n_steps: int,
        record_every: int,
        frames,
        filled: int,
        previous: np.ndarray | None,  # noqa: ANN001
    ) -> tuple[int, int, int]:
        """`advance` in a scene with welds: the chunk stops one step before each recorded step (when
        `previous` (K, body_count, 13) is given, for the joint_forces stream) and before the last step, so
        the state before those steps is kept: the welds' reactions are read off the step (module
        runner/weld_reactions.py). Bitwise the same steps as one chunk: a chunk carries nothing else."""
        from rbcli.physics.step import STATUS_OK

        s = self.data.state
        start, end = s.step, s.step + n_steps
        done, status = 0, STATUS_OK
        while done < n_steps and status == STATUS_OK:
            index = start + done
            due = (index // record_every + 1) * record_every if previous is not None else end
            target = min(due, end)
            if target - index > 1:  # nothing is recorded before `target`
                ran, filled, status = self._run_chunk(index, target - 1 - index, record_every, frames, filled)
                done += ran
                continue
            before = np.concatenate([s.x, s.q, s.P, s.L], axis=1)
            if previous is not None and target == due and filled < previous.shape[0]:
                previous[filled] = before
            ran, filled, status = self._run_chunk(index, 1, record_every, frames, filled)
            if ran:
                self._previous = before
            done += ran
        return done, filled, status

    def threads_report(self) -> str:
        """One line on the threads this Simulation's steps used and why (`rbsim run`'s summary)."""
        most = max(self.threads, self.contact_threads)
        if self.governor is not None:
            return f"threads: {self.governor.describe()} ({self.threads_why})"
        if most > 1:
            return f"threads: {most} ({self.threads_why})"
        return f"threads: 1 ({self.threads_why})"

    def load_kernels(self) -> None:
        """Load from numba's cache, or compile where it has none (a scene's first run), every kernel a
        `run` calls: the chunk loop, by advancing zero steps, and the recording's (runner/blocks.py), by
        making the block of the current state and dropping it. The state and the carried work are left
        as they were, so a run afterwards is bit for bit a run without it; only the compile is moved
        before the run (`rbsim run` shows it and can be stopped in it without a file opened)."""
        from rbcli.runner.blocks import make_block

        self.advance(0)
        s = self.data.state
        with np.errstate(all="ignore"):  # an out-of-bounds state is the run's to report, once (as diverged)
            make_block(self.compiled, np.array([s.step]), s.x[None], s.q[None], s.P[None], s.L[None])

    # ---- state ------------------------------------------------------------------------------------

    @property
    def state(self) -> BodyState:
        """A copy of the current state in the user's frames (see BodyState)."""
        s, model = self.data.state, self.model
        x, q, P, L = s.x.copy(), s.q, s.P.copy(), s.L.copy()
        if self.parts is not None:  # the scene's bodies, welded ones on their simulated body
            x, q, P, L = part_states(self.parts, model, s.x, s.q, s.P, s.L)
            model = self.parts.model
        return BodyState(
            step=s.step,
            t=self.time,
            x=x,
            q=user_orientation(model, q),
            v=P / model.body_mass[:, None],
            omega=body_angular_velocity(model, q, L),
            P=P,
            L=L,
        )

    @property
    def joint_reactions(self) -> dict[str, np.ndarray]:
        """What each joint did to its bodies over the last step: joint name -> (2, 6), row 0 for its
        first body and row 1 for its second (zeros for the world), each the force [N] and the torque
        about that body's centre of mass [N m], world frame, as the mean over the step (the step's
        impulse of the joint's rows, motor, damper and limit, divided by the step; with contact
        sub-steps, the last sub-step's). Zeros before the first step; {} in a scene without joints. In joint
        coordinates (a reduced integrator) the mean of the step's force evaluations' joint wrenches, computed
        when the scene records the joint_forces stream (they cost ~10 % of a step), else NaN.
        A kick's reaction (an impulse on a jointed body, or initial velocities that break a joint: the
        step's joint_begin projection) is not in it: it is an impulse, not a force over the step."""
        if self.parts is not None:
            names = [joint.name for joint in self.compiled.spec.joints]
            reactions = self.scene_reactions()
            return {name: reaction.reshape(2, 6) for name, reaction in zip(names, reactions, strict=True)}
        if self.data.joint is None and (self.data.tree is None or self.model.joint is None):
            return {}
        names = [joint.name for joint in self.compiled.spec.joints]
        return {name: reaction.reshape(2, 6) for name, reaction in zip(names, self.last_reactions(), strict=True)}

    def scene_reactions(self) -> np.ndarray:
        """(scene joints, 12): `joint_reactions` in the scene's joint order, the welds' among them (their
        reactions over the last step: runner/weld_reactions.py); NaN for a weld before the first step."""
        if self.parts is None:
            return self.last_reactions()
        from rbcli.runner.weld_reactions import joint_reactions

        s = self.data.state
        previous = self._previous if self.reactions_known else None
        table = self.last_reactions() if self.reactions_known else np.full_like(self.last_reactions(), np.nan)
        return joint_reactions(
            self.parts, self.model, self.settings.dt, np.array([s.step]), None if previous is None else previous[None],
            (s.x[None], s.q[None], s.P[None], s.L[None]), table[None],
        )[0]  # fmt: skip

    def previous_state(self) -> np.ndarray:
        """(body_count, 13): the simulated state before the last step (x, q, P, L), NaN when unknown."""
        if self.reactions_known and self._previous is not None:
            return self._previous
        return np.full((self.model.body_count, 13), np.nan)

    def last_reactions(self) -> np.ndarray:
        """(J, 12): `joint_reactions` as one array in joint order (the joint_forces stream's layout); NaN in
        joint coordinates (a reduced integrator: its joints' reactions are not computed yet, docs/trees.md)."""
        work = self.data.joint
        if work is None:
            joints, tree, data = self.model.joint, self.model.tree, self.data.tree
            if tree is not None and data is not None and joints is not None:  # joint coordinates
                out = np.full((joints.kind.shape[0], 12), np.nan)
                if data.reactions_on[0] == 1.0:
                    for i, (j, side) in enumerate(zip(tree.joint.tolist(), tree.joint_side.tolist(), strict=True)):
                        if j >= 0:
                            out[j] = data.reaction[i] if side > 0 else np.roll(data.reaction[i], 6)
                return out
            return np.zeros((0, 12))
        return work.joint_impulse / (self.settings.dt / self.data.substeps)

    def set_state(
        self,
        *,
        x: np.ndarray | None = None,
        q: np.ndarray | None = None,
        v: np.ndarray | None = None,
        omega: np.ndarray | None = None,
        P: np.ndarray | None = None,
        L: np.ndarray | None = None,
        step: int | None = None,
    ) -> None:
        """Change the state between steps, in the user's frames (as BodyState): give v or P, omega or L.

        q is normalised. omega is converted with the orientation in effect after this call
        (L = R I R^T omega), so set q and omega together when both change. The integrator's carried
        work is cleared, as at the start of a run.
        """
        s, model = self.data.state, self.model
        parts = self.parts
        if parts is not None:  # the scene's bodies: set on a copy of theirs, the simulated ones follow
            model = parts.model
            x_p, q_p, P_p, L_p = part_states(parts, self.model, s.x, s.q, s.P, s.L)
            s = State(x_p, q_p, P_p, L_p, s.step)
        n = model.body_count

        def rows(value: np.ndarray, width: int, name: str) -> np.ndarray:
            array = np.array(value, dtype=np.float64).reshape(-1, width) if np.ndim(value) else None
            if array is None or array.shape != (n, width) or not np.isfinite(array).all():
                raise ValueError(f"{name} must be finite numbers of shape ({n}, {width})")
            return array

        if v is not None and P is not None:
            raise ValueError("give v or P, not both")
        if omega is not None and L is not None:
            raise ValueError("give omega or L, not both")
        if x is not None:
            s.x[:] = rows(x, 3, "x")
        if q is not None:
            q_user = rows(q, 4, "q")
            norm = np.linalg.norm(q_user, axis=1, keepdims=True)
            if not (norm > 0).all():
                raise ValueError("q must be non-zero quaternions (w, x, y, z)")
            s.q[:] = internal_orientation(model, q_user / norm)
        if v is not None:
            s.P[:] = model.body_mass[:, None] * rows(v, 3, "v")
        if P is not None:
            s.P[:] = rows(P, 3, "P")
        if omega is not None:  # L = R diag(I) R^T omega, R world-from-principal
            w = rows(omega, 3, "omega")
            s.L[:] = quat_rotate(s.q, model.body_inertia * quat_rotate_inverse(s.q, w))
        if L is not None:
            s.L[:] = rows(L, 3, "L")
        if step is not None:
            if step < 0:
                raise ValueError(f"step must be >= 0, got {step}")
            s.step = int(step)
        if parts is not None:  # each simulated body follows its first part (scene/parts.py merged_state)
            state = self.data.state
            state.x[:], state.q[:], state.P[:], state.L[:] = merged_state(parts, self.model, s.x, s.q, s.P, s.L)
            state.step = s.step
        self.data.clear_work()
        self.reactions_known = False
        self._previous = None

    # ---- joint coordinates (reduced integrators) ------------------------------------------------------

    def _tree_links(self) -> dict[str, int]:
        """Joint name -> its tree link, in a run in joint coordinates (ValueError otherwise)."""
        tree = self.model.tree
        if tree is None or self.data.tree is None:
            raise ValueError(
                "joint coordinates are the state of the reduced integrators (reduced-euler, reduced-rk4, "
                f"reduced-implicit); this "
                f"run's integrator {self.settings.integrator!r} holds the joints in maximal coordinates"
            )
        names = [joint.name for joint in self.compiled.simulated_spec.joints]
        return {names[int(j)]: i for i, j in enumerate(tree.joint.tolist()) if j >= 0}

    def joint_state(self) -> dict[str, JointCoordinates]:
        """Every joint's coordinate and rate, by joint name (JointCoordinates), in a run in joint
        coordinates (docs/trees.md); ValueError in maximal coordinates."""
        from rbcli.physics.joints.tables import JOINT_BALL
        from rbcli.physics.rotation import quat_rotate

        links = self._tree_links()
        tree, data = self.model.tree, self.data.tree
        assert tree is not None and data is not None
        out = {}
        for name, i in links.items():
            kind, child, parent = int(tree.kind[i]), int(tree.body[i]), int(tree.parent[i])
            position = data.coord[tree.coord_start[i] : tree.coord_start[i + 1]].copy()
            rate = data.rate[tree.dof_start[i] : tree.dof_start[i + 1]].copy()
            if kind == JOINT_BALL:  # principal -> the child's user frame: e u e^*, R(e) omega
                e = self.model.body_frame_q[child]
                position = quat_multiply(quat_multiply(e, position), quat_conjugate(e))
                rate = quat_rotate(e[None], rate[None])[0]
            out[name] = JointCoordinates(
                _KIND_NAMES[kind], self.model.body_names[child],
                "world" if parent < 0 else self.model.body_names[int(tree.body[parent])], position, rate,
            )  # fmt: skip
        return out

    def set_joint_state(self, name: str, *, position: Sequence[float] | np.ndarray | None = None,
                        rate: Sequence[float] | np.ndarray | None = None) -> None:  # fmt: skip
        """Set one joint's coordinate and/or rate (JointCoordinates' units and frames; a ball's quaternion
        is normalised); the bodies follow by forward kinematics, and the carried work is cleared as by
        `set_state`. ValueError naming what is wrong (an unknown joint, a wrong shape, a maximal run)."""
        from rbcli.physics.joints.tables import JOINT_BALL
        from rbcli.physics.rotation import quat_rotate_inverse
        from rbcli.physics.tree.aba import forward_kinematics

        links = self._tree_links()
        if name not in links:
            raise ValueError(f"no joint {name!r} in joint coordinates; joints: {', '.join(links) or 'none'}")
        tree, data = self.model.tree, self.data.tree
        assert tree is not None and data is not None
        i = links[name]
        kind, child = int(tree.kind[i]), int(tree.body[i])
        c0, c1, d0, d1 = (int(v) for v in (tree.coord_start[i], tree.coord_start[i + 1], tree.dof_start[i],
                                            tree.dof_start[i + 1]))  # fmt: skip
        e = self.model.body_frame_q[child]
        if position is not None:
            value = np.array(position, dtype=np.float64).reshape(-1)
            if value.shape != (c1 - c0,) or not np.isfinite(value).all():
                raise ValueError(f"joint {name!r}: position must be {c1 - c0} finite number(s), got {position!r}")
            if kind == JOINT_BALL:
                norm = float(np.linalg.norm(value))
                if not norm > 0.0:
                    raise ValueError(f"joint {name!r}: a ball's position is a non-zero quaternion (w, x, y, z)")
                value = quat_multiply(quat_multiply(quat_conjugate(e), value / norm), e)
            data.coord[c0:c1] = value
        if rate is not None:
            value = np.array(rate, dtype=np.float64).reshape(-1)
            if value.shape != (d1 - d0,) or not np.isfinite(value).all():
                raise ValueError(f"joint {name!r}: rate must be {d1 - d0} finite number(s), got {rate!r}")
            data.rate[d0:d1] = quat_rotate_inverse(e[None], value[None])[0] if kind == JOINT_BALL else value
        s = self.data.state
        forward_kinematics(tree, data.coord, data.rate, data.work, s.x, s.q, s.P, s.L)
        data.fk_state[0] = 1.0
        self.data.clear_work(trees_from_state=False)
        self.reactions_known = False
        self._previous = None

    def checkpoint(self) -> Checkpoint:
        """A copy of everything the run carries between steps (Checkpoint): `restore` it into a
        Simulation of the same scene and settings and the steps that follow are bit for bit those this
        one would take. `state` / `set_state` are the user's view instead: rounded through the user
        frame, and setting them clears the carried work."""
        from rbcli.record.frame import Checkpoint

        arrays = {name: array.copy() for name, array in self.data.carried().items()}
        if self.parts is not None and self.reactions_known and self._previous is not None:
            arrays[WELD_PREVIOUS] = self._previous.copy()  # read by no step: the welds' first resumed reactions
        return Checkpoint(step=int(self.data.state.step), t=self.time, arrays=arrays)

    def restore(self, checkpoint: Checkpoint) -> None:
        """Continue from a `checkpoint` of this scene and settings (ValueError when its arrays do not
        fit this run: another scene, integrator or contact layout)."""
        if checkpoint.step < 0:
            raise ValueError(f"checkpoint step must be >= 0, got {checkpoint.step}")
        from rbcli.physics.data import JOINT_REACTIONS, TREE_REACTIONS

        arrays = dict(checkpoint.arrays)
        previous = arrays.pop(WELD_PREVIOUS, None) if self.parts is not None else None
        self.data.restore_carried(arrays)
        self.data.state.step = int(checkpoint.step)
        self._previous = None
        if previous is not None and np.shape(previous) == (self.model.body_count, 13):
            self._previous = np.array(previous, dtype=np.float64)
        # the last step's reactions are known when the checkpoint carries them (welds: the state before it)
        carried = JOINT_REACTIONS in arrays if self.data.joint is not None else self._previous is not None
        if self.data.tree is not None:
            carried = TREE_REACTIONS in arrays
        self.reactions_known = checkpoint.step > 0 and carried

    def reset(self) -> None:
        """Back to the scene's initial state at step 0, with cleared work arrays."""
        initial = self.compiled.initial_state
        s = self.data.state
        s.x[:], s.q[:], s.P[:], s.L[:] = initial.x, initial.q, initial.P, initial.L
        s.step = 0
        self.data.clear_work()
        self.reactions_known = False
        self._previous = None
        if self.data.adaptive_counters is not None:
            self.data.adaptive_counters[:] = 0
        self.data.force.term_evaluations[:] = 0
        if self.data.force.contact is not None:  # the contact work's counters and statistics, as fresh
            self.data.force.contact.counters[:] = 0
            self.data.force.contact.stats[:] = 0.0

    # ---- runs -------------------------------------------------------------------------------------

    def run(
        self,
        duration: float | None = None,
        *,
        sinks: Sequence[Sink] = (),
        record_every: int | None = None,
        progress: ProgressCallback | None = None,
        threaded: bool = True,
    ) -> RunSummary:
        """Run `duration` seconds (default: the scene's) from the current state, streaming recorded
        frames (every `record_every` grid steps, and always the first and last) to the sinks."""
        from rbcli.runner.loop import run_simulation

        steps = self.settings.steps if duration is None else _steps_for(duration, self.settings.dt)
        every = self.settings.record_every if record_every is None else int(record_every)
        if every < 1:
            raise ValueError(f"record_every must be >= 1, got {every}")
        return run_simulation(self, sinks, steps=steps, record_every=every, progress=progress, threaded=threaded)


def warm_up(compiled: CompiledScene) -> None:
    """Load from cache, or compile, the kernels a run of this compiled scene calls (`Simulation.load_kernels`
    in a Simulation made for it: where that Simulation is the one that runs, call its own load_kernels)."""
    Simulation(compiled).load_kernels()


def run(
    compiled: CompiledScene,
    sinks: Sequence[Sink],
    *,
    progress: ProgressCallback | None = None,
    threaded: bool = True,
) -> RunSummary:
    """Integrate the compiled scene from its initial state, streaming frames to every sink; always
    closes the sinks. threaded: write the recorded blocks in a background thread (runner.recorder),
    overlapping the integration; False writes them in this thread. The files are the same either way."""
    return Simulation(compiled).run(sinks=sinks, progress=progress, threaded=threaded)


def _steps_for(duration: float, dt: float) -> int:
    from rbcli.scene.compile import step_count

    if not duration > 0:
        raise ValueError(f"duration must be > 0 s, got {duration}")
    return step_count(duration, dt)
