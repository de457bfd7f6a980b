"""The ``walking`` service: the ZMP preview-control pattern generator (this package) on the bus.

Run: ``python -m services.walking.service`` (common service options: ``--config``, ``--robot``, ``--hub``,
``--log-level``; YAML section ``walking:``, :class:`WalkingConfig`).

Endpoint ``walking/plan`` (:mod:`services.bus.schemas.walking`): footsteps, timing, options and the
robot's starting configuration in; the 5 ms whole-body trajectory, CoM, ZMPs, soles, phases and figures
out. Stateless: the reply is a deterministic function of the request (no wall-clock figures in it; the
planning time is logged). :func:`plan_reply` is the whole adapter without the bus.

Endpoint ``walking/goal``: a goal relative to the stance now (a pose to reach, an angle to turn on the
spot, a stance to square; :mod:`services.walking.goals`) and the map's boxes in; the planner makes the
footsteps within the robot's bounds, checks them against the boxes and plans them as ``walking/plan``
does (:func:`goal_reply`). Kind ``settle``: no step, both soles brought back flat from the measured
configuration (:mod:`services.walking.settle`), the same reply shape. ``infeasible`` replies carry
``details.reason`` (``REASON_*`` of the schema).

Failure codes: ``invalid_request`` (malformed request: unknown model, q of the wrong size, overlapping
soles, a zero duration, a bad upper-body task, q_start and the starting soles more than 5 mm apart);
``infeasible`` (a step beyond the robot's bounds - the message and ``details.step_index`` name it -; a
multibody ZMP still outside the support polygon after the corrections; a joint faster than its limit;
an upper-body task missed by more than its tolerance); ``timeout`` (the request's ``time_budget_s``, or
the service's, ran out: ``details.stage``, ``knots_done``, ``knots``).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from services import budget
from services.bus.limits import MAX_BUDGET_S, check_budget
from services.bus.schemas import walking as msg
from services.bus.service import Service, handles, run_service
from services.collision.obstacles import BoxObstacle, Obstacle, obstacle_from_msg
from services.errors import InfeasibleError, InvalidRequestError
from services.model import load_robot
from services.model.ground import mid_feet
from services.walking.footsteps import (
    SIDES,
    Footstep,
    FootstepBounds,
    FootstepSequence,
    SolePose,
    other_side,
)
from services.walking.goals import (
    MapBox,
    back_and_turn_steps,
    check_clear,
    joined,
    soles_on,
    square_steps,
    turn_steps,
    walk_to_steps,
)
from services.walking.pattern import PatternOptions
from services.walking.settle import SettleMotion, settle_motion
from services.walking.sweep import check_legs_clear
from services.walking.timing import WalkTiming
from services.walking.two_stage import COM_LOWERINGS_M
from services.walking.upper_body import GazeTarget, HandTarget
from services.walking.wholebody import WholeBodyOptions, WholeBodyPlanner, WholeBodyResult, plan_walk

DT_S = 0.005


@dataclass(frozen=True)
class WalkingConfig:
    """Options of the walking service (YAML section ``walking:``).

    Attributes:
        knot_stride: samples between two IK knots of the whole-body stage (1: IK at every 5 ms).
        iterations_per_knot: Gauss-Newton steps of the IK hierarchy per knot (``WholeBodyOptions``).
        preload: robot models loaded at start-up (others are loaded on their first request).
        time_budget_s: wall-clock budget of a request that gives none [s] (at most
            ``services.bus.limits.MAX_BUDGET_S``); past it the reply is ``timeout``.
    """

    knot_stride: int = 8
    iterations_per_knot: int = 2
    preload: tuple[str, ...] = ("hrp2_like",)
    time_budget_s: float = MAX_BUDGET_S

    def __post_init__(self) -> None:
        check_budget(self.time_budget_s, "walking.time_budget_s")
        WholeBodyOptions(
            knot_stride=self.knot_stride, iterations_per_knot=self.iterations_per_knot
        ).validate()


log = logging.getLogger("humanoid.walking")


def _pose(value: Any, name: str) -> SolePose:
    """[x, y, yaw] -> SolePose, else InvalidRequestError naming the field."""
    if not isinstance(value, list | tuple) or len(value) != 3:
        raise InvalidRequestError(f"{name} must be [x, y, yaw] ([m], [m], [rad]), got {value!r}")
    x, y, yaw = (float(v) for v in value)
    if not all(math.isfinite(v) for v in (x, y, yaw)):
        raise InvalidRequestError(f"{name} must be finite numbers, got {value!r}")
    return SolePose(x, y, yaw)


def start_of(request: msg.PlanRequest, robot: Any) -> tuple[np.ndarray, SolePose, SolePose]:
    """(q_start, left sole, right sole) of a request: given, or measured, or half-sitting on the soles."""
    if (request.left_start is None) != (request.right_start is None):
        raise InvalidRequestError("give both left_start and right_start ([x, y, yaw]), or neither")
    left = right = None
    if request.left_start is not None:
        left = _pose(request.left_start, "left_start")
        right = _pose(request.right_start, "right_start")
    if request.q_start is not None:
        q = robot.check_q(request.q_start, "q_start")
    elif left is not None and right is not None:
        yaw = right.yaw_rad + 0.5 * math.remainder(left.yaw_rad - right.yaw_rad, 2.0 * math.pi)
        q = robot.half_sitting_at(0.5 * (left.x_m + right.x_m), 0.5 * (left.y_m + right.y_m), yaw)
    else:
        q = np.array(robot.q_half_sitting)
    if left is None or right is None:
        soles = soles_on(robot, q)
        left, right = soles["left"], soles["right"]
    return q, left, right


def footsteps_of(request: msg.PlanRequest, left: SolePose, right: SolePose) -> FootstepSequence:
    """The footstep sequence of a request (sides alternate from ``first_side`` where not given)."""
    if request.first_side not in SIDES:
        raise InvalidRequestError(f"first_side must be one of {list(SIDES)}, got {request.first_side!r}")
    steps = []
    side = request.first_side
    for i, step in enumerate(request.steps):
        if step.side:
            if step.side not in SIDES:
                raise InvalidRequestError(
                    f"steps[{i}].side must be one of {list(SIDES)} or '', got {step.side!r}"
                )
            side = step.side
        steps.append(Footstep(side, _pose(step.pose, f"steps[{i}].pose")))
        side = other_side(side)
    return FootstepSequence(left, right, tuple(steps))


def _hand(task: msg.HandTask, i: int) -> HandTarget:
    for k, p in enumerate(task.positions_m):
        if len(p) != 3:
            raise InvalidRequestError(f"hands[{i}].positions_m[{k}] must be [x, y, z] [m], got {p!r}")
    return HandTarget(
        side=task.side,
        frame=task.frame,
        times_s=tuple(float(t) for t in task.times_s),
        positions_m=tuple((float(p[0]), float(p[1]), float(p[2])) for p in task.positions_m),
        keep_orientation=task.keep_orientation,
    )


def plan_reply(request: msg.PlanRequest, config: WalkingConfig | None = None) -> msg.PlanReply:
    """Plan the walk of ``request`` (the whole endpoint, without the bus). Raises the typed errors of the
    module docstring."""
    config = config or WalkingConfig()
    robot = load_robot(request.model)
    q_start, left, right = start_of(request, robot)
    footsteps = footsteps_of(request, left, right)
    timing = WalkTiming(
        single_support_s=request.single_support_s,
        double_support_s=request.double_support_s,
        initial_double_support_s=request.initial_double_support_s,
        final_double_support_s=request.final_double_support_s,
        final_hold_s=request.final_hold_s if request.stop_at_end else 0.0,
        initial_hold_s=request.initial_hold_s,
        dt_s=DT_S,
    )
    step_height = robot.params.step_height_m if request.step_height_m is None else request.step_height_m
    options = PatternOptions(
        com_height_m=request.com_height_m,
        step_height_m=float(step_height),
        preview_horizon_s=request.preview_horizon_s,
    )
    wb_options = WholeBodyOptions(
        knot_stride=config.knot_stride,
        iterations_per_knot=config.iterations_per_knot,
        zmp_margin_m=request.zmp_margin_m,
        max_corrections=request.max_corrections,
    )
    for name in ("hand_tolerance_m", "gaze_tolerance_m"):
        value = getattr(request, name)
        if not (math.isfinite(value) and value > 0):
            raise InvalidRequestError(f"{name} must be > 0 m, got {value}")
    hands = [_hand(h, i) for i, h in enumerate(request.hands)]
    gaze = None
    if request.gaze is not None:
        point = tuple(float(v) for v in request.gaze.point_m)
        gaze = GazeTarget(point, request.gaze.frame, request.gaze.blend_s)  # type: ignore[arg-type]
    result = _walk_within_joint_speeds(robot, footsteps, q_start, timing, options, wb_options, hands, gaze)
    _check_result(result, request)
    return _reply(robot, result, footsteps)


def _walk_within_joint_speeds(
    robot: Any,
    footsteps: FootstepSequence,
    q_start: np.ndarray,
    timing: WalkTiming,
    options: PatternOptions,
    wb_options: WholeBodyOptions,
    hands: list[HandTarget],
    gaze: GazeTarget | None,
) -> WholeBodyResult:
    """``plan_walk``; where a joint would be faster than its limit (a leg stretched near its straight
    knee, ``COM_LOWERINGS_M``) the same walk with the CoM lowered, each lowering in turn, unless the
    request fixes the CoM height. InfeasibleError: the last lowering's, ``com_lowerings_tried_m``."""
    lowerings = COM_LOWERINGS_M if options.com_height_m is None else (0.0,)
    planner = WholeBodyPlanner(robot, wb_options)
    for i, lowering in enumerate(lowerings):
        try:
            return plan_walk(
                robot,
                footsteps,
                q_start,
                timing,
                options,
                planner=planner,
                hands=hands,
                gaze=gaze,
                com_lowering_m=lowering,
            )
        except InfeasibleError as exc:
            if "joint" in exc.details and i + 1 < len(lowerings):
                log.info("%s: planned again with the CoM lowered by %.2f m", exc.message, lowerings[i + 1])
                continue
            if i == 0:
                raise
            raise InfeasibleError(
                f"{exc.message} (with the CoM lowered by up to {lowering:.2f} m)",
                {**exc.details, "com_lowerings_tried_m": list(lowerings)},
            ) from exc
    raise AssertionError("unreachable: the last lowering returns or raises")


