"""Task-driven support polygon reshaping for reaching: the loop of Fig. 4 of the reaching paper.

"Task-driven Support Polygon Reshaping for Reaching" (Yoshida et al., ``001_771c0ce3779b0683.txt``):

1. The robot first tries to reach the target on its current support polygon, the CoM at its initial
   position, with the four prioritized tasks (i) foot placement, (ii) CoM, (iii) hand, (iv) gaze
   (:mod:`services.reaching.tracker`, eqs. 1-4), while the manipulability of the arm (eq. 5) and the
   end-effector error are monitored (:mod:`services.reaching.monitors`).
2. If a criterion leaves its admissible range, that motion is discarded ("The computation keeping the
   same support polygon is then discarded") and the support polygon planner chooses a step towards the
   target, turning the body towards it (Fig. 5, :mod:`services.reaching.support_polygon`).
3. The walking pattern generator (ZMP preview control, reference 7 of the paper:
   :mod:`services.walking.pattern`) gives the CoM motion of that step.
4. The whole-body motion is recomputed with the same IK, the CoM task now tracking the pattern's CoM and
   the foot task its sole trajectories; it is monitored again, and reshaped further (a walk) if needed.

The multibody ZMP of the final trajectory is checked against the support polygon and corrected by the
second preview-control stage when it comes closer than ``zmp_margin_m`` to the edge.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from typing import Any

import numpy as np
import pinocchio as pin

from services import budget
from services.bus.schemas.reaching import (
    CRITERION_EE_ERROR,
    CRITERION_HAND_OBSTACLE,
    CRITERION_MANIPULABILITY,
    CRITERION_MULTIBODY_ZMP,
    REASON_FAILED_AFTER_RESHAPING,
    REASON_HAND_OBSTACLE,
    REASON_STEPPING_NOT_ALLOWED,
    REASON_TOO_MANY_STEPS,
)
from services.errors import InfeasibleError, InternalError
from services.model import load_robot
from services.model.ground import sole_pose_at
from services.reaching.envelope import ReachEnvelope, measure_envelope
from services.reaching.monitors import MonitorSeries, Violation
from services.reaching.motion import MotionSpec, pattern_frame, standing_frame
from services.reaching.obstacles import ArmClearance
from services.reaching.options import CRITERIA, ReachingOptions
from services.reaching.posture import blended_postures, posture_references
from services.reaching.references import body_frame_path, body_frame_rotations, minimum_jerk
from services.reaching.request import ReachRequest, ReachTiming
from services.reaching.result import Attempt, ReachResult
from services.reaching.support_polygon import StepPlan, SupportPolygonPlanner, mid_pose
from services.reaching.tracker import DT_S, ReachTracker, TrackResult
from services.walking.footsteps import SolePose
from services.walking.pattern import PatternOptions, WalkPattern
from services.walking.preview_control import preview_gains
from services.walking.timing import DOUBLE, LEFT, RIGHT, WalkTiming
from services.walking.two_stage import SupportSamples, correct_multibody_zmp, robot_pattern
from services.walking.zmp_reference import smoothstep5

# One reshaping step (Fig. 5) is tried when it brings the target REACH_MARGIN_M [m] inside the reach
# envelope (measured straight ahead of the shoulder), preferably at most SINGLE_STEP_MAX_BEARING_RAD
# outwards from straight ahead (the upper body facing the target), else up to SINGLE_STEP_WIDE_RAD
# outwards (SINGLE_STEP_MAX_INWARD_RAD across the body); a walk aims WALK_MARGIN_M inside.
REACH_MARGIN_M = 0.0
SINGLE_STEP_MAX_BEARING_RAD = 0.2
SINGLE_STEP_WIDE_RAD = 1.0
SINGLE_STEP_MAX_INWARD_RAD = 0.6
SINGLE_STEP_GOOD_MARGIN_M = 0.05  # margins beyond this are equally good: the facing decides
WALK_MARGIN_M = 0.12
LOW_TARGET_REACH_RATIO = 0.8
# Criteria that only trigger the reshaping of the support polygon (paper 001, Fig. 4): with stepping
# disallowed they do not veto a motion that meets every other criterion (``ReachPlanner._without_trigger``).
TRIGGER_ONLY = (CRITERION_MANIPULABILITY,)
NOT_TRIGGER_ONLY = tuple(c for c in CRITERIA if c not in TRIGGER_ONLY)
# A request with its own timing is planned again at most TIMED_TRIES times, slower each time (by
# TIMED_SLOWDOWN when the hand lagged), before the defaults' timing (``ReachPlanner.plan``).
TIMED_TRIES = 3
TIMED_SLOWDOWN = 1.5
# Fade-in of the second preview stage's ZMP error at the start of a motion without a standing lead-in [s].
CORRECTION_FADE_IN_S = 0.4


def _no_zmp(exc: InfeasibleError, spec: MotionSpec) -> Violation:
    """A motion whose multibody ZMP does not exist (a joint jumps between two IK knots: the CoM would
    fall faster than gravity: ``value`` the vertical force [N]) or leaves the support polygon even
    after the second preview stage (``value`` by how much [m]) is discarded like a criterion out of
    range (``multibody_zmp``); any other error is raised again."""
    if "sample" not in exc.details:
        raise exc
    k = min(int(exc.details["sample"]), spec.n_samples - 1)
    details = exc.details
    value = details["zmp_outside_m"] if "zmp_outside_m" in details else details["vertical_force_n"]
    return Violation(CRITERION_MULTIBODY_ZMP, float(spec.times_s[k]), float(value), 0.0)


class ReachPlanner:
    """Reaching with support polygon reshaping for one robot; see the module docstring."""

    def __init__(self, robot: Any, options: ReachingOptions | None = None) -> None:
        self.robot = robot
        self.options = options or ReachingOptions()
        self.tracker = ReachTracker(robot, self.options)
        self.support = SupportPolygonPlanner(
            robot, self.options.step_bound_ratio, self.options.comfort_reach_ratio
        )
        params = robot.params
        opt = self.options
        double_s = opt.double_support_ratio * params.double_support_s
        double_s = double_s if opt.double_support_s is None else opt.double_support_s
        single_s = opt.step_slowdown * (params.step_duration_s - params.double_support_s)
        self.timing = WalkTiming(
            single_support_s=single_s if opt.single_support_s is None else opt.single_support_s,
            double_support_s=double_s,
            dt_s=DT_S,
        )
        self.pattern_options = PatternOptions(step_height_m=float(params.step_height_m))
        # The joints whose speed times a request with its own timing: all but the grippers.
        grippers = {robot.gripper_joint(side) for side in ("left", "right")}
        timed = [robot.joint_index(n) for n in robot.joint_names if n not in grippers]
        self._timed_q_idx = np.array([j.idx_q for j in timed], dtype=int)
        self._timed_v_max = np.asarray(robot.v_max, dtype=float)[[j.idx_v for j in timed]]
        self._envelopes: dict[str, ReachEnvelope] = {}

    # ---------------------------------------------------------------------------------------- plan
    def plan(self, request: ReachRequest) -> ReachResult:
        """The whole-body reaching motion of ``request`` (validated here).

        A request with its own timing (``request.timing``: e.g. a faster hand than the defaults'
        0.2 m/s and 1.4 s) is timed by the robot's joint-speed limits too, and never steps: its
        motion is planned on the current support polygon; when a joint of it (the grippers' aside)
        moves faster than ``timed_velocity_ratio`` of its velocity limit, it is planned again that
        much slower; when the hand falls behind its reference (``ee_error``: the IK bounds each joint's
        speed, ``velocity_ratio``), ``TIMED_SLOWDOWN`` slower; at most ``TIMED_TRIES`` times, and
        then (or once that is no faster than the defaults, or on any other refusal) the request is
        planned at the defaults' timing, stepping if it allows it, as without a timing of its own.
        The defaults' timing is the paper's experiment's slow reach and is not rescaled.

        Raises:
            InvalidRequestError: malformed request (names the field).
            InfeasibleError: the target cannot be reached; the message and ``details`` name the
                criterion that failed (``criterion``, ``time_s``, ``value``, ``threshold``); with
                ``hand_obstacles``, ``reason`` ``hand_obstacle`` when no motion keeps the arm clear of
                them (``sphere``, ``link``: :meth:`_clear_of_spheres`).
        """
        req = request.validated(self.robot)
        if req.hand_obstacles:
            return self._clear_of_spheres(req)
        return self._plan_timed(req)

    def _clear_of_spheres(self, req: ReachRequest) -> ReachResult:
        """:meth:`plan` of a validated request with ``hand_obstacles``: the motion whose arm (gripper and
        wrist included) keeps the clearance from every sphere (the IK's rows, then the executed
        trajectory checked: :mod:`services.reaching.obstacles`). A motion that comes within it, or
        whose hand the rows held back, is planned again with the hand first above the target, then
        straight down (each of ``options.approach_heights_m`` in turn; motions without a requested
        posture); then the request is refused: ``infeasible`` with ``details.reason``
        ``hand_obstacle``, ``details.sphere`` the sphere's index and ``details.link`` the capsule.
        When no motion came too near a sphere (each was refused for another reason), the first
        motion's refusal is the reply, as without spheres."""
        heights = [req.approach_above_m]
        if req.q_posture is None and req.approach_above_m == 0.0:
            heights += list(self.options.approach_heights_m)
        last: Violation | None = None
        first: InfeasibleError | None = None
        tried: list[str] = []
        for height in heights:
            variant = dataclasses.replace(req, approach_above_m=height)
            how = "straight" if height == 0.0 else f"from {height:.2f} m above"
            try:
                result = self._plan_timed(variant)
            except InfeasibleError as exc:
                first = first or exc
                if exc.details.get("criterion") != CRITERION_HAND_OBSTACLE:
                    tried.append(f"{how}: {exc.message.split(' m: ', 1)[-1]}")  # without "cannot reach"
                    continue
                d = exc.details
                last = Violation(
                    CRITERION_HAND_OBSTACLE,
                    d["time_s"],
                    d["value"],
                    d["threshold"],
                    d["sphere"],
                    d["link"],
                    d.get("held_back", ""),
                )
                tried.append(f"{how}: {last.describe()}")
                continue
            clearance = ArmClearance.of(self.robot, variant, self.options)
            assert clearance is not None
            violation = clearance.path_violation(result.q, result.times_s)
            if violation is None:
                return result
            last = violation
            tried.append(f"{how}: {violation.describe()}")
        if last is None:
            assert first is not None
            raise first
        raise self._infeasible(
            req,
            last,
            "no motion keeps the arm clear of it (" + "; ".join(tried) + ")",
            reason=REASON_HAND_OBSTACLE,
            distance_m=last.value,
            clearance_m=last.threshold,
            approach_heights_m=heights,
        )

    def _plan_timed(self, req: ReachRequest) -> ReachResult:
        """:meth:`plan` of a validated request, at its own timing first when it has one."""
        if req.timing is None:
            return self._plan(req)
        timed = dataclasses.replace(req, allow_stepping=False)
        for _ in range(TIMED_TRIES):
            try:
                result = self._plan(timed)
            except InfeasibleError as exc:
                if exc.details.get("criterion") != CRITERION_EE_ERROR:
                    break
                excess = TIMED_SLOWDOWN  # the hand lagged: the joints could not follow it
            else:
                excess = self._joint_speed_ratio(result.q) / self.options.timed_velocity_ratio
                if excess <= 1.0:
                    return result
            timed = self._slower(timed, max(excess, 1.05))
            if timed is None:
                break
        return self._plan(dataclasses.replace(req, timing=None))

    def _slower(self, req: ReachRequest, factor: float) -> ReachRequest | None:
        """``req`` with its timing ``factor`` slower (hand speed divided, shortest motion multiplied),
        or None once that is no faster than the defaults' timing."""
        opt, timing = self.options, req.timing
        assert timing is not None
        speed = (timing.hand_speed_m_s or opt.hand_speed_m_s) / factor
        shortest = min(opt.max_reach_s, (timing.min_duration_s or opt.min_reach_s) * factor)
        if speed <= opt.hand_speed_m_s and shortest >= opt.min_reach_s:
            return None
        slower = ReachTiming(speed, shortest, timing.final_hold_s)
        return dataclasses.replace(req, timing=slower)

    def _joint_speed_ratio(self, q: np.ndarray) -> float:
        """The fastest joint of the trajectory ``q`` (5 ms samples) over its velocity limit (the
        grippers and the free-flyer aside)."""
        speed = np.abs(np.diff(q[:, self._timed_q_idx], axis=0)) / DT_S
        return float((speed / self._timed_v_max).max()) if speed.size else 0.0

    def _plan(self, req: ReachRequest) -> ReachResult:
        """:meth:`plan` of a validated request at its timing."""
        t0 = time.perf_counter()
        robot, opt = self.robot, self.options
        q0 = req.q_start
        data = robot.new_data()
        left, right = (sole_pose_at(robot, q0, side, data) for side in ("left", "right"))
        attempts: list[Attempt] = []

        spec0 = self._standing_spec(req, left, right)
        track0 = self.tracker.track(spec0, q0, req.hand)
        violation = track0.violation
        if violation is None:
            kept = [Attempt("no_step", 0, None, track0.wall_time_s)]
            try:
                return self._finish(req, spec0, track0, None, track0, kept, t0)
            except InfeasibleError as exc:
                violation = _no_zmp(exc, spec0)
        attempts.append(Attempt("no_step", 0, violation, track0.wall_time_s))
        if not req.allow_stepping:
            kept = self._without_trigger(req, spec0, violation, attempts, t0)
            if kept is not None:
                return kept
            why = "stepping is not allowed (allow_stepping=false)"
            if len(attempts) > 1:  # computed again without the trigger: what failed then
                other = attempts[-1].violation
                if other is not None:
                    why += f"; without that trigger, '{other.criterion}' failed ({other.describe()})"
            raise self._infeasible(req, violation, why, reason=REASON_STEPPING_NOT_ALLOWED)

        candidates = self._reshapings(req, left, right)
        if not candidates:
            comfort = self.support.comfort_stance(left, right, req.target_world_m, req.hand)
            needed = self.support.steps_needed(left, right, comfort)
            raise self._infeasible(
                req,
                violation,
                f"reshaping the support polygon towards it would take at least {needed} steps "
                f"(max_steps={opt.max_steps})",
                reason=REASON_TOO_MANY_STEPS,
                steps_needed=needed,
            )
        last_violation = violation
        for plan in candidates:
            budget.check(
                f"the reshaping attempts, before {plan.kind} ({plan.n_steps} steps)",
                {"attempts": [_attempt_details(a) for a in attempts]},
            )
            pattern = self._pattern(req, plan, self.timing)
            extra_s = self._hand_overrun_s(req, pattern)
            if extra_s > 0.0:
                # The hand takes longer than the steps: the robot stands on its new polygon until the
                # hand arrives (the final hold lengthened by the difference).
                timing = dataclasses.replace(self.timing, final_hold_s=self.timing.final_hold_s + extra_s)
                pattern = self._pattern(req, plan, timing)
            spec = self._stepping_spec(req, pattern)
            track = self.tracker.track(spec, q0, req.hand)
            violation = track.violation
            if violation is None:
                try:
                    return self._finish(
                        req,
                        spec,
                        track,
                        plan,
                        track0,
                        [*attempts, Attempt(plan.kind, plan.n_steps, None, track.wall_time_s)],
                        t0,
                    )
                except InfeasibleError as exc:
                    violation = _no_zmp(exc, spec)
            attempts.append(Attempt(plan.kind, plan.n_steps, violation, track.wall_time_s))
            last_violation = violation
        raise self._infeasible(
            req,
            last_violation,
            "even after reshaping the support polygon ("
            + ", ".join(f"{p.kind}: {p.n_steps} steps" for p in candidates)
            + ")",
            reason=REASON_FAILED_AFTER_RESHAPING,
        )

    def _without_trigger(
        self,
        req: ReachRequest,
        spec0: MotionSpec,
        violation: Violation,
        attempts: list[Attempt],
        t0: float,
    ) -> ReachResult | None:
        """The motion on the current support polygon when stepping is not allowed and only the arm's
        manipulability left its range (``TRIGGER_ONLY``), or None.

        In the paper (Fig. 4, "Task-driven Support Polygon Reshaping") a low manipulability is the
        trigger that decides *when to reshape the support polygon*: the motion is discarded because a
        step would make it better, not because the hand cannot follow it. With stepping disallowed there
        is nothing to reshape, so the trigger must not veto a target the hand reaches: the motion is
        computed again to its end without that trigger and kept when every other criterion of
        :data:`CRITERIA` stays in its range (``NOT_TRIGGER_ONLY``, whether the robot's options monitor
        it or not): the end-effector error (the hand follows its reference within ``ee_error_m`` at
        every knot: the target is within reach), the arm's joint speeds (near a singular posture they
        grow without bound), joint limits and static torques, and the multibody ZMP. The result's
        ``attempts`` keep the trigger's violation on the first (discarded) computation; when the second
        is discarded too, its violation is appended to ``attempts`` (the refusal names it).
        """
        if violation.criterion not in TRIGGER_ONLY:
            return None
        track = self.tracker.track(spec0, req.q_start, req.hand, criteria=NOT_TRIGGER_ONLY)
        if track.violation is not None:
            attempts.append(Attempt("no_step", 0, track.violation, track.wall_time_s))
            return None
        kept = [*attempts, Attempt("no_step", 0, None, track.wall_time_s)]
        try:
            return self._finish(req, spec0, track, None, track, kept, t0, criteria=NOT_TRIGGER_ONLY)
        except InfeasibleError as exc:
            attempts.append(Attempt("no_step", 0, _no_zmp(exc, spec0), track.wall_time_s))
            return None

    def _pattern(self, req: ReachRequest, plan: StepPlan, timing: WalkTiming) -> WalkPattern:
        """The pattern generator's CoM, ZMP and soles for the steps of ``plan`` (first stage)."""
        return robot_pattern(self.robot, plan.footsteps, req.q_start, timing, self.pattern_options)

    def without_reshaping(self, request: ReachRequest) -> tuple[np.ndarray | None, MonitorSeries]:
        """The motion on the initial support polygon computed to its end instead of being discarded at
        the first violation (the "without reshaping" curve of Fig. 7): (trajectory (n, nq), monitors)."""
        req = request.validated(self.robot)
        data = self.robot.new_data()
        left, right = (sole_pose_at(self.robot, req.q_start, side, data) for side in ("left", "right"))
        track = self.tracker.track(
            self._standing_spec(req, left, right), req.q_start, req.hand, stop_at_violation=False
        )
        return track.q, track.monitors

    def envelope(self, hand: str) -> ReachEnvelope:
        """The reach envelope of ``hand`` (each grid height measured when first needed, then cached)."""
        if hand not in self._envelopes:
            robot = self.robot
            q0 = robot.q_half_sitting
            data = robot.new_data()
            left, right = (sole_pose_at(robot, q0, side, data) for side in ("left", "right"))

            def standing_spec(target: np.ndarray) -> MotionSpec:
                return self._standing_spec(ReachRequest(hand, target, q0).validated(robot), left, right)

            self._envelopes[hand] = measure_envelope(
                self.tracker, hand, self.support.shoulder_in_mid[hand], standing_spec
            )
        return self._envelopes[hand]

    def _reshapings(self, req: ReachRequest, left: SolePose, right: SolePose) -> list[StepPlan]:
        """Support polygon reshapings to try, in order (Fig. 5), all facing the target: one step when it
        brings the target within the reach envelope, in front of the shoulder ("so that the incomplete
        task is fulfilled"); a walk to the stance where the target is just inside the envelope; a walk
        to the comfort stance (well inside the arm's workspace)."""
        support, opt = self.support, self.options
        target = req.target_world_m
        reach = self.envelope(req.hand).at(float(target[2]))
        # The comfort stance, but no farther than LOW_TARGET_REACH_RATIO of the reach (low targets: the
        # arm's comfort distance may be beyond the whole body's reach at that height).
        comfort_m = min(support.comfort_reach_m[req.hand], LOW_TARGET_REACH_RATIO * reach)
        plans: list[StepPlan] = []
        near = support.comfort_stance(
            left, right, target, req.hand, reach_m=max(comfort_m, reach - WALK_MARGIN_M)
        )
        single = self._single_step(req, left, right, reach)
        if single is not None:
            plans.append(single)
        for goal in (near, support.comfort_stance(left, right, target, req.hand, reach_m=comfort_m)):
            walk = support.walk(left, right, goal, req.hand, opt.max_steps)
            if walk is not None and all(walk.footsteps != p.footsteps for p in plans):
                plans.append(walk)
        return plans

    def _single_step(
        self, req: ReachRequest, left: SolePose, right: SolePose, reach_m: float
    ) -> StepPlan | None:
        """Fig. 5's one step, when one suffices: among the single steps of either foot within the
        stepping bounds (:meth:`SupportPolygonPlanner.single_steps`), those whose final stance has the
        target at least ``REACH_MARGIN_M`` inside the reach envelope ``reach_m`` (measured straight
        ahead of the shoulder) and at most ``SINGLE_STEP_WIDE_RAD`` away from straight ahead (outwards,
        ``SINGLE_STEP_MAX_INWARD_RAD`` across the body). Preferred: the target within
        ``SINGLE_STEP_MAX_BEARING_RAD`` outwards (the upper body facing it: on hrp2_like the reach
        shrinks by ~0.2 m/rad away from the body, while TALOS' shoulder torque does not depend on it),
        then the largest margin up to ``SINGLE_STEP_GOOD_MARGIN_M`` ("keeping a large margin of
        accessible area for the task"), then the body facing the target most ("by facing the upper body
        to the target direction"), then the shortest step; None if no single step brings the target in
        reach."""
        support, target, hand = self.support, req.target_world_m, req.hand
        best: StepPlan | None = None
        best_key: tuple[bool, float, float, float] | None = None
        for plan in support.single_steps(left, right):
            distance, bearing = support.from_shoulder(plan.final_mid, target, hand)
            margin = reach_m - distance
            outward = bearing if hand == "left" else -bearing  # > 0: away from the body
            if margin < REACH_MARGIN_M or not -SINGLE_STEP_MAX_INWARD_RAD <= outward <= SINGLE_STEP_WIDE_RAD:
                continue
            step = plan.footsteps.steps[0]
            moving = left if step.side == "left" else right
            length = math.hypot(step.pose.x_m - moving.x_m, step.pose.y_m - moving.y_m)
            key = (
                outward <= SINGLE_STEP_MAX_BEARING_RAD,
                round(min(margin, SINGLE_STEP_GOOD_MARGIN_M), 2),
                -round(abs(bearing), 1),
                -length,
            )
            if best_key is None or key > best_key:
                best, best_key = plan, key
        return best

    # ------------------------------------------------------------------------------------ references
    def _reach_duration(
        self,
        distance_m: float,
        angle_rad: float = 0.0,
        timing: ReachTiming | None = None,
    ) -> float:
        """The hand's motion time [s]: its travel ``distance_m`` at ``hand_speed_m_s`` or its turn
        ``angle_rad`` at ``hand_turn_rad_s``, the longer, within [min_reach_s, max_reach_s]; a
        request's ``timing`` replaces the hand speed and the shortest motion."""
        opt = self.options
        speed, shortest = opt.hand_speed_m_s, opt.min_reach_s
        if timing is not None:
            speed = opt.hand_speed_m_s if timing.hand_speed_m_s is None else timing.hand_speed_m_s
            shortest = opt.min_reach_s if timing.min_duration_s is None else timing.min_duration_s
        seconds = max(distance_m / speed, angle_rad / opt.hand_turn_rad_s)
        return float(np.clip(seconds, min(shortest, opt.max_reach_s), opt.max_reach_s))

    def _final_hold_s(self, req: ReachRequest) -> float:
        """Standing still at the end of a reach without step [s]: the request's, else the options'."""
        if req.timing is not None and req.timing.final_hold_s is not None:
            return req.timing.final_hold_s
        return self.options.final_hold_s

    def _references(
        self, req: ReachRequest, frame: dict[str, np.ndarray], s: np.ndarray, yaw: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray | None, np.ndarray | None]:
        """Hand position, hand orientation and gaze point references along the profile ``s``, in the
        body frame on the planned CoM turning by ``yaw``."""
        robot, q0 = self.robot, req.q_start
        data = robot.new_data()
        T_hand0 = robot.frame_pose(q0, robot.frames.grasp(req.hand), data)
        body_xy = frame["com_xy_m"]
        hand = body_frame_path(body_xy, yaw, s, T_hand0.translation, req.target_world_m)
        rot = None
        if req.R_world_hand is not None:
            rot = body_frame_rotations(yaw, s, T_hand0.rotation, req.R_world_hand)
        gaze = None
        if req.gaze:
            T_gaze = robot.frame_pose(q0, robot.frames.gaze, data)
            distance = max(0.3, float(np.linalg.norm(req.target_world_m - T_gaze.translation)))
            start = T_gaze.translation + distance * T_gaze.rotation[:, 0]
            gaze = body_frame_path(body_xy, yaw, s, start, req.target_world_m)
        return hand, rot, gaze

    def _standing_spec(self, req: ReachRequest, left: SolePose, right: SolePose) -> MotionSpec:
        robot = self.robot
        T_hand0 = robot.frame_pose(req.q_start, robot.frames.grasp(req.hand))
        hand0 = T_hand0.translation
        turn = 0.0
        if req.R_world_hand is not None:
            turn = float(np.linalg.norm(pin.log3(T_hand0.rotation.T @ req.R_world_hand)))
        duration = self._reach_duration(float(np.linalg.norm(req.target_world_m - hand0)), turn, req.timing)
        if req.q_posture is not None:  # the joints' travel to the posture, at the hand's turning speed
            travel = float(np.abs(req.q_posture[7:] - req.q_start[7:]).max())
            duration = max(duration, self._reach_duration(0.0, travel, req.timing))
        via = req.approach_above_m > 0.0 and req.q_posture is None
        if via:  # first above the target (the hand's travel and turn), then straight down onto it
            above = req.target_world_m + np.array([0.0, 0.0, req.approach_above_m])
            first_s = self._reach_duration(float(np.linalg.norm(above - hand0)), turn, req.timing)
            duration = first_s + self._reach_duration(req.approach_above_m, 0.0, req.timing)
        n = round((duration + self._final_hold_s(req)) / DT_S) + 1
        frame = standing_frame(
            n,
            DT_S,
            [left.x_m, left.y_m, 0.0, left.yaw_rad],
            [right.x_m, right.y_m, 0.0, right.yaw_rad],
            robot.com(req.q_start)[:2],
            mid_pose(left, right)[2],
        )
        s = minimum_jerk(frame["times_s"], 0.0, duration)
        hand, rot, gaze = self._references(req, frame, s, frame["body_yaw_rad"])
        if via:
            times, body_xy, yaw = frame["times_s"], frame["com_xy_m"], frame["body_yaw_rad"]
            s_first = minimum_jerk(times, 0.0, first_s)
            s_down = minimum_jerk(times, first_s, duration - first_s)
            hand = np.where(
                (times <= first_s)[:, None],
                body_frame_path(body_xy, yaw, s_first, hand0, above),
                body_frame_path(body_xy, yaw, s_down, above, req.target_world_m),
            )
            if req.R_world_hand is not None:  # turned on the way up, kept on the way down
                rot = body_frame_rotations(yaw, s_first, T_hand0.rotation, req.R_world_hand)
        posture = None
        if req.q_posture is not None:
            # The requested final posture reached with the hand: its joints (the hand's references along
            # the same blend: :mod:`services.reaching.posture`) and its CoM, which the footstep plan
            # kept inside this support polygon (paper 000 eq. 11), reached slowly (ZMP reference on
            # the CoM, corrected by the second preview stage).
            posture = blended_postures(req.q_start, req.q_posture, s)
            hand, rot, com_xy = posture_references(
                robot, req.hand, posture, s, req.q_start, req.target_world_m, req.R_world_hand
            )
            # The footstep plan's posture has its own gaze task on the object (paper 000 §4): the blend
            # carries the head there; a second gaze task above the posture drove the arm off it.
            gaze = None
            frame = {**frame, "com_xy_m": com_xy, "zmp_planned_m": com_xy, "zmp_reference_m": com_xy}
        return MotionSpec(
            hand_ref_m=hand,
            hand_rot=rot,
            gaze_ref_m=gaze,
            reach_end_s=duration,
            posture_ref=posture,
            clearance=ArmClearance.of(robot, req, self.options),
            **frame,
        )

    def _stepping_spec(self, req: ReachRequest, pattern: WalkPattern) -> MotionSpec:
        frame = pattern_frame(pattern)
        # The hand arrives when the last weight transfer ends (the robot then stands on its new polygon).
        hold = [seg for seg in pattern.schedule.segments if seg.role == "hold"]
        t_arrive = float(frame["times_s"][hold[0].start]) if hold else float(frame["times_s"][-1])
        hand0 = self.robot.frame_pose(req.q_start, self.robot.frames.grasp(req.hand)).translation
        # Duration from the hand's motion relative to the body (the steps carry it the rest of the way).
        r0 = _in_body(hand0, frame["com_xy_m"][0], frame["body_yaw_rad"][0])
        r1 = _in_body(req.target_world_m, frame["com_xy_m"][-1], frame["body_yaw_rad"][-1])
        duration = self._reach_duration(float(np.linalg.norm(r1 - r0)), 0.0, req.timing)
        # The hand arrives with the last weight transfer, or after it when it needs longer than the
        # steps (then the pattern's final hold must leave it the time: see ``plan``).
        t_end = min(max(t_arrive, duration), float(frame["times_s"][-1]))
        duration = min(duration, t_end)
        s = minimum_jerk(frame["times_s"], t_end - duration, duration)
        # The feet turn the waist step by step; the references turn smoothly over the whole walk (a hand
        # carried by each quick swing turn would have to whip round).
        yaw = frame["body_yaw_rad"]
        smooth_yaw = yaw[0] + (yaw[-1] - yaw[0]) * minimum_jerk(frame["times_s"], 0.0, t_arrive)
        hand, rot, gaze = self._references(req, frame, s, smooth_yaw)
        return MotionSpec(
            hand_ref_m=hand,
            hand_rot=rot,
            gaze_ref_m=gaze,
            reach_end_s=t_end,
            pattern=pattern,
            clearance=ArmClearance.of(self.robot, req, self.options),
            **frame,
        )

    def _hand_overrun_s(self, req: ReachRequest, pattern: WalkPattern) -> float:
        """How much longer [s] than the steps (to the end of the last weight transfer) the hand's own
        motion takes at ``hand_speed_m_s``."""
        frame = pattern_frame(pattern)
        hold = [seg for seg in pattern.schedule.segments if seg.role == "hold"]
        t_arrive = float(frame["times_s"][hold[0].start]) if hold else float(frame["times_s"][-1])
        hand0 = self.robot.frame_pose(req.q_start, self.robot.frames.grasp(req.hand)).translation
        r0 = _in_body(hand0, frame["com_xy_m"][0], frame["body_yaw_rad"][0])
        r1 = _in_body(req.target_world_m, frame["com_xy_m"][-1], frame["body_yaw_rad"][-1])
        duration = self._reach_duration(float(np.linalg.norm(r1 - r0)), 0.0, req.timing)
        return max(0.0, duration - t_arrive)

    # ------------------------------------------------------------------------------------ finishing
    def _finish(
        self,
        req: ReachRequest,
        spec: MotionSpec,
        track: TrackResult,
        plan: StepPlan | None,
        track0: TrackResult,
        attempts: list[Attempt],
        t0: float,
        *,
        criteria: tuple[str, ...] | None = None,
    ) -> ReachResult:
        """Multibody ZMP check (second preview stage where needed), foot slide, the result; ``criteria``:
        those monitored when the motion is computed again (None: the options'; see ``_without_trigger``)."""
        robot, opt = self.robot, self.options
        q = track.q
        if q is None:
            raise InternalError("a motion kept by the planner has no trajectory")
        com_z = float(robot.com(req.q_start)[2])
        gains = spec.pattern.gains if spec.pattern is not None else preview_gains(DT_S, com_z)
        kept = [track]

        def retrack(com_offset_xy_m: np.ndarray) -> np.ndarray | None:
            candidate = self.tracker.track(
                spec, req.q_start, req.hand, com_offset_xy_m=com_offset_xy_m, criteria=criteria
            )
            if candidate.violation is not None:
                return None
            kept.append(candidate)
            return candidate.q

        # Second preview stage (Kajita 2003, IV-B): CoM correction from p_ref - p_multibody.
        support = SupportSamples(
            spec.phase, spec.left_sole, spec.right_sole, robot.sole_size_m, DT_S, spec.zmp_reference_m
        )
        out = correct_multibody_zmp(
            robot.model,
            q,
            support,
            gains,
            retrack,
            window=_correction_window(spec),
            settle_samples=round(self._final_hold_s(req) / DT_S),
            margin_m=opt.zmp_margin_m,
            max_corrections=opt.max_corrections,
        )
        track, q, mb, distance, corrections = kept[-1], out.q, out.zmp, out.distance_m, out.corrections
        if distance.max() > 0.0:
            # Still outside the support polygon after the corrections: the motion is not dynamically
            # stable (the paper's pattern generator guarantees the ZMP inside): discarded.
            k = int(np.argmax(distance))
            raise InfeasibleError(
                f"the multibody ZMP leaves the support polygon by {1e3 * distance[k]:.0f} mm at "
                f"t={spec.times_s[k]:.2f} s",
                {"sample": k, "zmp_outside_m": float(distance[k])},
            )
        slide = _max_sole_slide(robot, q, spec)
        hand_final = robot.frame_pose(q[-1], robot.frames.grasp(req.hand)).translation
        return ReachResult(
            robot=robot.name,
            hand=req.hand,
            target_world_m=req.target_world_m.copy(),
            times_s=spec.times_s,
            q=q,
            stepped=plan is not None,
            footsteps=() if plan is None else plan.footsteps.steps,
            monitors=track.monitors,
            no_step_monitors=track0.monitors,
            attempts=tuple(attempts),
            thresholds=opt.thresholds(robot),
            left_sole=spec.left_sole,
            right_sole=spec.right_sole,
            phase=spec.phase,
            com_m=mb.com_m,
            zmp_planned_m=spec.zmp_planned_m,
            zmp_multibody_m=mb.zmp_m,
            zmp_distance_m=distance,
            corrections=corrections,
            hand_error_m=float(np.linalg.norm(hand_final - req.target_world_m)),
            max_sole_slide_m=slide,
            reach_end_s=spec.reach_end_s,
            wall_time_s=time.perf_counter() - t0,
        )

    def _infeasible(
        self, req: ReachRequest, violation: Violation, why: str, reason: str, **details: Any
    ) -> InfeasibleError:
        t = req.target_world_m
        return InfeasibleError(
            f"the {req.hand} hand cannot reach the target ({t[0]:.2f}, {t[1]:.2f}, {t[2]:.2f}) m: criterion "
            f"'{violation.criterion}' failed ({violation.describe()}) and {why}",
            {
                "reason": reason,
                "criterion": violation.criterion,
                "time_s": violation.time_s,
                "value": violation.value,
                "threshold": violation.threshold,
                **(
                    {"sphere": violation.sphere, "link": violation.link, "held_back": violation.held_back}
                    if violation.sphere >= 0
                    else {}
                ),
                **details,
            },
        )


def _attempt_details(attempt: Attempt) -> dict[str, Any]:
    """An attempt as JSON-able details (a ``timeout`` reply's partial result)."""
    v = attempt.violation
    return {
        "kind": attempt.kind,
        "steps": attempt.n_steps,
        "violation": "" if v is None else v.criterion,
        "wall_time_s": attempt.wall_time_s,
    }


def _in_body(point: np.ndarray, body_xy: np.ndarray, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    dx, dy = point[0] - body_xy[0], point[1] - body_xy[1]
    return np.array([c * dx + s * dy, -s * dx + c * dy, point[2]])


def _correction_window(spec: MotionSpec) -> np.ndarray:
    """Weight (n,) of the ZMP error fed to the second preview stage: faded in at the start (a correction
    cannot act before t = 0) and out once the hand has arrived (the robot comes to rest)."""
    t = spec.times_s
    if spec.pattern is not None:
        start = [seg for seg in spec.pattern.schedule.segments if seg.role == "start"]
        fade_in = (start[0].n * DT_S) if start else CORRECTION_FADE_IN_S
    else:
        fade_in = CORRECTION_FADE_IN_S
    tail = max(DT_S, 0.5 * (t[-1] - spec.reach_end_s))
    w = smoothstep5(t / fade_in) * (1.0 - smoothstep5((t - spec.reach_end_s) / tail))
    return w


def _max_sole_slide(robot: Any, q: np.ndarray, spec: MotionSpec) -> float:
    """Largest horizontal distance [m] between a supporting sole and its planned pose over the motion."""
    model, data = robot.model, robot.new_data()
    ids = {side: robot.frame_id(robot.frames.sole(side)) for side in ("left", "right")}
    planned = {"left": spec.left_sole, "right": spec.right_sole}
    support = {"left": (DOUBLE, LEFT), "right": (DOUBLE, RIGHT)}
    worst = 0.0
    for k in range(q.shape[0]):
        pin.forwardKinematics(model, data, q[k])
        for side, fid in ids.items():
            if spec.phase[k] in support[side]:
                p = pin.updateFramePlacement(model, data, fid).translation
                worst = max(worst, math.hypot(p[0] - planned[side][k, 0], p[1] - planned[side][k, 1]))
    return worst


@functools.lru_cache(maxsize=8)
def planner_for(robot_name: str, options: ReachingOptions | None = None) -> ReachPlanner:
    """The shared :class:`ReachPlanner` of a robot (by name) and options (its reach envelopes are
    measured once)."""
    return ReachPlanner(load_robot(robot_name), options or ReachingOptions())


def plan_reach(robot: Any, request: ReachRequest, options: ReachingOptions | None = None) -> ReachResult:
    """Plan a whole-body reach with support polygon reshaping (a cached :class:`ReachPlanner` per robot
    and options). ``robot`` is a ``services.model.RobotModel`` or its name."""
    name = robot if isinstance(robot, str) else robot.name
    return planner_for(name, options or ReachingOptions()).plan(request)
