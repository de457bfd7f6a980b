"""Whole-body joint trajectory of a walking pattern through the prioritized IK, with the multibody ZMP
check and the second preview-control stage of Kajita et al. 2003.

Priorities (``services.ik`` hierarchy, highest first): both soles on their pattern poses > the CoM on
the pattern CoM > waist and chest at their starting roll and pitch, turning with the pattern's waist
yaw > the caller's upper-body levels (holding a bar, a hand path, a gaze point) > the rest posture (the
starting configuration).

Speed: the IK is solved on knots every ``knot_stride`` samples, warm-started from the previous knot
extrapolated at constant velocity (q_pred = q_k (+) (q_k (-) q_{k-1})) and corrected by one (or more)
Gauss-Newton steps of the hierarchy; the 5 ms trajectory is a C2 cubic spline of the knots (joints, base
position, base roll/pitch/yaw). The tracking errors this leaves at the 5 ms samples are measured and
reported (``max_sole_error_m``, ``max_com_error_m``).

ZMP (Kajita 2003, section IV-B): the multibody ZMP of the joint trajectory is computed from pinocchio's
centroidal dynamics (:mod:`services.walking.multibody_zmp`). Where it is not inside the support polygon
with ``zmp_margin_m``, the error dp = p_ref - p_multibody goes through the same preview controller, whose
CoM output is added to the CoM reference, and the whole body is solved again (up to
``max_corrections`` times).
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin
from scipy.interpolate import CubicSpline

from services import budget
from services.errors import InfeasibleError, InvalidRequestError
from services.ik import (
    ComPositionTask,
    FrameOrientationTask,
    FramePoseTask,
    HierarchicalSolver,
    Level,
    PostureTask,
)
from services.walking.footsteps import FootstepSequence
from services.walking.multibody_zmp import MultibodyZmp
from services.walking.pattern import PatternOptions, WalkPattern
from services.walking.timing import WalkTiming
from services.walking.two_stage import SupportSamples, correct_multibody_zmp, robot_pattern
from services.walking.upper_body import GazeTarget, HandTarget, TaskError, UpperBody
from services.walking.zmp_reference import smoothstep5

KnotCallback = Callable[[int, float, np.ndarray], None]
"""``update(k, t_s, com_ref_m)`` called before the IK of knot sample ``k`` (time ``t_s``) so the caller
can move the targets of its own tasks."""


@dataclass(frozen=True)
class WholeBodyOptions:
    """Options of :class:`WholeBodyPlanner`.

    Attributes:
        knot_stride: samples between two IK knots (1: IK at every 5 ms sample).
        iterations_per_knot: Gauss-Newton steps of the hierarchy per knot; with caller levels at least
            ``min_iterations_with_extra_levels``. Two: with one, a robot standing 2.5-3.5 cm higher
            than half-sitting (after a reach) walking 0.2 m steps had a free arm ringing from knot to
            knot at 84-110 rad/s (the CoM level uses the arms where a stretched leg cannot hold the
            CoM height; the fetch's "LARM_JOINT0 would move at 4.8-11.5 rad/s" refusals); with two
            only the stretched knee is left (4.7-5.4 rad/s, which a lowered CoM removes: walking/plan
            and navigation/goto do that, ``COM_LOWERINGS_M``), for ~25 % more IK time.
        min_iterations_with_extra_levels: Gauss-Newton steps per knot when the caller adds levels.
            An upper-body task can be near-singular (an arm stretched out) or conflict with the CoM;
            with a single step per knot the constant-velocity prediction then rings from knot to
            knot (measured: a free arm alternating at 20 rad/s under a left-hand path on hrp2_like),
            two steps damp it out.
        zmp_margin_m: required distance of the multibody ZMP inside the support polygon [m].
        max_corrections: passes of the second preview stage at most.
        locked_joints: joints held at their starting value and left out of the IK (default: the
            grippers, whose open position is at a joint limit).
        posture_damping: damping of the posture level.
    """

    knot_stride: int = 8
    iterations_per_knot: int = 2
    min_iterations_with_extra_levels: int = 2
    zmp_margin_m: float = 0.010
    max_corrections: int = 2
    locked_joints: tuple[str, ...] | None = None
    posture_damping: float = 1e-6

    def validate(self) -> None:
        """InvalidRequestError on a bad value."""
        if not isinstance(self.knot_stride, int) or self.knot_stride < 1:
            raise InvalidRequestError(f"knot_stride must be an integer >= 1, got {self.knot_stride!r}")
        if not isinstance(self.iterations_per_knot, int) or self.iterations_per_knot < 1:
            raise InvalidRequestError(f"iterations_per_knot must be >= 1, got {self.iterations_per_knot!r}")
        if (
            not isinstance(self.min_iterations_with_extra_levels, int)
            or self.min_iterations_with_extra_levels < 1
        ):
            raise InvalidRequestError(
                "min_iterations_with_extra_levels must be >= 1, got "
                f"{self.min_iterations_with_extra_levels!r}"
            )
        if not (math.isfinite(self.zmp_margin_m) and self.zmp_margin_m >= 0):
            raise InvalidRequestError(f"zmp_margin_m must be >= 0 m, got {self.zmp_margin_m}")
        if self.max_corrections < 0:
            raise InvalidRequestError(f"max_corrections must be >= 0, got {self.max_corrections}")


@dataclass(frozen=True)
class WholeBodyResult:
    """The whole-body walk on the pattern's grid (n samples) and its figures.

    ``q`` is (n, nq) of the full robot model (base and every joint). ``zmp_distance_m`` is the signed
    distance of the multibody ZMP to the support polygon (< 0 inside). ``com_ref_m`` is the CoM target
    given to the IK (the pattern CoM plus the second-stage corrections). ``task_errors`` has the largest
    error of each upper-body task of :func:`plan_walk` (``hands``, ``gaze``), empty without them.
    """

    times_s: np.ndarray
    q: np.ndarray
    com_m: np.ndarray
    com_ref_m: np.ndarray
    zmp_planned_m: np.ndarray
    zmp_multibody_m: np.ndarray
    zmp_distance_m: np.ndarray
    pattern: WalkPattern
    corrections: int
    max_sole_error_m: float
    max_com_error_m: float
    wall_time_s: float
    history: tuple[dict[str, float], ...] = field(default=())
    task_errors: dict[str, TaskError] = field(default_factory=dict)

    @property
    def worst_zmp_outside_m(self) -> float:
        """Largest distance of the multibody ZMP outside the support polygon [m] (0 if always inside)."""
        return max(0.0, float(self.zmp_distance_m.max()))

    @property
    def min_zmp_margin_m(self) -> float:
        """Smallest distance of the multibody ZMP inside the polygon [m] (< 0 when it leaves it)."""
        return float(-self.zmp_distance_m.max())

    @property
    def real_time_factor(self) -> float:
        """Trajectory duration / computation time."""
        return float(self.times_s[-1] / self.wall_time_s)

    def figures(self) -> dict[str, Any]:
        """Plain-data summary for replies and benchmarks."""
        return {
            "duration_s": float(self.times_s[-1]),
            "wall_time_s": self.wall_time_s,
            "real_time_factor": self.real_time_factor,
            "worst_zmp_outside_mm": 1e3 * self.worst_zmp_outside_m,
            "min_zmp_margin_mm": 1e3 * self.min_zmp_margin_m,
            "corrections": self.corrections,
            "max_sole_error_mm": 1e3 * self.max_sole_error_m,
            "max_com_error_mm": 1e3 * self.max_com_error_m,
            "passes": list(self.history),
            "task_errors": {name: e.max_error for name, e in self.task_errors.items()},
        }


class WholeBodyPlanner:
    """Whole-body walking on one robot (``services.model.RobotModel``).

    ``model`` is the pinocchio model the IK works on (the robot with ``locked_joints`` removed): build
    the tasks of extra levels on it.
    """

    def __init__(self, robot: Any, options: WholeBodyOptions | None = None) -> None:
        self.robot = robot
        self.options = options or WholeBodyOptions()
        self.options.validate()
        locked = self.options.locked_joints
        if locked is None:
            locked = tuple(robot.gripper_joint(side) for side in ("left", "right"))
        for name in locked:
            robot.joint_index(name)  # InvalidRequestError naming the valid joints
        self.locked_joints = tuple(locked)
        self._locked_q_idx = np.array([robot.joint_index(n).idx_q for n in self.locked_joints], dtype=int)
        self._free_q_idx = np.setdiff1d(np.arange(robot.nq), self._locked_q_idx)
        ids = [robot.model.getJointId(n) for n in self.locked_joints]
        self.model: pin.Model = (
            pin.buildReducedModel(robot.model, ids, robot.q_half_sitting) if ids else robot.model
        )
        self.solver = HierarchicalSolver(self.model)
        self._sole_frames = {side: robot.frames.sole(side) for side in ("left", "right")}
        self._sole_ids = {side: self.model.getFrameId(f) for side, f in self._sole_frames.items()}

    # ------------------------------------------------------------------------------------ mapping
    def reduce_q(self, q_full: np.ndarray) -> np.ndarray:
        """Configuration of the IK model from a full one."""
        return np.asarray(q_full, dtype=float)[self._free_q_idx]

    def expand_q(self, q_reduced: np.ndarray, q_locked_from: np.ndarray) -> np.ndarray:
        """Full configurations (..., nq) from IK ones, locked joints taken from ``q_locked_from``."""
        q_reduced = np.asarray(q_reduced)
        out = np.empty((*q_reduced.shape[:-1], self.robot.nq))
        out[..., self._free_q_idx] = q_reduced
        out[..., self._locked_q_idx] = np.asarray(q_locked_from)[self._locked_q_idx]
        return out

    # ------------------------------------------------------------------------------------- solve
    def solve(
        self,
        pattern: WalkPattern,
        q_start: np.ndarray,
        *,
        extra_levels: Sequence[Level] = (),
        update_extra: KnotCallback | None = None,
    ) -> WholeBodyResult:
        """Joint trajectory of ``pattern`` from ``q_start`` (full model, soles on the pattern's start).

        Args:
            pattern: the first-stage pattern (its initial CoM should be the CoM of ``q_start``).
            q_start: starting configuration (nq of the full model).
            extra_levels: caller levels (upper-body tasks built on :attr:`model`), placed below the
                waist/chest orientation and above the posture. Their targets at t = 0 should hold at
                ``q_start``: the trajectory starts exactly at ``q_start``.
            update_extra: called before each knot's IK to move the caller's task targets.
        """
        t_start = time.perf_counter()
        robot = self.robot
        q_start = robot.check_q(q_start)
        self._check_start(pattern, q_start)
        com_pattern = np.array(pattern.com_m, dtype=float)

        def track(com_offset_xy_m: np.ndarray) -> np.ndarray:
            com_ref = com_pattern.copy()
            com_ref[:, :2] += com_offset_xy_m
            qs = self.expand_q(self._track(pattern, com_ref, q_start, extra_levels, update_extra), q_start)
            self._check_joint_motion(qs, pattern.dt_s, bool(extra_levels))
            return qs

        # Second preview stage (Kajita 2003 IV-B): CoM correction from dp = p_ref - p_multibody, faded
        # in over the standing start (a correction cannot act before t = 0) and brought to rest at zero
        # over the final segment (the robot stops there).
        out = correct_multibody_zmp(
            robot.model,
            track(np.zeros((pattern.n_samples, 2))),
            SupportSamples.of_pattern(pattern, robot.sole_size_m),
            pattern.gains,
            track,
            window=_correction_window(pattern),
            settle_samples=pattern.schedule.segments[-1].n + 1,
            margin_m=self.options.zmp_margin_m,
            max_corrections=self.options.max_corrections,
        )
        qs, mb, dist, corrections = out.q, out.zmp, out.distance_m, out.corrections
        com_ref = com_pattern.copy()
        com_ref[:, :2] += out.com_offset_m
        sole_err, com_err = self._tracking_errors(pattern, qs, mb, com_ref)
        wall = time.perf_counter() - t_start
        return WholeBodyResult(
            times_s=pattern.times_s,
            q=qs,
            com_m=mb.com_m,
            com_ref_m=com_ref,
            zmp_planned_m=pattern.zmp_planned_m,
            zmp_multibody_m=mb.zmp_m,
            zmp_distance_m=dist,
            pattern=pattern,
            corrections=corrections,
            max_sole_error_m=sole_err,
            max_com_error_m=com_err,
            wall_time_s=wall,
            history=out.history,
        )

    def _check_joint_motion(self, qs: np.ndarray, dt_s: float, has_extra_levels: bool) -> None:
        """Clip the splined joints to their limits (the knots are within them; the spline between two
        knots may overshoot by a hair) and raise InfeasibleError for a joint faster than its limit."""
        robot = self.robot
        lo, hi = robot.q_lower[7:], robot.q_upper[7:]
        np.clip(qs[:, 7:], lo, hi, out=qs[:, 7:])
        speed = np.abs(np.diff(qs[:, 7:], axis=0)) / dt_s
        ratio = speed / robot.v_max[6:]
        k, j = np.unravel_index(int(np.argmax(ratio)), ratio.shape)
        if ratio[k, j] > 1.0:
            over = np.flatnonzero(ratio.max(axis=1) > 1.0)
            breaks = np.flatnonzero(np.diff(over) > 1)
            starts = np.concatenate([[over[0]], over[breaks + 1]])
            stops = np.concatenate([over[breaks], [over[-1]]])
            hint = (
                ": an upper-body target is probably out of reach (the arm stretches and flips); bring it "
                "closer or hold it in the walk frame"
                if has_extra_levels
                else ""
            )
            name = robot.joint_names[j]
            raise InfeasibleError(
                f"joint {name} would move at {speed[k, j]:.1f} rad/s at t={k * dt_s:.3f} s, above its "
                f"limit {robot.v_max[6 + j]:.1f} rad/s{hint}",
                {
                    "joint": name,
                    "time_s": float(k * dt_s),
                    "speed": float(speed[k, j]),
                    "limit": float(robot.v_max[6 + j]),
                    # every stretch of time [s] in which some joint is faster than its limit
                    "over_limit_s": [
                        [float(a * dt_s), float((b + 1) * dt_s)] for a, b in zip(starts, stops, strict=True)
                    ],
                },
            )

    def _check_start(self, pattern: WalkPattern, q_start: np.ndarray) -> None:
        data = self.robot.new_data()
        for side in ("left", "right"):
            T = self.robot.sole_pose(q_start, side, data)
            target = pattern.sole(side)[0]
            err = float(np.linalg.norm(T.translation - target[:3]))
            if err > 0.005:
                raise InvalidRequestError(
                    f"the {side} sole of q_start is at ({T.translation[0]:.3f}, {T.translation[1]:.3f}, "
                    f"{T.translation[2]:.3f}) m but the footsteps start it at ({target[0]:.3f}, "
                    f"{target[1]:.3f}, {target[2]:.3f}) m ({1e3 * err:.1f} mm apart; at most 5 mm)"
                )

    def _levels(self, q_rest: np.ndarray, extra: Sequence[Level]) -> tuple[list[Level], dict[str, Any]]:
        m = self.model
        frames = self.robot.frames
        feet = {
            side: FramePoseTask(m, self._sole_frames[side], pin.SE3.Identity(), name=f"{side}_sole")
            for side in ("left", "right")
        }
        com = ComPositionTask(m, np.zeros(3))
        waist = FrameOrientationTask(m, frames.base, np.eye(3), name="waist")
        chest = FrameOrientationTask(m, frames.torso, np.eye(3), name="chest")
        posture = PostureTask(m, q_rest)
        levels = [
            Level((feet["left"], feet["right"]), name="feet"),
            Level((com,), name="com"),
            Level((waist, chest), name="waist_chest"),
            *extra,
            Level((posture,), name="posture", damping=self.options.posture_damping),
        ]
        return levels, {"feet": feet, "com": com, "waist": waist, "chest": chest}

    def _track(
        self,
        pattern: WalkPattern,
        com_ref: np.ndarray,
        q_start: np.ndarray,
        extra: Sequence[Level],
        update_extra: KnotCallback | None,
    ) -> np.ndarray:
        """IK on the knots, spline to every sample: (n, nq_reduced)."""
        n = pattern.n_samples
        stride = self.options.knot_stride
        knots = list(range(0, n, stride))
        if knots[-1] != n - 1:
            knots.append(n - 1)
        q = self.reduce_q(q_start)
        iterations = self.options.iterations_per_knot
        if extra:
            iterations = max(iterations, self.options.min_iterations_with_extra_levels)
        levels, tasks = self._levels(q.copy(), extra)
        feet, com, waist, chest = tasks["feet"], tasks["com"], tasks["waist"], tasks["chest"]
        model = self.model
        # Waist and chest keep their starting roll and pitch and turn with the feet (the pattern's yaw).
        data = self.robot.new_data()
        R_waist0 = self.robot.frame_pose(q_start, self.robot.frames.base, data).rotation
        R_chest0 = self.robot.frame_pose(q_start, self.robot.frames.torso, data).rotation
        Q = np.empty((len(knots), model.nq))
        Q[0] = q  # the trajectory starts exactly at the robot's configuration
        q_prev = None
        dq_prev: np.ndarray | None = None  # tangent step between the last two knots
        for i, k in enumerate(knots):
            if i == 0:
                q_prev = q.copy()
                continue
            budget.check(
                f"the whole-body IK of the walk, knot {i} of {len(knots)}",
                {"knots_done": i, "knots": len(knots), "samples": n},
            )
            for side in ("left", "right"):
                feet[side].set_target(pin.SE3(pattern.sole_transform(side, k)))
            com.set_target(com_ref[k])
            yaw = float(pattern.waist_yaw_rad[k] - pattern.waist_yaw_rad[0])
            c, s = math.cos(yaw), math.sin(yaw)
            Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
            waist.set_target(Rz @ R_waist0)
            chest.set_target(Rz @ R_chest0)
            if update_extra is not None:
                update_extra(k, float(pattern.times_s[k]), com_ref[k])
            # Prediction from the last knots, then Gauss-Newton steps. Without caller levels: constant
            # acceleration from the last three knots (the residual one step leaves is half that of a
            # constant-velocity prediction: a walk with 0.7 s of single support tracked its CoM within
            # 0.6 mm, 1.15 mm before). With caller levels (two steps per knot, see the options) constant
            # velocity: a near-singular arm's step would be extrapolated further and ring.
            h = (k - knots[i - 1]) / stride
            dq = pin.difference(model, q_prev, q)
            step = dq * h
            if dq_prev is not None and not extra:
                step += 0.5 * (dq - dq_prev) * h * (h + 1.0)
            q_pred = pin.integrate(model, q, step)
            q_prev, q, dq_prev = q, q_pred, dq
            for _ in range(iterations):
                q = pin.integrate(model, q, self.solver.solve(levels, q))
            Q[i] = q
        return _spline_configurations(pattern.times_s[knots], Q, pattern.times_s)

    def _tracking_errors(
        self, pattern: WalkPattern, qs: np.ndarray, mb: MultibodyZmp, com_ref: np.ndarray
    ) -> tuple[float, float]:
        """Largest sole position error and CoM error [m] over every sample."""
        model, data = self.robot.model, self.robot.new_data()
        ids = {side: self.robot.frame_id(self._sole_frames[side]) for side in ("left", "right")}
        soles = {"left": pattern.left_sole, "right": pattern.right_sole}
        err = 0.0
        for k in range(qs.shape[0]):
            if k % 500 == 0:
                budget.check(f"the tracking errors of the walk, sample {k} of {qs.shape[0]}")
            pin.forwardKinematics(model, data, qs[k])
            for side, fid in ids.items():
                p = pin.updateFramePlacement(model, data, fid).translation
                err = max(err, float(np.abs(p - soles[side][k, :3]).max()))
        com_err = float(np.abs(mb.com_m - com_ref).max())
        return err, com_err


def _correction_window(pattern: WalkPattern) -> np.ndarray:
    """Weight (n,) of the ZMP error fed to the second stage: 0 -> 1 over the standing start segment,
    1 -> 0 over the first half of the final hold (if the schedule has these segments), else 1."""
    w = np.ones(pattern.n_samples)
    for seg in pattern.schedule.segments:
        if seg.role == "start":
            w[seg.start : seg.stop] = smoothstep5(np.arange(seg.n) / seg.n)
        elif seg.role == "hold":
            half = max(1, seg.n // 2)
            w[seg.start : seg.start + half] = 1.0 - smoothstep5(np.arange(half) / half)
            w[seg.start + half :] = 0.0
    return w


def _spline_configurations(t_knots: np.ndarray, Q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """C2 cubic spline of free-flyer configurations: base position, base roll/pitch/(unwrapped) yaw and
    joints are splined; the quaternion is rebuilt from the angles. (knots, nq) -> (len(t), nq)."""
    if Q.shape[0] == 1:
        return np.repeat(Q, t.shape[0], axis=0)
    quat = Q[:, 3:7]  # x, y, z, w
    rpy = _quat_to_rpy(quat)
    rpy[:, 2] = np.unwrap(rpy[:, 2])
    values = np.column_stack([Q[:, :3], rpy, Q[:, 7:]])
    S = CubicSpline(t_knots, values, bc_type="clamped")(t)
    out = np.empty((t.shape[0], Q.shape[1]))
    out[:, :3] = S[:, :3]
    out[:, 3:7] = _rpy_to_quat(S[:, 3:6])
    out[:, 7:] = S[:, 6:]
    return out


def _quat_to_rpy(q: np.ndarray) -> np.ndarray:
    """(n, 4) quaternions (x, y, z, w) -> (n, 3) roll, pitch, yaw (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    x, y, z, w = q.T
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.column_stack([roll, pitch, yaw])


def _rpy_to_quat(rpy: np.ndarray) -> np.ndarray:
    """Inverse of :func:`_quat_to_rpy`: (n, 3) -> (n, 4) quaternions (x, y, z, w)."""
    cr, sr = np.cos(rpy[:, 0] / 2), np.sin(rpy[:, 0] / 2)
    cp, sp = np.cos(rpy[:, 1] / 2), np.sin(rpy[:, 1] / 2)
    cy, sy = np.cos(rpy[:, 2] / 2), np.sin(rpy[:, 2] / 2)
    return np.column_stack(
        [
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy,
        ]
    )


def plan_walk(
    robot: Any,
    footsteps: FootstepSequence,
    q_start: np.ndarray,
    timing: WalkTiming | None = None,
    options: PatternOptions | None = None,
    wholebody_options: WholeBodyOptions | None = None,
    *,
    extra_levels: Sequence[Level] = (),
    update_extra: KnotCallback | None = None,
    planner: WholeBodyPlanner | None = None,
    hands: Sequence[HandTarget] = (),
    gaze: GazeTarget | None = None,
    com_lowering_m: float = 0.0,
) -> WholeBodyResult:
    """Footsteps -> whole-body walk in one call: the pattern (footsteps validated against the robot's
    bounds, CoM starting at the CoM of ``q_start``, the ground at the height of its soles, step height
    from the robot's parameters unless ``options`` says otherwise; ``com_lowering_m`` [m] as in
    :func:`services.walking.two_stage.robot_pattern`), then :meth:`WholeBodyPlanner.solve`.
    Pass ``planner`` to reuse one.

    ``hands`` and ``gaze`` add the upper-body tasks of :mod:`services.walking.upper_body` below
    ``extra_levels``; their largest errors over the trajectory are in ``result.task_errors``."""
    q_start = robot.check_q(q_start)
    pattern = robot_pattern(robot, footsteps, q_start, timing, options, com_lowering_m=com_lowering_m)
    planner = planner or WholeBodyPlanner(robot, wholebody_options)
    if not hands and gaze is None:
        return planner.solve(pattern, q_start, extra_levels=extra_levels, update_extra=update_extra)
    upper = UpperBody(
        planner.model,
        robot,
        q_start,
        pattern.com_m[0],
        pattern.waist_yaw_rad,
        pattern.times_s,
        hands=hands,
        gaze=gaze,
    )

    def update(k: int, t_s: float, com_ref_m: np.ndarray) -> None:
        if update_extra is not None:
            update_extra(k, t_s, com_ref_m)
        upper.update(k, t_s, com_ref_m)

    levels = (*extra_levels, *upper.levels)
    try:
        result = planner.solve(pattern, q_start, extra_levels=levels, update_extra=update)
    except InfeasibleError as exc:
        if "joint" not in exc.details:
            raise
        # A joint too fast under upper-body tasks: name the task that cannot be met (one more IK pass).
        qs = planner.expand_q(planner._track(pattern, pattern.com_m, q_start, levels, update), q_start)
        errors = {n: e for n, e in upper.errors(qs, pattern.com_m).items() if e.unit == "m"}
        name, worst = max(errors.items(), key=lambda item: item[1].max_error)
        d = exc.details
        raise InfeasibleError(
            f"upper-body task {name} cannot be met: it stays {1e3 * worst.max_error:.0f} mm from its target "
            f"(worst at t={worst.time_s:.3f} s) and reaching for it moves joint {d['joint']} at "
            f"{d['speed']:.1f} rad/s (limit {d['limit']:.1f}) at t={d['time_s']:.3f} s; bring the target "
            "closer to the body",
            {**exc.details, "task": name, "task_error_m": worst.max_error, "task_time_s": worst.time_s},
        ) from exc
    return dataclasses.replace(result, task_errors=upper.errors(result.q, result.com_ref_m))
