"""Messages of the ``reaching`` service: whole-body reaching with task-driven support polygon reshaping
("Task-driven Support Polygon Reshaping for Reaching", ``001_771c0ce3779b0683.txt``).

Configurations follow the pinocchio layout of the service's robot model (``ReachReply.model``):
``q = [x, y, z, qx, qy, qz, qw, joints...]`` (base position [m] and orientation in the world, then joint
positions [rad], or [m] for prismatic grippers). World frame: z up, ground at z = 0. Arrays travel as raw
bytes (binary frames of ``services.bus.codec``).
"""

from __future__ import annotations

from typing import Annotated

import msgspec
import numpy as np

from services.bus.limits import MAX_OBSTACLES, Budget, Margin, Name, Point3, Quaternion
from services.bus.schemas.common import Footstep, Sphere
from services.bus.spec import EndpointSpec

#: The monitored criteria (paper 001 Fig. 4): the names of ``Attempt.violation`` and of
#: ``details["criterion"]`` of ``reaching/reach``'s ``infeasible`` replies (sub-reasons across processes).
CRITERION_MANIPULABILITY = "manipulability"  # the arm's manipulability (eq. 5) below its threshold
CRITERION_EE_ERROR = "ee_error"  # the hand behind its reference by more than its threshold
CRITERION_JOINT_SPEED = "joint_speed"  # an arm joint faster than its share of the velocity limit
CRITERION_JOINT_TORQUE = "joint_torque"  # a static torque above its share of the effort limit
CRITERION_JOINT_LIMITS = "joint_limits"  # an arm joint at its limit
CRITERION_MULTIBODY_ZMP = "multibody_zmp"  # the multibody ZMP leaves the support polygon (or has none)
# the arm (gripper and wrist included) within the clearance of a ``hand_obstacles`` sphere, or held off it
# while the hand falls behind its path
CRITERION_HAND_OBSTACLE = "hand_obstacle"

#: ``details["reason"]`` of ``reaching/reach``'s ``infeasible`` replies: why no motion was kept.
REASON_STEPPING_NOT_ALLOWED = "stepping_not_allowed"  # a criterion failed and allow_stepping is false
REASON_TOO_MANY_STEPS = "too_many_steps"  # reshaping the support polygon would need more than max_steps
REASON_FAILED_AFTER_RESHAPING = "failed_after_reshaping"  # a criterion still fails after every reshaping
# the hand's path passes within the clearance of a ``hand_obstacles`` sphere however it is planned
# (``details``: ``sphere`` its index, ``link`` the capsule, ``distance_m``, ``clearance_m``, ``time_s``)
REASON_HAND_OBSTACLE = "hand_obstacle"


#: Bounds of a request's own timing (``hand_speed_m_s``, ``min_duration_s``, ``final_hold_s``).
MAX_HAND_SPEED_M_S = 0.6  # mean hand speed [m/s] (1.125 m/s at the peak of the minimum-jerk profile)
MIN_DURATION_RANGE_S = (0.4, 5.0)  # the shortest motion [s]
MAX_FINAL_HOLD_S = 2.0  # standing still at the end [s]
HandSpeed = Annotated[float, msgspec.Meta(gt=0.0, le=MAX_HAND_SPEED_M_S, description="hand speed [m/s]")]
ReachDuration = Annotated[
    float, msgspec.Meta(ge=MIN_DURATION_RANGE_S[0], le=MIN_DURATION_RANGE_S[1], description="duration [s]")
]
HoldTime = Annotated[float, msgspec.Meta(ge=0.0, le=MAX_FINAL_HOLD_S, description="hold [s]")]


