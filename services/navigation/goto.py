"""The whole two-stage planner behind ``navigation/goto`` (Figure 1 of `001_771c0ce3779b0683.txt`).

Stage 1 (:mod:`path`): a car-like collision-free path of the lower body's bounding box (and of the arms'
box, measured in the starting configuration) from the robot's current pose to the goal (a pose, or "in
front of the yellow table, facing it, at 0.4 m"), and the carried bar's 3D sweep along it at the carry
height (:mod:`upper_body`); the path becomes footsteps (:mod:`footsteps_along_path`). Stage 2
(:mod:`stage2`): the walking pattern and the whole-body motion holding the bar, checked in 3D and
smoothly reshaped until collision-free.

Planners are stateless: the scene's obstacles (from perception or the supervisor's map, never the sim's
ground truth) and the robot's starting configuration come with every request.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from services import budget
from services.bus.schemas import navigation as nav_msg
from services.bus.schemas.common import START_SOLE_MAX_HEIGHT_M, START_SOLE_MAX_TILT_RAD
from services.collision.carried import CarriedBar
from services.collision.obstacles import Scene
from services.errors import InfeasibleError, InvalidRequestError
from services.model.ground import FootstepBounds, sole_pose_of
from services.navigation.body_extents import with_arms_of
from services.navigation.carry import grip_from_configuration
from services.navigation.footsteps_along_path import FootstepOptions, PathFootsteps, footsteps_along_path
from services.navigation.geometry import Pose2D, body_model
from services.navigation.goals import ObjectGoal
from services.navigation.path import PlannerConfig, SampledPath, escape_pose, plan_path, stage1_checker
from services.navigation.stage2 import Stage2Options, WholeBodyMotion, plan_motion
from services.navigation.straight import StraightWalkOptions, straight_walk
from services.navigation.upper_body import SweepResult, sweep_carried_object
from services.walking.footsteps import FootstepSequence, SolePose
from services.walking.timing import WalkTiming, build_schedule
from services.walking.two_stage import COM_LOWERINGS_M

REPLAN_EXTRA_MARGIN_M = 0.02
"""Margin [m] added, beyond the clearance missing, when stage 2 sends stage 1 back for a new path."""
SLOW_WALK_FACTOR = 1.5
"""Single supports this much longer when stage 2's walk moves a joint faster than its limit: first those
of the steps moving while it does, then (once more too fast) every step's."""
STRETCHED_LEG_LOWERING_M = COM_LOWERINGS_M[1]
"""CoM lowering [m] tried first when stage 2's walk moves a joint faster than its limit (the first nonzero
of ``COM_LOWERINGS_M``: 2 cm made seed 6's walks with a stretched leg executable, 4 cm made others ring)."""
ESCAPE_EXTRA_MARGIN_M = 0.02
"""A start overlapping an obstacle escapes to a pose this much clearer [m] than stage 1 requires."""
log = logging.getLogger("humanoid.navigation")

MAX_START_SOLE_HEIGHT_M = START_SOLE_MAX_HEIGHT_M
"""The starting configuration must have both soles on the floor (flat ground z = 0) within this [m]."""


@dataclass(frozen=True)
class GotoOptions:
    """Options of :func:`plan_goto`: stage 1 (``planner``), footstep placement (``footsteps``; None:
    :meth:`FootstepOptions.for_body` of the robot), stage 2 (``stage2``), ``max_replans``: how many
    times a ``body_collision`` of stage 2 sends stage 1 back for a path with a larger margin, and
    ``straight``: when a near goal is walked straight instead of along a detour (None: never;
    :mod:`services.navigation.straight`)."""

    planner: PlannerConfig = field(default_factory=PlannerConfig)
    footsteps: FootstepOptions | None = None
    stage2: Stage2Options = field(default_factory=Stage2Options)
    max_replans: int = 2
    straight: StraightWalkOptions | None = field(default_factory=StraightWalkOptions)


@dataclass(frozen=True, eq=False)
class GotoResult:
    """The plan: the stage-1 path and the bar's stage-1 sweep along it (None without a bar), the
    footsteps, the stage-2 whole-body motion, wall times [s] per stage (summed over the replans), and
    ``replans``: how many times stage 2 sent stage 1 back for a path with a larger margin."""

    path: SampledPath
    sweep: SweepResult | None
    footsteps: PathFootsteps
    motion: WholeBodyMotion
    timings_s: dict[str, float]
    replans: int = 0

    @property
    def goal(self) -> Pose2D:
        """The base pose reached (for an object goal: the approach pose chosen)."""
        return self.path.goal


