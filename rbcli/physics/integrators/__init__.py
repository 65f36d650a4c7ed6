"""Registry of integrators: metadata here (cheap to import: no numba), kernels loaded on demand.

Every integrator module defines only its update maths:
  step(model, forces, contact, force_data, t, dt, x, q, P, L, F, tau, scratch)   # numba njit, in place
  step_numpy(model, forces, t, dt, x, q, P, L)                                  # numpy reference, in place
and `SCRATCH_WIDTH`, the float64 scratch columns per body its compiled step needs. model: the body
arrays (KernelBodies); contact: the model's contact table (None without contact), for the force pass.
The forces come only from `accumulate_wrench`. The chunk loop that runs a step's stages around it is
physics/chunk_loop.py `run_chunk`, written once and compiled per integrator with that module's `step`
(`IntegratorInfo.chunk`; `parallel_chunk`: with `step_parallel`, the passes over the bodies on threads,
for those flagged `parallel`). `kinematics.py` holds the per-body kernels they share (not a method).
Adaptive time stepping (a tolerance instead of dt) is `rbcli.physics.adaptive` (the method) and
physics/adaptive_loop.py (its loop), for the methods flagged `adaptive`. docs/integrators.md has the
measured orders, errors and costs.
"""

from __future__ import annotations

import difflib
import importlib
from dataclasses import dataclass
from types import ModuleType
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from rbcli.physics.chunk_loop import ChunkLoop


@dataclass(frozen=True)
class IntegratorInfo:
    """What a user needs to choose an integrator: order, structure, conservation, cost.

    order: global order of accuracy (error ~ dt^order), checked against measured slopes in the tests.
    conserves: what the method keeps exactly (to round-off): "L, P force-free" = world angular
      momentum without torques and linear momentum without forces; symplectic methods also keep the
      energy error bounded (no drift), which is not exact conservation and is said so.
    force_evals: wrench evaluations per step.
    adaptive: has an embedded error estimate, so `simulation.tolerance` can choose its steps.
    demonstration: kept only to show a failure mode (documented in `summary`); not for real runs.
    """

    name: str
    module: str
    order: int
    symplectic: bool
    conserves: str
    force_evals: int
    summary: str
    adaptive: bool = False
    demonstration: bool = False
    joints: bool = False  # holds joints (physics/joints/: its loop runs the joint stages; docs/joints.md)
    # has `step_parallel` (its passes over the bodies on threads) and a chunk loop that calls it
    # (`parallel_chunk`; docs/performance.md, "Threads")
    parallel: bool = False
    # its step defers the state of some bodies (exact: torque-free bodies under constant forces, written
    # from their anchors): its loop runs the module's `materialise` after each step
    defers: bool = False
    # integrates articulated trees in joint coordinates (physics/tree/, docs/trees.md): every dynamic body is
    # a link of a tree (a free root where no joint holds it), the joints hold by construction; its loop
    # runs its module's `step` as the tree_update stage. Listed apart (REDUCED_INTEGRATORS)
    reduced: bool = False
    # its contact forces are linearly implicit (tree/implicit_contact.py): the contact work keeps each
    # evaluation's contacts, the search runs serially, and `substeps: auto` follows the contacts' travel
    # alone (their stiffness does not limit its step)
    implicit_contact: bool = False

    def load(self) -> ModuleType:
        """Import the integrator's module: step, step_numpy, SCRATCH_WIDTH (pulls in numba)."""
        return importlib.import_module(self.module)

    def chunk(self) -> ChunkLoop:
        """Its chunk loop (physics/chunk_loop.py): run_chunk(model, forces, data, dt, step0, n_steps,
        record_every, frames, filled), compiled with this integrator's step, and SCRATCH_WIDTH."""
        from rbcli.physics.chunk_loop import fixed_step_loop

        return fixed_step_loop(self.module, joints=self.joints, defers=self.defers, reduced=self.reduced)

    def parallel_chunk(self) -> ChunkLoop:
        """The chunk loop that calls `step_parallel`: `chunk`'s interface; bitwise its results at any
        thread count (numba.set_num_threads before the call)."""
        if not self.parallel:
            raise ValueError(f"{self.name!r} has no threaded step")
        from rbcli.physics.chunk_loop import fixed_step_loop

        return fixed_step_loop(self.module, joints=self.joints, defers=self.defers, threaded=True)

    def adaptive_chunk(self) -> ChunkLoop:
        """The error-controlled loop of an `adaptive` method (physics/adaptive_loop.py): run_chunk with the
        same arguments as `chunk`'s, on a Data made with adaptive=True (its work is the Data's `adaptive`:
        SCRATCH_WIDTH 0)."""
        if not self.adaptive:
            raise ValueError(f"{self.name!r} is fixed-step: it has no adaptive loop")
        from rbcli.physics.chunk_loop import adaptive_loop

        return adaptive_loop()


_PKG = "rbcli.physics.integrators"

