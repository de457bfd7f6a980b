"""The generalized IK over time: the whole-body motion of a :class:`MotionSpec` with the four
prioritized tasks of the reaching paper, and the monitoring of the task execution criteria.

Priorities ("Experimental Results" of "Task-driven Support Polygon Reshaping for Reaching"): (i) foot
placement (with the waist kept above the robot's fall height: an inequality), (ii) CoM position,
(iii) hand reaching, (iv) gaze direction, solved by the strict hierarchy of ``services.ik`` (eqs. 1-3:
each task in the null space of the ones above), every level with the weighted pseudo-inverse of eq. (4)
(W_i = m_i / M, ``options.weighted``) and optionally the joint-limit selection matrix S_l
(``options.joint_limit_selection_rad``). Below them, a rest level (the waist upright, turning with the
body yaw) only uses the redundancy left; what remains after it is the minimum (weighted) norm step of
eqs. (3)-(4) with y = 0, so joints no task needs do not move.

The IK runs on knots every ``knot_stride`` samples: each knot starts from the previous one and takes
Gauss-Newton steps of the hierarchy until the hand is within ``knot_tolerance_m`` of its reference. The
criteria are evaluated at every knot (Fig. 4); the first one out of its admissible range stops the
computation when asked to (the motion is then discarded). The 5 ms trajectory is a C2 spline of the
knots.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

from services import budget
from services.ik import (
    ComPositionTask,
    FrameOrientationTask,
    FramePoseTask,
    FramePositionTask,
    GazeTask,
    HierarchicalSolver,
    Level,
    PostureTask,
    link_mass_weights,
)
from services.ik.dofs import joint_dofs
from services.reaching.monitors import ArmMonitor, KnotValues, MonitorSeries, Violation, first_violation
from services.reaching.motion import MotionSpec
from services.reaching.options import ReachingOptions
from services.reaching.references import rot_z
from services.reaching.spline import spline_configurations
from services.walking.zmp_reference import smoothstep5

# The waist level pulls only this fraction of its error per knot: a full step would break the
# linearization of every task above it (and move the robot at a jump).
REST_GAIN = 0.1
DT_S = 0.005  # the trajectory grid [s]
# Largest task-space step per Gauss-Newton iteration [m]: a hand that cannot follow its reference (out
# of reach) stays where the linearization holds instead of being thrown by a huge step.
MAX_HAND_STEP_M = 0.03
MAX_GAZE_STEP = 0.1  # [-]: sine of the gaze direction error
GAZE_AXIS = (1.0, 0.0, 0.0)  # the robot's ``gaze`` frame looks along its x axis
# Damping of the hand level (damped least squares, in the level's metric): near the arm's singularity
# the step stays bounded instead of flipping the arm; away from it the knot iterations remove the bias.
HAND_DAMPING = 1e-3
# Gain of the requested-posture level (``MotionSpec.posture_ref``) per Gauss-Newton step: it follows a
# moving reference, in the null space of the tasks above it.
POSTURE_GAIN = 0.5
MODEL_CACHE_SIZE = 8  # IK models kept per tracker (one per hand and locked-arm configuration)


@dataclass(frozen=True)
class TrackResult:
    """Outcome of :meth:`ReachTracker.track`.

    ``q`` is the (n, nq) trajectory of the full robot model on the spec's grid, or None when the
    computation stopped at a violation. ``monitors`` holds the criteria at the knots computed.
    """

    q: np.ndarray | None
    monitors: MonitorSeries
    violation: Violation | None
    knots: int
    wall_time_s: float


class IKModel:
    """The IK's model for one reaching hand and one starting configuration: the robot with its
    grippers locked (their open position is a joint limit) and, with ``other_arm_still``, the other
    arm locked where it is (the selection matrix S of eq. 4 without that arm: it has no task, and with
    the weighted pseudo-inverse its light links would otherwise swing to help the CoM).
    """

    def __init__(self, robot: Any, hand: str, q_start: np.ndarray, options: ReachingOptions) -> None:
        self.robot = robot
        self.hand = hand
        locked = [robot.gripper_joint(side) for side in ("left", "right")]
        if options.other_arm_still:
            locked += robot.arm_joints("right" if hand == "left" else "left")
        self.locked_q_idx = np.array([robot.joint_index(n).idx_q for n in locked], dtype=int)
        self.free_q_idx = np.setdiff1d(np.arange(robot.nq), self.locked_q_idx)
        self.free_v_idx = np.setdiff1d(np.arange(robot.nv), [robot.joint_index(n).idx_v for n in locked])
        ids = [robot.model.getJointId(n) for n in locked]
        self.model: pin.Model = pin.buildReducedModel(robot.model, ids, np.asarray(q_start, dtype=float))
        self.q_lower = np.asarray(robot.q_lower)[self.free_q_idx]
        self.q_upper = np.asarray(robot.q_upper)[self.free_q_idx]
        # Joint speed: each Gauss-Newton step moves a joint by at most velocity_ratio of its velocity
        # limit over one knot period; a knot whose arm joints move faster than that in total fails the
        # ``joint_speed`` criterion (near a singularity the arm's joints would have to fly).
        v_max = np.asarray(robot.v_max)[self.free_v_idx]
        knot_dt_s = options.knot_stride * DT_S
        dq_max = options.velocity_ratio * v_max * knot_dt_s
        self.weights = link_mass_weights(self.model) if options.weighted else None
        self.monitor = ArmMonitor(
            self.model,
            robot.frames.grasp(hand),
            robot.arm_joints(hand),
            self.q_lower,
            self.q_upper,
            np.asarray(robot.effort_max)[self.free_v_idx],
            (robot.frames.left_sole, robot.frames.right_sole),
            options.manipulability_of,
        )
        self.v_max_arm = v_max[self.monitor.arm_v_idx]
        # The arms' joints move at most velocity_ratio of their limits over a whole knot (the
        # Gauss-Newton steps of a knot share it): near a singular configuration the reaching arm
        # cannot whip round to keep up (the hand falls behind its reference and the paper's
        # end-effector error criterion, or the manipulability, is what fails, as on HRP-2), nor the
        # other arm, free with S = I, swing to help the CoM.
        if options.arm_speed_per_knot:
            arms = [n for side in ("left", "right") for n in robot.arm_joints(side)]
            arm_v = joint_dofs(self.model, [n for n in arms if self.model.existJointName(n)])
            dq_max[arm_v] /= options.max_iterations_per_knot
        self.solver = HierarchicalSolver(self.model, dq_max=dq_max)

    def reduce_q(self, q_full: np.ndarray) -> np.ndarray:
        """IK configuration of a full one."""
        return np.asarray(q_full, dtype=float)[..., self.free_q_idx]

    def expand_q(self, q_reduced: np.ndarray, q_locked_from: np.ndarray) -> np.ndarray:
        """Full configurations (..., nq), locked joints taken from ``q_locked_from``."""
        q_reduced = np.asarray(q_reduced)
        out = np.empty((*q_reduced.shape[:-1], self.robot.nq))
        out[..., self.free_q_idx] = q_reduced
        out[..., self.locked_q_idx] = np.asarray(q_locked_from)[self.locked_q_idx]
        return out


class ReachTracker:
    """Whole-body IK of reaching motions for one robot (a ``services.model.RobotModel``)."""

    def __init__(self, robot: Any, options: ReachingOptions | None = None) -> None:
        self.robot = robot
        self.options = options or ReachingOptions()
        self._models: dict[tuple, IKModel] = {}

    def ik_model(self, hand: str, q_start: np.ndarray) -> IKModel:
        """The IK model for ``hand`` from ``q_start`` (cached on the locked joints' values)."""
        locked = [self.robot.gripper_joint(side) for side in ("left", "right")]
        if self.options.other_arm_still:
            locked += self.robot.arm_joints("right" if hand == "left" else "left")
        key = (hand, *np.round(np.asarray(q_start)[[self.robot.joint_index(n).idx_q for n in locked]], 9))
        model = self._models.get(key)
        if model is None:
            if len(self._models) >= MODEL_CACHE_SIZE:
                self._models.pop(next(iter(self._models)))
            model = self._models[key] = IKModel(self.robot, hand, q_start, self.options)
        return model

    # ------------------------------------------------------------------------------------- levels
    def _levels(
        self, ik: IKModel, spec: MotionSpec, q_start: np.ndarray
    ) -> tuple[list[Level], dict[str, Any]]:
        m, frames, opt = ik.model, self.robot.frames, self.options
        identity = pin.SE3.Identity()
        feet = {
            side: FramePoseTask(m, frames.sole(side), identity, name=f"{side}_sole")
            for side in ("left", "right")
        }
        com = ComPositionTask(m, np.zeros(3), mask=(True, True, opt.com_height), name="com")
        if spec.hand_rot is None:
            hand_task: Any = FramePositionTask(
                m, frames.grasp(ik.hand), spec.hand_ref_m[0], max_step=MAX_HAND_STEP_M, name="hand"
            )
        else:
            hand_task = FramePoseTask(
                m,
                frames.grasp(ik.hand),
                pin.SE3(spec.hand_rot[0], spec.hand_ref_m[0]),
                max_step=MAX_HAND_STEP_M,
                name="hand",
            )
        waist = FrameOrientationTask(m, frames.base, np.eye(3), gain=REST_GAIN, name="waist")
        W, S_l = ik.weights, opt.joint_limit_selection_rad
        # The waist never crouches below the robot's fall height (plus a margin): an inequality task
        # (eq. 4 of the footstep paper) with the feet, so that no motion of the hand can ask for it.
        base_min_z = float(self.robot.params.fall_base_height_m) + opt.base_height_margin_m
        base_height = FramePositionTask(
            m, frames.base, np.zeros(3), mask=(False, False, True), lower=base_min_z, name="base_height"
        )
        # The request's spheres (paper 000 eqs. 12-13 on the arm's capsules, the gripper's included):
        # inequalities with the feet, so that no task below can move the arm into one.
        spheres: tuple[Any, ...] = ()
        if spec.clearance is not None:
            start = spec.clearance.distances(m).at(q_start)
            spheres = tuple(spec.clearance.tasks(m, start))
        levels = [
            Level((feet["left"], feet["right"], base_height, *spheres), name="feet", weights=W),
            Level((com,), name="com", weights=W, lock_near_limits_rad=S_l),
            Level((hand_task,), name="hand", weights=W, lock_near_limits_rad=S_l, damping=HAND_DAMPING),
        ]
        tasks: dict[str, Any] = {"feet": feet, "com": com, "hand": hand_task, "waist": waist}
        if spec.gaze_ref_m is not None:
            gaze = GazeTask(
                m,
                frames.gaze,
                spec.gaze_ref_m[0],
                axis_in_camera=GAZE_AXIS,
                max_step=MAX_GAZE_STEP,
                name="gaze",
                form="direction",
            )
            levels.append(Level((gaze,), name="gaze", weights=W, lock_near_limits_rad=S_l))
            tasks["gaze"] = gaze
        if spec.posture_ref is not None:
            # The requested final posture (a footstep plan's, paper 000 §7) in the redundancy the four
            # tasks leave, its own level above the rest: the motion goes where that plan checked it.
            posture = PostureTask(m, ik.reduce_q(spec.posture_ref[0]), gain=POSTURE_GAIN, name="posture")
            levels.append(Level((posture,), name="posture", weights=W, lock_near_limits_rad=S_l))
            tasks["posture"] = posture
        rest: tuple[Any, ...] = (waist,)
        if opt.com_height_rest and not opt.com_height:
            # The CoM height back to its initial value with the waist, in the redundancy left: the
            # body does not crouch unless the hand needs it (a crouch that no task asks for ends on
            # the waist-height inequality and bounces there).
            com_z = ComPositionTask(m, np.zeros(3), mask=(False, False, True), gain=REST_GAIN, name="com_z")
            tasks["com_z"] = com_z
            rest = (waist, com_z)
        if opt.other_arm_rest and not opt.other_arm_still:
            # The arm without a task (free with S = I: the weighted pseudo-inverse moves it to help the
            # CoM) pulled back to where it started, in the redundancy the four tasks leave.
            other = self.robot.arm_joints("right" if ik.hand == "left" else "left")
            arm = PostureTask(m, q_start, other, gain=REST_GAIN, name="other_arm")
            tasks["other_arm"] = arm
            rest = (*rest, arm)
        levels.append(Level(rest, name="waist", weights=W))
        return levels, tasks

    # -------------------------------------------------------------------------------------- track
    def track(
        self,
        spec: MotionSpec,
        q_start: np.ndarray,
        hand: str,
        *,
        stop_at_violation: bool = True,
        com_offset_xy_m: np.ndarray | None = None,
        criteria: tuple[str, ...] | None = None,
    ) -> TrackResult:
        """Whole-body motion of ``spec`` from ``q_start`` (full model) reaching with ``hand``.

        ``com_offset_xy_m`` (n, 2) is added to the CoM reference (second preview stage corrections).
        With ``stop_at_violation`` the computation stops at the first criterion out of range (Fig. 4)
        and returns no trajectory. ``criteria``: the criteria monitored (None: the options'); all
        are recorded in ``monitors``.
        """
        t0 = time.perf_counter()
        opt = self.options
        limits = opt.thresholds(self.robot)
        criteria = opt.criteria_for(self.robot) if criteria is None else criteria
        n = spec.n_samples
        knots = list(range(0, n, opt.knot_stride))
        if knots[-1] != n - 1:
            knots.append(n - 1)
        ik = self.ik_model(hand, q_start)
        q = ik.reduce_q(q_start).copy()
        levels, tasks = self._levels(ik, spec, q)
        feet, com, hand_task, waist = tasks["feet"], tasks["com"], tasks["hand"], tasks["waist"]
        gaze = tasks.get("gaze")
        monitor = ik.monitor
        R_waist0 = self.robot.frame_pose(q_start, self.robot.frames.base).rotation
        yaw0 = float(spec.body_yaw_rad[0])
        com_xy = np.asarray(spec.com_xy_m) if com_offset_xy_m is None else spec.com_xy_m + com_offset_xy_m
        com_z = float(self.robot.com(q_start)[2])
        fade_s = max(DT_S, 0.8 * (spec.duration_s - spec.reach_end_s))

        clearance = spec.clearance
        if clearance is not None:
            sphere_distances = clearance.distances(ik.model)
            allowed = clearance.allowed(sphere_distances.at(q))
        values = [self._knot_values(ik, q, q, spec, 0, 1.0)]
        Q = np.empty((len(knots), ik.model.nq))
        Q[0] = q
        violation = None
        for i in range(1, len(knots)):
            budget.check(
                f"the reaching IK, knot {i} of {len(knots)}", {"knots_done": i, "knots": len(knots)}
            )
            k = knots[i]
            t_k = float(spec.times_s[k])
            for side, soles in (("left", spec.left_sole), ("right", spec.right_sole)):
                if i == 1 or np.any(soles[k] != soles[knots[i - 1]]):  # stance soles stay put
                    feet[side].set_target(pin.SE3(rot_z(float(soles[k, 3])), np.asarray(soles[k, :3])))
            com.set_target(np.array([com_xy[k, 0], com_xy[k, 1], com_z]))
            if "com_z" in tasks:
                tasks["com_z"].set_target(np.array([0.0, 0.0, com_z]))
            if spec.hand_rot is None:
                hand_task.set_target(spec.hand_ref_m[k])
            else:
                hand_task.set_target(pin.SE3(spec.hand_rot[k], spec.hand_ref_m[k]))
            if gaze is not None:
                gaze.set_target(spec.gaze_ref_m[k])
            if "posture" in tasks:
                tasks["posture"].set_rest(ik.reduce_q(spec.posture_ref[k]))
            if i == 1 or spec.body_yaw_rad[k] != spec.body_yaw_rad[knots[i - 1]]:
                waist.set_target(rot_z(float(spec.body_yaw_rad[k]) - yaw0) @ R_waist0)
            # Gauss-Newton steps from the previous knot (no velocity extrapolation: it would carry a
            # motion in the null space of the tasks that nothing brings back to rest). The waist level
            # pulls once per knot (refinement steps solve the four tasks alone, minimum norm) and fades
            # out once the hand has arrived, so that the motion ends at rest.
            waist_gain = REST_GAIN * float(1.0 - smoothstep5((t_k - spec.reach_end_s) / fade_s))
            waist.gain = max(waist_gain, 1e-9)
            if "other_arm" in tasks:
                tasks["other_arm"].gain = waist.gain
            q_knot = q
            # A hand still beyond the end-effector threshold after them gets ``recovery_iterations``
            # more (a joint reaching its limit, a foot landing: the IK redistributes the motion); a
            # hand out of reach stays behind and fails the criterion all the same.
            n_iterations = opt.max_iterations_per_knot + opt.recovery_iterations
            for iteration in range(n_iterations):
                step_levels = levels if iteration == 0 and waist_gain > 0.0 else levels[:-1]
                q = pin.integrate(ik.model, q, ik.solver.solve(step_levels, q))
                np.clip(q, ik.q_lower, ik.q_upper, out=q)
                error = np.linalg.norm(monitor.hand_position(q) - spec.hand_ref_m[k])
                if iteration + 1 >= opt.max_iterations_per_knot and error <= limits.ee_error_m:
                    break
                if error < opt.knot_tolerance_m:
                    break
            Q[i] = q
            values.append(self._knot_values(ik, q_knot, q, spec, k, (k - knots[i - 1]) * DT_S))
            if violation is None:
                violation = first_violation(criteria, values[-1], limits)
                if clearance is not None:  # the arm too near a sphere, or held off one
                    violation = clearance.at_knot(sphere_distances.at(q), allowed, t_k, violation)
                if violation is not None and stop_at_violation:
                    break
        monitors = MonitorSeries.from_knots(values)
        if violation is not None and stop_at_violation:
            return TrackResult(None, monitors, violation, len(values), time.perf_counter() - t0)
        q_red = spline_configurations(spec.times_s[knots], Q, spec.times_s)
        # The knots respect the joint limits; the spline between them may overshoot by a hair.
        np.clip(q_red, ik.q_lower, ik.q_upper, out=q_red)
        q_full = ik.expand_q(q_red, q_start)
        return TrackResult(q_full, monitors, violation, len(values), time.perf_counter() - t0)

    @staticmethod
    def _knot_values(
        ik: IKModel, q_before: np.ndarray, q: np.ndarray, spec: MotionSpec, k: int, dt_s: float
    ) -> KnotValues:
        hand, w, margin, torque_ratio = ik.monitor.evaluate(q)
        arm_step = pin.difference(ik.model, q_before, q)[ik.monitor.arm_v_idx]
        speed_ratio = float(np.max(np.abs(arm_step) / (dt_s * ik.v_max_arm)))
        return KnotValues(
            time_s=float(spec.times_s[k]),
            manipulability=w,
            ee_error_m=float(np.linalg.norm(hand - spec.hand_ref_m[k])),
            joint_limit_margin_rad=margin,
            joint_speed_ratio=speed_ratio,
            torque_ratio=torque_ratio,
            hand_m=hand,
            hand_ref_m=np.array(spec.hand_ref_m[k]),
        )
