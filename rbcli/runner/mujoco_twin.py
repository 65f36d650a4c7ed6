"""MuJoCo twin of a scene, for the study's comparison rows (`mujoco-euler`, `mujoco-rk4`).

A scene MuJoCo can express exactly is built into an MJCF model: every body a free joint with its mass,
its principal moments of inertia (`diaginertia`) and its principal frame as the MuJoCo body frame
(`quat` = the internal world-from-principal q at t = 0), under the scene's uniform gravity, nothing else
(no geoms, so nothing collides). The initial state is the scene's: qpos = (x, q), qvel = (v world,
omega body frame = I^-1 R^T L). Its recorded states are converted back to the user's frames exactly as
rbsim's own (`physics/frames.py`), so the study measures both engines' errors the same way.

Only free bodies under uniform gravity are expressed (`refusal` says why a scene is not): MuJoCo has
tendon springs, but their damping, anchor and schedule semantics differ from rbsim's force terms, and a
row built on a different model would compare two problems instead of two integrators.

MuJoCo's "Euler" is semi-implicit Euler (velocities first, then positions with the new velocities:
order 1); "RK4" is the classic fourth-order Runge-Kutta on (qpos, qvel). mujoco is imported lazily by
this module alone (the `[bench]` extra): rbcli works without it.

MuJoCo's default warning handler prints and appends to MUJOCO_LOG.TXT in the working directory (a
diverging run warns at every step); runs go through `quiet_warnings()`, which swallows the messages for
its duration; the warnings are still counted in `MjData.warning`, which `diverged` reads.
"""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from rbcli.physics.energy import invariants
from rbcli.physics.forces import force_terms_present
from rbcli.physics.frames import body_angular_velocity, user_orientation
from rbcli.physics.rotation import quat_rotate, quat_rotate_inverse
from rbcli.record.frame import RunSummary
from rbcli.record.memory_sink import Trajectory
from rbcli.scene.compile import CompiledScene


@dataclass(frozen=True)
class MujocoMethod:
    """A MuJoCo integrator as a study row: its `<option integrator=...>` name and nominal order."""

    name: str
    option: str
    order: int


MUJOCO_METHODS = {
    "mujoco-euler": MujocoMethod("mujoco-euler", "Euler", 1),
    "mujoco-rk4": MujocoMethod("mujoco-rk4", "RK4", 4),
}
# MuJoCo's compiler grows quadratically with the body count (~40 s at 10,000 bodies, benchmarks/
# bench_speed.py): above this many bodies the rows are skipped rather than spend minutes building.
MUJOCO_MAX_BODIES = 2000
# MuJoCo's own guards (mj_checkPos/Vel/Acc) reset the state to the model's qpos0 when it becomes
# non-finite or huge, and count a warning: a run with any of these warnings has diverged.
_DIVERGENCE_WARNINGS = ("mjWARN_BADQPOS", "mjWARN_BADQVEL", "mjWARN_BADQACC")


def mujoco_version() -> str | None:
    """The installed MuJoCo's version, or None when the `mujoco` package is not importable."""
    try:
        import mujoco
    except ImportError:
        return None
    return str(mujoco.__version__)


def refusal(compiled: CompiledScene) -> str | None:
    """Why MuJoCo cannot run this scene as rbsim does, or None when it can (free bodies under uniform
    gravity, or under no force at all)."""
    terms = [t for t in force_terms_present(compiled.forces, compiled.model.contact) if t != "gravity"]
    contact = compiled.model.contact
    if contact.static_body.size:
        terms.append("static bodies")
    if contact.sphere_body.size and "contact" not in terms:
        terms.append("contact")
    if compiled.model.joint is not None or compiled.parts is not None:  # free bodies only (a jointed twin: next)
        terms.append("joints")
    if terms:
        return (
            f"the scene has {', '.join(terms)}: the MuJoCo rows cover free bodies under uniform gravity only "
            "(other force models differ between the engines)"
        )
    if compiled.model.body_count > MUJOCO_MAX_BODIES:
        return (
            f"{compiled.model.body_count} bodies: MuJoCo's model compiler is quadratic in the body count "
            f"(rows are built up to {MUJOCO_MAX_BODIES} bodies)"
        )
    if compiled.settings.substeps != 1:
        return "the scene sub-steps its integrator (contact.substeps), which MuJoCo's step does not"
    return None


def _numbers(values: np.ndarray | float) -> str:
    """Numbers for an XML attribute, exactly (repr of a float64 round-trips)."""
    return " ".join(repr(float(v)) for v in np.ravel(values))


def mujoco_xml(compiled: CompiledScene, method: MujocoMethod) -> str:
    """MJCF of the scene's bodies (see the module docstring); timestep = the scene's dt."""
    model, state = compiled.model, compiled.initial_state
    bodies = "".join(
        f'<body pos="{_numbers(state.x[b])}" quat="{_numbers(state.q[b])}"><freejoint/>'
        f'<inertial pos="0 0 0" mass="{_numbers(model.body_mass[b])}" diaginertia="{_numbers(model.body_inertia[b])}"/>'
        "</body>"
        for b in range(model.body_count)
    )
    gravity = compiled.forces.gravity if compiled.forces.has_gravity else np.zeros(3)
    return (
        f'<mujoco model="{compiled.spec.name}-twin">'
        f'<option timestep="{_numbers(compiled.settings.dt)}" integrator="{method.option}" '
        f'gravity="{_numbers(gravity)}"/>'
        f"<worldbody>{bodies}</worldbody></mujoco>"
    )