def obstacles_of(request: msg.GoalRequest) -> list[Obstacle]:
    """The obstacles of a ``walking/goal`` request (world frame), each message read and checked once by
    :func:`~services.collision.obstacle_from_msg` (an error names ``obstacles[i].field``)."""
    return [obstacle_from_msg(o, i) for i, o in enumerate(request.obstacles)]


def goal_steps(
    request: msg.GoalRequest,
    robot: Any,
    lead: str | None = None,
    obstacles: Sequence[Obstacle] | None = None,
) -> tuple[np.ndarray, FootstepSequence]:
    """(q_start, the footsteps) of a ``walking/goal`` request, checked against its obstacles (their
    floor rectangles, a cylinder's its bounding square); ``lead``: the foot that steps first in a walk
    to a pose or a step back (None: the planner's choice, :func:`~services.walking.goals.walk_to_steps`);
    ``obstacles``: the request's, already read by :func:`obstacles_of` (None: read here).

    Raises:
        InvalidRequestError: unknown kind or frame, a pose not [x, y, yaw], negative distances, a
            square stance asked to be squared.
        InfeasibleError: ``details.reason`` ``REASON_OUT_OF_BOUNDS`` (no count of steps fits the
            bounds), ``REASON_BLOCKED`` or ``REASON_NO_ROOM_TO_TURN`` (:func:`check_clear`).
    """
    if request.kind not in msg.GOAL_KINDS:
        raise InvalidRequestError(f"kind must be one of {list(msg.GOAL_KINDS)}, got {request.kind!r}")
    if request.back_m != 0.0 and request.kind != "turn":
        raise InvalidRequestError(
            f"back_m is for kind 'turn' (a step back, then the turn, one walk), got back_m="
            f"{request.back_m} with kind {request.kind!r}"
        )
    for name in ("clearance_m", "sole_margin_m", "turn_room_m"):
        value = getattr(request, name)
        if not (math.isfinite(value) and value >= 0.0):
            raise InvalidRequestError(f"{name} must be >= 0 m, got {value}")
    q = robot.check_q(request.q_start, "q_start")
    soles = soles_on(robot, q)
    limits = FootstepBounds.from_robot(robot)
    if obstacles is None:
        obstacles = obstacles_of(request)
    boxes = [MapBox(o.name, o.footprint) for o in obstacles]
    turn_room = None
    back = None  # kind "turn" with back_m: the step back, checked as a walk of its own
    try:
        if request.kind == "pose":
            if request.frame not in ("robot", "world"):
                raise InvalidRequestError(f"frame must be 'robot' or 'world', got {request.frame!r}")
            goal = _pose(request.pose, "pose")
            if request.frame == "world":
                mid = mid_feet(soles["left"], soles["right"])
                dx, dy, _ = SolePose(goal.x_m, goal.y_m, 0.0).relative_to(mid)
                dyaw = math.remainder(goal.yaw_rad - mid.yaw_rad, 2.0 * math.pi)
            else:
                dx, dy, dyaw = goal.x_m, goal.y_m, math.remainder(goal.yaw_rad, 2.0 * math.pi)
            sequence = walk_to_steps(soles, dx, dy, dyaw, limits, lead)
        elif request.kind == "turn":
            if not math.isfinite(request.angle_rad):
                raise InvalidRequestError(f"angle_rad must be finite, got {request.angle_rad}")
            if request.back_m > 0.0:
                back, sequence = back_and_turn_steps(soles, request.back_m, request.angle_rad, limits, lead)
            else:
                sequence = turn_steps(soles, request.angle_rad, limits)
            turn_room = request.turn_room_m
        else:
            sequence = square_steps(soles, limits)
            if not sequence.steps:
                raise InvalidRequestError(
                    "the stance is already square: no step to make", {"reason": msg.REASON_ALREADY_SQUARE}
                )
    except InfeasibleError as exc:
        if "reason" in exc.details:
            raise
        raise InfeasibleError(exc.message, {**exc.details, "reason": msg.REASON_OUT_OF_BOUNDS}) from exc
    sole_size = (limits.sole_length_m, limits.sole_width_m)
    if back is not None:
        check_clear(
            back,
            boxes,
            clearance_m=request.clearance_m,
            sole_margin_m=request.sole_margin_m,
            sole_size_m=sole_size,
        )
    check_clear(
        sequence,
        boxes,
        clearance_m=request.clearance_m,
        sole_margin_m=request.sole_margin_m,
        sole_size_m=sole_size,
        turn_room_m=turn_room,
    )
    return q, sequence if back is None else joined(back, sequence)


