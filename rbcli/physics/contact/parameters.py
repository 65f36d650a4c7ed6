"""Contact parameters from physical quantities: default stiffness, damping from a coefficient of
restitution, and the stable step of a contact (numpy, used when compiling a scene).

Default stiffness. A body of mass M resting under gravity g on its contact spheres of radius r should
sink by a small, fixed fraction of r: k_body = M g / (PENETRATION_AT_REST r). Shared over the spheres
that carry it when it lies on its largest flat side (`support_count`: one for a sphere-shaped body,
the spheres of its largest face for a box), each sphere gets k = k_body / support. The default depends on the body, not
on dt: a run at a larger dt does not silently soften its contacts; it warns or sub-steps instead.
Without gravity g = REFERENCE_GRAVITY sets the scale. The 1,000-sphere pile of the collisions issue
(r = 5 cm, 0.52 kg) gets k = 4.1e4 N/m, the value measured there to settle cleanly at dt = 2 ms.

Plane stiffness. `support` counts the spheres of the outermost layer within half the smallest radius:
those that can carry the body at once (a 13-sphere ball's vertex and, 1 cm above it, the next ones).
Resting on a plane, the body is carried only by the spheres level with its lowest one within its sink
at rest (`support_count` with tolerance PENETRATION_AT_REST r: the face of a box, the edge of an
icosahedral cloud), `rest` of them, so k_plane = k_body / rest makes it sink PENETRATION_AT_REST r
as the rule says. It is capped at twice the pair value, k_plane = k_body / max(rest, support / 2),
because a plane is a partner of infinite mass: a contact against it has m_eff = M where one between two
equal bodies has M / 2, so k_body * support / rest <= 2 k_body keeps the plane's frequency
(k_plane support / M) within the pair's (2 k_body / M) and the stable step unchanged. A box or a
one-sphere ball (rest = support) keeps k_plane = k; it is not a blanket factor of 2, which made a brick
resting flat at dt = 1 ms rock in a period-2 limit cycle: dt was then 0.9 of its estimated stable step,
so the estimate is at least 10 % optimistic for its coupled rocking-sliding mode (1.5x was still stable).

Damping from restitution. The linear spring-dashpot m d'' + c d' + k d = 0 with c = 2 zeta sqrt(k m)
would give e = exp(-pi zeta / sqrt(1 - zeta^2)) if the contact lasted half a period; but the force is
clamped at zero (a dashpot does not pull), so the contact ends earlier, when k d + c d' = 0, and the
restitution is larger (Schwager & Poeschel 2007, "Coefficient of restitution and linear-dashpot model
revisited", Granular Matter 9). `restitution_for_damping_ratio` is that clamped model's e(zeta) in
closed form; `damping_ratio_for_restitution` inverts it, so a configured e is what a resolved
collision gives.

Stable step. The explicit update of an undamped spring of frequency w = sqrt(k / m_eff) is stable for
dt < 2 / w; with damping ratio zeta, dt < 2 (sqrt(1 + zeta^2) - zeta) / w (leapfrog / symplectic Euler
on the damped oscillator). `stable_step` estimates the smallest over the pairs a scene can form.
"""

from __future__ import annotations

import math

import numpy as np

PENETRATION_AT_REST = 0.0025  # fraction of the sphere radius a body sinks under its own weight
REFERENCE_GRAVITY = 9.81  # [m/s^2] the default stiffness' scale in a scene without gravity
DEFAULT_RESTITUTION = 0.5
DEFAULT_FRICTION = 0.5
# auto sub-steps keep each sub-step at this fraction of the stable step: margin for several contacts
# stiffening one body at once and for accuracy (a collision resolved in about ten sub-steps)
SUBSTEP_SAFETY = 0.5


# auto sub-steps also keep the distance the fastest contact sphere can move in one sub-step under this
# fraction of the smallest sphere radius: a contact with a plane or a resting body is found within 0.25 r of
# its first touch (two spheres meeting head-on, each at that speed, within 0.5 r, DEPTH_FRACTION), so a
# late-found contact does not act on an overlap it never had (an impact stiffer than its spring)
TRAVEL_FRACTION = 0.25
# the deepest a contact sphere should go, as a fraction of its radius: beyond it a sphere of a lattice
# surface reaches past the next layer and a resting body's contacts change which spheres carry it
DEPTH_FRACTION = 0.5
# auto sub-steps stop here: a scene that would need more is warned about (the speed it cannot take), not run
# at a million sub-steps a step
MAX_AUTO_SUBSTEPS = 1000