class MujocoTwin:
    """The scene in MuJoCo with one integrator at the scene's dt: reset, advance, record at a cadence.

    The arrays are those of `mujoco.MjData`; `advance(n)` is `mj_step(m, d, nstep=n)` (the loop in C).
    """

    def __init__(self, compiled: CompiledScene, method: MujocoMethod) -> None:
        import mujoco

        reason = refusal(compiled)
        if reason is not None:
            raise ValueError(f"MuJoCo cannot run this scene: {reason}")
        self.compiled, self.method = compiled, method
        self._mujoco = mujoco
        self.m: Any = mujoco.MjModel.from_xml_string(mujoco_xml(compiled, method))
        self.d: Any = mujoco.MjData(self.m)
        model, state = compiled.model, compiled.initial_state
        n = model.body_count
        self._qpos0 = self.m.qpos0.copy()
        qvel = np.zeros((n, 6))
        qvel[:, :3] = state.P / model.body_mass[:, None]  # free joint: world linear velocity of the centre of mass
        qvel[:, 3:] = quat_rotate_inverse(state.q, state.L) / model.body_inertia  # body-frame omega = I^-1 R^T L
        self._qvel0 = qvel.reshape(-1)
        self._warnings = [int(getattr(mujoco.mjtWarning, w)) for w in _DIVERGENCE_WARNINGS]
        self.reset()

    @contextmanager
    def quiet_warnings(self) -> Iterator[None]:
        """MuJoCo's warnings neither printed nor logged to MUJOCO_LOG.TXT meanwhile (process-wide; the
        previous handler is restored)."""
        mujoco = self._mujoco
        previous = mujoco.get_mju_user_warning()
        mujoco.set_mju_user_warning(_ignore_warning)
        try:
            yield
        finally:
            mujoco.set_mju_user_warning(previous)

    def reset(self) -> None:
        """Back to the scene's initial state at t = 0, MuJoCo's warnings cleared."""
        self._mujoco.mj_resetData(self.m, self.d)
        self.d.qpos[:], self.d.qvel[:] = self._qpos0, self._qvel0

    def advance(self, steps: int) -> int:
        """`mj_step(m, d, nstep=steps)`; returns the steps done. nstep = 0 steps nothing but still makes the
        call (the binding's overhead, which the study's timing takes off)."""
        self._mujoco.mj_step(self.m, self.d, nstep=int(steps))
        return int(steps)

    def diverged(self) -> bool:
        """True once MuJoCo has reset a bad state (its warnings) or the state is not finite."""
        if any(self.d.warning[w].number > 0 for w in self._warnings):
            return True
        return not (np.isfinite(self.d.qpos).all() and np.isfinite(self.d.qvel).all())

    def _state(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(x, q world-from-principal, P, L world) of the current MuJoCo state, rbsim's internal form."""
        model = self.compiled.model
        qpos = self.d.qpos.reshape(-1, 7)
        qvel = self.d.qvel.reshape(-1, 6)
        q = qpos[:, 3:] / np.linalg.norm(qpos[:, 3:], axis=1, keepdims=True)
        P = qvel[:, :3] * model.body_mass[:, None]
        L = quat_rotate(q, qvel[:, 3:] * model.body_inertia)  # L = R I omega_body
        return qpos[:, :3].copy(), q, P, L

    def trajectory(self, steps: int, record_every: int) -> Trajectory:
        """Run `steps` steps from the initial state, recording every `record_every` steps and the last,
        as rbsim's runner does; the frames in the user's frames with the scene's invariants."""
        self.reset()
        model, forces, dt = self.compiled.model, self.compiled.forces, self.compiled.settings.dt
        marks = list(range(0, steps + 1, record_every))
        if marks[-1] != steps:
            marks.append(steps)
        frames, done, status = [self._state()], 0, "completed"
        with self.quiet_warnings():
            for mark in marks[1:]:
                done += self.advance(mark - done)
                if self.diverged():
                    status = "diverged"
                    break
                frames.append(self._state())
        x, q, P, L = (np.stack(parts) for parts in zip(*frames, strict=True))
        omega = body_angular_velocity(model, q, L)
        index = np.array(marks[: len(frames)], dtype=np.int64)
        return Trajectory(
            body_names=model.body_names,
            t=index * dt,
            step=index,
            x=x,
            q=user_orientation(model, q),
            v=P / model.body_mass[:, None],
            omega=omega,
            P=P,
            L=L,
            invariants=invariants(model, forces, x, q, P, L, omega),
            summary=RunSummary(status=status, steps=done, frames=len(frames), t_end=done * dt),
        )


def _ignore_warning(message: str) -> None:
    """A MuJoCo warning handler that drops the message (the counters in MjData.warning remain)."""