class ReachRequest(msgspec.Struct, kw_only=True, frozen=True, forbid_unknown_fields=True):
    """Reach ``target`` with the grasp frame of ``hand``, starting from ``q_start`` (planners are
    stateless: plan from the robot's measured configuration, e.g. ``sim/state``)."""

    hand: Name  # "left" or "right"
    target: Point3  # [x, y, z] of the grasp frame origin, world frame [m]
    q_start: np.ndarray  # (nq,) float64 starting configuration, both soles flat on the ground
    orientation: Quaternion | None = (
        None  # [qx, qy, qz, qw] of the grasp frame at the target; None: position only
    )
    gaze: bool = True  # keep the gaze on the target (task iv)
    allow_stepping: bool = True  # the support polygon may be reshaped by stepping
    weighted: bool | None = (
        None  # weighted pseudo-inverse of eq. (4) (link mass ratios); None: service default
    )
    # selection matrix S_l margin [rad]; None: service default
    joint_limit_selection_rad: Margin | None = None
    # the end-effector criterion's threshold [m] (the hand's distance behind its reference at a knot);
    # None: the robot's (the paper's 4e-5 m, a trigger for support polygon reshaping). A motion whose
    # stance a footstep plan chose (no stepping) may allow the hand a larger lag on its way.
    ee_error_threshold_m: Margin | None = None
    # (nq,) float64 final whole-body posture to go to with the hand (a footstep plan's final posture
    # for the stance the robot stands in, paper 000 §7), a task below the paper's four, in the motion
    # without stepping; None: none (the robot's own IK decides). Joints within their limits.
    posture: np.ndarray | None = None
    # wall-clock planning budget [s] (<= 60); None: the service's time_budget_s. Past it: ``timeout``
    # with the stage reached and the attempts made (``details.stage``, ``attempts``).
    time_budget_s: Budget | None = None
    # The motion's own timing (None: the service's, the paper's slow reach: 0.2 m/s, at least 1.4 s,
    # 0.3 s hold): the hand's mean speed at most [m/s], the shortest motion [s], the final hold [s].
    # Slowed down where a joint would exceed its share of the velocity limit, never stepping; refused
    # at that timing, the request is planned at the service's timing (stepping if allowed).
    hand_speed_m_s: HandSpeed | None = None
    min_duration_s: ReachDuration | None = None
    final_hold_s: HoldTime | None = None
    # Spheres (world) the arm keeps out of over the whole motion, the gripper and wrist included (a ball
    # beside the one to grasp): paper 000's eqs. 12-13 on the arm's capsules, at least
    # ``hand_clearance_m`` surface to surface. The gripper is not kept out of a sphere that ``target``
    # lies in or straight above (the object it closes on); the forearm and upper arm are. A path
    # closer than that is planned again (the hand first above the target, then down), else refused:
    # ``infeasible``, ``details.reason`` ``hand_obstacle`` naming the sphere and the link. Empty: no
    # such constraint (the motion as without the field).
    hand_obstacles: Annotated[list[Sphere], msgspec.Meta(max_length=MAX_OBSTACLES)] = []
    hand_clearance_m: Margin | None = None  # None: the service's (2 cm)


class Monitors(msgspec.Struct, kw_only=True, frozen=True):
    """Criteria monitored at the IK knots (k of them) while the motion was generated (Fig. 4)."""

    times_s: np.ndarray  # (k,) knot times [s]
    manipulability: np.ndarray  # (k,) w = sqrt(det(J J^T)) of the arm (eq. 5)
    ee_error_m: np.ndarray  # (k,) hand reference - hand computed by the IK [m]
    joint_limit_margin_rad: np.ndarray  # (k,) smallest distance of an arm joint to a limit [rad]
    joint_speed_ratio: np.ndarray  # (k,) fastest arm joint over its velocity limit
    torque_ratio: np.ndarray  # (k,) largest static torque of a joint without contact over its effort limit


class Attempt(msgspec.Struct, kw_only=True, frozen=True):
    """A motion computed by the planner: ``kind`` no_step | single | walk; ``violation`` is the criterion
    that made it be discarded ("" if it was kept), at ``time_s`` [s], ``value`` against ``threshold``."""

    kind: str
    steps: int
    violation: str = ""
    time_s: float = 0.0
    value: float = 0.0
    threshold: float = 0.0
    wall_time_s: float = 0.0  # computation time of this motion [s]


class ReachReply(msgspec.Struct, kw_only=True, frozen=True):
    """The whole-body reaching motion (send ``q`` to ``sim/execute``) and what was monitored."""

    model: str  # robot model the configurations belong to
    joint_names: list[str]  # actuated joints in q order (after the 7 base coordinates)
    dt_s: float  # sample period of q [s] (0.005)
    q: np.ndarray  # (N, nq) float64 whole-body trajectory, q[0] = q_start
    duration_s: float  # (N - 1) * dt_s [s]
    stepped: bool  # whether the support polygon was reshaped
    footsteps: list[Footstep]  # the steps taken, in order
    monitors: Monitors  # of the returned motion
    no_step_monitors: Monitors  # of the motion on the initial support polygon (discarded when stepped)
    attempts: list[Attempt]  # every motion computed, in order
    manipulability_threshold: float  # criteria thresholds used
    ee_error_threshold_m: float
    zmp_multibody: np.ndarray  # (N, 2) ZMP of the whole-body motion [m]
    zmp_planned: np.ndarray  # (N, 2) ZMP of the planned CoM (pattern generator) [m]
    zmp_distance_m: np.ndarray  # (N,) signed distance of zmp_multibody to the support polygon, < 0 inside [m]
    phase: np.ndarray  # (N,) int8 support phase: 0 double, 1 left foot supports, 2 right foot supports
    left_sole: np.ndarray  # (N, 4) planned left sole x, y, z [m], yaw [rad]
    right_sole: np.ndarray  # (N, 4) planned right sole
    hand_error_m: float  # hand to target at the end of the plan [m]
    max_sole_slide_m: float  # largest drift of a supporting sole in the plan [m]
    planning_time_s: float  # wall time of the planning [s]


REACH = EndpointSpec(
    "reaching",
    "reach",
    ReachRequest,
    ReachReply,
    "whole-body reach of a point (support polygon reshaping by stepping when a criterion fails)",
)
