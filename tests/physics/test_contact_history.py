"""Contact search and history against independent references (issue 30: mutations that survived the suite).

Each test kills one hand mutation of the contact code that every other test let through:
- the hashed grid's cell check removed (bucket collisions count pairs twice): a hash table of 16 or 64
  buckets must find exactly the contacts of the dense grid, with the same per-contact values;
- the end-of-step commit advancing the tangential spring with the evaluation's velocity instead of the
  end-of-step one: the committed spring of a stuck contact equals the one integrated by hand;
- history slots cut to one per sphere: a pyramid of three balls, whose bottom balls each own two
  contacts at once (the ground and the top ball), follows a brute-force numpy simulation that keeps
  every contact's history (contact/reference.py).
"""

from __future__ import annotations

import numpy as np
import pytest

import rbcli
from rbcli.physics.contact.force import accumulate_contact
from rbcli.physics.contact.reference import contact_energy_numpy, contact_step_numpy
from rbcli.physics.contact.tables import COUNT_OVERFLOW, STAT_CONTACTS, make_contact_work
from rbcli.scene.load import load_scene_text

G = 9.81


def ball(name: str, position, velocity=(0.0, 0.0, 0.0), radius=0.05, mass=0.5) -> str:  # noqa: ANN001
    """A solid sphere as one particle with a radius: one contact sphere at its centre."""
    return (
        f"  - {{name: {name}, particles: {{positions: [[0, 0, 0]], masses: [{mass!r}], radius: [{radius!r}]}}, "
        f"position: {list(map(float, position))}, velocity: {list(map(float, velocity))}}}"
    )


def simulation(bodies: list[str], contact: str, *, dt: float = 1e-3, integrator: str = "semi-implicit",
               gravity: bool = True) -> rbcli.Simulation:  # fmt: skip
    text = (
        f"name: t\nsimulation: {{dt: {dt!r}, steps: 10, integrator: {integrator}}}\n"
        + ("gravity: [0, 0, -9.81]\n" if gravity else "")
        + "contact:\n  substeps: 1\n"
        + contact
        + "bodies:\n"
        + "\n".join(bodies)
        + "\n"
    )
    return rbcli.Simulation(load_scene_text(text))


# ---- the hashed grid: bucket collisions ----------------------------------------------------------------


def _cloud(seed: int = 11, count: int = 160) -> rbcli.Simulation:
    """Equal-ish balls packed densely in a 0.5 m cube (about 3 contacts per ball), with friction so that
    every contact is written to the trial arrays; no gravity, random velocities and spins."""
    rng = np.random.default_rng(seed)
    bodies = [
        ball(f"b{i}", rng.uniform(-0.25, 0.25, 3), rng.normal(size=3), radius=float(rng.uniform(0.03, 0.045)))
        for i in range(count)
    ]
    contact = "  planes: [{point: [0, 0, -0.22], normal: [0, 0.1, 1]}]\n  material: {restitution: 0.4, friction: 0.6}\n"
    return simulation(bodies, contact, gravity=False)


def _contacts(sim: rbcli.Simulation, buckets: int | None) -> tuple[dict, np.ndarray, np.ndarray, int]:
    """One force evaluation at the start of a step: {(owner, partner): (point, normal, xi, limit)},
    F, tau and the contact count, with the scene's table or one of `buckets` buckets."""
    table = sim.model.contact
    if buckets is not None:
        table = table._replace(bucket_count=buckets)
    work = make_contact_work(table, sim.model.body_count)
    work.clock[1] = 1e-3
    s = sim.data.state
    F, tau = np.zeros_like(s.x), np.zeros_like(s.x)
    accumulate_contact(sim.model.kernel_bodies(), table, work, 0.0, s.x, s.q, s.P, s.L, F, tau)
    assert work.counters[COUNT_OVERFLOW] == 0
    found = {}
    for i in range(work.trial_count.shape[0]):
        for k in range(work.trial_count[i]):
            key = (i, int(work.trial_partner[i, k]))
            assert key not in found, f"contact {key} found twice"
            found[key] = (
                *work.trial_point[i, k],
                *work.trial_normal[i, k],
                *work.trial_xi[i, k],
                work.trial_limit[i, k],
            )
    return found, F, tau, int(work.stats[STAT_CONTACTS])


