"""Task execution criteria monitored while the motion is generated (Fig. 4 of the reaching paper).

"While the motion is being computed by the generalized IK, several properties are monitored": the
manipulability w = sqrt(det(J J^T)) of the arm (eq. 5), the error between the reference end-effector
position and the one calculated by the IK solver, and the joint limits. When one of them leaves its
admissible range the motion on the current support polygon is discarded and the support polygon is
reshaped.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.bus.schemas.reaching import (
    CRITERION_EE_ERROR,
    CRITERION_HAND_OBSTACLE,
    CRITERION_JOINT_LIMITS,
    CRITERION_JOINT_SPEED,
    CRITERION_JOINT_TORQUE,
    CRITERION_MANIPULABILITY,
    CRITERION_MULTIBODY_ZMP,
)
from services.ik import ArmManipulability
from services.ik.dofs import joint_dofs
from services.ik.kinematics import frame_id, frame_jacobian
from services.ik.monitors import manipulability

MANIPULABILITY_ROWS = {"pose": 6, "position": 3}
"""Rows of the arm's Jacobian in the manipulability of eq. (5): ``pose``, the whole 6 x n Jacobian of the
arm (Yoshikawa's manipulability of the arm as a manipulator, translation and rotation: for a 6-joint arm
|det J|, which vanishes at every singular configuration of the arm: the elbow stretched, the wrist
aligned); ``position``, its 3 translation rows only (it vanishes only when the hand cannot move along
some direction: a redundant arm keeps it high)."""


@dataclass(frozen=True)
class KnotValues:
    """The monitored values at one IK knot (see :class:`MonitorSeries` for the meanings)."""

    time_s: float
    manipulability: float
    ee_error_m: float
    joint_limit_margin_rad: float
    joint_speed_ratio: float
    torque_ratio: float
    hand_m: np.ndarray
    hand_ref_m: np.ndarray


@dataclass(frozen=True)
class MonitorSeries:
    """Monitored values at the IK knots of a motion (k knots).

    Attributes:
        times_s: (k,) knot times [s].
        manipulability: (k,) w of eq. (5) (translation Jacobian of the arm, shoulder to grasp frame) [m^3
            for a 3 x 6 Jacobian: the product of its singular values].
        ee_error_m: (k,) distance between the hand reference and the hand computed by the IK [m].
        joint_limit_margin_rad: (k,) smallest distance of an arm joint to one of its limits [rad].
        joint_speed_ratio: (k,) largest speed of an arm joint since the previous knot over its velocity
            limit.
        torque_ratio: (k,) largest static (gravity) torque of a joint without contact (chest, head,
            arms) over its effort limit.
        hand_m: (k, 3) grasp frame position [m]; hand_ref_m: (k, 3) its reference [m].
    """

    times_s: np.ndarray
    manipulability: np.ndarray
    ee_error_m: np.ndarray
    joint_limit_margin_rad: np.ndarray
    joint_speed_ratio: np.ndarray
    torque_ratio: np.ndarray
    hand_m: np.ndarray
    hand_ref_m: np.ndarray

    @staticmethod
    def from_knots(knots: list[KnotValues]) -> MonitorSeries:
        """Stack the values of consecutive knots."""
        return MonitorSeries(
            np.array([k.time_s for k in knots]),
            np.array([k.manipulability for k in knots]),
            np.array([k.ee_error_m for k in knots]),
            np.array([k.joint_limit_margin_rad for k in knots]),
            np.array([k.joint_speed_ratio for k in knots]),
            np.array([k.torque_ratio for k in knots]),
            np.array([k.hand_m for k in knots]).reshape(-1, 3),
            np.array([k.hand_ref_m for k in knots]).reshape(-1, 3),
        )


@dataclass(frozen=True)
class Thresholds:
    """Admissible ranges: manipulability >= ``manipulability``, end-effector error <= ``ee_error_m``,
    arm joint-limit margin >= ``joint_limit_margin_rad``, joint speed ratio <= ``joint_speed_ratio``,
    static torque ratio <= ``torque_ratio``."""

    manipulability: float
    ee_error_m: float
    joint_limit_margin_rad: float
    joint_speed_ratio: float
    torque_ratio: float


@dataclass(frozen=True)
class Violation:
    """A criterion out of its admissible range at ``time_s`` [s]: ``value`` against ``threshold``; for
    ``hand_obstacle``, ``sphere`` is the index of the request's sphere and ``link`` the arm's capsule."""

    criterion: str
    time_s: float
    value: float
    threshold: float
    sphere: int = -1
    link: str = ""
    held_back: str = ""  # hand_obstacle: the criterion that failed while the sphere held the arm off

    def describe(self) -> str:
        """A sentence for error messages."""
        if self.criterion == CRITERION_MANIPULABILITY:
            return (
                f"the arm's manipulability (eq. 5) fell to {self.value:.3g} < {self.threshold:.3g} at "
                f"t={self.time_s:.2f} s (the arm approaches a singular configuration)"
            )
        if self.criterion == CRITERION_EE_ERROR:
            return (
                f"the hand fell {1e3 * self.value:.3g} mm behind its reference (threshold "
                f"{1e3 * self.threshold:.3g} mm) at t={self.time_s:.2f} s"
            )
        if self.criterion == CRITERION_JOINT_SPEED:
            return (
                f"an arm joint had to move at {100 * self.value:.0f} % of its velocity limit (admissible "
                f"{100 * self.threshold:.0f} %) at t={self.time_s:.2f} s"
            )
        if self.criterion == CRITERION_JOINT_TORQUE:
            return (
                f"holding the posture takes {100 * self.value:.0f} % of a joint's effort limit (admissible "
                f"{100 * self.threshold:.0f} %) at t={self.time_s:.2f} s"
            )
        if self.criterion == CRITERION_HAND_OBSTACLE and self.held_back:
            return (
                f"'{self.held_back}' failed while hand_obstacles[{self.sphere}] held the arm's {self.link} "
                f"off at {1e3 * self.value:.0f} mm (clearance {1e3 * self.threshold:.0f} mm) at "
                f"t={self.time_s:.2f} s: the hand's path passes by it"
            )
        if self.criterion == CRITERION_HAND_OBSTACLE:
            return (
                f"the arm's {self.link} comes within {1e3 * self.value:.0f} mm of "
                f"hand_obstacles[{self.sphere}] (clearance {1e3 * self.threshold:.0f} mm) at "
                f"t={self.time_s:.2f} s"
            )
        if self.criterion == CRITERION_MULTIBODY_ZMP and self.value > 0:
            return (
                f"the multibody ZMP leaves the support polygon by {1e3 * self.value:.0f} mm at "
                f"t={self.time_s:.2f} s"
            )
        if self.criterion == CRITERION_MULTIBODY_ZMP:
            return (
                f"the whole-body motion has no ZMP at t={self.time_s:.2f} s (vertical contact force "
                f"{self.value:.3g} N: a joint jumps between two IK knots)"
            )
        return (
            f"an arm joint reached its limit (margin {self.value:.2g} rad < {self.threshold:.2g} rad) at "
            f"t={self.time_s:.2f} s"
        )


class ArmMonitor:
    """Evaluates the criteria of one hand on a pinocchio model (the IK's reduced model)."""

    def __init__(
        self,
        model: pin.Model,
        grasp_frame: str,
        arm_joints: list[str],
        q_lower: np.ndarray,
        q_upper: np.ndarray,
        effort_max: np.ndarray,
        sole_frames: tuple[str, ...],
        manipulability_of: str = "pose",
    ) -> None:
        self.model = model
        self.manipulability_rows = MANIPULABILITY_ROWS[manipulability_of]
        self.data = model.createData()
        self.frame_id = frame_id(model, grasp_frame)
        self.manipulability = ArmManipulability(model, grasp_frame, arm_joints[0])
        v_idx = joint_dofs(model, arm_joints)
        q_idx = np.array([model.joints[model.getJointId(n)].idx_q for n in arm_joints], dtype=int)
        self.arm_v_idx = v_idx
        self.arm_q_idx = q_idx
        self.arm_lower = np.asarray(q_lower, dtype=float)[q_idx]
        self.arm_upper = np.asarray(q_upper, dtype=float)[q_idx]
        # Joints carrying no contact (no sole below them: chest, head, arms): their static torque is the
        # gravity term of the dynamics whatever the contact forces at the feet.
        support = {
            j for f in sole_frames for j in model.supports[model.frames[frame_id(model, f)].parentJoint]
        }
        free = [j for j in range(2, model.njoints) if j not in support]
        self.free_v_idx = np.array([model.joints[j].idx_v for j in free], dtype=int)
        self.free_effort = np.asarray(effort_max, dtype=float)[self.free_v_idx]

    def evaluate(self, q: np.ndarray) -> tuple[np.ndarray, float, float, float]:
        """(hand position [m], manipulability, arm joint-limit margin [rad], largest static torque of
        a joint without contact over its effort limit) at ``q``."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacement(self.model, self.data, self.frame_id)
        hand = self.data.oMf[self.frame_id].translation.copy()
        J = frame_jacobian(self.model, self.data, self.frame_id)
        w = manipulability(J[: self.manipulability_rows, self.manipulability.v_idx])
        arm_q = q[self.arm_q_idx]
        margin = float(np.minimum(arm_q - self.arm_lower, self.arm_upper - arm_q).min())
        gravity = pin.computeGeneralizedGravity(self.model, self.data, q)[self.free_v_idx]
        torque_ratio = float(np.max(np.abs(gravity) / self.free_effort))
        return hand, w, margin, torque_ratio

    def hand_position(self, q: np.ndarray) -> np.ndarray:
        """Grasp frame position [m] at ``q`` (forward kinematics only)."""
        pin.forwardKinematics(self.model, self.data, q)
        return pin.updateFramePlacement(self.model, self.data, self.frame_id).translation.copy()


def first_violation(criteria: tuple[str, ...], values: KnotValues, limits: Thresholds) -> Violation | None:
    """The first criterion of ``criteria`` out of its admissible range at a knot, or None."""
    t = values.time_s
    for criterion in criteria:
        if criterion == CRITERION_MANIPULABILITY and values.manipulability < limits.manipulability:
            return Violation(criterion, t, values.manipulability, limits.manipulability)
        if criterion == CRITERION_EE_ERROR and values.ee_error_m > limits.ee_error_m:
            return Violation(criterion, t, values.ee_error_m, limits.ee_error_m)
        if criterion == CRITERION_JOINT_SPEED and values.joint_speed_ratio > limits.joint_speed_ratio:
            return Violation(criterion, t, values.joint_speed_ratio, limits.joint_speed_ratio)
        if criterion == CRITERION_JOINT_TORQUE and values.torque_ratio > limits.torque_ratio:
            return Violation(criterion, t, values.torque_ratio, limits.torque_ratio)
        margin = values.joint_limit_margin_rad
        if criterion == CRITERION_JOINT_LIMITS and margin < limits.joint_limit_margin_rad:
            return Violation(criterion, t, values.joint_limit_margin_rad, limits.joint_limit_margin_rad)
    return None