# the default stiffness of a primitive (scene/compile_contact.py) also keeps its deepest impact at its
# speed bound (scene/contact_speed.py, its assembly's mass behind one contact point) within this fraction
# of its size: the rest rule alone let a capsule ragdoll dropped 1 m sink 0.96 of an arm's radius, and at
# 0.1 a shin pinned under the falling torso (more than the bound covers) still sank 0.14 of its radius
IMPACT_DEPTH = 0.05
# restitutions below this need zeta > 4 (stable steps 8x shorter than undamped): refused at load
LOWEST_RESTITUTION = 0.01
_ZETA_MAX = 1000.0


def restitution_for_damping_ratio(zeta: float) -> float:
    """Coefficient of restitution of the clamped linear spring-dashpot with damping ratio zeta >= 0.

    With w = 1 and approach speed 1, d'' + 2 zeta d' + d = 0, d(0) = 0, d'(0) = 1; the contact ends
    when the force d + 2 zeta d' first vanishes, and e = -d'(t_end). Underdamped (zeta < 1):
    d = exp(-zeta t) sin(wd t) / wd, wd = sqrt(1 - zeta^2), and the force is exp(-zeta t) (A sin(wd t)
    + B cos(wd t)), A = (1 - 2 zeta^2) / wd, B = 2 zeta, zero first at wd t_end = pi - atan2(B, A).
    Critically and overdamped (zeta >= 1): d = (exp(l1 t) - exp(l2 t)) / (l1 - l2), l = -zeta +-
    sqrt(zeta^2 - 1), t_end found by bisection.
    """
    if zeta <= 0.0:
        return 1.0
    if zeta < 1.0:
        wd = math.sqrt(1.0 - zeta * zeta)
        theta = math.pi - math.atan2(2.0 * zeta, (1.0 - 2.0 * zeta * zeta) / wd)
        t_end = theta / wd
        return -math.exp(-zeta * t_end) * (math.cos(theta) - zeta / wd * math.sin(theta))
    root = math.sqrt(zeta * zeta - 1.0)
    l1, l2 = -zeta + root, -zeta - root

    def rate(t: float) -> float:  # d'(t)
        if root == 0.0:
            return (1.0 - t) * math.exp(-t)
        return (l1 * math.exp(l1 * t) - l2 * math.exp(l2 * t)) / (l1 - l2)

    def force(t: float) -> float:  # d + 2 zeta d'
        d = t * math.exp(-t) if root == 0.0 else (math.exp(l1 * t) - math.exp(l2 * t)) / (l1 - l2)
        return d + 2.0 * zeta * rate(t)

    lo, hi = 0.0, 1.0
    while force(hi) > 0.0:
        hi *= 2.0
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if force(mid) > 0.0:
            lo = mid
        else:
            hi = mid
    return -rate(hi)


def damping_ratio_for_restitution(restitution: float) -> float:
    """The damping ratio whose clamped spring-dashpot rebounds with `restitution` in
    [LOWEST_RESTITUTION, 1] (bisection; e(zeta) decreases monotonically)."""
    if not LOWEST_RESTITUTION <= restitution <= 1.0:
        raise ValueError(f"coefficient of restitution must be in [{LOWEST_RESTITUTION}, 1], got {restitution}")
    if restitution == 1.0:
        return 0.0
    lo, hi = 0.0, _ZETA_MAX
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if restitution_for_damping_ratio(mid) > restitution:
            lo = mid
        else:
            hi = mid
        if hi - lo < 1e-14 * max(1.0, hi):
            break
    return 0.5 * (lo + hi)


def default_body_stiffness(mass: np.ndarray, radius: np.ndarray, gravity: float) -> np.ndarray:
    """k_body [N/m] per body: M g / (PENETRATION_AT_REST r) (module docstring)."""
    g = gravity if gravity > 0.0 else REFERENCE_GRAVITY
    return np.asarray(mass, dtype=float) * g / (PENETRATION_AT_REST * np.asarray(radius, dtype=float))


def support_count(
    offsets: np.ndarray, radii: np.ndarray, E: np.ndarray | None = None, tolerance: float | None = None
) -> int:
    """How many contact spheres can carry the body against a plane at once: the most spheres in one
    outermost layer (within `tolerance` [m] of the extreme; default half the smallest radius) over the 6
    directions of the principal axes and, given E (user-from-principal rotation), the 6 of the user's
    axes (a sampled shape's lattice axes). 1 for a one-sphere body; 32 for the 0.2 x 0.1 face of a box at
    spacing 0.025. With tolerance PENETRATION_AT_REST r: the spheres that carry it at rest (docstring)."""
    offsets = np.asarray(offsets, dtype=float)
    if len(offsets) <= 1:
        return 1
    axes = [np.eye(3)] + ([np.asarray(E)] if E is not None else [])  # rows: directions in the principal frame
    if tolerance is None:
        tolerance = 0.5 * float(np.min(radii))
    best = 1
    for basis in axes:
        for direction in (*basis, *(-basis)):
            reach = offsets @ direction + radii
            best = max(best, int(np.count_nonzero(reach >= reach.max() - tolerance)))
    return best