def _steps_too_fast(
    footsteps: FootstepSequence, timing: WalkTiming, details: dict[str, Any]
) -> tuple[int, ...]:
    """The steps moving while a joint is faster than its limit (``details["over_limit_s"]``, the time
    stretches [s] of the walking planner's error; else its ``time_s``) on the schedule of ``timing``."""
    schedule = build_schedule([s.side for s in footsteps.steps], timing)
    stretches = details.get("over_limit_s") or [[details.get("time_s", -1.0)] * 2]
    out: set[int] = set()
    for t0, t1 in stretches:
        for t in np.arange(float(t0), float(t1) + schedule.dt_s, schedule.dt_s):
            out.update(schedule.steps_at(float(t)))
    return tuple(sorted(out))


def start_soles(robot: Any, q: np.ndarray) -> tuple[SolePose, SolePose]:
    """The (left, right) sole poses of configuration ``q``; InvalidRequestError unless both soles are flat
    on the floor."""
    data = robot.new_data()
    soles = []
    for side in ("left", "right"):
        T = robot.sole_pose(q, side, data)
        tilt = math.acos(max(-1.0, min(1.0, float(T.rotation[2, 2]))))
        if abs(T.translation[2]) > MAX_START_SOLE_HEIGHT_M or tilt > START_SOLE_MAX_TILT_RAD:
            raise InvalidRequestError(
                f"the {side} sole of the starting configuration is at z={T.translation[2]:.3f} m, tilted "
                f"{math.degrees(tilt):.1f} deg: navigation starts standing on flat ground (soles within "
                f"{1e3 * MAX_START_SOLE_HEIGHT_M:.0f} mm of z = 0); send the robot's current configuration",
                {"field": "q_start", "side": side},
            )
        soles.append(sole_pose_of(T))
    return soles[0], soles[1]


def start_pose(robot: Any, q: np.ndarray) -> Pose2D:
    """The base pose on the floor (mid-feet point, mean sole yaw) of configuration ``q``."""
    x, y, yaw = robot.mid_feet_pose(q)
    return Pose2D(float(x), float(y), float(yaw))


def _escaped(
    robot: Any,
    scene: Scene,
    body: Any,
    start: Pose2D,
    soles: tuple[SolePose, SolePose],
    options: GotoOptions,
) -> tuple[Pose2D, tuple[SolePose, SolePose], tuple[SampledPath, PathFootsteps] | None]:
    """Where stage 1 starts from: the robot's mid-feet pose when its footprint (margin included, as
    :func:`plan_path` checks it) is free; else the nearest free pose (:func:`escape_pose`, computed from
    the overlap), reached by a straight walk checked against the obstacles
    (:func:`straight_walk`), which the goto's footsteps then begin with. Returns (start pose, soles
    there (left, right), the escape walk or None). A start with no free pose within reach, or no
    clear straight walk to it, is left to :func:`plan_path` (``start_in_collision``)."""
    checker = stage1_checker(scene, body, options.planner)
    # the stance reached is within millimetres of the pose aimed at: aim ESCAPE_EXTRA_MARGIN_M clear
    free = escape_pose(checker.with_margin(checker.body.margin_m + ESCAPE_EXTRA_MARGIN_M), start)
    if free is None or free == start:
        return start, soles, None
    walk = straight_walk(robot, scene, soles, start, free, options.straight or StraightWalkOptions())
    if walk is None:
        return start, soles, None
    sequence = walk[1].sequence
    left, right = sequence.final_stance()
    return (
        Pose2D((left.x_m + right.x_m) / 2.0, (left.y_m + right.y_m) / 2.0, free.theta_rad),
        (left, right),
        walk,
    )