@pytest.mark.parametrize("buckets", [16, 64])
def test_a_tiny_hash_table_finds_exactly_the_contacts_of_the_dense_grid(buckets):
    """With 16 or 64 buckets for ~500 occupied cells nearly every bucket holds several cells, most of
    them not neighbours: the walk must compare cells, or a pair is found once per shared bucket (the
    removed check gave 155 and 197 contacts instead of 128 on the issue's scene). Each contact's values
    do not depend on which sphere found it (p_i - p_j is exactly -(p_j - p_i)), so they must be
    bitwise equal; F and tau sum the same terms in another order: equal to 1e-12 of the largest."""
    sim = _cloud()
    dense, F_dense, tau_dense, count_dense = _contacts(sim, None)
    table = sim.model.contact
    assert table.bucket_count >= 640  # the scene's own grid is dense
    hashed, F_hashed, tau_hashed, count_hashed = _contacts(sim, buckets)
    assert count_dense > 150  # sphere pairs and plane contacts
    assert count_hashed == count_dense
    assert hashed.keys() == dense.keys()
    for key, values in dense.items():
        assert hashed[key] == values, key
    scale = np.abs(F_dense).max()
    np.testing.assert_allclose(F_hashed, F_dense, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(tau_hashed, tau_dense, rtol=0, atol=1e-12 * scale)


# ---- the end-of-step commit: a stuck contact integrated by hand ------------------------------------------


def test_end_of_step_spring_of_a_stuck_contact_equals_the_hand_integrated_one():
    """A ball on the ground pushed sideways at 5 cm/s sticks at once (mu = 0.8): its tangential spring
    swings between +-1.6e-4 m, lightly damped (restitution 0.9). Over one semi-implicit step [t, t + h)
    the force is evaluated at s = 0 on the start state, so by docs/contact.md the committed spring is

        xi(t + h) = xi(t) + h v_t(t + h),   v_t = v - (v . n) n,   v = v_b + w_b x (c - x_b(t + h))

    at the contact point c = x(t) - (r - d / 2) n of the evaluation (n = z, d = r - z(t)), with the
    velocities of the END of the step (the leapfrog's own drift of a position). The evaluation's velocity
    instead gives an xi 5-10 % off; round-off of the sum is 1e-16 of its terms, the tolerance 1e-12."""
    r, m = 0.05, 0.5
    sink = 0.0025 * r  # its sink at rest under the default stiffness (docs/contact.md)
    sim = simulation([ball("a", (0, 0, r - sink), (0.05, 0.0, 0.0), radius=r, mass=m)],
                     "  ground: 0\n  material: {restitution: 0.9, friction: 0.8}\n", dt=1e-3)  # fmt: skip
    work = sim.data.force.contact
    h = sim.dt
    n = np.array([0.0, 0.0, 1.0])
    inertia = 0.4 * m * r * r
    sim.step(1)
    for _ in range(30):  # more than a period (22 ms) of the stuck spring's oscillation
        assert work.hist_count[0] == 1
        xi_before = work.hist_xi[0, 0].copy()
        x0 = sim.data.state.x[0].copy()
        sim.step(1)
        x1, P1, L1 = sim.data.state.x[0], sim.data.state.P[0], sim.data.state.L[0]
        d = r - x0[2]
        c = x0 - (r - 0.5 * d) * n
        v = P1 / m + np.cross(L1 / inertia, c - x1)
        drift = h * (v - (v @ n) * n)
        expected = xi_before + drift
        assert np.linalg.norm(expected) < work.trial_limit[0, 0]  # stuck: not cut back to the Coulomb limit
        scale = np.linalg.norm(xi_before) + np.linalg.norm(drift)
        np.testing.assert_allclose(work.hist_xi[0, 0], expected, rtol=0, atol=1e-12 * scale)
    assert np.abs(work.hist_xi[0, 0]).max() > 1e-5  # the spring did hold the ball


# ---- history slots: a sphere with two contacts at once ----------------------------------------------------


def _pyramid() -> tuple[rbcli.Simulation, float]:
    """Two balls on the ground 2 mm apart, a third on top of them: each bottom ball owns two contacts
    (the ground and the top ball, index 2 > its own), held by friction (mu = 0.3)."""
    r = 0.05
    gap = 0.001
    top = r + np.sqrt((2 * r) ** 2 - (r + gap) ** 2) - 0.0005
    bodies = [ball("left", (-(r + gap), 0, r)), ball("right", (r + gap, 0, r)), ball("top", (0, 0.0, top))]
    return simulation(bodies, "  ground: 0\n  material: {restitution: 0.5, friction: 0.3}\n", dt=5e-4), r


def test_two_simultaneous_contacts_keep_their_histories_as_the_brute_force_reference_does():
    """The compiled run against contact/reference.py's brute-force step (every pair, every history kept,
    semi-implicit Euler), 400 steps of 0.5 ms: the pile settles, its bottom balls held from sliding
    apart by the tangential springs of both their contacts. Losing the second history (one slot per
    sphere) leaves only the damper on the balls' mutual contacts: the bottom balls end 0.28 mm elsewhere
    (measured), where the two computations agree to 1e-12 m (round-off of sums in another order)."""
    sim, r = _pyramid()
    s = sim.data.state
    x, q, P, L = s.x.copy(), s.q.copy(), s.P.copy(), s.L.copy()
    history: dict = {}
    gravity = np.array([0.0, 0.0, -G]) * sim.model.body_mass[:, None]
    work = sim.data.force.contact
    most = 0
    for _ in range(400):
        sim.step(1)
        history = contact_step_numpy(sim.model, sim.model.contact, x, q, P, L, history, sim.dt, gravity)
        most = max(most, int(work.hist_count.max()))
    np.testing.assert_allclose(sim.data.state.x, x, rtol=0, atol=1e-12)
    np.testing.assert_allclose(sim.data.state.P, P, rtol=0, atol=1e-12)
    assert most == 2  # the bottom balls owned two contacts at once
    assert len(history) == 4  # two ground contacts and two between balls, all still touching
    for (owner, partner), xi in history.items():
        slots = [k for k in range(work.hist_count[owner]) if work.hist_partner[owner, k] == partner]
        assert len(slots) == 1, (owner, partner)
        np.testing.assert_allclose(work.hist_xi[owner, slots[0]], xi, rtol=0, atol=1e-12)


# ---- the recorded contact energy: of the recorded state -----------------------------------------------------


@pytest.mark.parametrize("integrator", ["split2", "semi-implicit"])
def test_recorded_total_energy_is_that_of_each_recorded_state(integrator):
    """A frictionless ball dropped on two others and the ground (restitution 1: elastic springs, so the
    energy is conserved up to the integrator's bounded error). At every recorded frame

        energy_total = sum |P|^2 / 2M + L . omega / 2 + M g z + V_c(x),   V_c = sum 1/2 k d^2

    with V_c of the frame's own positions (contact/reference.py, brute force), to round-off (1e-12 of
    the energy scale): the energy of the step's last force evaluation instead (split2: mid-step;
    semi-implicit: the step's start) was off by 1.6 % / 3.2 % of the impact energy (issue 30)."""
    bodies = [ball("low_a", (-0.051, 0, 0.05)), ball("low_b", (0.051, 0, 0.05)),
              ball("drop", (0.0, 0.0, 0.3), (0.0, 0.0, -1.0))]  # fmt: skip
    text = (
        f"name: bounce\nsimulation: {{dt: 0.0005, duration: 0.4, integrator: {integrator}, record: {{every: 5}}}}\n"
        "gravity: [0, 0, -9.81]\ncontact:\n  ground: 0\n  substeps: 1\n  material: {restitution: 1.0, friction: 0.0}\n"
        "bodies:\n" + "\n".join(bodies) + "\n"
    )
    spec = load_scene_text(text)
    traj = rbcli.simulate(spec)
    compiled = rbcli.prepare(spec)
    contact, model = compiled.model.contact, compiled.model
    m = model.body_mass
    potential = np.array([contact_energy_numpy(contact, x, q) for x, q in zip(traj.x, traj.q, strict=True)])
    kinetic = 0.5 * (m[:, None] * traj.v**2).sum(axis=(1, 2)) + 0.5 * (traj.omega * traj.L).sum(axis=(1, 2))
    expected = kinetic + G * (m * traj.x[:, :, 2]).sum(axis=1) + potential
    inv = traj.invariants
    scale = float(np.abs(expected).max())
    assert potential.max() > 1e-3 * scale  # the frames do catch the springs loaded
    np.testing.assert_allclose(inv["contact_energy"], potential, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(inv["energy_total"], expected, rtol=0, atol=1e-12 * scale)


# ---- history overflow: reported -----------------------------------------------------------------------------


def _crowded_hub(spokes: int) -> str:
    """A ball of 10 cm ('hub', sphere 0: the owner of all its pairs) touched by `spokes` balls of 2 cm
    (2 mm overlap, spread evenly over its surface, not touching each other), with friction, no gravity."""
    golden = np.pi * (3.0 - np.sqrt(5.0))
    bodies = [ball("hub", (0, 0, 0), radius=0.1, mass=4.0)]
    for i in range(spokes):
        z = 1.0 - 2.0 * (i + 0.5) / spokes
        direction = np.array([np.sqrt(1 - z * z) * np.cos(golden * i), np.sqrt(1 - z * z) * np.sin(golden * i), z])
        bodies.append(ball(f"spoke{i}", 0.118 * direction, radius=0.02, mass=0.03))
    return (
        "name: hub\nsimulation: {dt: 0.0001, steps: 20, integrator: split2, record: {every: 5}}\n"
        "contact:\n  substeps: 1\n  material: {restitution: 0.5, friction: 0.5}\nbodies:\n" + "\n".join(bodies) + "\n"
    )


@pytest.mark.parametrize("spokes", [12, 16])
def test_history_overflow_is_warned_naming_the_body_and_recorded(tmp_path, capsys, spokes):
    """12 contacts fit the hub's 12 history slots; 16 leave 4 per force evaluation without one (split2:
    one evaluation per step). `rbsim run` then warns once, naming the hub, and the recording holds the
    cumulative count per frame as the invariant contact_history_overflow = 4 x steps (MCAP and memory)."""
    from rbcli.cli.app import run_app

    scene = tmp_path / "hub.yaml"
    scene.write_text(_crowded_hub(spokes))
    out = tmp_path / "hub.mcap"
    assert run_app(["run", str(scene), "-o", str(out), "--quiet"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning:" in line]
    recorded = rbcli.read_recording(out)
    memory = rbcli.simulate(load_scene_text(_crowded_hub(spokes)))
    expected = 4 * recorded.step if spokes == 16 else 0 * recorded.step
    np.testing.assert_array_equal(recorded.invariants["contact_history_overflow"], expected)
    np.testing.assert_array_equal(memory.invariants["contact_history_overflow"], expected)
    if spokes == 16:
        assert len(warnings) == 1 and "body 'hub'" in warnings[0] and "(80 contact evaluations" in warnings[0], warnings
    else:
        assert warnings == []