def goal_reply(request: msg.GoalRequest, config: WalkingConfig | None = None) -> msg.PlanReply:
    """The whole ``walking/goal`` endpoint without the bus: the footsteps of the goal
    (:func:`goal_steps`), then :func:`plan_reply` of them with the request's timing, its legs checked
    against the boxes in 3D (:func:`~services.walking.sweep.check_legs_clear`). A walk to a pose (or a
    step back) whose legs come too near a box is tried once more led by the other foot (which foot
    takes the weight first decides where the hips sway and which knee comes forward)."""
    robot = load_robot(request.model)
    if not (math.isfinite(request.leg_clearance_m) and request.leg_clearance_m >= 0.0):
        raise InvalidRequestError(f"leg_clearance_m must be >= 0 m, got {request.leg_clearance_m}")
    obstacles = obstacles_of(request)  # read once: the footsteps' check and the legs' sweep use them
    if request.kind == "settle":
        return _settle_reply(robot, settle_motion(robot, robot.check_q(request.q_start, "q_start")))
    boxes = [o for o in obstacles if isinstance(o, BoxObstacle)]
    q, sequence = goal_steps(request, robot, obstacles=obstacles)
    try:
        return _goal_walk(request, robot, q, sequence, boxes, config)
    except InfeasibleError as exc:
        leads = request.kind == "pose" or (request.kind == "turn" and request.back_m > 0.0)
        if "link" not in exc.details or not leads or not sequence.steps:
            raise
        other = other_side(sequence.steps[0].side)
        try:
            q, sequence = goal_steps(request, robot, other, obstacles)
            return _goal_walk(request, robot, q, sequence, boxes, config)
        except InfeasibleError:
            raise exc from None