def _joined(
    escape: tuple[SampledPath, PathFootsteps], path: SampledPath, steps: PathFootsteps
) -> tuple[SampledPath, PathFootsteps]:
    """The escape walk followed by the path planned from its end: one path (its ``curve`` "escape+" the
    path's), one footstep sequence."""
    first, first_steps = escape
    length = first.length_m
    theta = path.theta_rad + 2.0 * math.pi * round(
        (first.theta_rad[-1] - path.theta_rad[0]) / (2.0 * math.pi)
    )
    joined = replace(
        path,
        xy_m=np.vstack([first.xy_m, path.xy_m[1:]]),
        theta_rad=np.concatenate([first.theta_rad, theta[1:]]),
        s_m=np.concatenate([first.s_m, length + path.s_m[1:]]),
        forward=np.concatenate([first.forward, path.forward[1:]]),
        waypoints=np.vstack([first.waypoints, path.waypoints]),
        curve=f"escape+{path.curve}",
    )
    sequence = FootstepSequence(
        first_steps.sequence.left_start,
        first_steps.sequence.right_start,
        first_steps.sequence.steps + steps.sequence.steps,
    )
    return joined, PathFootsteps(sequence, first_steps.s_m + tuple(length + s for s in steps.s_m))


def plan_goto(
    robot: Any,
    scene: Scene,
    q_start: np.ndarray,
    goal: Pose2D | ObjectGoal,
    bar: CarriedBar | None = None,
    options: GotoOptions | None = None,
) -> GotoResult:
    """Plan the walk of ``robot`` (a ``services.model.RobotModel``) from ``q_start`` to ``goal`` among
    ``scene``'s obstacles, holding ``bar`` in both hands as at ``q_start`` (None: nothing carried).

    A near goal whose stage-1 path is a detour, or to which stage 1 finds no path within its budget, is
    walked straight when that is clear of the obstacles (``options.straight``; the path's ``curve`` is
    then "straight"); nothing is carried then. A ``body_collision`` of stage 2 (the body or an arm too
    close to an obstacle: the floor boxes were too small for the dynamic motion) sends stage 1 back for
    a path with the footprint margin grown by the clearance missing (+ 2 cm), at most ``max_replans``
    times ("the planner goes back to the first stage", "Two-stage Planning Method").

    A start whose footprint overlaps an obstacle (margin included: the robot ended a reach or a turn
    beside a chair) is left first: the footsteps begin with a straight walk to the nearest free pose,
    computed from the overlap (:func:`_escaped`), and stage 2 plans the whole walk as one motion.

    Raises the errors of the stages: InfeasibleError (``details["reason"]`` from :func:`plan_path`,
    :func:`footsteps_along_path` and :func:`plan_motion`), NotFoundError (unknown object or robot),
    InvalidRequestError (bad configuration, pose outside the scene, bad options).
    """
    options = options or GotoOptions()
    t0 = time.perf_counter()
    q_start = robot.check_q(q_start)
    soles_now = start_soles(robot, q_start)
    body = with_arms_of(body_model(robot.name), robot, q_start)  # the arms as they are (and stay)
    grip = grip_from_configuration(robot, q_start, bar) if bar is not None else None
    timings = {"path_s": 0.0, "footsteps_s": 0.0, "stage2_s": 0.0}
    replans = 0
    slowed = False
    slowed_steps: tuple[int, ...] = ()
    start_now = start_pose(robot, q_start)
    straight_options = options.straight if bar is None else None
    while True:
        budget.check(
            f"navigation's stage 1 (replans {replans}, slowed {slowed})",
            {"replans": replans, "timings_s": dict(timings)},
        )
        t1 = time.perf_counter()
        steps = None
        start, soles, escape = _escaped(robot, scene, body, start_now, soles_now, options)
        try:
            # the search gets what the whole goto's budget leaves, at most its own time_budget_s
            planner = replace(options.planner, time_budget_s=budget.remaining(options.planner.time_budget_s))
            path = plan_path(scene, body, start, goal, planner)
            if straight_options is not None and straight_options.is_detour(start, path.goal, path.length_m):
                straight = straight_walk(robot, scene, soles, start, path.goal, straight_options)
                if straight is not None:
                    path, steps = straight
        except InfeasibleError as error:
            # No car-like path in the budget: a near goal is walked straight if that is clear.
            if (
                error.details.get("reason") != nav_msg.REASON_NO_PATH_WITHIN_BUDGET
                or straight_options is None
            ):
                raise
            for tried in error.details.get("goals", []):
                near = Pose2D(*(float(v) for v in tried))
                if straight_options.is_near(start, near):
                    straight = straight_walk(robot, scene, soles, start, near, straight_options)
                    if straight is not None:
                        path, steps = straight
                        break
            else:
                raise
        t2 = time.perf_counter()
        sweep = None
        if bar is not None and grip is not None:
            # stage 1's view of the bar: where the hands hold it at the start, carried at the carry height
            start = path.start
            ahead = grip.centre_world_m[:2] - (start.x_m, start.y_m)
            forward = float(ahead @ (math.cos(start.theta_rad), math.sin(start.theta_rad)))
            height = options.stage2.carry_height_m or float(grip.centre_world_m[2])
            sweep = sweep_carried_object(scene, path, replace(bar, forward_m=forward, height_m=height), body)
        if steps is None:
            footstep_options = options.footsteps or FootstepOptions.for_body(body)
            steps = footsteps_along_path(
                path, FootstepBounds.from_robot(robot), footstep_options, start_soles=soles
            )
        if escape is not None:
            path, steps = _joined(escape, path, steps)
        t3 = time.perf_counter()
        timings["path_s"] += t2 - t1
        n_steps = len(steps.sequence.steps)
        budget.check(
            f"navigation's stage 2 (a path of {path.length_m:.2f} m and {n_steps} steps found)",
            {"replans": replans, "path_length_m": path.length_m, "steps": n_steps},
        )
        timings["footsteps_s"] += t3 - t2
        try:
            motion = plan_motion(robot, scene, steps.sequence, q_start, bar, options.stage2)
        except InfeasibleError as error:
            timings["stage2_s"] += time.perf_counter() - t3
            lowered = options.stage2.com_lowering_m or 0.0
            if "joint" in error.details and lowered < STRETCHED_LEG_LOWERING_M:
                # a joint faster than its limit, most often a leg stretched near its straight knee (the
                # IK flips the knee or swings a free arm to hold the CoM height): the same footsteps
                # with the CoM lowered (services.walking.two_stage.COM_LOWERINGS_M), then slower
                log.info("stage 2: %s; the CoM lowered by %.2f m", error.message, STRETCHED_LEG_LOWERING_M)
                stage2 = replace(options.stage2, com_lowering_m=STRETCHED_LEG_LOWERING_M)
                options = replace(options, stage2=stage2)
                continue
            if "joint" in error.details and not slowed:
                # a joint faster than its limit (a knee on a turning step): the same footsteps with slower
                # single supports (the second stage's pattern and whole-body IK again), first of the
                # steps moving while it is too fast, then (a second time) of every step
                timing = options.stage2.timing
                too_fast = () if slowed_steps else _steps_too_fast(steps.sequence, timing, error.details)
                if too_fast:
                    slow = replace(timing, slow_steps=too_fast, slow_step_factor=SLOW_WALK_FACTOR)
                    slowed_steps = too_fast
                else:
                    slow = replace(
                        timing, single_support_s=timing.single_support_s * SLOW_WALK_FACTOR, slow_steps=()
                    )
                    slowed = True
                log.info(
                    "stage 2: %s; walking %s of the %d steps slower",
                    error.message,
                    f"steps {list(too_fast)}" if too_fast else "every one",
                    n_steps,
                )
                options = replace(options, stage2=replace(options.stage2, timing=slow))
                continue
            # "the planner goes back to the first stage": the body's boxes were too small for the
            # dynamic motion (sway, swing); plan the path again with the margin grown by what was missing
            if error.details.get("reason") != nav_msg.REASON_BODY_COLLISION or replans >= options.max_replans:
                raise
            straight_options = None  # the straight line came too near: stage 1's path, with more margin
            if slowed_steps:  # step indices of the old footsteps: the new ones start at full speed
                timing = replace(options.stage2.timing, slow_steps=())
                options = replace(options, stage2=replace(options.stage2, timing=timing))
                slowed_steps = ()
            missing = options.stage2.reshape.required_clearance_m - float(error.details["distance_m"])
            body = body.with_margin(body.margin_m + missing + REPLAN_EXTRA_MARGIN_M)
            replans += 1
            continue
        timings["stage2_s"] += time.perf_counter() - t3
        break
    timings["total_s"] = time.perf_counter() - t0
    return GotoResult(
        path=path,
        sweep=sweep,
        footsteps=steps,
        motion=motion,
        timings_s=timings,
        replans=replans,
    )
