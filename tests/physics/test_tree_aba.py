"""Articulated trees in joint coordinates (physics/tree/): the compiled forward kinematics and ABA against
the numpy reference (CRBA mass matrix + RNEA bias, dense solve), against homogeneous transforms composed
here with scipy's rotations, and against two identities that share nothing with either: the rate of the
energy equals the applied forces' power, and a compound pendulum's angular acceleration.

Tolerances: the kernels and the reference are two exact algorithms in float64 on well-conditioned trees
(masses 0.5-2 kg, links ~0.5 m, at most 12 links: cond(M) <= ~1e4, measured errors ~1e-15), so 1e-12
relative; the finite differences of the energy test (central, h = 1e-5) leave h^2 ~ 1e-10 of its scale.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from rbcli.physics.joints.tables import JOINT_BALL, JOINT_FIXED, JOINT_HINGE, JOINT_SLIDER
from rbcli.physics.tree import reference
from rbcli.physics.tree.aba import forward_kinematics, tree_accelerations
from rbcli.physics.tree.limits import tree_response
from rbcli.physics.tree.table import TREE_FREE, make_tree_work, tree_table, zero_coords

GRAVITY = np.array([0.0, 0.0, -9.81])


def random_tree(rng: np.random.Generator, n: int, free_root: bool = False, kinds=None):  # noqa: ANN001, ANN201
    """A random tree of n links: random parents (parent < child; several roots unless free_root), joint
    kinds, anchors, axes, rest rotations, masses and box-like principal moments; with random coordinates
    and rates. Link bodies are stored in reverse order in the state (body = n - 1 - i), so the kernels'
    body indexing is exercised."""
    parent = np.array([-1] + [int(rng.integers(0 if free_root else -1, i)) for i in range(1, n)])
    if kinds is None:
        kinds = rng.choice([JOINT_HINGE, JOINT_SLIDER, JOINT_BALL, JOINT_FIXED], size=n, p=[0.4, 0.2, 0.3, 0.1])
    kinds = np.array(kinds)
    if free_root:
        kinds[0] = TREE_FREE
    mass = rng.uniform(0.5, 2.0, n)
    sides = rng.uniform(0.1, 0.6, (n, 3))
    inertia = mass[:, None] / 12.0 * (np.sum(sides**2, axis=1, keepdims=True) - sides**2)  # a box's moments
    tree = tree_table(
        parent, kinds, 0.3 * rng.normal(size=(n, 3)), 0.3 * rng.normal(size=(n, 3)), rng.normal(size=(n, 3)),
        Rotation.random(n, random_state=rng).as_quat(scalar_first=True), mass, inertia, body=np.arange(n)[::-1],
    )  # fmt: skip
    coord = zero_coords(tree)
    for i, k in enumerate(tree.kind.tolist()):
        c0 = tree.coord_start[i]
        if k in (JOINT_HINGE, JOINT_SLIDER):
            coord[c0] = rng.normal()
        elif k == JOINT_BALL:
            coord[c0 : c0 + 4] = Rotation.random(random_state=rng).as_quat(scalar_first=True)
        elif k == TREE_FREE:
            coord[c0 : c0 + 3] = rng.normal(size=3)
            coord[c0 + 3 : c0 + 7] = Rotation.random(random_state=rng).as_quat(scalar_first=True)
    rate = rng.normal(size=int(tree.dof_start[-1]))
    return tree, coord, rate


class Kernels:
    """The compiled kernels on one tree, with the state arrays they write (indexed by body)."""

    def __init__(self, tree) -> None:  # noqa: ANN001
        n = tree.parent.shape[0]
        self.tree, self.work = tree, make_tree_work(tree)
        self.x, self.q, self.P, self.L = np.zeros((n, 3)), np.zeros((n, 4)), np.zeros((n, 3)), np.zeros((n, 3))

    def kinematics(self, coord: np.ndarray, rate: np.ndarray) -> Kernels:
        forward_kinematics(self.tree, coord, rate, self.work, self.x, self.q, self.P, self.L)
        return self

    def accelerations(self, coord, rate, joint_force, force, torque) -> np.ndarray:  # noqa: ANN001
        self.kinematics(coord, rate)
        qdd = np.full_like(rate, np.nan)
        tree_accelerations(self.tree, self.work, force, torque, joint_force, qdd)
        return qdd

    def omega(self) -> np.ndarray:
        """World angular velocities (bodies, 3) from L: R diag(I)^-1 R^T L."""
        R = Rotation.from_quat(self.q, scalar_first=True).as_matrix()
        inertia = self.tree.inertia[np.argsort(self.tree.body)]
        return np.einsum("nij,nj->ni", R, np.einsum("nji,nj->ni", R, self.L) / inertia)


CASES = [(seed, n, free) for seed, (n, free) in enumerate([(1, False), (2, True), (5, False), (8, True), (12, False),
                                                            (12, True), (9, False), (10, True)])]  # fmt: skip


@pytest.mark.parametrize("seed, n, free_root", CASES)
def test_aba_equals_the_dense_solve(seed, n, free_root):
    """M(q) qdd = tau - b(q, rate): qdd by ABA against the CRBA mass matrix and the RNEA bias (reference.py)
    solved densely, with random joint forces and external forces and torques on every link."""
    rng = np.random.default_rng(seed)
    tree, coord, rate = random_tree(rng, n, free_root)
    tau, force, torque = rng.normal(size=rate.shape), rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    expected = reference.accelerations(tree, coord, rate, tau, force, torque)
    qdd = Kernels(tree).accelerations(coord, rate, tau, force, torque)
    assert np.linalg.norm(qdd - expected) <= 1e-12 * np.linalg.norm(expected)


@pytest.mark.parametrize("seed, n, free_root", CASES)
def test_the_impulse_response_is_the_inverse_mass_matrix(seed, n, free_root):
    """limits.py's tree_response on the factors ABA left: delta = (M + diag(armature))^-1 tau against the
    CRBA mass matrix solved densely, for a random generalized impulse and a random armature (the implicit
    dampers' h c; a ball's the same on its three rates), and each link's velocity change it reports
    against S delta summed down the tree (the reference's link velocities of delta at these coordinates)."""
    rng = np.random.default_rng(100 + seed)
    tree, coord, rate = random_tree(rng, n, free_root)
    kernels = Kernels(tree)
    armature = rng.uniform(0.0, 0.5, size=rate.shape)
    for i in np.flatnonzero(tree.kind == JOINT_BALL):  # a ball's damper is one on its relative spin: isotropic
        armature[tree.dof_start[i] : tree.dof_start[i] + 3] = armature[tree.dof_start[i]]
    kernels.work.armature[:] = armature
    kernels.accelerations(coord, rate, np.zeros_like(rate), np.zeros((n, 3)), np.zeros((n, 3)))
    tau = rng.normal(size=rate.shape)
    delta, acc = np.full_like(rate, np.nan), np.full((n, 6), np.nan)
    tree_response(tree, kernels.work, tau, delta, np.zeros((n, 6)), acc)
    expected = np.linalg.solve(reference.mass_matrix(tree, coord) + np.diag(armature), tau)
    assert np.linalg.norm(delta - expected) <= 1e-12 * np.linalg.norm(expected)
    # each link's spatial velocity change (omega, v of its centre of mass: world) is the one the rates delta give
    v, omega = reference.world_velocities(tree, coord, delta)
    assert np.allclose(acc[:, :3], omega, rtol=0, atol=1e-12 * np.abs(omega).max())
    assert np.allclose(acc[:, 3:], v, rtol=0, atol=1e-12 * np.abs(v).max())


def test_aba_covers_every_joint_kind():
    """The cases above hold every kind on some link (so a kind's code path cannot go untested)."""
    seen = set()
    for seed, n, free_root in CASES:
        seen |= set(random_tree(np.random.default_rng(seed), n, free_root)[0].kind.tolist())
    assert seen == {JOINT_HINGE, JOINT_SLIDER, JOINT_BALL, JOINT_FIXED, TREE_FREE}


def homogeneous_poses(tree, coord: np.ndarray) -> np.ndarray:  # noqa: ANN001
    """World-from-link 4 x 4 transforms composed link by link from the joint model (table.py), with
    scipy's rotations: T = T_parent Trans(anchor_parent) Rot(rest) Rot_joint Trans(travel axis - anchor_child)."""

    def transform(rotation: np.ndarray | None = None, offset: np.ndarray | None = None) -> np.ndarray:
        T = np.eye(4)
        T[:3, :3] = np.eye(3) if rotation is None else rotation
        T[:3, 3] = 0.0 if offset is None else offset
        return T

    poses = np.zeros((tree.parent.shape[0], 4, 4))
    for i, k in enumerate(tree.kind.tolist()):
        c0 = tree.coord_start[i]
        if k == TREE_FREE:
            rot = Rotation.from_quat(coord[c0 + 3 : c0 + 7], scalar_first=True).as_matrix()
            poses[i] = transform(rot, coord[c0 : c0 + 3])
            continue
        joint, travel = np.eye(3), 0.0
        if k == JOINT_HINGE:
            joint = Rotation.from_rotvec(coord[c0] * tree.axis[i]).as_matrix()
        elif k == JOINT_BALL:
            joint = Rotation.from_quat(coord[c0 : c0 + 4], scalar_first=True).as_matrix()
        elif k == JOINT_SLIDER:
            travel = coord[c0]
        rest = Rotation.from_quat(tree.rest_q[i], scalar_first=True).as_matrix()
        T = transform(offset=tree.anchor_parent[i]) @ transform(rest @ joint)
        T = T @ transform(offset=travel * tree.axis[i] - tree.anchor_child[i])
        poses[i] = T if tree.parent[i] < 0 else poses[tree.parent[i]] @ T
    return poses


@pytest.mark.parametrize("seed", [11, 12])
def test_forward_kinematics_composes_the_joint_transforms(seed):
    """The kernel's x and q (written at each link's body row) are the composed homogeneous transforms'
    (to round-off: 1e-13 m over a few links of ~0.5 m); |q| = 1; the reference's poses are the same."""
    tree, coord, rate = random_tree(np.random.default_rng(seed), 12, free_root=seed % 2 == 0)
    poses = homogeneous_poses(tree, coord)
    kernels = Kernels(tree).kinematics(coord, rate)
    x, q = kernels.x[tree.body], kernels.q[tree.body]
    assert np.abs(x - poses[:, :3, 3]).max() < 1e-13
    assert np.abs(Rotation.from_quat(q, scalar_first=True).as_matrix() - poses[:, :3, :3]).max() < 1e-13
    assert np.abs(np.linalg.norm(q, axis=1) - 1.0).max() < 1e-14
    R_ref, x_ref = reference.forward_kinematics(tree, coord)
    assert np.abs(x_ref - poses[:, :3, 3]).max() < 1e-13 and np.abs(R_ref - poses[:, :3, :3]).max() < 1e-13


def advance(tree, coord: np.ndarray, rate: np.ndarray, h: float) -> np.ndarray:  # noqa: ANN001
    """The coordinates moved by h along the rates, on a curve symmetric in h (so central differences over
    +-h are second order): angles and travels + h rate; a ball's u exp(h omega / 2) (omega in the link frame:
    du/dt = u (0, omega) / 2); a free root's x + h R v and q exp(h omega / 2)."""
    out = coord.copy()
    for i, k in enumerate(tree.kind.tolist()):
        c0, d0 = tree.coord_start[i], tree.dof_start[i]
        if k in (JOINT_HINGE, JOINT_SLIDER):
            out[c0] += h * rate[d0]
        elif k == JOINT_BALL:
            u = Rotation.from_quat(coord[c0 : c0 + 4], scalar_first=True) * Rotation.from_rotvec(h * rate[d0 : d0 + 3])
            out[c0 : c0 + 4] = u.as_quat(scalar_first=True)
        elif k == TREE_FREE:
            u = Rotation.from_quat(coord[c0 + 3 : c0 + 7], scalar_first=True)
            out[c0 : c0 + 3] += h * u.apply(rate[d0 + 3 : d0 + 6])
            out[c0 + 3 : c0 + 7] = (u * Rotation.from_rotvec(h * rate[d0 : d0 + 3])).as_quat(scalar_first=True)
    return out


@pytest.mark.parametrize("seed", [21, 22])
def test_velocities_are_the_derivative_of_the_poses(seed):
    """P / m and omega (from L) are d/dt of the kernel's own x and q along the rates (central differences,
    h = 1e-6: error ~h^2 + eps / h ~ 1e-10 m/s)."""
    tree, coord, rate = random_tree(np.random.default_rng(seed), 10, free_root=seed % 2 == 0)
    kernels = Kernels(tree).kinematics(coord, rate)
    velocity, omega = kernels.P / tree.mass[np.argsort(tree.body)][:, None], kernels.omega()
    h = 1e-6
    ahead, behind = (
        Kernels(tree).kinematics(advance(tree, coord, rate, h), rate),
        Kernels(tree).kinematics(advance(tree, coord, rate, -h), rate),
    )
    assert np.abs((ahead.x - behind.x) / (2 * h) - velocity).max() < 1e-8
    turn = Rotation.from_quat(ahead.q, scalar_first=True) * Rotation.from_quat(behind.q, scalar_first=True).inv()
    assert np.abs(turn.as_rotvec() / (2 * h) - omega).max() < 1e-8


def energy(kernels: Kernels) -> float:
    """Kinetic + gravitational energy of the kernels' last state: sum |P|^2 / 2m + L . omega / 2 - m g . x."""
    mass = kernels.tree.mass[np.argsort(kernels.tree.body)]
    kinetic = 0.5 * np.sum(kernels.P**2 / mass[:, None]) + 0.5 * np.sum(kernels.L * kernels.omega())
    return float(kinetic - np.sum(mass * (kernels.x @ GRAVITY)))


@pytest.mark.parametrize("seed, free_root", [(31, False), (32, True), (33, False)])
def test_energy_rate_equals_the_applied_power(seed, free_root):
    """d/dt (T + V) = tau . rate + sum (F . v + T . omega): gravity as a potential (entering ABA as the external
    force m g), random joint forces and random extra forces and torques on each link doing work. The left side
    is a central difference of the kernels' energy along the motion (coordinates +-h along the rates, rates
    +-h qdd from ABA): it knows nothing of M or b, so a wrong inertia, bias or transform shows."""
    rng = np.random.default_rng(seed)
    n = 9
    tree, coord, rate = random_tree(rng, n, free_root)
    tau, extra_force, extra_torque = rng.normal(size=rate.shape), rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    kernels = Kernels(tree)
    gravity = kernels.tree.mass[np.argsort(tree.body)][:, None] * GRAVITY
    qdd = kernels.accelerations(coord, rate, tau, gravity + extra_force, extra_torque)
    mass = tree.mass[np.argsort(tree.body)]
    power = tau @ rate + np.sum(extra_force * kernels.P / mass[:, None]) + np.sum(extra_torque * kernels.omega())
    h = 1e-5
    ahead = energy(Kernels(tree).kinematics(advance(tree, coord, rate, h), rate + h * qdd))
    behind = energy(Kernels(tree).kinematics(advance(tree, coord, rate, -h), rate - h * qdd))
    scale = abs(tau @ rate) + np.sum(np.abs(qdd)) + abs(power)
    assert abs((ahead - behind) / (2 * h) - power) < 1e-8 * scale


@pytest.mark.parametrize("theta, theta_dot", [(0.3, 0.0), (2.5, 4.0), (-1.2, -7.0)])
def test_compound_pendulum(theta, theta_dot):
    """One link on a hinge to the world, its centre of mass d below the pivot at angle 0, principal axes tilted
    by a random rest rotation: theta'' = -M g d sin(theta) / I_pivot, I_pivot = a^T diag(I) a + M d^2 (the
    rate does not enter: the pivot is fixed)."""
    rng = np.random.default_rng(41)
    rest = Rotation.random(random_state=rng)
    M, d, moments = 1.7, 0.35, np.array([0.02, 0.05, 0.06])
    axis, anchor = rest.inv().apply([0.0, 1.0, 0.0]), rest.inv().apply([0.0, 0.0, d])  # world y, pivot above
    tree = tree_table([-1], [JOINT_HINGE], [[0.0, 0.0, 0.0]], [anchor], [axis], [rest.as_quat(scalar_first=True)],
                      [M], [moments])  # fmt: skip
    qdd = Kernels(tree).accelerations(
        np.array([theta]), np.array([theta_dot]), np.zeros(1), M * GRAVITY[None], np.zeros((1, 3))
    )
    expected = -M * 9.81 * d * np.sin(theta) / (axis @ (moments * axis) + M * d * d)
    assert abs(qdd[0] - expected) <= 1e-13 * abs(expected)


def test_tree_table_refuses_what_it_cannot_hold():
    ones = dict(anchor_parent=np.zeros((2, 3)), anchor_child=np.zeros((2, 3)), axis=[[0, 0, 1]] * 2,
                rest_q=[[1, 0, 0, 0]] * 2, mass=[1, 1], inertia=np.ones((2, 3)))  # fmt: skip
    with pytest.raises(ValueError, match="topological order"):
        tree_table([1, -1], [JOINT_HINGE] * 2, **ones)
    with pytest.raises(ValueError, match="free joint"):
        tree_table([-1, 0], [JOINT_HINGE, TREE_FREE], **ones)
    with pytest.raises(ValueError, match="non-zero axis"):
        tree_table([-1, 0], [JOINT_HINGE] * 2, **{**ones, "axis": [[0, 0, 1], [0, 0, 0]]})
