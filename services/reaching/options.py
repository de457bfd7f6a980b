"""Options of the reaching planner (one frozen dataclass, defaults in code, validated).

The monitored thresholds default to the robot's parameters (``services/model/data/<robot>.yaml``),
which carry the values of the reaching paper ("Experimental Results" of "Task-driven Support Polygon
Reshaping for Reaching", ``001_771c0ce3779b0683.txt``): manipulability 1.5e-4 and end-effector error
4.0e-5 m.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import Any

from services.bus.schemas.reaching import (
    CRITERION_EE_ERROR,
    CRITERION_JOINT_LIMITS,
    CRITERION_JOINT_SPEED,
    CRITERION_JOINT_TORQUE,
    CRITERION_MANIPULABILITY,
)
from services.errors import InvalidRequestError
from services.reaching.monitors import MANIPULABILITY_ROWS, Thresholds

CRITERIA = (
    CRITERION_MANIPULABILITY,
    CRITERION_EE_ERROR,
    CRITERION_JOINT_SPEED,
    CRITERION_JOINT_TORQUE,
    CRITERION_JOINT_LIMITS,
)
"""Monitored criteria (Fig. 4): the arm's manipulability (eq. 5) below its threshold, the end-effector
error above its threshold, an arm joint faster than ``velocity_ratio`` of its limit, the static torque
of a joint without contact above ``torque_ratio`` of its effort limit, an arm joint at its limit."""


PAPER_CRITERIA = (CRITERION_MANIPULABILITY, CRITERION_EE_ERROR)
"""The criteria of the paper's experiment ("Experimental Results"): the arm's manipulability below
1.5e-4 and the end-effector error above 4e-5 m."""

TORQUE_TRIGGER_PARAM = "reaching_joint_torque_trigger"
"""Robot parameter (``extra`` of ``services/model/data/<robot>.yaml``): nonzero when the robot's arms
cannot hold themselves stretched out (TALOS: 22 N m shoulders), so that ``joint_torque`` is a default
trigger on that robot besides the paper's two."""

PAPER_EXPERIMENT: dict[str, Any] = {
    "criteria": PAPER_CRITERIA,
    "manipulability_of": "pose",
    "weighted": True,
    "other_arm_still": False,
    "joint_limit_selection_rad": None,
}
"""The settings of the paper's experiment (see :meth:`ReachingOptions.paper_experiment`); the defaults
are the same on a robot without :data:`TORQUE_TRIGGER_PARAM`."""


