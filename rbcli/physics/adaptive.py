"""Adaptive time stepping: error-controlled dopri5 steps between uniform recording times.

With `simulation.tolerance` the runner calls the adaptive loop `physics/adaptive_loop.py: run_chunk`
(the stages of physics/pipeline.py's list that it has, taking the fixed-step loop's arguments;
`IntegratorInfo.adaptive_chunk`) instead of the fixed-step one. This module holds the method:
the controller's constants, the first step, the work arrays. Time is
still counted on the grid t = index * dt (dt = the scene's dt, the output spacing), so frames carry
integer step indices exactly as in fixed-step runs; between grid points the steps are free. The
integrator lands EXACTLY on every recorded grid time (a step is shortened to end there) and on the
chunk's last grid point, so nothing is interpolated and the sinks see uniform times. The runner
should end chunks on recorded grid points (n_steps a multiple of record_every, except the last):
then the steps do not depend on how the run was chunked (bitwise; the controller state persists in
`control`), whereas a chunk ending elsewhere adds a landing there and changes the later steps.

What the tolerance means: the sum of the local errors over the whole run. Each step's error
estimate (`integrators/dopri5.py`, per component scaled by 1 + |y|, max over components and bodies)
must stay below tolerance * h / duration ("error per unit step", Hairer, Norsett & Wanner, Solving
ODEs I, II.4), so the local errors of all steps add up to at most `tolerance`; the global error is
that sum carried forward by the problem's own conditioning: about the tolerance for well-conditioned
motion (measured 0.01-0.1x on I = diag(1, 2, 3), omega0 = (1, 1, 2)), a few times it next to the
separatrix (1-5x on the intermediate-axis flip), where every method's error is amplified. A plain
per-step tolerance would leave the global error at ~400x tol on the flip, growing with the run.

Step-size control (HNW II.4): accept when err <= 1; the next step is
h * clip(SAFETY err^(-1/4), FAC_MIN, FAC_MAX) (err ~ h^4 per unit step for the 4th-order estimate),
with no growth right after a rejection. A step below STEP_MIN_RELATIVE * max(1, |t|) stops the run
(status STATUS_STEP_TOO_SMALL): the problem is stiff or singular there and would never finish.

The loop runs the stages of STEP_STAGES that belong to it (adaptive_loop.py: where each runs): the
impulses at the start of the grid step that holds them (the loop lands on that grid index, applies them
and evaluates k_1 afresh, as a chunk ending there and one starting there did when the runner applied
them between chunks); per attempt contact_begin (the springs' clock: this attempt's [t, t + h)) and
kinematic_begin, and only for an accepted attempt kinematic_end and contact_commit (the last evaluation,
f(y_new) at t + h, becomes the history); contact_record and record on recorded grid times. A rejected
attempt's evaluations wrote only trial arrays, so `restore` plus the untouched history is exactly the
state before it: the step is retried as if never tried (tested), and k_1 (FSAL) stays valid. Kinematic
bodies (physics/kinematic.py) are put at their mean motion over each attempt, which changes the state,
so k_1 is evaluated again for them (one evaluation more per attempt, only in scenes that have kinematic
bodies). Stiffness: contact forces switch on and off (the dashpot at first touch, the Coulomb cap), so
the error estimate rejects steps across a switch until they are short, and no accuracy argument bounds
the step inside a long resting contact, where an explicit method must still resolve the contact's
period; so steps never exceed the contacts' stable step (ContactTable.stable_step, the leapfrog bound 2
(sqrt(1 + zeta^2) - zeta) / w, which is about half of dopri5's own stability bound on the damped
oscillator: there the error estimate, not instability, decides). At a touch-down the dashpot force jumps
by c v_n, and the estimated error of P in a step across the jump is ~ h c v_n / 20: proportional to h,
so its error per unit step never falls and the controller would shrink the step to nothing (it did:
"step below 1e-12 t" at the first bounce). So with contact a step shorter than CONTACT_STEP_FLOOR times
the stable step is allowed the error of a step that long (error per step below it, HNW's other
criterion): the step across a jump shrinks to ~tol / (c v_n) relative and is accepted, and the few short
steps around each touch-down add a few per cent of the tolerance each to the global error (measured: see
docs/integrators.md). Tolerances much below 1e-9 then still fail at touch-down, the jump step falling
under 1e-12 t. A schedule's window edge (a force or torque switched on or off at `start`, `stop`) is
the same jump, so in a scene with schedules a step shorter than forces/schedule.py SCHEDULE_STEP_FLOOR dt is judged the
same way (issue 30: a torque window opening at 0.1 s stopped dopri5 at 1e-8 with "step below 1e-12 t");
each edge then adds at most tolerance * SCHEDULE_STEP_FLOOR dt / duration to the error.
"""

from __future__ import annotations

import numba
import numpy as np

from rbcli.physics.integrators import dopri5

# after STATUS_OK, STATUS_DIVERGED, STATUS_FULL of physics/step.py
STATUS_STEP_TOO_SMALL = 3

SAFETY = 0.9  # HNW's safety factor: aim at err = 0.9^4 ~ 0.65 so most steps are accepted
FAC_MIN = 0.2  # the step shrinks at most 5x per attempt ...
FAC_MAX = 5.0  # ... and grows at most 5x per step (HNW use 5 to 10)
STEP_MIN_RELATIVE = 1e-12  # far above round-off of t (1e-16 |t|), far below any useful step
# with contact, a step shorter than this fraction of the contacts' stable step is allowed the error of
# one that long (module docstring: the step across a touch-down)
CONTACT_STEP_FLOOR = 0.1
# with schedules: forces/schedule.py SCHEDULE_STEP_FLOOR (module docstring)

# control: float64 (2,)
CONTROL_STEP = 0  # the step size [s] proposed for the next attempt; <= 0: choose one from the rates
CONTROL_REJECTED_LAST = 1  # 1.0 when the last attempt was rejected (then the step may not grow)
# counters: int64 (2,)
COUNT_ACCEPTED = 0
COUNT_REJECTED = 1


def adaptive_work(body_count: int) -> dict[str, np.ndarray]:
    """The arrays the adaptive loop keeps between chunks: stage work, controller state, counters (Data
    holds them: physics/data.py make_data(adaptive=True))."""
    return {
        "work": np.zeros((body_count, dopri5.SCRATCH_WIDTH)),
        "control": np.zeros(2),
        "counters": np.zeros(2, dtype=np.int64),
    }


@numba.njit(cache=True)
def initial_step(x, q, P, L, work, tolerance, limit) -> float:  # noqa: ANN001
    """h0 = 0.01 |y0| / |f(y0)| in the scaled norm (HNW II.4's first guess), at most `limit`."""
    size, rate = 0.0, 0.0
    for b in range(x.shape[0]):
        s = work[b]
        for j in range(dopri5.STATE_SIZE):
            scale = tolerance * (1.0 + abs(s[j]))
            size = max(size, abs(s[j]) / scale)
            rate = max(rate, abs(s[16 + j]) / scale)
    if rate <= 0.0 or size <= 0.0:
        return limit
    return min(limit, 0.01 * size / rate)