INTEGRATORS: dict[str, IntegratorInfo] = {
    info.name: info
    for info in [
        IntegratorInfo(
            "euler-matrix",
            f"{_PKG}.euler_matrix",
            order=1,
            symplectic=False,
            conserves="L, P force-free",
            force_evals=1,
            summary="The tutorial's explicit Euler on x, P, R, L with Gram-Schmidt (baseline).",
        ),
        IntegratorInfo(
            "euler-quat",
            f"{_PKG}.euler_quat",
            order=1,
            symplectic=False,
            conserves="L, P force-free",
            force_evals=1,
            summary="Explicit Euler with a renormalised unit quaternion instead of Gram-Schmidt.",
        ),
        IntegratorInfo(
            "semi-implicit",
            f"{_PKG}.semi_implicit",
            order=1,
            symplectic=False,
            conserves="L, P force-free",
            force_evals=1,
            summary="Game-engine update (Bullet/Box2D): kick, then drift with the new velocity and "
            "q <- exp(dt omega/2) q; energy drifts, the intermediate-axis flip is lost at game-size dt.",
        ),
        IntegratorInfo(
            "semi-implicit-gyro",
            f"{_PKG}.semi_implicit_gyro",
            order=1,
            symplectic=False,
            conserves="P force-free (|L| grows)",
            force_evals=1,
            summary="Counter-example: omega integrated with the explicit gyroscopic term "
            "I dw/dt = tau - w x I w; |L| grows every step and fast spin blows up.",
            demonstration=True,
        ),
        IntegratorInfo(
            "rk4",
            f"{_PKG}.rk4",
            order=4,
            symplectic=False,
            conserves="L, P force-free",
            force_evals=4,
            summary="Classical Runge-Kutta on (x, q, P, L), every stage on a unit quaternion; "
            "accurate, but energy drifts over long runs.",
        ),
        IntegratorInfo(
            "split2",
            f"{_PKG}.split2",
            order=2,
            symplectic=True,
            conserves="L, P force-free; energy error bounded, no drift (with joints too: RATTLE)",
            force_evals=1,
            summary="Symplectic splitting: leapfrog for the centre of mass, exact turns about the "
            "principal axes (McLachlan 1993, Reich 1994, Dullweber et al. 1997). The default choice.",
            joints=True,
            parallel=True,
        ),
        IntegratorInfo(
            "split4",
            f"{_PKG}.split4",
            order=4,
            symplectic=True,
            conserves="L, P force-free; energy error bounded, no drift (with joints too: RATTLE)",
            force_evals=5,
            summary="Suzuki's 5-stage fourth-order composition of split2 (Suzuki 1990).",
        ),
        IntegratorInfo(
            "exact",
            f"{_PKG}.exact",
            order=2,
            symplectic=True,
            conserves="L, P, energy: the whole force-free motion",
            force_evals=1,
            summary="Exact free-body rotation (Jacobi elliptic functions) between force kicks "
            "(Celledoni, Fasso, Safstrom & Zanna 2008); second order only through the forces.",
            defers=True,
        ),
        IntegratorInfo(
            "exact4",
            f"{_PKG}.exact4",
            order=4,
            symplectic=True,
            conserves="L, P, energy: the whole force-free motion",
            force_evals=5,
            summary="Suzuki's fourth-order composition of `exact`.",
        ),
        IntegratorInfo(
            "dopri5",
            f"{_PKG}.dopri5",
            order=5,
            symplectic=False,
            conserves="L, P force-free",
            force_evals=6,
            summary="Dormand-Prince 5(4) on (x, q, P, L); with `simulation.tolerance` its embedded "
            "4th-order estimate chooses the steps (Hairer, Norsett & Wanner).",
            adaptive=True,
        ),
    ]
}

# integrators in joint coordinates (docs/trees.md): apart from INTEGRATORS, whose every entry steps any
# scene in maximal coordinates (x, q, P, L), as the tests over INTEGRATORS run them; `integrator_names`,
# `get_integrator` and `check_integrator` know both
REDUCED_INTEGRATORS: dict[str, IntegratorInfo] = {
    info.name: info
    for info in [
        IntegratorInfo(
            "reduced-euler",
            "rbcli.physics.tree.reduced_euler",
            order=1,
            symplectic=False,
            conserves="joints exactly (by construction); P, L of a free tree force-free only as dt -> 0",
            force_evals=1,
            summary="Articulated trees in joint coordinates (Featherstone's ABA, O(n)): semi-implicit Euler "
            "on the joint rates and coordinates, MuJoCo's default method. One freedom per hinge.",
            reduced=True,
        ),
        IntegratorInfo(
            "reduced-rk4",
            "rbcli.physics.tree.reduced_rk4",
            order=4,
            symplectic=False,
            conserves="joints exactly (by construction); energy drifts at O(dt^4)",
            force_evals=4,
            summary="Articulated trees in joint coordinates (ABA): classical Runge-Kutta on the joint "
            "coordinates and rates, quaternion coordinates normalised.",
            reduced=True,
        ),
        IntegratorInfo(
            "reduced-implicit",
            # reduced-euler's step and chunk loop (its cache files too): what differs is the contact work,
            # which keeps its contacts for the correction (implicit_contact), so a scene without contact
            # runs reduced-euler's compiled loop as it is and one with contact compiles its own types
            "rbcli.physics.tree.reduced_euler",
            order=1,
            symplectic=False,
            conserves="joints exactly (by construction); P in body-body contact",
            force_evals=1,
            summary="reduced-euler with the contact springs and dashpots linearly implicit (backward "
            "Euler, one dense solve over the contacts a step): stiff contact without sub-steps.",
            reduced=True,
            implicit_contact=True,
        ),
    ]
}