def plane_stiffness(stiffness: float, support: int, rest: int) -> float:
    """k_plane [N/m] of a contact sphere whose pair stiffness is `stiffness`: k support / max(rest,
    support / 2), at most 2 k (module docstring)."""
    return stiffness * support / max(rest, 0.5 * support)


def stable_step(
    mass: np.ndarray,
    body_stiffness: np.ndarray,
    damping_ratio: np.ndarray,
    movable: np.ndarray,
    planes: bool,
    plane_stiffness: np.ndarray | None = None,
) -> tuple[float, int]:
    """(dt_crit [s], the body that sets it) over the contacts a scene can form: each body against a
    plane (m_eff = M, stiffness plane_stiffness: k_plane support, default body_stiffness), against an
    identical body (M / 2) and against the lightest movable body, with the body-level stiffness k_body
    (all supporting spheres in contact at once) and the largest zeta."""
    mass = np.asarray(mass, dtype=float)
    k = np.asarray(body_stiffness, dtype=float)
    k_plane = k if plane_stiffness is None else np.asarray(plane_stiffness, dtype=float)
    movable = np.asarray(movable, dtype=bool)
    if not movable.any():
        return math.inf, -1
    zeta = float(np.max(damping_ratio)) if len(damping_ratio) else 0.0
    inv_m = np.where(movable, 1.0 / mass, 0.0)
    omega2 = np.zeros_like(mass)
    if planes:
        omega2 = np.maximum(omega2, k_plane * inv_m)
    lightest = int(np.argmax(inv_m))
    k_light = k[lightest]
    pair_k = 2.0 * k * k_light / (k + k_light)
    omega2 = np.maximum(omega2, pair_k * (inv_m + inv_m[lightest]))
    omega2 = np.maximum(omega2, np.where(movable, k * 2.0 * inv_m, 0.0))
    worst = int(np.argmax(omega2))
    if omega2[worst] <= 0.0:
        return math.inf, -1
    return 2.0 * (math.sqrt(1.0 + zeta * zeta) - zeta) / math.sqrt(omega2[worst]), worst


def substeps_needed(dt: float, dt_crit: float, travel_step: float = math.inf) -> int:
    """Sub-steps that bring dt / n under SUBSTEP_SAFETY dt_crit and under travel_step [s] (the time in
    which the fastest contact sphere moves TRAVEL_FRACTION of the smallest radius: `travel_step`), uncapped."""
    n = 1
    if math.isfinite(dt_crit) and dt_crit > 0.0:
        n = max(n, math.ceil(dt / (SUBSTEP_SAFETY * dt_crit) - 1e-9))
    if math.isfinite(travel_step) and travel_step > 0.0:
        n = max(n, math.ceil(min(dt / travel_step, 1e18) - 1e-9))
    return n


def substeps_for(dt: float, dt_crit: float, travel_step: float = math.inf) -> int:
    """`substeps_needed`, at most MAX_AUTO_SUBSTEPS (beyond it the scene is warned about: scene/checks.py)."""
    return min(MAX_AUTO_SUBSTEPS, substeps_needed(dt, dt_crit, travel_step))


def travel_step(speed: float, radius: float) -> float:
    """[s] The time in which a sphere moving at `speed` [m/s] moves TRAVEL_FRACTION of `radius` [m] (inf
    when nothing moves)."""
    if not speed > 0.0:
        return math.inf
    return TRAVEL_FRACTION * radius / speed


def peak_compression(zeta: float) -> float:
    """The deepest compression of the linear spring-dashpot d'' + 2 zeta w d' + w^2 d = 0 hit at speed v,
    as a multiple of v / w: d(0) = 0, d'(0) = v. (The clamp of the dashpot acts only after the peak: while
    d grows, k d + c d' > 0.) Underdamped, d = v exp(-zeta w t) sin(wd t) / wd, wd = w sqrt(1 - zeta^2),
    peaks where tan(wd t) = wd / (zeta w), at exp(-zeta atan2(s, zeta) / s) v / w, s = sqrt(1 - zeta^2);
    overdamped, d = v (exp(l1 t) - exp(l2 t)) / (l1 - l2) peaks at t = ln(l2 / l1) / (l1 - l2)."""
    if zeta <= 0.0:
        return 1.0
    if zeta < 1.0:
        root = math.sqrt(1.0 - zeta * zeta)
        return math.exp(-zeta * math.atan2(root, zeta) / root)
    if zeta == 1.0:
        return math.exp(-1.0)
    root = math.sqrt(zeta * zeta - 1.0)
    l1, l2 = -zeta + root, -zeta - root
    t = math.log(l2 / l1) / (l1 - l2)
    return (math.exp(l1 * t) - math.exp(l2 * t)) / (l1 - l2)
