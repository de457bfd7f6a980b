"""Executing a contact plan set by set, re-planning each transition from the measured state.

A quasi-static plan played open loop by position control does not hold: the supports slide a few
centimetres under the internal forces of the closed kinematic loops (hands on the table, soles on the
floor, thighs on the seat), and a posture whose CoM is 2-4 cm inside its support then tips (the traces
in ``services/contacts/README.md``). The feedback here works at the level of the plan: after each
transition the measured configuration is read, every contact held is re-read where its spot now is,
the next witness posture is generated again for those contacts (the same posture generator as the
search, §2.2, with the planned witness as the reference posture), and the transition to it is
interpolated from the measured configuration (§3.3) and played. Errors do not accumulate: each witness
is statically stable on the supports as they are, not as they were planned.

The executor is given as callables (the sim in one process, or ``sim/execute`` over the bus), so this
module imports neither pybullet nor zenoh.

Each transition also names the joints to play with a reduced effort (``ReplannedTransition.
effort_scale``): the limb of every hand or forearm in contact from the transition's start (a hand
coming onto the table keeps its full effort: at 60 % the reaching arm, catching the table's edge,
tipped the robot over in the rise), at
``SUPPORT_EFFORT_SCALE`` of its effort limits. Position control makes the loop floor - stance leg -
body - arm - table rigid: its internal forces are set by millimetre errors, not by the plan, and with
full effort the arm pushed the table with 300-500 N (the plan needed about 120 N) until its shoulder and
wrist reached their limits and the stance sole's centre of pressure ran to its heel
(services/contacts/README.md, session 8). With the arm capped it yields first and the legs carry the
rest, as the plan's equilibrium allows.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from services import budget
from services.contacts.contact_forces import force_targets
from services.contacts.defaults import LIMB_LOAD
from services.contacts.environment import Environment
from services.contacts.interpolate import InterpolationConfig, interpolate_transition
from services.contacts.limb_load import limb_joints
from services.contacts.posture import (
    ARM_SPOTS,
    Floating,
    PostureConfig,
    PostureGenerator,
    posture_config,
)
from services.contacts.sets import Contact, ContactSet, contact_at
from services.contacts.spots import robot_spots
from services.contacts.volumes import around
from services.errors import InfeasibleError
from services.ik import PostureTask
from services.model import RobotModel
from sim.force_target import ForceTarget

# plays (N, nq) samples every dt [s] with the joints' effort scales (name -> fraction of the limit) and
# the arms' force targets (sim.compliance); returns (outcome, message): outcome "completed" goes on
PlaySegment = Callable[[np.ndarray, float, dict[str, float], tuple[ForceTarget, ...]], tuple[str, str]]
Measure = Callable[[], np.ndarray]  # the measured configuration q (pinocchio layout, world base)
StepHook = Callable[["TransitionReport"], None]


@dataclass(frozen=True)
class TransitionReport:
    """One transition played: ``index`` (to set ``index``), the executor's ``outcome`` and ``message``
    ("infeasible": no witness from the measured supports, nothing played), whether the witness was
    generated again from the measured supports (``replanned``), what went wrong (``reason``: the
    posture generator's, or a segment still colliding after local re-planning), the largest distance
    [m] between a held contact's measured and planned place (``support_error_m``), samples played and
    the wall time of re-planning [s]."""

    index: int
    outcome: str
    message: str
    replanned: bool
    reason: str
    support_error_m: float
    samples: int
    replan_s: float


@dataclass
class ClosedLoopResult:
    """The whole run: ``outcome`` of the last transition played ("completed" when all were), its
    message, the per-transition reports, total samples and re-planning time [s]."""

    outcome: str
    message: str
    transitions: list[TransitionReport] = field(default_factory=list)
    samples: int = 0
    replan_s: float = 0.0


REREAD_M = 0.01  # a held contact is re-read where its spot is when it slid more than this [m]
# a regenerated witness: contacts matched within 5 mm (the sim's contacts comply by that much), more
# iterations (it starts from a measured posture a few cm off)
REGENERATE_TOL_M = 5e-3
REGENERATE_ITERS = 150
# one contact holding the robot (a sole): the CoM this far inside its region [m] in an execution's
# postures (the search's 4 cm: a swing in single support drifted the CoM 5-8 cm outboard)
SINGLE_SUPPORT_MARGIN_M = 0.055
# any contacts holding the robot: the CoM this far inside their region [m] in an execution's postures
# (the search's 2 cm: rising from the chair on the soles alone, the sim leaned 5 deg more than the
# witness, 3.2 cm from the toes' edge, the CoM ran 2.8 cm further forward and the robot tipped onto its
# toes as it left the seat)
EXECUTION_COM_MARGIN_M = 0.055
# the effort of an arm in contact (hand or forearm) during a transition, as a fraction of its limits
SUPPORT_EFFORT_SCALE = 0.6
# a regenerated witness is first sought statically stable on the contacts other than the arms' (the
# hands and forearms in contact kept as geometry, helpers): on the chair egress the sim's hand carried
# 30-50 N where the plan needed 173 N, and the robot, its CoM past its stance sole's edge, tipped over
PREFER_UNASSISTED = True
# likewise the postures of a transition: statically stable without the arms in contact when both of
# its ends are (interpolate.stability_contacts): during a swing on one sole, postures stable with the
# hand drifted the CoM 6-9 cm outboard while the sim's hand carried 0-131 N, and the robot tipped over
ARMS_AS_HELPERS = True
# a new contact the measured supports do not admit where it was planned is searched again in this
# volume around its planned place (x [m], y [m], theta [rad] half sizes)
FLOAT_HALF = (0.05, 0.05, 0.25)


def execution_generator(robot: RobotModel, env: Environment, limb_load: bool = LIMB_LOAD) -> PostureGenerator:
    """The posture generator of an execution (every contact spot of ``robot`` in ``env``, the arms'
    limb-load bound on or off). Its QPs are the dual active-set method's, reset at every generation
    (:class:`PostureGenerator`): the same plan played from the same state re-plans every transition
    identically, so a run can be replayed and a fall analysed (with proxsuite, two replays of one plan
    parted after transition 2)."""
    return PostureGenerator(robot, env, robot_spots(robot), posture_config(limb_load))


def measured_contacts(
    gen: PostureGenerator, planned: ContactSet, q: np.ndarray, min_slip_m: float = REREAD_M
) -> ContactSet:
    """The contacts of ``planned`` re-read where their spots are at ``q`` (projected on their surfaces)
    when they slid more than ``min_slip_m`` [m]; the others as planned (a few mm are the contact's
    compliance and the tracking error, and a posture generation from a spot a few mm off its surface,
    tilted, can fail to match it)."""
    out = []
    for c in planned:
        measured = contact_at(gen.spots[c.spot], c.surface, gen.env, gen.spot_pose(q, c.spot))
        slip = np.linalg.norm(gen.contact_pose(measured).translation - gen.contact_pose(c).translation)
        out.append(measured if slip > min_slip_m else c)
    return tuple(out)


def support_effort_scale(gen: PostureGenerator, contacts: Sequence[Contact]) -> dict[str, float]:
    """The joints of the limb (``limb_load.limb_joints``) of every hand or forearm among ``contacts``,
    at ``SUPPORT_EFFORT_SCALE`` (module docstring)."""
    out: dict[str, float] = {}
    for c in contacts:
        if c.spot not in ARM_SPOTS:
            continue
        frame = gen.model.frames[gen.model.getFrameId(gen.spots[c.spot].frame_name)]
        for j in limb_joints(gen.model, frame.parentJoint):
            out[gen.model.names[j]] = SUPPORT_EFFORT_SCALE
    return out


def _support_error(gen: PostureGenerator, planned: ContactSet, q: np.ndarray) -> float:
    """Largest distance [m] between a planned contact's place and where its spot is at ``q``."""
    errors = [
        float(np.linalg.norm(gen.spot_pose(q, c.spot).translation - gen.contact_pose(c).translation))
        for c in planned
    ]
    return max(errors, default=0.0)


def _relaxed(gen: PostureGenerator) -> PostureConfig:
    """The generator's settings with contacts matched within ``REGENERATE_TOL_M`` in at most
    ``REGENERATE_ITERS`` iterations (postures generated from a measured state), the CoM
    ``EXECUTION_COM_MARGIN_M`` inside the support region (``SINGLE_SUPPORT_MARGIN_M`` on one contact)."""
    return replace(
        gen.config,
        tol=REGENERATE_TOL_M,
        max_iters=REGENERATE_ITERS,
        com_margin_m=max(gen.config.com_margin_m, EXECUTION_COM_MARGIN_M),
        single_contact_margin_m=max(gen.config.single_contact_margin_m, SINGLE_SUPPORT_MARGIN_M),
    )


def regenerate_witness(
    gen: PostureGenerator,
    s1_planned: ContactSet,
    s2_planned: ContactSet,
    q2_planned: np.ndarray,
    q_measured: np.ndarray,
) -> tuple[ContactSet, ContactSet, np.ndarray | None, str]:
    """(s1 measured, s2 with its held contacts measured, the new witness or None, why not): the son's
    rule of the search (§2.3): a removal keeps the removed contact as geometry with the stability on the
    rest; an addition puts the new contact (at its planned place) out of the stability. Tries, in order:
    0 (``PREFER_UNASSISTED``, when arms are in contact) a witness statically stable without the arms
    (kept as geometry), from the measured posture, then (an addition) with the new contact placed by
    the posture generator within ``FLOAT_HALF`` of its planned place (§2.6's floating contact,
    :func:`_new_contact_moved`); 1 the stability on all the contacts from the measured posture; 2 from
    the planned witness; 3 (an addition) the new contact moved as in try 0. When all fail, the planned
    sets and witness are returned with the reason (the transition then drags the slid supports back, as
    the open-loop replay does). The request's time budget (:mod:`services.budget`) is checked before
    each posture generation (RequestTimeoutError)."""
    s1 = measured_contacts(gen, s1_planned, q_measured)
    by_pair = {c.pair: c for c in s1}
    s2 = tuple(by_pair.get(c.pair, c) for c in s2_planned)
    added = [c for c in s2 if c.pair not in by_pair]
    geometric = s1 + tuple(added)
    stable = s1 if added else s2
    reference = PostureTask(gen.model, q2_planned)
    reasons = []
    relaxed = _relaxed(gen)
    unassisted = tuple(c for c in stable if c.spot not in ARM_SPOTS)
    if PREFER_UNASSISTED and unassisted and len(unassisted) < len(stable):
        # the arms in contact as helpers: a witness statically stable without them, if there is one
        budget.check("the witness's regeneration, try 0 (stable without the arms)")
        result = gen.generate(geometric, unassisted, q_measured, reference, config=relaxed)
        if result.ok:
            return s1, s2, result.q, ""
        if added:
            try_0 = "try 0 (the new contact moved)"
            moved, q, _why = _new_contact_moved(
                gen, s1, s2, added[0], unassisted, q_measured, reference, relaxed, try_0
            )
            if q is not None:
                return s1, moved, q, ""
    for k, start in enumerate((q_measured, q2_planned)):
        budget.check(f"the witness's regeneration, try {k + 1}")
        result = gen.generate(geometric, stable, start, reference, config=relaxed)
        if result.ok:
            return s1, s2, result.q, ""
        reasons.append(result.reason)
    if added:
        new = added[0]
        moved, q, why = _new_contact_moved(
            gen, s1, s2, new, s1, q_measured, reference, relaxed, "try 3 (the new contact moved)"
        )
        if q is not None:
            return s1, moved, q, ""
        reasons.append(f"{new.spot} within {FLOAT_HALF} of its place: {why}")
    if s1 != tuple(s1_planned):
        reason = f"no witness for the supports where they slid ({'; '.join(reasons)}): the planned one"
        return tuple(s1_planned), tuple(s2_planned), np.asarray(q2_planned, float), reason
    tried = ("from the measured posture", "from the planned one", "the new contact moved")
    return s1, s2, None, "; ".join(f"{t}: {r}" for t, r in zip(tried, reasons, strict=False))


def _new_contact_moved(
    gen: PostureGenerator,
    s1: ContactSet,
    s2: ContactSet,
    new: Contact,
    stable: ContactSet,
    q_measured: np.ndarray,
    reference: PostureTask,
    config: PostureConfig,
    attempt: str,
) -> tuple[ContactSet, np.ndarray | None, str]:
    """The witness of an addition with the new contact ``new`` placed by the posture generator within
    ``FLOAT_HALF`` of its planned place (§2.6's floating contact), statically stable on ``stable``,
    from the measured posture: (s2 with the new contact where it was put, the witness, "") or (s2, None,
    the posture generator's reason). ``attempt`` names the try in the budget's timeout message."""
    budget.check(f"the witness's regeneration, {attempt}")
    floating = Floating(new.spot, new.surface, around((new.x, new.y, new.theta), FLOAT_HALF))
    result = gen.generate(s1, stable, q_measured, reference, floating, config=config)
    if result.ok and result.contact is not None:
        return tuple(result.contact if c.pair == new.pair else c for c in s2), result.q, ""
    return s2, None, result.reason


@dataclass(frozen=True)
class ReplannedTransition:
    """A transition re-planned from the measured state: the samples (``q``, every ``dt_s``, the first
    at the measured configuration), the new ``witness``, the largest distance [m] between a held
    contact's measured and planned place, and a segment still colliding after local re-planning
    or a fallback to the planned witness (``collision``: what was played anyway, "" if nothing), and
    the joints to play with a reduced effort (``effort_scale``, module docstring), and the arms'
    planned contact forces when ``InterpolationConfig.force_control`` is on (``force_targets``)."""

    q: np.ndarray
    dt_s: float
    witness: np.ndarray
    support_error_m: float
    collision: str
    effort_scale: dict[str, float] = field(default_factory=dict)  # joints played with less effort
    force_targets: tuple[ForceTarget, ...] = ()  # the arms' planned contact forces (contact_forces.py)


def replan_transition(
    gen: PostureGenerator,
    s1_planned: ContactSet,
    s2_planned: ContactSet,
    q2_planned: np.ndarray,
    q_measured: np.ndarray,
    released_planned: ContactSet = (),
    config: InterpolationConfig | None = None,
) -> ReplannedTransition:
    """The transition from set ``s1_planned`` (holding at ``q_measured``) to ``s2_planned`` (planned
    witness ``q2_planned``) from the measured state (module docstring); ``released_planned``: the
    contacts removed at the previous transition (their bodies leave them now). Raises InfeasibleError
    when the measured supports admit no witness of the next set, or an interpolation step fails."""
    config = config or InterpolationConfig()
    # from a measured posture the held contacts are matched within the sim's compliance, as the witness
    config = replace(
        config,
        posture=config.posture or _relaxed(gen),
        arms_as_helpers=config.arms_as_helpers or ARMS_AS_HELPERS,
    )
    q1 = np.asarray(q_measured, float)
    s1, s2, q2, reason = regenerate_witness(gen, s1_planned, s2_planned, np.asarray(q2_planned, float), q1)
    error = _support_error(gen, s1_planned, q1)
    if q2 is None:
        raise InfeasibleError(
            f"no witness of the next set from the measured supports (off the plan by up to "
            f"{error * 100:.1f} cm): {reason}",
            {"support_error_m": error},
        )
    released = measured_contacts(gen, released_planned, q1)
    v_max = np.asarray(gen.robot.v_max, float)
    timed, _path, hit, _refined = interpolate_transition(gen, s1, q1, s2, q2, released, config, v_max)
    collision = reason  # a fallback to the planned witness, if any
    if hit is not None and hit[0] > config.collision_tol_m:
        segment = f"segment {hit[0] * 100:.1f} cm into {hit[2]} ({hit[1]})"
        collision = f"{collision}; {segment}" if collision else segment
    scale = support_effort_scale(gen, s1)  # held from q1 (a contact made now: its arm still moves)
    targets = force_targets(gen, s1, s2, timed, config.dt_s) if config.force_control else ()
    return ReplannedTransition(timed, config.dt_s, q2, error, collision, scale, targets)


def execute_set_by_set(
    gen: PostureGenerator,
    sets: Sequence[ContactSet],
    witnesses: Sequence[np.ndarray],
    play: PlaySegment,
    measure: Measure,
    config: InterpolationConfig | None = None,
    on_transition: StepHook | None = None,
) -> ClosedLoopResult:
    """Play the plan (``sets`` and their ``witnesses``) transition by transition, each re-planned from
    the measured state (module docstring). Stops at the first transition that cannot be re-planned
    (outcome "infeasible", nothing played) or that the executor does not complete."""
    config = config or InterpolationConfig()
    out = ClosedLoopResult("completed", f"played {len(sets) - 1} transitions")
    released: ContactSet = ()
    for k in range(1, len(sets)):
        t0 = time.perf_counter()
        try:
            step = replan_transition(gen, sets[k - 1], sets[k], witnesses[k], measure(), released, config)
        except InfeasibleError as exc:
            message = f"transition {k} of {len(sets) - 1}: {exc}"
            error = float(exc.details.get("support_error_m", 0.0)) if exc.details else 0.0
            report = TransitionReport(
                k, "infeasible", message, False, str(exc), error, 0, time.perf_counter() - t0
            )
            out.transitions.append(report)
            if on_transition is not None:
                on_transition(report)
            out.outcome, out.message = "infeasible", message
            return out
        replan_s = time.perf_counter() - t0
        outcome, message = play(step.q, step.dt_s, step.effort_scale, step.force_targets)
        report = TransitionReport(
            k, outcome, message, True, step.collision, step.support_error_m, len(step.q), replan_s
        )
        out.transitions.append(report)
        out.samples += len(step.q)
        out.replan_s += replan_s
        if on_transition is not None:
            on_transition(report)
        released = tuple(c for c in sets[k - 1] if c not in sets[k])
        if outcome != "completed":
            out.outcome, out.message = outcome, f"transition {k} of {len(sets) - 1}: {message}"
            return out
    return out
