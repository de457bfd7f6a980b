"""From a footstep plan to a whole-body motion: the planned footsteps go through the walking pattern
generator (``services.walking``, ZMP preview control, Kajita et al. 2003) and its whole-body stage, then
the final reaching motion brings the robot, standing on the final footprints, to the planned final
configuration. Section 4.2 of the footstep paper: "a dynamic walk is planned over the support polygons
produced by the local foot placement planner, then the whole body is driven by a reaching task".

The reaching motion tracks a smooth (quintic in time) joint-space interpolation from the end of the
walk to the planned configuration with the prioritized IK, under both soles held on their footprints,
the CoM over the support polygon (eq. 11) and the self-collision constraints (eqs. 12-13: Fig. 8's
"the whole body is driven by a reaching task while observing self-collision avoidance constraints");
the 5 ms samples between IK knots are a C2 spline of the knots. The hands' collision boxes stay above
the floor as in the plan (``services.footsteps.hand_floor``).
Execution in the simulator is the caller's (the sim service plays ``q``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.footsteps.hand_floor import hand_floor_task
from services.footsteps.request import FootstepPlanRequest, FootstepPlanResult
from services.ik.level import Level
from services.ik.solver import HierarchicalSolver
from services.ik.tasks.com_support_polygon import ComSupportPolygonTask
from services.ik.tasks.frame_pose import FramePoseTask
from services.ik.tasks.frame_position import FramePositionTask
from services.ik.tasks.ground_clearance import GroundClearanceTask
from services.ik.tasks.posture import PostureTask
from services.ik.tasks.self_collision import SelfCollisionTask
from services.model import RobotModel
from services.model.ground import signed_distance, smoothstep5
from services.reaching.spline import spline_configurations
from services.walking.multibody_zmp import multibody_zmp
from services.walking.timing import WalkTiming
from services.walking.two_stage import WalkAdjustment, executable_walk
from services.walking.wholebody import WholeBodyResult


@dataclass(frozen=True)
class FootstepExecution:
    """The whole motion on a regular grid.

    Attributes:
        times_s: (n,) sample times [s] from 0, step ``dt_s``.
        q: (n, nq) robot configurations (world free-flyer).
        walk_end_s: time at which the walk ends and the reaching motion starts [s] (0 without steps).
        walk: the walking planner's result (None without steps).
        reach_max_sole_drift_m: largest sole displacement from its footprint during the reach [m].
        reach_min_com_margin_m: smallest distance of the CoM projection inside the support polygon
            during the reach [m].
        reach_min_self_distance_m: smallest surface distance between two checked capsules of the
            robot during the reach [m] (nan: the robot has no collision pairs).
        final_errors_m: distance of each reaching hand to its target at the last sample [m].
        walk_adjustment: the CoM lowering and support slowdown the walk needed to keep every joint
            within its speed limit (``services.walking.two_stage.executable_walk``; None without steps).
        reach_min_hand_floor_m: lowest height above the floor of a corner of the hands' collision
            boxes during the reach [m].
        reach_speed_rad_s: the speed of the largest joint motion of the reach, after the slowdowns
            that keep its multibody ZMP inside the support polygon [rad/s].
        reach_min_zmp_margin_m: smallest distance of the reach's multibody ZMP inside the support
            polygon [m] (negative: outside).
    """

    times_s: np.ndarray
    q: np.ndarray
    dt_s: float
    walk_end_s: float
    walk: WholeBodyResult | None
    reach_max_sole_drift_m: float
    reach_min_com_margin_m: float
    final_errors_m: dict[str, float]
    reach_min_self_distance_m: float = math.nan
    walk_adjustment: WalkAdjustment | None = None
    reach_min_hand_floor_m: float = math.nan
    reach_speed_rad_s: float = math.nan
    reach_min_zmp_margin_m: float = math.nan

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])


# lambda of eqs. (11) and (13) [1/s]: the CoM and the capsules approach their bounds at most lambda times
# their distance to them per second, so that the approach slows down smoothly. A gain of 1 per
# Gauss-Newton step (lambda = 1/step) stops the approach within one knot: a velocity jump whose multibody
# ZMP leaves the support polygon (the section 4.2 pick-up tipped over in the sim when the right arm
# reached the 1 cm margin to the right leg: 7 m/s^2 of CoM acceleration in one sample).
CONSTRAINT_RATE_PER_S = 5.0
# A constraint that starts or stops binding (a hand sliding along its 1 cm margin to the thigh: the
# closest points of two near-parallel capsules jump along them) turns the IK's velocity in one knot: a
# kink whose acceleration moved the multibody ZMP up to 0.6 m out of the support polygon in the section
# 4.2 pick-up, and the robot rocked in the sim. The knots are therefore smoothed by a Gaussian of this
# standard deviation [s] before the spline (the ends held: the robot at rest); the constraints' margins
# (1 cm) absorb the rounding of the path, and the distances reported are those of the smoothed motion.
KNOT_SMOOTHING_S = 0.1
# The reach is kinematic (soles held, the CoM's projection d = 3 cm inside the support polygon); its
# multibody ZMP must stay this far inside the polygon [m], else it is replanned this much slower (at
# most REACH_SLOWDOWNS times): the section 4.2 pick-up, the hand reaching the floor 13 cm ahead of the
# toes, tipped onto its toes in the sim at 0.3 rad/s (ZMP 5 cm outside); at 0.1 rad/s it stays inside.
REACH_ZMP_MARGIN_M = 0.005
REACH_SLOWDOWN = 0.6
REACH_SLOWDOWNS = 4
REACH_HAND_SPEED_M_S = 0.15  # the hands' speed along their approach paths at 0.3 rad/s [m/s]
SETTLE_KNOTS = 25  # at most this many knots after the last one of the interpolation ...
SETTLE_TOL = 1e-4  # ... until a knot moves no coordinate more than this [rad or m]


def smooth_knots(q_knots: np.ndarray, sigma_knots: float) -> np.ndarray:
    """``q_knots`` (k, nq; free flyer first: position, quaternion) smoothed along the knots by a
    Gaussian of ``sigma_knots`` knots, padded with the first and last knot (held); quaternions
    renormalized."""
    if sigma_knots <= 0.0 or q_knots.shape[0] < 3:
        return q_knots
    half = math.ceil(3.0 * sigma_knots)
    offsets = np.arange(-half, half + 1, dtype=float)
    kernel = np.exp(-0.5 * (offsets / sigma_knots) ** 2)
    kernel /= kernel.sum()
    padded = np.concatenate((np.repeat(q_knots[:1], half, 0), q_knots, np.repeat(q_knots[-1:], half, 0)))
    windows = np.lib.stride_tricks.sliding_window_view(padded, q_knots.shape[0], axis=0)  # (2h+1, nq, k)
    out = np.einsum("w,wqk->kq", kernel, windows)
    out[:, 3:7] /= np.linalg.norm(out[:, 3:7], axis=1, keepdims=True)
    return out


def self_collision(robot: RobotModel, margin_m: float, gain: float = 1.0) -> SelfCollisionTask | None:
    """Eqs. (12)-(13) on the robot's capsules and checked pairs (None: the robot has none); ``gain``:
    lambda of eq. (13) per solver step."""
    if not robot.collision_pairs:
        return None
    pairs = list(robot.collision_pairs)
    return SelfCollisionTask(robot.model, list(robot.capsules), pairs, margin_m=margin_m, gain=gain)


def _support_level(
    robot: RobotModel,
    q_stance: np.ndarray,
    com_margin_m: float,
    collision: SelfCollisionTask | None,
    gain: float = 1.0,
    floor: GroundClearanceTask | None = None,
) -> Level:
    """Both soles held where they are at ``q_stance``, the CoM over the support polygon (eq. 11, lambda
    ``gain`` per solver step), the self-collision constraints (eqs. 12-13) and the hands above the floor
    when given."""
    model = robot.model
    data = robot.new_data()
    tasks = [
        FramePoseTask(model, f, robot.frame_pose(q_stance, f, data), name=f"hold:{f}")
        for f in (robot.frames.left_sole, robot.frames.right_sole)
    ]
    tasks.append(
        ComSupportPolygonTask(
            model,
            com_margin_m,
            sole_frames=(robot.frames.left_sole, robot.frames.right_sole),
            sole_size_m=robot.sole_size_m,
            gain=gain,
        )
    )
    if collision is not None:
        tasks.append(collision)
    if floor is not None:
        tasks.append(floor)
    return Level(tuple(tasks), name="support")


def approach_path(p_start: np.ndarray, p_target: np.ndarray, clearance_m: float = 0.08) -> np.ndarray:
    """Hand waypoints (3, 3) [m]: straight from ``p_start`` to ``clearance_m`` above the target, then
    down on it (the hand does not sweep into what holds the object)."""
    p_start = np.asarray(p_start, dtype=float)
    p_target = np.asarray(p_target, dtype=float)
    return np.array([p_start, p_target + np.array([0.0, 0.0, clearance_m]), p_target])


def _along(path: np.ndarray, s: float) -> np.ndarray:
    """The point at arc-length fraction ``s`` of a polyline."""
    lengths = np.linalg.norm(np.diff(path, axis=0), axis=1)
    total = float(lengths.sum())
    if total < 1e-12:
        return path[-1].copy()
    d = min(max(s, 0.0), 1.0) * total
    for i, seg in enumerate(lengths):
        if d <= seg or i == len(lengths) - 1:
            return path[i] + (path[i + 1] - path[i]) * (d / seg if seg > 0 else 1.0)
        d -= seg
    return path[-1].copy()


def reaching_motion(
    robot: RobotModel,
    q_from: np.ndarray,
    q_to: np.ndarray,
    *,
    dt_s: float = 0.005,
    speed_rad_s: float = 0.5,
    min_duration_s: float = 1.0,
    knot_stride: int = 4,
    com_margin_m: float = 0.03,
    hand_paths: dict[str, np.ndarray] | None = None,
    hand_speed_m_s: float = REACH_HAND_SPEED_M_S,
    self_collision_margin_m: float | None = 0.01,
    iterations_per_knot: int = 2,
    hand_floor_margin_m: float | None = 0.01,
) -> tuple[np.ndarray, float, float, float, float]:
    """Motion from ``q_from`` to ``q_to`` (both standing on the same footprints): (q (n, nq), largest
    sole drift [m], smallest CoM margin [m], smallest self-collision distance [m], nan without
    collision pairs, lowest hand box corner above the floor [m]). The joints follow a quintic-in-time
    interpolation (the largest moving at about ``speed_rad_s``) and, in a level above, each frame of
    ``hand_paths`` follows its polyline (at about ``hand_speed_m_s``), under the soles held, the CoM
    over the support polygon, the capsules kept ``self_collision_margin_m`` apart (None: self-collisions
    not constrained) and the hands' collision boxes ``hand_floor_margin_m`` above the floor z = 0 (None:
    not constrained)."""
    q_from = robot.check_q(q_from)
    q_to = robot.check_q(q_to)
    model = robot.model
    data = robot.new_data()
    sole_frames = (robot.frames.left_sole, robot.frames.right_sole)
    T_soles = [robot.frame_pose(q_to, f, data) for f in sole_frames]
    posture = PostureTask(model, q_to, joint_names=list(robot.joint_names))
    paths = {f: np.asarray(path, dtype=float) for f, path in (hand_paths or {}).items()}
    hands = [FramePositionTask(model, f, path[0]) for f, path in paths.items()]
    # Eqs. (11) and (13) with lambda = CONSTRAINT_RATE_PER_S over the knots' solver steps (two per knot).
    gain = min(1.0, CONSTRAINT_RATE_PER_S * knot_stride * dt_s / iterations_per_knot)
    collision = (
        None if self_collision_margin_m is None else self_collision(robot, self_collision_margin_m, gain)
    )
    floor = (
        None if hand_floor_margin_m is None else hand_floor_task(robot, model, hand_floor_margin_m, gain=gain)
    )
    levels = [_support_level(robot, q_to, com_margin_m, collision, gain, floor)]
    if hands:
        levels.append(Level(tuple(hands), name="hands"))
    levels.append(Level((posture,), name="posture"))
    solver = HierarchicalSolver(model)
    move = float(np.max(np.abs(pin.difference(model, q_from, q_to)[6:])))
    path_length = max(
        (float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum()) for p in paths.values()), default=0.0
    )
    duration = max(min_duration_s, move / speed_rad_s, path_length / hand_speed_m_s)
    n = math.ceil(duration / dt_s) + 1
    knots = list(range(0, n, knot_stride))
    if knots[-1] != n - 1:
        knots.append(n - 1)
    q = q_from.copy()
    q_knots = [q.copy()]
    for k in knots[1:]:
        s = float(smoothstep5(k * dt_s / duration))
        posture.set_rest(pin.interpolate(model, q_from, q_to, s))
        for task, path in zip(hands, paths.values(), strict=True):
            task.set_target(_along(path, s))
        for _ in range(iterations_per_knot):
            q = pin.integrate(model, q, solver.solve(levels, q))
        q_knots.append(q.copy())
    # Settle on the planned configuration over more knots (the IK's last corrections, slowed by the
    # dampers of eqs. 11 and 13, jolted the multibody ZMP when they were squeezed into the last knot).
    for _ in range(SETTLE_KNOTS):
        before = q
        for _ in range(iterations_per_knot):
            q = pin.integrate(model, q, solver.solve(levels, q))
        knots.append(knots[-1] + knot_stride)
        q_knots.append(q.copy())
        if float(np.max(np.abs(pin.difference(model, before, q)))) < SETTLE_TOL:
            break
    n = knots[-1] + 1
    q_smooth = smooth_knots(np.array(q_knots), KNOT_SMOOTHING_S / (knot_stride * dt_s))
    # C2 spline through the knots (a piecewise-linear path jumps in velocity at every knot, and the
    # multibody ZMP with it).
    out = spline_configurations(dt_s * np.asarray(knots, dtype=float), q_smooth, dt_s * np.arange(n))
    drift, margin = 0.0, math.inf
    floor_checker = floor or hand_floor_task(robot, model, 0.0)
    hand_floor = math.inf
    checker = collision or self_collision(robot, 0.0)
    self_distance = math.inf if checker is not None else math.nan
    for qk in out[:: max(1, knot_stride // 2)]:
        pin.framesForwardKinematics(model, data, qk)
        if checker is not None:
            self_distance = min(self_distance, float(checker.distances(data).min()))
        hand_floor = min(hand_floor, float(floor_checker.heights(data).min()))
        for f, T in zip(sole_frames, T_soles, strict=True):
            drift = max(
                drift, float(np.linalg.norm(data.oMf[model.getFrameId(f)].translation - T.translation))
            )
        margin = min(
            margin, -float(signed_distance(robot.com(qk, data)[:2], robot.support_polygon(qk, data=data))[0])
        )
    return out, drift, margin, self_distance, hand_floor


def zmp_margin_m(robot: RobotModel, q: np.ndarray, dt_s: float) -> float:
    """Smallest distance [m] of the multibody ZMP of the motion ``q`` (n, nq), at rest before and after,
    inside the support polygon of its soles (at the first sample; negative: outside)."""
    polygon = robot.support_polygon(q[0])
    zmp = multibody_zmp(robot.model, q, dt_s).zmp_m
    return -float(signed_distance(zmp, polygon).max())


def execute_plan(
    robot: RobotModel,
    request: FootstepPlanRequest,
    result: FootstepPlanResult,
    *,
    dt_s: float = 0.005,
    reach_speed_rad_s: float = 0.3,
    timing: WalkTiming | None = None,
) -> FootstepExecution:
    """Footsteps -> walking pattern generator (whole body) -> final reaching motion.

    Raises:
        InvalidRequestError / InfeasibleError from the walking planner (footsteps it rejects).
    """
    if robot.name != request.robot:
        raise InvalidRequestError(f"robot {robot.name!r} does not match request.robot {request.robot!r}")
    q_start = np.asarray(
        request.q_start if request.q_start is not None else robot.q_half_sitting, dtype=float
    )
    q_final = np.asarray(result.q_final, dtype=float)
    walk = adjustment = None
    if result.footsteps:
        # The footsteps may sit at the corners of the paper's bounds: the walk's CoM height and timing
        # are derived so that the joints stay within their speed limits.
        walk, adjustment = executable_walk(robot, result.footstep_sequence(), q_start, timing)
        if abs(walk.pattern.dt_s - dt_s) > 1e-12:
            raise InvalidRequestError(f"dt_s must be the walking grid {walk.pattern.dt_s} s, got {dt_s}")
        q_walk = walk.q
    else:
        q_walk = q_start[None, :]
    # The reaching hands lift, move over their target and come down on it (approach_path).
    data = robot.new_data()
    hand_paths = {
        robot.frames.grasp(t.hand): approach_path(
            robot.frame_pose(q_walk[-1], robot.frames.grasp(t.hand), data).translation, np.asarray(t.target_m)
        )
        for t in request.tasks
        if t.kind == "reach"
    }
    speed = reach_speed_rad_s
    for attempt in range(REACH_SLOWDOWNS + 1):
        q_reach, drift, margin, self_distance, hand_floor = reaching_motion(
            robot,
            q_walk[-1],
            q_final,
            dt_s=dt_s,
            speed_rad_s=speed,
            hand_speed_m_s=REACH_HAND_SPEED_M_S * speed / reach_speed_rad_s,
            hand_paths=hand_paths,
            hand_floor_margin_m=request.options.hand_floor_margin_m if request.options.hand_floor else None,
        )
        zmp_margin = zmp_margin_m(robot, q_reach, dt_s)
        if zmp_margin >= REACH_ZMP_MARGIN_M or attempt == REACH_SLOWDOWNS:
            break
        speed *= REACH_SLOWDOWN
    segments = [q_walk, q_reach[1:]]
    q = np.vstack(segments)
    times = dt_s * np.arange(q.shape[0])
    data = robot.new_data()
    errors = {}
    for task in request.tasks:
        if task.kind == "reach":
            p = robot.frame_pose(q[-1], robot.frames.grasp(task.hand), data).translation
            errors[task.name] = float(np.linalg.norm(p - np.asarray(task.target_m)))
    return FootstepExecution(
        times_s=times,
        q=q,
        dt_s=dt_s,
        walk_end_s=float(dt_s * (q_walk.shape[0] - 1)),
        walk=walk,
        reach_max_sole_drift_m=drift,
        reach_min_com_margin_m=margin,
        final_errors_m=errors,
        reach_min_self_distance_m=self_distance,
        walk_adjustment=adjustment,
        reach_min_hand_floor_m=hand_floor,
        reach_speed_rad_s=speed,
        reach_min_zmp_margin_m=zmp_margin,
    )