def _goal_walk(
    request: msg.GoalRequest,
    robot: Any,
    q: np.ndarray,
    sequence: FootstepSequence,
    boxes: list[BoxObstacle],
    config: WalkingConfig | None,
) -> msg.PlanReply:
    """:func:`plan_reply` of a goal's footsteps with its timing; its legs checked against ``boxes``."""
    plan = msg.PlanRequest(
        steps=[msg.Step(pose=s.pose.as_array().tolist(), side=s.side) for s in sequence.steps],
        model=request.model,
        q_start=q,
        left_start=sequence.left_start.as_array().tolist(),
        right_start=sequence.right_start.as_array().tolist(),
        single_support_s=request.single_support_s,
        double_support_s=request.double_support_s,
    )
    reply = plan_reply(plan, config)
    check_legs_clear(robot, np.asarray(reply.q), reply.dt_s, boxes, clearance_m=request.leg_clearance_m)
    return reply


def _settle_reply(robot: Any, motion: SettleMotion) -> msg.PlanReply:
    """The reply of a ``settle`` goal: no step; the ZMP reference and the planned ZMP are the CoM
    reference (a quasi-static motion), the multibody ZMP the motion's."""
    zmp_ref = np.ascontiguousarray(motion.com_ref_m[:, :2])
    margin = -motion.zmp_distance_m
    final = {
        side: [float(v) for v in rows[-1, [0, 1, 3]]]
        for side, rows in (("left", motion.left_sole), ("right", motion.right_sole))
    }
    return msg.PlanReply(
        model=robot.name,
        joint_names=list(robot.joint_names),
        dt_s=motion.dt_s,
        times_s=motion.times_s,
        q=np.ascontiguousarray(motion.q),
        com_m=np.ascontiguousarray(motion.com_m),
        com_ref_m=np.ascontiguousarray(motion.com_ref_m),
        zmp_ref_m=zmp_ref,
        zmp_planned_m=zmp_ref,
        zmp_multibody_m=np.ascontiguousarray(motion.zmp_m),
        zmp_margin_m=margin,
        left_sole=np.ascontiguousarray(motion.left_sole),
        right_sole=np.ascontiguousarray(motion.right_sole),
        phase=motion.phase,
        steps=[],
        final_left_sole=final["left"],
        final_right_sole=final["right"],
        figures=msg.PlanFigures(
            duration_s=float(motion.times_s[-1]),
            n_samples=int(motion.times_s.shape[0]),
            min_zmp_margin_m=float(margin.min()),
            worst_zmp_outside_m=max(0.0, float(motion.zmp_distance_m.max())),
            second_stage_passes=0,
            second_stage_acted=False,
            min_zmp_margin_first_pass_m=float(margin.min()),
            max_zmp_error_m=float(np.abs(motion.zmp_m - zmp_ref).max()),
            max_sole_error_m=motion.max_sole_error_m,
            max_com_error_m=float(np.abs(motion.com_m - motion.com_ref_m).max()),
        ),
    )


