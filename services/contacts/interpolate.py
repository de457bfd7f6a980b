"""A statically stable motion between consecutive contact sets (§3.3 of Escande et al.; §4 for the
speed profile).

For two consecutive sets S1, S2 with witness postures q1, q2:

* when a body's spot moves between q1 and q2 (a contact geometrically created, broken or changed), a
  Cartesian trajectory of that spot is generated: a short straight line along the surface normal when
  it leaves a surface, another when it enters one, a smooth (C1) connection in between, the
  orientation interpolated by slerp; it is cut into n - 1 steps giving n frame constraints C_i;
* otherwise (a contact created or broken only at the stability level) there is no C_i;

then the posture generator runs n times with the contacts of S1 and S2 that do not move, the C_i,
stability on the contacts held during the motion (S1 for a removal: the contact is released at q2;
S1 for an addition: the new contact is only made at q2), and the squared distance to q_i, the linear
interpolation between q1 and q2, as criterion. The discrete path is then timed with a sinusoidal speed
profile (null speed at every contact change, §4) through a clamped cubic spline of the postures, and
sampled every ``dt_s`` (5 ms).

Collisions (§4: "the interpolation must be checked for collisions"): every posture of the path is
generated collision free (capsules against the scene's boxes and each other), and the timed segment
between them is checked sample by sample (capsules against boxes, the pairs in contact excluded); a
segment that comes closer than ``clearance_m`` to a box is re-planned locally: twice as many
posture generations (so with collision constraints between the former samples), then the moving
body's path bent sideways or up around the obstacle (``DETOURS_M``), up to ``max_refinements`` tries;
a segment still more than ``collision_tol_m`` into a box is listed in ``Motion.collisions`` (never
hidden).
A segment whose posture generation fails is reported (no hand correction).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np
import pinocchio as pin

from services import budget
from services.contacts.hold import hold_spots
from services.contacts.posture import ARM_SPOTS, PostureConfig, PostureGenerator
from services.contacts.sets import ContactSet, spot_surface_gap
from services.contacts.timing import ZMP_SLOWDOWNS, interval_times, knots, time_segment, zmp_shift
from services.errors import InfeasibleError, RequestTimeoutError
from services.ik import FramePoseTask, PostureTask
from services.ik.tasks.capsule_box import CapsuleBoxTask
from services.model.ground import signed_distance

#: The collision check of a timed segment looks at the request's time budget every this many samples.
BUDGET_CHECK_SAMPLES = 50


@dataclass(frozen=True)
class InterpolationConfig:
    """``n`` postures per transition (the paper's n = 20), lift/approach height along the normal [m],
    quasi-static speed limits: base ``base_speed_m_s`` [m/s], moving spot ``spot_speed_m_s`` [m/s],
    joints ``joint_speed_ratio`` of their velocity limits, ``min_segment_s`` [s], sample ``dt_s`` [s],
    collision check of the timed segments every ``check_every`` samples, a segment closer than
    ``clearance_m`` [m] to a box re-planned with 2x the postures at most ``max_refinements`` times (one
    still deeper than ``collision_tol_m`` [m] into a box reported),
    the largest distance ``zmp_shift_m`` [m] between the ZMP the timed motion needs and the CoM's
    projection (a quasi-static motion: ``services.contacts.timing``), the posture generator's settings
    ``posture`` (None: the generator's own). The request's time budget (:mod:`services.budget`) is
    checked before every posture generation, every re-planning try and every ``BUDGET_CHECK_SAMPLES``
    collision-checked samples: past it, RequestTimeoutError names the transition and step reached
    (issue 16)."""

    n: int = 20
    lift_m: float = 0.03
    base_speed_m_s: float = 0.08
    spot_speed_m_s: float = 0.15
    joint_speed_ratio: float = 0.1
    min_segment_s: float = 0.8
    dt_s: float = 0.005
    collision_tol_m: float = 0.005
    zmp_shift_m: float = 0.01
    posture: PostureConfig | None = None  # the posture generator's settings (None: the generator's)
    max_refinements: int = 4
    check_every: int = 4
    # a timed segment coming closer than this to a box it does not touch is re-planned locally (the
    # n postures keep collision_margin_m; the spline between them cut a swinging foot to 1 mm of the
    # chair's leg, and the executed foot struck it)
    clearance_m: float = 0.01
    # held contacts kept in place at every sample, not only at the n postures (hold.py)
    hold_contacts: bool = True
    # the n postures statically stable without the arms in contact (hands and forearms kept as geometry,
    # helpers) when both ends are, by ``helpers_end_margin_m`` [m] inside the region of the other
    # contacts; the transition with the arms counted if that fails (:func:`stability_contacts`)
    arms_as_helpers: bool = False
    helpers_end_margin_m: float = 0.02
    # an execution set by set (closed_loop.py) gives each transition the arms' planned normal forces
    # (contact_forces.py) for the sim's damping control (sim/compliance.py): an experiment, off: every
    # variant tried on the chair egress fell earlier than without it (services/contacts/README.md,
    # session 9); `humanoid scenario chair-egress --force-control` runs it
    force_control: bool = False


@dataclass(frozen=True)
class Motion:
    """The interpolated motion: ``q`` (N x nq) every ``dt_s``, the index in ``q`` where each contact
    set's witness posture is reached (``set_samples``), the discrete path (``waypoints``), the
    interpolation time [s], the segments still colliding after local re-planning (``collisions``) and
    the number of local re-plannings done (``refinements``)."""

    q: np.ndarray
    dt_s: float
    set_samples: list[int]
    waypoints: np.ndarray
    interpolation_s: float
    collisions: tuple[SegmentCollision, ...] = ()
    refinements: int = 0


@dataclass(frozen=True)
class SegmentCollision:
    """The deepest capsule-box penetration of a timed segment (transition ``transition``: from set
    ``transition - 1`` to ``transition``): ``depth_m`` > 0 into ``box``, capsule ``capsule``, at sample
    ``sample`` of the whole motion."""

    transition: int
    depth_m: float
    capsule: str
    box: str
    sample: int


def moving_candidates(s1: ContactSet, s2: ContactSet, released: ContactSet) -> list[str]:
    """The spots that may move between the witnesses of S1 and S2: that of a contact made now (in S2,
    not S1) or released at the previous transition (``released``). A contact held in S1 and S2, or
    removed now (it stays in place until q2, §2.3), does not move, even when q1 is a measured posture
    with its spot a few mm off (executing set by set): taken for the moving body, a sole 6 mm off left
    the stability and the first posture threw the CoM 10 cm onto the other sole (1.6 m/s^2: the robot
    tipped over its toes, services/contacts/README.md)."""
    return sorted({c.spot for c in s2 if c not in s1} | {c.spot for c in released})


def _moving_spots(gen: PostureGenerator, spots: Sequence[str], q1: np.ndarray, q2: np.ndarray) -> list[str]:
    """The spots among ``spots`` that move more than 5 mm between q1 and q2, the one moving most first."""
    moves = [
        (float(np.linalg.norm(gen.spot_pose(q1, s).translation - gen.spot_pose(q2, s).translation)), s)
        for s in spots
    ]
    return [s for d, s in sorted(moves, reverse=True) if d > 5e-3]


def _moving_spot(gen: PostureGenerator, spots: Sequence[str], q1: np.ndarray, q2: np.ndarray) -> str | None:
    """The spot in (or about to be in) contact that moves most between q1 and q2 (> 5 mm), if any."""
    moving = _moving_spots(gen, spots, q1, q2)
    return moving[0] if moving else None


def held_frames(
    gen: PostureGenerator,
    s1: ContactSet,
    s2: ContactSet,
    released: ContactSet,
    q1: np.ndarray,
    q2: np.ndarray,
) -> list[str]:
    """The spot frames held in place during the transition from q1 to q2: every contact of S1 but the
    moving body's, and only those whose spot moves less than 5 mm between q1 and q2 (``hold.py`` keeps
    them in place at every sample)."""
    moving = _moving_spot(gen, moving_candidates(s1, s2, released), q1, q2)

    def still(spot: str) -> bool:
        shift = gen.spot_pose(q1, spot).translation - gen.spot_pose(q2, spot).translation
        return bool(np.linalg.norm(shift) < 5e-3)

    return [gen.spots[c.spot].frame_name for c in s1 if c.spot != moving and still(c.spot)]


def _on_surface(gen: PostureGenerator, T: pin.SE3) -> np.ndarray | None:
    """The outer normal of a surface the frame ``T`` lies on (within 5 mm and 0.1 rad), if any."""
    for surface in gen.env.surfaces:
        height, tilt, inside = spot_surface_gap(T, gen.env, surface.name)
        if abs(height) < 5e-3 and tilt < 0.1 and inside:
            return surface.T_world_surface.rotation[:, 2].copy()
    return None


RISE_M = 0.05  # a body coming onto a surface this much higher goes over its edge (_over_the_edge)
EDGE_CLEARANCE_M = 0.12  # height above the surface the body passes at [m] (a hand capsule's radius + margin)
RISE_FORWARD = 0.5  # the rise reaches that height this fraction of the way across (_over_the_edge)


def _over_the_edge(
    T1: pin.SE3, T2: pin.SE3, a: np.ndarray, n2: np.ndarray, n: int, detour_m: tuple[float, float]
) -> list[pin.SE3]:
    """n frames onto a surface higher than the body (a hand from hanging to a table's top): straight up
    to ``EDGE_CLEARANCE_M`` above the surface's level, across, then straight down along its normal; a
    Hermite chord from below would cut the surface's edge, and the posture generator's collision
    constraints then hold the body under the edge until the witness makes it jump through (§4)."""
    p2 = T2.translation
    above = p2 + EDGE_CLEARANCE_M * n2
    # up and forward at once, to the level above the surface halfway across (a surface is reached near
    # its edge, past the halfway point): straight up from a hand beside the thigh, the posture
    # generator pulled the body 17 cm back and the chest struck the chair's backrest (session 9)
    mid = a[:2] + RISE_FORWARD * (above[:2] - a[:2])
    rise = np.array([mid[0], mid[1], above[2]])
    points = [T1.translation, a, rise, above, p2]
    chord = (above - rise)[:2]
    across = np.array([-chord[1], chord[0], 0.0]) / max(float(np.linalg.norm(chord)), 1e-9)
    bend = detour_m[0] * across + np.array([0.0, 0.0, detour_m[1]])
    points[2:4] = [rise + 0.5 * bend, above + 0.5 * bend] if np.any(bend) else points[2:4]
    lengths = np.array([np.linalg.norm(points[k + 1] - points[k]) for k in range(len(points) - 1)])
    total = max(float(lengths.sum()), 1e-9)
    cumulative = np.concatenate([[0.0], np.cumsum(lengths)])
    r1, r2 = pin.Quaternion(T1.rotation), pin.Quaternion(T2.rotation)
    out = []
    for i in range(n):
        s = (i + 1) / n * total
        k = min(int(np.searchsorted(cumulative, s, side="right")) - 1, len(lengths) - 1)
        u = (s - cumulative[k]) / max(float(lengths[k]), 1e-12)
        p = points[k] + min(u, 1.0) * (points[k + 1] - points[k])
        out.append(pin.SE3(r1.slerp(s / total, r2).toRotationMatrix(), np.asarray(p, float)))
    return out


def spot_path(
    gen: PostureGenerator,
    T1: pin.SE3,
    T2: pin.SE3,
    n: int,
    lift_m: float,
    detour_m: tuple[float, float] = (0.0, 0.0),
) -> list[pin.SE3]:
    """n frames from T1 to T2 (§3.3): straight out along the normal when T1 is on a surface, straight in
    along the normal when T2 is, a C1 cubic (Hermite) between, orientation by slerp (a surface higher
    than the body is reached over its edge: :func:`_over_the_edge`). ``detour_m``
    (sideways, up) [m] bends the cubic by that much at its middle (sin(pi u) profile): sideways is
    horizontal, across the chord (a path around an obstacle, §4)."""
    n1, n2 = _on_surface(gen, T1), _on_surface(gen, T2)
    p1, p2 = T1.translation, T2.translation
    a = p1 + (lift_m * n1 if n1 is not None else 0.0)
    if n2 is not None and p2[2] > a[2] + RISE_M:
        return _over_the_edge(T1, T2, a, n2, n, detour_m)
    b = p2 + (lift_m * n2 if n2 is not None else 0.0)
    span = max(float(np.linalg.norm(b - a)), 1e-6)
    # Hermite tangents: along the normals at the ends of the straight lines (C1 junctions)
    # a body leaving no surface (a hand hanging) first rises: a straight chord to a table's top would
    # run into its edge from below
    up = np.array([0.0, 0.0, 1.0])
    ta = (n1 if n1 is not None else (up if b[2] > a[2] else (b - a) / span)) * span
    tb = (-n2 if n2 is not None else (b - a) / span) * span
    chord = (b - a)[:2]
    across = np.array([-chord[1], chord[0], 0.0]) / max(float(np.linalg.norm(chord)), 1e-9)
    bend = detour_m[0] * across + detour_m[1] * up
    lengths = [lift_m if n1 is not None else 0.0, span, lift_m if n2 is not None else 0.0]
    total = sum(lengths)
    out = []
    q1, q2 = pin.Quaternion(T1.rotation), pin.Quaternion(T2.rotation)
    for i in range(n):
        s = (i + 1) / n * total
        if s <= lengths[0]:
            p = p1 + s * n1
            r = q1
        elif s <= lengths[0] + lengths[1]:
            u = (s - lengths[0]) / lengths[1]
            h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
            h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
            p = h00 * a + h10 * ta + h01 * b + h11 * tb + math.sin(math.pi * u) * bend
            r = q1.slerp(u, q2)
        else:
            p = b - (s - lengths[0] - lengths[1]) * n2
            r = q2
        out.append(pin.SE3(r.toRotationMatrix(), np.asarray(p, float)))
    return out


def path_mask(spot: str) -> tuple[bool, ...]:
    """The components of a moving spot's path C_i the interpolation follows: a hand's position only (a
    fist kept pointing down while it is raised over a table's edge is beyond the arm's joint limits: the
    6-D path held the hand under the edge), the whole pose of other spots (a sole stays level)."""
    return (True, True, True, False, False, False) if spot.endswith("_hand") else (True,) * 6


def stands_on(gen: PostureGenerator, contacts: ContactSet, q: np.ndarray, margin_m: float) -> bool:
    """Whether the CoM at ``q`` is at least ``margin_m`` [m] inside the static-equilibrium region of
    ``contacts`` (§2.2, :meth:`PostureGenerator.region`; a region of fewer than 3 vertices: False)."""
    region = gen.region(contacts)
    if region.shape[0] < 3:
        return False
    com = pin.centerOfMass(gen.model, gen.data, np.asarray(q, float))
    return bool(signed_distance(com[:2], region)[0] <= -margin_m)


def stability_contacts(
    gen: PostureGenerator,
    stable: ContactSet,
    q1: np.ndarray,
    q2: np.ndarray,
    config: InterpolationConfig,
) -> list[ContactSet]:
    """The stability sets to try for the n postures of a transition, in order: ``stable`` (§3.3: the
    contacts held during the motion), preceded, when ``config.arms_as_helpers`` and both witnesses q1,
    q2 stand on the contacts other than the arms' (``config.helpers_end_margin_m`` inside their
    region), by those. During a swing on one sole with a hand on the table, postures stable with the
    hand drifted the CoM 6-9 cm toward the stance sole's outer edge while the sim's hand carried
    0-131 N, and the robot tipped over that edge (services/contacts/README.md, session 9)."""
    unassisted = tuple(c for c in stable if c.spot not in ARM_SPOTS)
    if not (config.arms_as_helpers and unassisted and len(unassisted) < len(stable)):
        return [stable]
    margin = config.helpers_end_margin_m
    if stands_on(gen, unassisted, q1, margin) and stands_on(gen, unassisted, q2, margin):
        return [unassisted, stable]
    return [stable]


def transition(
    gen: PostureGenerator,
    s1: ContactSet,
    q1: np.ndarray,
    s2: ContactSet,
    q2: np.ndarray,
    geometric_extra: ContactSet,
    config: InterpolationConfig,
    detour_m: tuple[float, float] = (0.0, 0.0),
    lead: float = 1.0,
) -> list[np.ndarray]:
    """The n postures from q1 to q2 (q2 last). ``geometric_extra``: a contact removed at the previous
    transition, still in place at q1 (its body leaves it now). Raises InfeasibleError naming the step."""
    pairs1 = {c.pair: c for c in (*s1, *geometric_extra)}
    candidates = moving_candidates(s1, s2, geometric_extra)
    moving = _moving_spot(gen, candidates, q1, q2)
    # held: every contact in place at q1 that stays in place at q2 (a contact removed at this
    # transition is still there at q2, §2.3: it is released at q2)
    held = tuple(
        c
        for c in pairs1.values()
        if c.spot != moving
        and np.linalg.norm(gen.spot_pose(q2, c.spot).translation - gen.contact_pose(c).translation) < 5e-3
    )
    stable_sets = stability_contacts(gen, tuple(c for c in s1 if c in held) or held, q1, q2, config)
    # the body moving most gets its path (bent by a detour if asked), and so does an arm's spot moving
    # besides it: a hand released at the previous transition leaves the table while the other comes
    # onto it, and unguided it went 2 cm into the table's underside. (A released thigh rises with the
    # whole body: a path of its own changed the rise, and the rise fell.)
    paths: dict[str, list[pin.SE3]] = {}
    for spot in _moving_spots(gen, candidates, q1, q2):
        if spot != moving and spot not in ARM_SPOTS:
            continue
        T1, T2 = gen.spot_pose(q1, spot), gen.spot_pose(q2, spot)
        bend = detour_m if spot == moving else (0.0, 0.0)
        paths[spot] = spot_path(gen, T1, T2, config.n, config.lift_m, bend)
    # the moving body may touch the surface it leaves during the first step and the one it enters
    # during the last (within the straight lines along the normal); elsewhere it must clear them
    leaving = [c.pair for c in pairs1.values() if c.spot == moving]
    entering = [c.pair for c in s2 if c.spot == moving]
    # a contact released now that is not the moving body's: its body leaves the surface with the
    # interpolated posture (it touches it at q1: a collision margin there would fight the held contacts)
    released = [c.pair for c in geometric_extra if c not in held and c.spot != moving]
    failure: InfeasibleError | None = None
    for stable in stable_sets:
        out: list[np.ndarray] = []
        q = q1.copy()
        for i in range(1, config.n + 1):
            budget.check(f"the interpolation's posture {i} of {config.n}")
            q_ref = pin.interpolate(gen.model, q1, q2, min(1.0, lead * i / config.n))
            extra = [
                FramePoseTask(
                    gen.model,
                    gen.spots[spot].frame_name,
                    frames[i - 1],
                    max_step=0.1,
                    name=f"C_{i}:{spot}",
                    mask=path_mask(spot),
                )
                for spot, frames in paths.items()
            ]
            touching = (leaving if i <= 1 else []) + (entering if i >= config.n - 1 else []) + released
            result = gen.generate(
                held,
                stable,
                q,
                PostureTask(gen.model, q_ref),
                guide=extra,
                extra_touching=touching,
                config=config.posture,
            )
            if not result.ok:
                failure = InfeasibleError(
                    f"interpolation step {i}/{config.n} from {[c.describe() for c in s1]} to "
                    f"{[c.describe() for c in s2]} failed: {result.reason}",
                    {"step": i, "moving_spot": moving or ""},
                )
                break
            q = result.q
            out.append(q)
        else:
            return out
    assert failure is not None
    raise failure


def timed_segment(
    gen: PostureGenerator,
    waypoints: np.ndarray,
    config: InterpolationConfig,
    v_max: np.ndarray,
    held: Sequence[str] = (),
) -> np.ndarray:
    """Samples every ``config.dt_s`` of the discrete path ``waypoints`` (``services.contacts.timing``):
    knots spaced by each interval's time at the quasi-static speed limits, the sinusoidal profile over
    twice their sum (at least ``min_segment_s``), slowed down while the needed ZMP leaves the CoM's
    projection by more than ``zmp_shift_m``; joints clipped to their limits (a cubic through postures
    at a limit can overshoot it by a hair); the ``held`` spot frames kept in place at every sample
    when ``config.hold_contacts`` (``hold.py``)."""
    times = interval_times(gen.model, waypoints, config.base_speed_m_s, config.joint_speed_ratio * v_max[6:])
    u = knots(times)
    duration = max(config.min_segment_s, 2.0 * float(times.sum()))
    bound = gen.solver.bound_q_idx
    for attempt in range(ZMP_SLOWDOWNS + 1):
        budget.check(f"the interpolation's timing, try {attempt + 1}")
        q = time_segment(gen.model, waypoints, duration, config.dt_s, u)
        q[:, bound] = q[:, bound].clip(gen.solver.q_lower[bound], gen.solver.q_upper[bound])
        if config.hold_contacts and held:
            q, _ = hold_spots(gen.model, held, q, bound, gen.solver.q_lower, gen.solver.q_upper)
        shift = float(zmp_shift(gen.model, q, config.dt_s, config.check_every).max())
        if shift <= config.zmp_shift_m or attempt == ZMP_SLOWDOWNS:
            return q
        duration *= 1.05 * math.sqrt(min(shift, 100.0) / config.zmp_shift_m)
    return q


# local re-planning of a colliding transition (§4): twice the postures, then detours of the moving
# body's path: (sideways [m], up [m]) at mid-path, sideways = horizontal, across the path's chord
# ``lead``: the reference posture runs ahead of the moving body (the torso leans before the hand
# comes over a table's edge)
DETOURS_M = ((0.0, 0.0), (0.12, 0.0), (-0.12, 0.0), (0.0, 0.12), (0.25, 0.0), (-0.25, 0.0))
# (postures x config.n, detour, lead) in order
TRIES = (
    (1, (0.0, 0.0), 1.0),
    (2, (0.0, 0.0), 1.0),
    (2, (0.0, 0.0), 2.0),
    *((2, d, 1.0) for d in DETOURS_M[1:]),
)


def interpolate_transition(
    gen: PostureGenerator,
    s1: ContactSet,
    q1: np.ndarray,
    s2: ContactSet,
    q2: np.ndarray,
    removed: ContactSet,
    config: InterpolationConfig,
    v_max: np.ndarray,
) -> tuple[np.ndarray, list[np.ndarray], tuple[float, str, str, int] | None, int]:
    """One transition, timed and checked (§3.3, §4): (samples every dt from q1 to q2, the discrete path,
    the deepest collision of the samples or None, local re-plannings done). A segment closer than
    ``config.clearance_m`` to a box (or whose posture generation fails) is re-planned locally:
    with twice the postures, with the reference posture leading, then with the moving body's path bent
    around (``TRIES``), at most
    ``config.max_refinements`` times; the least colliding try is returned with its collision, or
    InfeasibleError when every try failed."""
    # held contacts: their objects are excluded; a body that leaves or comes: only its surface's box
    touching = [c.pair for c in s1 if c in s2]
    moving = [c.pair for c in (*s1, *s2, *removed) if c.pair not in touching]
    tries = [(k * config.n, detour, lead) for k, detour, lead in TRIES]
    best: tuple[float, np.ndarray, list[np.ndarray], tuple[float, str, str, int] | None] | None = None
    failure: InfeasibleError | None = None
    refinements = 0
    for attempt, (n, detour, lead) in enumerate(tries[: config.max_refinements + 1]):
        budget.check(f"the interpolation's re-planning try {attempt + 1} (collision or failed posture)")
        # the last posture generated aims at q2; the witness itself (stable and collision free by
        # construction) ends the segment, so that the next one starts exactly there
        try:
            generated = transition(gen, s1, q1, s2, q2, removed, replace(config, n=n), detour, lead)
        except InfeasibleError as exc:
            failure = failure or exc
            refinements += 1
            continue
        path = [q1, *generated[:-1], q2]
        segment = np.array(path)
        timed = timed_segment(gen, segment, config, v_max, held_frames(gen, s1, s2, removed, q1, q2))
        hit = deepest_collision(gen, timed, touching, config.check_every, moving, config.clearance_m)
        depth = -config.clearance_m if hit is None else hit[0]
        if best is None or depth < best[0]:
            best = (depth, timed, path, hit)
        if depth <= -config.clearance_m:  # clear of every box by the clearance
            break
        refinements += 1
    if best is None:
        assert failure is not None
        raise failure
    return best[1], best[2], best[3], refinements


def interpolate_plan(
    gen: PostureGenerator,
    sets: Sequence[ContactSet],
    witnesses: Sequence[np.ndarray],
    config: InterpolationConfig | None = None,
) -> Motion:
    """The whole motion through the plan's sets and witness postures."""
    config = config or InterpolationConfig()
    t0 = time.perf_counter()
    v_max = np.asarray(gen.robot.v_max, float)
    samples = [np.asarray(witnesses[0], float)[None]]
    set_samples = [0]
    waypoints = [np.asarray(witnesses[0], float)]
    count = 1
    removed: ContactSet = ()
    collisions: list[SegmentCollision] = []
    refinements = 0
    for k in range(1, len(sets)):
        s1, s2 = sets[k - 1], sets[k]
        q1, q2 = np.asarray(witnesses[k - 1], float), np.asarray(witnesses[k], float)
        try:
            timed, path, hit, refined = interpolate_transition(gen, s1, q1, s2, q2, removed, config, v_max)
        except RequestTimeoutError as exc:
            raise RequestTimeoutError(
                f"{exc.message} (interpolating transition {k} of {len(sets) - 1})",
                {**exc.details, "transitions_done": k - 1},
            ) from exc
        refinements += refined
        if hit is not None and hit[0] > config.collision_tol_m:
            collisions.append(SegmentCollision(k, hit[0], hit[1], hit[2], count + hit[3] - 1))
        removed = tuple(c for c in s1 if c not in s2)
        samples.append(timed[1:])
        count += len(timed) - 1
        set_samples.append(count - 1)
        waypoints.extend(path[1:])
    return Motion(
        np.concatenate(samples),
        config.dt_s,
        set_samples,
        np.array(waypoints),
        time.perf_counter() - t0,
        tuple(collisions),
        refinements,
    )


def deepest_collision(
    gen: PostureGenerator,
    q: np.ndarray,
    touching: Sequence[tuple[str, str]],
    every: int = 1,
    moving: Sequence[tuple[str, str]] = (),
    clearance_m: float = 0.0,
) -> tuple[float, str, str, int] | None:
    """The deepest penetration (depth [m] > -``clearance_m``, capsule, box, sample index) of the robot's
    capsules into the scene's boxes over the samples ``q[::every]`` (and the last one), the objects of
    the ``touching`` (spot, surface) pairs excluded for their spots, and for the ``moving`` pairs only the
    surface's own box (:meth:`PostureGenerator.box_pairs`); None if every sample stays ``clearance_m``
    away (a negative depth: closer than the clearance, not into the box)."""
    pairs = gen.box_pairs(touching, moving)
    if not pairs:
        return None
    task = CapsuleBoxTask(gen.model, gen.capsules, gen.boxes, pairs)
    data = gen.model.createData()
    worst: tuple[float, str, str, int] | None = None
    indices = sorted({*range(0, len(q), max(1, every)), len(q) - 1})
    for n, i in enumerate(indices):
        if n % BUDGET_CHECK_SAMPLES == 0:
            budget.check(f"the interpolation's collision check, sample {i} of {len(q)}")
        pin.framesForwardKinematics(gen.model, data, q[i])
        d = task.distances(data)
        j = int(np.argmin(d))
        if d[j] < clearance_m and (worst is None or -d[j] > worst[0]):
            c, b = pairs[j]
            worst = (float(-d[j]), gen.capsules[c].name, gen.boxes[b].name, i)
    return worst
