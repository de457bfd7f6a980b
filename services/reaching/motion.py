"""What the whole-body IK tracks over time: the soles (task i), the CoM (task ii), the hand (task iii) and
the gaze point (task iv), on the 5 ms grid; built for standing still or from a walking pattern."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from services.walking.pattern import WalkPattern
from services.walking.timing import DOUBLE


@dataclass(frozen=True)
class MotionSpec:
    """References on ``times_s`` (n samples every ``dt_s``), world frame.

    Attributes:
        left_sole, right_sole: (n, 4) sole poses x, y, z [m], yaw [rad].
        phase: (n,) support phase codes of ``services.walking.timing`` (DOUBLE / LEFT / RIGHT).
        com_xy_m: (n, 2) horizontal CoM [m] (the height is left free).
        body_yaw_rad: (n,) yaw of the body frame (the waist yaw of the pattern) [rad].
        zmp_planned_m: (n, 2) ZMP of the planned CoM motion [m] (cart-table for a walking pattern).
        zmp_reference_m: (n, 2) ZMP reference of the pattern generator [m] (the CoM when standing).
        hand_ref_m: (n, 3) grasp frame reference [m]; hand_rot: (n, 3, 3) its orientation or None.
        gaze_ref_m: (n, 3) point to look at [m], or None (no gaze task).
        reach_end_s: time [s] at which the hand reference reaches the target.
        pattern: the walking pattern when the motion steps, else None.
        posture_ref: (n, nq) whole-body posture reference (joint coordinates used), or None: from the
            starting configuration to a requested final posture along the hand's profile (a rest-level
            task below the four of the paper: it only uses the redundancy they leave).
        clearance: the request's spheres the arm keeps out of
            (:class:`services.reaching.obstacles.ArmClearance`), or None.
    """

    times_s: np.ndarray
    left_sole: np.ndarray
    right_sole: np.ndarray
    phase: np.ndarray
    com_xy_m: np.ndarray
    body_yaw_rad: np.ndarray
    zmp_planned_m: np.ndarray
    zmp_reference_m: np.ndarray
    hand_ref_m: np.ndarray
    hand_rot: np.ndarray | None
    gaze_ref_m: np.ndarray | None
    reach_end_s: float
    pattern: WalkPattern | None = None
    posture_ref: np.ndarray | None = None
    clearance: Any = None

    @property
    def n_samples(self) -> int:
        return int(self.times_s.shape[0])

    @property
    def dt_s(self) -> float:
        return float(self.times_s[1] - self.times_s[0]) if self.n_samples > 1 else 0.005

    @property
    def duration_s(self) -> float:
        return float(self.times_s[-1])


def standing_frame(
    n: int, dt_s: float, left_sole: np.ndarray, right_sole: np.ndarray, com_xy_m: np.ndarray, yaw_rad: float
) -> dict[str, np.ndarray]:
    """Soles, phase, CoM and body yaw of a robot standing still for ``n`` samples."""
    return {
        "times_s": np.arange(n) * dt_s,
        "left_sole": np.repeat(np.asarray(left_sole, dtype=float)[None, :], n, axis=0),
        "right_sole": np.repeat(np.asarray(right_sole, dtype=float)[None, :], n, axis=0),
        "phase": np.full(n, DOUBLE, dtype=np.int8),
        "com_xy_m": np.repeat(np.asarray(com_xy_m, dtype=float)[None, :], n, axis=0),
        "body_yaw_rad": np.full(n, float(yaw_rad)),
        "zmp_planned_m": np.repeat(np.asarray(com_xy_m, dtype=float)[None, :], n, axis=0),
        "zmp_reference_m": np.repeat(np.asarray(com_xy_m, dtype=float)[None, :], n, axis=0),
    }


def pattern_frame(pattern: WalkPattern) -> dict[str, np.ndarray]:
    """Soles, phase, CoM, body yaw and planned ZMP of a walking pattern."""
    return {
        "times_s": np.asarray(pattern.times_s),
        "left_sole": np.asarray(pattern.left_sole),
        "right_sole": np.asarray(pattern.right_sole),
        "phase": np.asarray(pattern.phase),
        "com_xy_m": np.asarray(pattern.com_m)[:, :2],
        "body_yaw_rad": np.asarray(pattern.waist_yaw_rad),
        "zmp_planned_m": np.asarray(pattern.zmp_planned_m),
        "zmp_reference_m": np.asarray(pattern.zmp_ref_m),
    }