def _check_result(result: WholeBodyResult, request: msg.PlanRequest) -> None:
    """InfeasibleError when the ZMP leaves the polygon or an upper-body task is missed."""
    if result.worst_zmp_outside_m > 0.0:
        k = int(np.argmax(result.zmp_distance_m))
        t = float(result.times_s[k])
        raise InfeasibleError(
            f"the multibody ZMP leaves the support polygon by {1e3 * result.worst_zmp_outside_m:.1f} mm at "
            f"t={t:.3f} s even after {result.corrections} second-stage pass(es): slow the steps down "
            "(longer single/double support), shorten them, or lower the step height",
            {"time_s": t, "outside_m": result.worst_zmp_outside_m, "corrections": result.corrections},
        )
    for name, err in result.task_errors.items():
        if name.endswith("_rotation"):
            continue  # an orientation is held as well as the position allows; reported, not checked
        tol = request.gaze_tolerance_m if name == "gaze" else request.hand_tolerance_m
        if err.max_error > tol:
            raise InfeasibleError(
                f"upper-body task {name} is missed by {1e3 * err.max_error:.0f} mm at t={err.time_s:.3f} s "
                f"(tolerance {1e3 * tol:.0f} mm): its target is out of reach while the feet, the CoM and "
                "the waist follow the walk; bring it closer to the body",
                {"task": name, "error_m": err.max_error, "time_s": err.time_s},
            )