def _known(name: object) -> IntegratorInfo | None:
    if not isinstance(name, str):
        return None
    return INTEGRATORS.get(name) or REDUCED_INTEGRATORS.get(name)


DEFAULT_INTEGRATOR = "euler-matrix"


@dataclass(frozen=True)
class IntegratorRefusal:
    """Why a requested integrator (and tolerance) cannot run. `check_integrator` is the one place that
    decides; the scene loader, compile's overrides, the CLI and `get_integrator` only phrase it for
    their reader (a located scene issue, `--integrator 'rk5': ...`, a KeyError).

    key: the setting at fault, "integrator" or "tolerance".
    reason: what is wrong, without the value: "unknown integrator (did you mean 'rk4'?)".
    expected: what would be accepted: "one of euler-matrix, ...".
    hint: the closest known name when the value looks like a typo, else None.
    """

    key: str
    reason: str
    expected: str
    hint: str | None = None

    def naming(self, value: object) -> str:
        """The reason with the value named: "unknown integrator 'rk5' (did you mean 'rk4'?)"."""
        what, _, rest = self.reason.partition(" (")
        return f"{what} {value!r}" + (f" ({rest}" if rest else "")


def closest_integrator(name: object) -> str | None:
    """The known name a mistyped one most likely meant (difflib's ratio >= 0.6, the rule of the scene
    keys' "did you mean")."""
    close = difflib.get_close_matches(str(name), list(integrator_names()), n=1, cutoff=0.6)
    return close[0] if close else None


def joint_integrators() -> tuple[str, ...]:
    """The integrators that hold joints: RATTLE in their loops (joints/rattle.py: docs/joints.md), or
    joint coordinates (the reduced ones: docs/trees.md)."""
    return tuple(name for name, info in INTEGRATORS.items() if info.joints) + tuple(REDUCED_INTEGRATORS)


def check_integrator(name: object, *, tolerance: bool = False, joints: bool = False) -> IntegratorRefusal | None:
    """None when `name` is a known integrator that can run as asked (with a tolerance: an adaptive
    one; for a scene with joints: one that holds them, fixed-step), else the refusal. Checks names
    only: nothing is imported or compiled."""
    info = _known(name)
    if info is None:
        hint = closest_integrator(name)
        guess = f" (did you mean {hint!r}?)" if hint else ""
        known = ", ".join(integrator_names())
        return IntegratorRefusal("integrator", f"unknown integrator{guess}", "one of " + known, hint)
    if tolerance and not info.adaptive:
        adaptive = ", ".join(n for n, info in INTEGRATORS.items() if info.adaptive)
        return IntegratorRefusal(
            "tolerance",
            f"a tolerance needs an adaptive integrator ({adaptive}); {name!r} is fixed-step",
            f"integrator: one of {adaptive} with a tolerance, or no tolerance (fixed dt)",
        )
    if joints and (tolerance or not (info.joints or info.reduced)):
        holding = ", ".join(joint_integrators())
        if tolerance:
            return IntegratorRefusal(
                "tolerance",
                f"joints need a fixed step: adaptive stepping does not hold them (integrators that do: {holding})",
                f"no tolerance, a fixed dt with integrator {holding}",
            )
        return IntegratorRefusal(
            "integrator",
            f"integrator {name!r} does not hold joints; the ones that do: {holding}",
            f"integrator: {holding} (docs/joints.md)",
        )
    return None


def get_integrator(name: str) -> IntegratorInfo:
    """Look an integrator up by name; the KeyError says `check_integrator`'s refusal, with the known
    names."""
    refusal = check_integrator(name)
    if refusal is not None:
        raise KeyError(f"{refusal.naming(name)}; known: {', '.join(integrator_names())}")
    info = _known(name)
    assert info is not None
    return info


def implicit_contact(name: object) -> bool:
    """Whether integrator `name` (a known one) takes its contact forces linearly implicit, so that the
    contacts' stable step does not bound its step (tree/implicit_contact.py); False for an unknown name."""
    info = _known(name)
    return info is not None and info.implicit_contact


def integrator_names() -> tuple[str, ...]:
    """Every integrator's name: the maximal ones (INTEGRATORS), then the reduced ones."""
    return (*INTEGRATORS, *REDUCED_INTEGRATORS)
