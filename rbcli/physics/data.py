"""Data: every mutable array of a run, allocated once (MuJoCo's mjData beside the constant Model).

The Model (physics/model.py, with its contact, joint and kinematic tables) and the force tables never
change during a run; everything a step writes lives here, so kernels never allocate and a run's memory
is known when it starts:

    x, q, P, L   the state (physics/state.py has the frames and units); `step` counts grid steps
    F, tau       wrench accumulators [N], [N m], shape (body_count, 3), world frame, about each centre
                 of mass: the force pass sets them, the integrator reads them
    scratch      the integrator's work columns, shape (body_count, SCRATCH_WIDTH of its module); `exact`
                 keeps each body's anchor there (the state its closed form starts from, with the flow's
                 constants and an evaluation counter), so clear_work (set_state, reset) restarts it
    force        what the force pass writes besides F and tau (forces/tables.py ForceData): stage
                 counters, and the contact stage's grid, per-evaluation arrays and contact history
                 (None without a contact stage, so the kernels compile none of it)
    joint        the joint stages' work (joints/tables.py JointWork): Jacobians, the solver's work, the
                 last step's multipliers and reactions; None without joints (the model's joint table
                 None) or in reduced coordinates, so the joint stages compile to nothing
    tree         reduced coordinates (the model's tree table, physics/tree/): the trees' joint
                 coordinates and rates, which x, q, P, L are forward kinematics of, and the tree
                 integrators' work (tree/table.py TreeData); None in maximal coordinates
    substeps     integrator steps per grid step (contact sub-stepping; 1 otherwise), a run setting
    adaptive     error-controlled runs only (physics/adaptive.py): stage work (body_count, dopri5
                 width), controller state `control` (2,) and step `counters` int64 (2,) that persist
                 between chunks, and two run settings: the error budget `tolerance` of a run
                 `duration` [s] long (the scene's duration, whatever a call runs)

Frame buffers are the recorder's (runner/recorder.py): they are handed between threads, so they are
passed to a chunk beside the Data rather than owned by it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from rbcli.physics.contact.tables import ROWS_HISTORY
from rbcli.physics.forces.tables import ForceData, ForceTables, KernelForceTables, make_force_data
from rbcli.physics.joints.tables import JointWork, make_joint_work
from rbcli.physics.model import KernelModel, Model
from rbcli.physics.state import State
from rbcli.physics.tree.table import TreeData, TreeTable, make_tree_data

# the joints' last (sub-)step impulses in a checkpoint: optional (logs written before it was carried lack it)
JOINT_REACTIONS = "joint.joint_impulse"
# the joints' last two position multipliers and their count: the next step's first Newton iterate
# (joints/rattle.py); a log from before they were carried resumes with none (to round-off, not bitwise)
JOINT_GUESS = ("joint.guess", "joint.guess_count")
# in joint coordinates, the joints' wrenches of the last step (tree/table.py TreeData.reaction), likewise
TREE_REACTIONS = "tree.reaction"


class KernelAdaptive(NamedTuple):
    """What the adaptive loop (physics/adaptive_loop.py) reads besides the state: see Data."""

    work: np.ndarray
    control: np.ndarray
    counters: np.ndarray
    tolerance: float
    duration: float


class KernelData(NamedTuple):
    """The arrays of a Data as compiled chunk loops take them (numba-friendly named tuple); `adaptive` is
    None in fixed-step runs (numba types it NoneType: the fixed-step loops never read it)."""

    x: np.ndarray
    q: np.ndarray
    P: np.ndarray
    L: np.ndarray
    F: np.ndarray
    tau: np.ndarray
    scratch: np.ndarray
    force: ForceData
    joint: JointWork | None
    substeps: int
    adaptive: KernelAdaptive | None = None
    tree: TreeData | None = None  # reduced coordinates: the trees' coordinates, rates and work


@dataclass
class Data:
    """The mutable arrays of one run (see the module docstring); `state` views x, q, P, L and step."""

    state: State
    F: np.ndarray
    tau: np.ndarray
    scratch: np.ndarray
    force: ForceData
    joint: JointWork | None = None
    substeps: int = 1
    adaptive_work: np.ndarray | None = None
    adaptive_control: np.ndarray | None = None
    adaptive_counters: np.ndarray | None = None
    adaptive_tolerance: float = 0.0
    adaptive_duration: float = 0.0
    tree: TreeData | None = None
    tree_table: TreeTable | None = None  # the model's, for clear_work: (coord, rate) from a state set outside

    def kernel(self) -> KernelData:
        s = self.state
        adaptive = None
        if self.adaptive_work is not None:
            assert self.adaptive_control is not None and self.adaptive_counters is not None
            adaptive = KernelAdaptive(
                self.adaptive_work, self.adaptive_control, self.adaptive_counters,
                float(self.adaptive_tolerance), float(self.adaptive_duration),
            )  # fmt: skip
        return KernelData(
            s.x, s.q, s.P, s.L, self.F, self.tau, self.scratch, self.force, self.joint, int(self.substeps), adaptive,
            self.tree,
        )  # fmt: skip

    def carried(self) -> dict[str, np.ndarray]:
        """Every array a step reads that an earlier step wrote, by name: what an exact continuation
        needs (`Simulation.checkpoint`, `rbsim run --resume`). The state in the internal principal frame,
        the integrator's carried work (scratch, F, tau), the stage counters, the contact history and
        statistics, the adaptive controller's arrays. The contact grid and trial arrays are not carried:
        every force evaluation rebuilds them; nor are the kept body pairs, which change no step
        (body_phase.kept_box_pairs). Views, not copies."""
        s = self.state
        arrays = {"x": s.x, "q": s.q, "P": s.P, "L": s.L, "F": self.F, "tau": self.tau, "scratch": self.scratch}
        arrays["term_evaluations"] = self.force.term_evaluations
        contact = self.force.contact
        if contact is not None:
            for name in ("hist_count", "hist_partner", "hist_xi", "stats", "counters"):
                arrays[f"contact.{name}"] = getattr(contact, name)
        for name in ("work", "control", "counters"):
            array = getattr(self, f"adaptive_{name}")
            if array is not None:
                arrays[f"adaptive.{name}"] = array
        if self.tree is not None:  # the trees' state: x, q, P, L are forward kinematics of it
            arrays["tree.coord"], arrays["tree.rate"] = self.tree.coord, self.tree.rate
            arrays[TREE_REACTIONS] = self.tree.reaction  # read by no step: the last step's, for the first frame
        if self.joint is not None:  # read by no step: the last step's reactions, for the first frame
            arrays[JOINT_REACTIONS] = self.joint.joint_impulse  # a resumed run records (joint_forces)
            arrays[JOINT_GUESS[0]], arrays[JOINT_GUESS[1]] = self.joint.guess, self.joint.guess_count
        return arrays

    def restore_carried(self, arrays: dict[str, np.ndarray]) -> None:
        """Write arrays taken by `carried` (of a Data of the same scene and run settings) back, bit for
        bit; ValueError naming the first array that is missing, unexpected or of another shape or type."""
        mine = self.carried()
        if JOINT_REACTIONS in mine and JOINT_REACTIONS not in arrays:  # a log from before it was carried
            mine[JOINT_REACTIONS][...] = 0.0
            del mine[JOINT_REACTIONS]
        if TREE_REACTIONS in mine and TREE_REACTIONS not in arrays:
            mine[TREE_REACTIONS][...] = np.nan
            del mine[TREE_REACTIONS]
        for name in JOINT_GUESS:
            # likewise, and a log whose history of multipliers has another length (written before the
            # first iterate's degree was chosen: joints/rattle.py): the first step after it starts cold
            if name in mine and (name not in arrays or np.shape(arrays[name]) != mine[name].shape):
                for other in JOINT_GUESS:
                    mine[other][...] = 0.0
                    del mine[other]
                arrays = {key: value for key, value in arrays.items() if key not in JOINT_GUESS}
                break
        if set(arrays) != set(mine):
            missing, extra = sorted(set(mine) - set(arrays)), sorted(set(arrays) - set(mine))
            raise ValueError(f"checkpoint arrays do not fit this run: missing {missing}, unexpected {extra}")
        for name, target in mine.items():
            value = np.asarray(arrays[name])
            if value.shape != target.shape or value.dtype != target.dtype:
                raise ValueError(
                    f"checkpoint array {name!r} is {value.dtype}{list(value.shape)}, "
                    f"this run needs {target.dtype}{list(target.shape)}"
                )
        for name, target in mine.items():
            target[...] = arrays[name]
        if self.tree is not None:  # the state arrays are rewritten by the next step's forward kinematics
            self.tree.fk_state[0] = 0.0
        if self.force.contact is not None:  # the restored history may sit on any row (force.commit_contacts)
            self.force.contact.row_counts[ROWS_HISTORY] = -1
            self.force.contact.quiet_state[:] = 0  # and the quiet skin is this run's (contact/quiet.py)

    def clear_work(self, *, trees_from_state: bool = True) -> None:
        """Forget everything carried between steps but the state (after the state is set from outside):
        the adaptive controller then chooses its first step afresh, as at the start of a run. In joint
        coordinates the trees' (coord, rate) are taken from the state as it now is, unless
        trees_from_state is False (they were set, and the state written from them)."""
        self.F[:] = 0.0
        self.tau[:] = 0.0
        self.scratch[:] = 0.0
        if self.force.contact is not None:  # None: the scene has no contact stage
            self.force.contact.hist_count[:] = 0  # contacts form afresh from the new state
            self.force.contact.row_counts[ROWS_HISTORY] = 0
            self.force.contact.quiet_state[:] = 0
        if self.joint is not None:  # the joints' Newton starts from the free drift (joints/rattle.py)
            self.joint.guess_count[:] = 0.0
        if trees_from_state and self.tree is not None and self.tree_table is not None:  # (coord, rate) from the state
            from rbcli.physics.tree.coordinates import set_from_bodies

            s = self.state
            set_from_bodies(self.tree_table, self.tree, s.x, s.q, s.P, s.L)
        if self.adaptive_work is not None:
            assert self.adaptive_control is not None
            self.adaptive_work[:] = 0.0
            self.adaptive_control[:] = 0.0


def make_data(
    initial: State,
    model: Model | KernelModel,
    scratch_width: int,
    *,
    adaptive: bool = False,
    substeps: int = 1,
    tolerance: float = 0.0,
    duration: float = 0.0,
    contact_threads: int = 1,
    tree_reactions: bool = False,
    implicit_contact: bool = False,
    forces: ForceTables | KernelForceTables | None = None,
) -> Data:
    """A Data for `initial` (copied) and the model `model` (either form; its contact and joint tables
    size the contact and joint work): zeroed accumulators, scratch, force data and joint work; with
    `adaptive`, the adaptive loop's arrays (physics/adaptive.py: adaptive_work, their one definition)
    and its error budget `tolerance` for a run `duration` [s] long; contact_threads > 1: the contact
    pair search on that many threads (contact/threaded.py); tree_reactions: in joint coordinates, the run
    computes the joints' reactions (the joint_forces stream: tree/reactions.py); implicit_contact: the
    contact stage keeps its contacts for the integrator's implicit correction (contact/implicit_rows.py);
    forces: the scene's force tables (either form), which size the dampers' work (None: no dampers)."""
    n = initial.x.shape[0]
    state = initial.copy()
    if substeps < 1:
        raise ValueError(f"substeps must be >= 1, got {substeps}")
    F, tau, scratch = np.zeros((n, 3)), np.zeros((n, 3)), np.zeros((n, scratch_width))
    tree = model.tree
    # reduced coordinates hold the joints by construction: no joint stage runs, no joint work
    joint = None
    if model.joint is not None and model.joint.body_a.shape[0] and tree is None:
        joint = make_joint_work(model.joint)
    force_data = make_force_data(model, contact_threads, implicit_contact, forces)
    data = Data(state, F, tau, scratch, force_data, joint, substeps=int(substeps))
    if tree is not None:  # the trees' state from the bodies' (the velocities the joints allow: tree/coordinates.py)
        from rbcli.physics.tree.coordinates import set_from_bodies

        data.tree, data.tree_table = make_tree_data(tree, tree_reactions), tree
        set_from_bodies(tree, data.tree, state.x, state.q, state.P, state.L)
    if adaptive:
        from rbcli.physics.adaptive import adaptive_work

        work = adaptive_work(n)
        data.adaptive_work = work["work"]
        data.adaptive_control = work["control"]
        data.adaptive_counters = work["counters"]
        if not (tolerance > 0.0 and duration > 0.0):
            raise ValueError(f"an adaptive run needs tolerance > 0 and duration > 0, got {tolerance}, {duration}")
        data.adaptive_tolerance, data.adaptive_duration = float(tolerance), float(duration)
    return data