@dataclass(frozen=True)
class ReachingOptions:
    """Settings of :func:`services.reaching.planner.plan_reach`.

    Monitoring (Fig. 4 of the reaching paper):
        manipulability_threshold: w = sqrt(det(J J^T)) (eq. 5) of the arm's Jacobian (its rows:
            ``manipulability_of``) below which the task counts as failing; ``None``: the robot's
            ``params.manipulability_threshold``.
        ee_error_threshold_m: distance [m] between the hand reference and the hand computed by the IK
            above which the task counts as failing; ``None``: ``params.ee_error_threshold_m``.
        joint_limit_margin_rad: an arm joint closer than this to a limit [rad] fails ``joint_limits``.
        manipulability_of: the rows of the arm's Jacobian in w (eq. 5): ``pose`` (default), the whole
            6 x n Jacobian of the arm from the shoulder to the grasp frame (Yoshikawa's manipulability
            of the arm as a manipulator: |det J| for a 6-joint arm, small when the elbow stretches or
            the wrist aligns); ``position``, its 3 translation rows (with the whole body free to help,
            it stays above 1.5e-4 until the elbow is on its limit: then ``ee_error`` fires instead).
        criteria: the criteria that trigger support polygon reshaping (a subset of :data:`CRITERIA`);
            ``None`` (default): the paper's two (:data:`PAPER_CRITERIA`), plus ``joint_torque`` on a
            robot whose parameters set :data:`TORQUE_TRIGGER_PARAM` (a stretched arm weighs more
            than its shoulder can hold: TALOS). ``joint_speed`` (an arm joint beyond
            ``velocity_ratio`` of its limit) is an extension, off by default. Joint limits are always
            monitored and reported; as a trigger they are too eager (an arm joint may rest on a limit
            while the hand follows its reference perfectly), so they are opt-in.
        torque_ratio: admissible static torque of the joints without contact (chest, head, arms) as
            a fraction of their effort limits.

    Generalized IK (eqs. 1-4):
        weighted: weighted pseudo-inverse of eq. (4), W_i = m_i / M, on the four prioritized tasks (the
            paper's experiment uses it for all tasks).
        com_height: the CoM task of level (ii) also holds the CoM height at its initial value (the
            pattern generator's constant height); off: x, y only.
        com_height_rest: the CoM height pulled back to its initial value in the rest level (the body
            does not crouch unless the hand needs it).
        arm_speed_per_knot: the arms' joints move at most ``velocity_ratio`` of their limits over a
            whole knot (not per Gauss-Newton step): near a singular configuration the hand then falls
            behind its reference and ``ee_error`` fires instead of ``joint_speed``.
        recovery_iterations: Gauss-Newton steps a knot may add when the hand is still beyond the
            end-effector threshold after ``max_iterations_per_knot`` (transients: a joint reaching
            its limit, a foot landing).
        other_arm_still: the selection matrix S leaves out the arm that does not reach (no task uses
            it; with the weighted pseudo-inverse the light arm swings to help the CoM). Off by
            default: S = I_n as in the paper's experiment.
        other_arm_rest: with the other arm free, it is pulled back towards its starting posture in the
            rest level (below the four tasks: only the redundancy they leave), so that it does not end
            the reach swung out (the robot's width, for navigation afterwards).
        joint_limit_selection_rad: the selection matrix S_l: joints closer than this to a limit [rad] are
            left out of the CoM, hand and gaze levels; ``None``: S = I_n (the paper's experiment).
        knot_stride: 5 ms samples between two IK knots (the trajectory is a C2 spline of the knots).
        max_iterations_per_knot: Gauss-Newton steps of the hierarchy per knot at most.
        knot_tolerance_m: a knot stops iterating once the hand is this close to its reference [m].
        velocity_ratio: admissible joint speed as a fraction of the velocity limits (each Gauss-Newton
            step is bounded by it over one knot period; an arm joint faster than it fails ``joint_speed``).

    Motion:
        hand_speed_m_s: mean hand speed [m/s] that sets the reaching duration (the hand follows a
            minimum-jerk profile), clipped to [min_reach_s, max_reach_s] [s]; hand_turn_rad_s: with an
            orientation asked, the mean turning speed [rad/s] of the hand that sets it too (the longer
            of the two): without it a wrist turning by 90 deg or more over a short travel lagged
            behind its reference (fingers down between two balls, fetch seed 37).
        final_hold_s: standing still at the end of a reach without step [s].
        timed_velocity_ratio: a request with its own timing (``ReachRequest.timing``) is planned again
            slower when a joint of its motion moves faster than this fraction of its velocity limit
            (``ReachPlanner.plan``).

    Spheres to keep out of (``ReachRequest.hand_obstacles``, paper 000 eqs. 12-13 on the arm's capsules,
    the gripper's included):
        hand_clearance_m: the surface-to-surface clearance [m] a motion keeps from them (a request may
            give its own); the IK's inequality rows keep ``hand_clearance_slack_m`` more, so that the
            5 ms spline between its knots stays outside the clearance.
        approach_heights_m: a motion that passes within the clearance is planned again with the hand
            first this far [m] above the target, then straight down, each in turn; then refused.

    Stepping (pattern generator):
        single_support_s, double_support_s: step timing [s]; ``None``: from the robot's parameters,
            the single support ``step_slowdown`` times ``step_duration_s - double_support_s`` and the
            double support ``double_support_ratio`` times ``double_support_s``. Slower than the
            robots' walking parameters: the sim plays trajectories open loop, and long walks at HRP-2's
            0.7 s / 0.1 s (TALOS: 0.9 s / 0.1 s) tip over in it now and then (see README).
        base_height_margin_m: the waist stays this much above the robot's fall height
            (``params.fall_base_height_m``) when it crouches to reach low (an inequality in level i).

    Support polygon reshaping (Fig. 5):
        max_steps: most footsteps the support polygon planner may use (more: ``infeasible``).
        step_bound_ratio: fraction of the robot's footstep bounds the planner uses (margin for the
            pattern generator and the sim).
        comfort_reach_ratio: the target is brought this fraction of the arm length in front of the
            reaching shoulder (the "large margin of accessible area" of Fig. 5).
        zmp_margin_m: required margin of the multibody ZMP inside the support polygon [m]; beyond it the
            second preview stage corrects the CoM (up to ``max_corrections`` passes).
    """

    manipulability_threshold: float | None = None
    ee_error_threshold_m: float | None = None
    manipulability_of: str = "pose"
    joint_limit_margin_rad: float = 1e-3
    criteria: tuple[str, ...] | None = None
    weighted: bool = True
    com_height: bool = False
    com_height_rest: bool = False
    other_arm_still: bool = False
    other_arm_rest: bool = True
    joint_limit_selection_rad: float | None = None
    knot_stride: int = 10
    max_iterations_per_knot: int = 3
    recovery_iterations: int = 0
    knot_tolerance_m: float = 1e-6
    velocity_ratio: float = 0.5
    arm_speed_per_knot: bool = False
    torque_ratio: float = 0.6
    hand_speed_m_s: float = 0.2
    hand_turn_rad_s: float = 0.6
    min_reach_s: float = 1.4
    max_reach_s: float = 5.0
    final_hold_s: float = 0.3
    timed_velocity_ratio: float = 0.8
    single_support_s: float | None = None
    double_support_s: float | None = None
    step_slowdown: float = 1.3
    double_support_ratio: float = 3.0
    base_height_margin_m: float = 0.02
    max_steps: int = 20
    step_bound_ratio: float = 0.9
    comfort_reach_ratio: float = 0.55
    zmp_margin_m: float = 0.01
    max_corrections: int = 2
    hand_clearance_m: float = 0.02
    hand_clearance_slack_m: float = 0.005
    approach_heights_m: tuple[float, ...] = (0.1, 0.2)

    def __post_init__(self) -> None:
        if self.criteria is not None:
            object.__setattr__(self, "criteria", tuple(self.criteria))
            unknown = sorted(set(self.criteria) - set(CRITERIA))
            if unknown:
                raise InvalidRequestError(f"unknown criteria {unknown}; valid criteria are {list(CRITERIA)}")
        if self.manipulability_of not in MANIPULABILITY_ROWS:
            raise InvalidRequestError(
                f"option manipulability_of must be one of {sorted(MANIPULABILITY_ROWS)}, got "
                f"{self.manipulability_of!r}"
            )
        positive = {
            "knot_tolerance_m": self.knot_tolerance_m,
            "velocity_ratio": self.velocity_ratio,
            "torque_ratio": self.torque_ratio,
            "step_slowdown": self.step_slowdown,
            "double_support_ratio": self.double_support_ratio,
            "hand_speed_m_s": self.hand_speed_m_s,
            "hand_turn_rad_s": self.hand_turn_rad_s,
            "min_reach_s": self.min_reach_s,
            "max_reach_s": self.max_reach_s,
            "timed_velocity_ratio": self.timed_velocity_ratio,
            "step_bound_ratio": self.step_bound_ratio,
            "comfort_reach_ratio": self.comfort_reach_ratio,
        }
        for name in (
            "manipulability_threshold",
            "ee_error_threshold_m",
            "joint_limit_selection_rad",
            "single_support_s",
            "double_support_s",
        ):
            value = getattr(self, name)
            if value is not None:
                positive[name] = value
        for name, value in positive.items():
            if not (isinstance(value, int | float) and math.isfinite(value) and value > 0):
                raise InvalidRequestError(f"option {name} must be a positive number, got {value!r}")
        object.__setattr__(self, "approach_heights_m", tuple(self.approach_heights_m))
        if not all(isinstance(h, int | float) and 0.0 < h <= 0.5 for h in self.approach_heights_m):
            raise InvalidRequestError(
                f"option approach_heights_m must be heights in (0, 0.5] m, got {self.approach_heights_m!r}"
            )
        for name in (
            "joint_limit_margin_rad",
            "final_hold_s",
            "zmp_margin_m",
            "base_height_margin_m",
            "hand_clearance_m",
            "hand_clearance_slack_m",
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise InvalidRequestError(f"option {name} must be >= 0, got {value!r}")
        integers = (
            ("knot_stride", 1),
            ("max_iterations_per_knot", 1),
            ("recovery_iterations", 0),
            ("max_steps", 0),
        )
        for name, low in integers:
            value = getattr(self, name)
            if not isinstance(value, int) or value < low:
                raise InvalidRequestError(f"option {name} must be an integer >= {low}, got {value!r}")
        if self.max_corrections < 0:
            raise InvalidRequestError(f"option max_corrections must be >= 0, got {self.max_corrections}")
        if self.min_reach_s > self.max_reach_s:
            raise InvalidRequestError("option min_reach_s must not exceed max_reach_s")
        if self.step_bound_ratio > 1.0:
            raise InvalidRequestError(f"option step_bound_ratio must be <= 1, got {self.step_bound_ratio}")

    def criteria_for(self, robot: Any) -> tuple[str, ...]:
        """The criteria that trigger reshaping on ``robot`` (``criteria``, or its default)."""
        if self.criteria is not None:
            return self.criteria
        extra = getattr(robot.params, "extra", None) or {}
        torque = (CRITERION_JOINT_TORQUE,) if extra.get(TORQUE_TRIGGER_PARAM, 0.0) else ()
        return PAPER_CRITERIA + torque

    def thresholds(self, robot: Any) -> Thresholds:
        """The admissible ranges of the criteria for ``robot``."""
        w_min = self.manipulability_threshold
        e_max = self.ee_error_threshold_m
        return Thresholds(
            manipulability=float(robot.params.manipulability_threshold if w_min is None else w_min),
            ee_error_m=float(robot.params.ee_error_threshold_m if e_max is None else e_max),
            joint_limit_margin_rad=self.joint_limit_margin_rad,
            joint_speed_ratio=self.velocity_ratio,
            torque_ratio=self.torque_ratio,
        )

    @classmethod
    def paper_experiment(cls, **overrides: Any) -> ReachingOptions:
        """The settings of the paper's experiment ("Experimental Results"): the two monitored criteria
        (manipulability 1.5e-4 of the arm's Jacobian, end-effector error 4e-5 m) as the only triggers
        on every robot, the weighted pseudo-inverse with S = I_n for every task (the other arm free
        too), S_l off; ``overrides`` change any field."""
        values: dict[str, Any] = {**PAPER_EXPERIMENT, **overrides}
        return cls(**values)

    @staticmethod
    def field_names() -> list[str]:
        """Names of the options (for messages listing them)."""
        return [f.name for f in fields(ReachingOptions)]