def _reply(robot: Any, result: WholeBodyResult, footsteps: FootstepSequence) -> msg.PlanReply:
    pattern = result.pattern
    dt = pattern.dt_s
    steps = [
        msg.StepTiming(
            index=seg.step_index,
            side=footsteps.steps[seg.step_index].side,
            lift_off_s=seg.start * dt,
            touch_down_s=seg.stop * dt,
            pose=footsteps.steps[seg.step_index].pose.as_array().tolist(),
        )
        for seg in pattern.schedule.segments
        if seg.role == "swing"
    ]
    final_left, final_right = footsteps.final_stance()
    first = result.history[0]
    last = result.history[-1]
    return msg.PlanReply(
        model=robot.name,
        joint_names=list(robot.joint_names),
        dt_s=dt,
        times_s=np.array(pattern.times_s),
        q=np.ascontiguousarray(result.q),
        com_m=np.ascontiguousarray(result.com_m),
        com_ref_m=np.ascontiguousarray(result.com_ref_m),
        zmp_ref_m=np.ascontiguousarray(pattern.zmp_ref_m),
        zmp_planned_m=np.ascontiguousarray(result.zmp_planned_m),
        zmp_multibody_m=np.ascontiguousarray(result.zmp_multibody_m),
        zmp_margin_m=-np.asarray(result.zmp_distance_m),
        left_sole=np.ascontiguousarray(pattern.left_sole),
        right_sole=np.ascontiguousarray(pattern.right_sole),
        phase=np.asarray(pattern.phase, dtype=np.int8),
        steps=steps,
        final_left_sole=final_left.as_array().tolist(),
        final_right_sole=final_right.as_array().tolist(),
        figures=msg.PlanFigures(
            duration_s=pattern.duration_s,
            n_samples=pattern.n_samples,
            min_zmp_margin_m=result.min_zmp_margin_m,
            worst_zmp_outside_m=result.worst_zmp_outside_m,
            second_stage_passes=result.corrections,
            second_stage_acted=result.corrections > 0,
            min_zmp_margin_first_pass_m=1e-3 * first["min_margin_mm"],
            max_zmp_error_m=1e-3 * last["max_zmp_error_mm"],
            max_sole_error_m=result.max_sole_error_m,
            max_com_error_m=result.max_com_error_m,
            task_errors={name: e.max_error for name, e in result.task_errors.items()},
        ),
    )


#: Longest walk one request may ask for [s of motion]: the planning work grows with it (issue 16);
#: a longer walk is planned in several requests.
MAX_WALK_S = 120.0


def check_walk_length(request: msg.PlanRequest) -> None:
    """InvalidRequestError before any work when the walk asked for lasts more than MAX_WALK_S."""
    per_step = request.single_support_s + request.double_support_s
    total = (
        request.initial_hold_s
        + request.initial_double_support_s
        + len(request.steps) * per_step
        + request.final_double_support_s
        + (request.final_hold_s if request.stop_at_end else 0.0)
    )
    if total > MAX_WALK_S:
        raise InvalidRequestError(
            f"the walk asked for lasts {total:.1f} s ({len(request.steps)} steps of {per_step:.2f} s plus "
            f"the holds and transfers): at most {MAX_WALK_S:.0f} s per walking/plan request; split it",
            {"field": "steps", "limit_s": MAX_WALK_S},
        )


class WalkingService(Service):
    """Walking pattern generator: footsteps -> 5 ms whole-body walk (ZMP preview control, Kajita 2003)."""

    name = "walking"
    Config = WalkingConfig

    def start(self) -> None:
        for model in self.config.preload:
            load_robot(model)  # fail early on a bad name; warms the model cache

    @handles(msg.PLAN)
    def plan(self, request: msg.PlanRequest) -> msg.PlanReply:
        check_walk_length(request)
        started = time.perf_counter()
        with budget.within(request.time_budget_s or self.config.time_budget_s):
            reply = plan_reply(request, self.config)
        self.log.info(
            "%s: %d steps, %.2f s of walk planned in %.2f s (ZMP margin %.1f mm, %d second-stage passes)",
            reply.model,
            len(reply.steps),
            reply.figures.duration_s,
            time.perf_counter() - started,
            1e3 * reply.figures.min_zmp_margin_m,
            reply.figures.second_stage_passes,
        )
        return reply

    @handles(msg.GOAL)
    def goal(self, request: msg.GoalRequest) -> msg.PlanReply:
        started = time.perf_counter()
        with budget.within(request.time_budget_s or self.config.time_budget_s):
            reply = goal_reply(request, self.config)
        self.log.info(
            "%s goal %s: %d steps, %.2f s of walk planned in %.2f s",
            request.kind,
            {"pose": request.pose, "turn": f"{request.angle_rad:.3f} rad", "settle": "from q_start"}.get(
                request.kind, "the stance"
            ),
            len(reply.steps),
            reply.figures.duration_s,
            time.perf_counter() - started,
        )
        return reply


if __name__ == "__main__":
    raise SystemExit(run_service(WalkingService))
