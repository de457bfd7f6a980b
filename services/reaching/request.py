"""A reaching request: everything the stateless planner needs, validated against the robot."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import pinocchio as pin

from services.bus.schemas.common import START_SOLE_MAX_HEIGHT_M, START_SOLE_MAX_TILT_RAD
from services.bus.schemas.reaching import MAX_FINAL_HOLD_S, MAX_HAND_SPEED_M_S, MIN_DURATION_RANGE_S
from services.errors import InvalidRequestError
from services.ik.hand_obstacles import SphereObstacle, check_spheres
from services.model.specs import check_side

MAX_SOLE_HEIGHT_M = START_SOLE_MAX_HEIGHT_M  # a starting sole farther from the ground is not standing
MAX_SOLE_TILT_RAD = START_SOLE_MAX_TILT_RAD  # nor a sole tilted by more than this
MAX_HAND_CLEARANCE_M = 0.2  # a hand_clearance_m above this is not a clearance but a request to stay away
MAX_APPROACH_ABOVE_M = 0.5  # the hand's detour above its target at most [m]


@dataclass(frozen=True)
class ReachTiming:
    """A reach's own timing, in place of the planner's defaults (``ReachingOptions.hand_speed_m_s``,
    ``min_reach_s``, ``final_hold_s``): the hand's mean speed ``hand_speed_m_s`` [m/s] over its travel
    (a minimum-jerk profile: 1.875 times that at its peak), ``min_duration_s`` the shortest motion [s],
    ``final_hold_s`` standing still at the end [s]. With a timing of its own a motion is also slowed
    down where its joints would move faster than the planner's ``timed_velocity_ratio`` of their
    velocity limits (``ReachPlanner.plan``): a request asks for *at most* this speed, the joints decide
    the rest. ``None`` fields: the planner's defaults."""

    hand_speed_m_s: float | None = None
    min_duration_s: float | None = None
    final_hold_s: float | None = None

    def validated(self) -> ReachTiming:
        """Itself; InvalidRequestError naming the field and its range otherwise."""
        checks = (
            ("hand_speed_m_s", self.hand_speed_m_s, 0.0, MAX_HAND_SPEED_M_S, "m/s", False),
            ("min_duration_s", self.min_duration_s, *MIN_DURATION_RANGE_S, "s", True),
            ("final_hold_s", self.final_hold_s, 0.0, MAX_FINAL_HOLD_S, "s", True),
        )
        for name, value, low, high, unit, low_ok in checks:
            if value is None:
                continue
            ok = isinstance(value, int | float) and math.isfinite(value)
            ok = ok and (low <= value if low_ok else low < value) and value <= high
            if not ok:
                bracket = "[" if low_ok else "("
                raise InvalidRequestError(
                    f"timing {name} must be in {bracket}{low}, {high}] {unit}, got {value!r}",
                    {"field": name},
                )
        return self


@dataclass(frozen=True)
class ReachRequest:
    """Reach ``target_world_m`` with the grasp frame of ``hand``.

    Attributes:
        hand: "left" or "right".
        target_world_m: (3,) target point of the grasp frame origin in the world frame [m].
        q_start: (nq,) the robot's starting configuration (both soles flat on the ground z = 0).
        R_world_hand: optional (3, 3) orientation of the grasp frame at the target; ``None``: position
            only (the paper's experiment).
        gaze: keep the gaze on the target (task iv).
        allow_stepping: the support polygon may be reshaped by stepping.
        q_posture: optional (nq,) final whole-body posture to go to on the way (a footstep plan's final
            posture for this stance, paper 000 §7), its joints within their limits: the hand's, CoM's
            and joints' references follow the joints' interpolation to it
            (:mod:`services.reaching.posture`; its own gaze replaces the gaze task), in the motion on
            the current support polygon only (a reshaping step changes the stance it was planned for).
        timing: the motion's own timing (None: the planner's defaults); see :class:`ReachTiming`.
        hand_obstacles: spheres (world [m]) the arm keeps out of over the whole motion, its gripper and
            wrist included (paper 000 eqs. 12-13 on the arm's capsules: ``services.ik.hand_obstacles``;
            the gripper not out of a sphere the target lies in or straight above, the object it closes
            on); the planner re-plans a motion that passes within ``hand_clearance_m`` of one or
            refuses it (``ReachPlanner.plan``).
        hand_clearance_m: surface-to-surface clearance [m] kept from ``hand_obstacles``; None: the
            planner's ``ReachingOptions.hand_clearance_m``.
        approach_above_m: the hand goes first this far [m] straight above the target (its orientation
            reached there), then down onto it; 0: straight to the target. Set by the planner when it
            re-plans a motion that passed too close to a sphere; motions on the current support
            polygon without a requested posture only.
    """

    hand: str
    target_world_m: np.ndarray
    q_start: np.ndarray = field(repr=False)
    R_world_hand: np.ndarray | None = None
    gaze: bool = True
    allow_stepping: bool = True
    q_posture: np.ndarray | None = field(default=None, repr=False)
    timing: ReachTiming | None = None
    hand_obstacles: tuple[SphereObstacle, ...] = ()
    hand_clearance_m: float | None = None
    approach_above_m: float = 0.0

    def validated(self, robot: Any) -> ReachRequest:
        """A copy with arrays checked and converted; InvalidRequestError naming the field otherwise."""
        check_side(self.hand)
        target = np.asarray(self.target_world_m, dtype=float).reshape(-1)
        if target.shape != (3,) or not np.all(np.isfinite(target)):
            raise InvalidRequestError(f"target must be 3 finite numbers [m], got {self.target_world_m!r}")
        if target[2] < 0.0:
            raise InvalidRequestError(f"target z={target[2]:.3f} m is below the ground (z = 0)")
        q = robot.check_q(self.q_start)
        rotation = None
        if self.R_world_hand is not None:
            rotation = np.asarray(self.R_world_hand, dtype=float)
            if rotation.shape != (3, 3) or not np.all(np.isfinite(rotation)):
                raise InvalidRequestError("orientation must be a 3x3 rotation matrix")
            if np.abs(rotation @ rotation.T - np.eye(3)).max() > 1e-6 or np.linalg.det(rotation) < 0:
                raise InvalidRequestError("orientation is not a rotation matrix (R R^T != I or det < 0)")
        posture = None
        if self.q_posture is not None:
            posture = np.asarray(self.q_posture, dtype=float).reshape(-1)
            if posture.shape != q.shape or not np.all(np.isfinite(posture)):
                raise InvalidRequestError(
                    f"posture must be {q.shape[0]} finite numbers (a configuration of {robot.name}), "
                    f"got {posture.size}"
                )
            joints = slice(7, None)  # the free flyer's 7 coordinates first
            lower, upper = np.asarray(robot.q_lower)[joints], np.asarray(robot.q_upper)[joints]
            outside = np.flatnonzero((posture[joints] < lower - 1e-6) | (posture[joints] > upper + 1e-6))
            if outside.size:
                name = robot.joint_names[int(outside[0])]
                raise InvalidRequestError(
                    f"posture: joint {name} at {posture[7 + outside[0]]:.3f} rad is outside its limits "
                    f"[{lower[outside[0]]:.3f}, {upper[outside[0]]:.3f}] rad"
                )
        data = robot.new_data()
        for side in ("left", "right"):
            T = robot.sole_pose(q, side, data)
            tilt = math.acos(max(-1.0, min(1.0, float(T.rotation[2, 2]))))
            if abs(T.translation[2]) > MAX_SOLE_HEIGHT_M or tilt > MAX_SOLE_TILT_RAD:
                raise InvalidRequestError(
                    f"q_start does not stand on flat ground: the {side} sole is at "
                    f"z={T.translation[2]:.4f} m tilted by {tilt:.3f} rad (at most {MAX_SOLE_HEIGHT_M} m "
                    f"and {MAX_SOLE_TILT_RAD} rad); "
                    "plan from the robot's measured standing configuration"
                )
        timing = None if self.timing is None else self.timing.validated()
        spheres = tuple(self.hand_obstacles)
        check_spheres(spheres)
        for name, value, high in (
            ("hand_clearance_m", self.hand_clearance_m, MAX_HAND_CLEARANCE_M),
            ("approach_above_m", self.approach_above_m, MAX_APPROACH_ABOVE_M),
        ):
            if value is not None and not (
                isinstance(value, int | float) and math.isfinite(value) and 0.0 <= value <= high
            ):
                raise InvalidRequestError(f"{name} must be in [0, {high}] m, got {value!r}", {"field": name})
        return ReachRequest(
            self.hand,
            target,
            q.copy(),
            rotation,
            bool(self.gaze),
            bool(self.allow_stepping),
            q_posture=posture,
            timing=timing,
            hand_obstacles=spheres,
            hand_clearance_m=None if self.hand_clearance_m is None else float(self.hand_clearance_m),
            approach_above_m=float(self.approach_above_m),
        )


def quaternion_to_matrix(quaternion_xyzw: Any) -> np.ndarray:
    """3x3 rotation of a quaternion (x, y, z, w); InvalidRequestError if it is not one (norm far from 1)."""
    quat = np.asarray(quaternion_xyzw, dtype=float).reshape(-1)
    if quat.shape != (4,) or not np.all(np.isfinite(quat)):
        raise InvalidRequestError(
            f"orientation must be a quaternion [qx, qy, qz, qw], got {quaternion_xyzw!r}"
        )
    norm = float(np.linalg.norm(quat))
    if abs(norm - 1.0) > 1e-3:
        raise InvalidRequestError(f"orientation quaternion must have norm 1, got {norm:.4f}")
    return pin.Quaternion(quat[3], quat[0], quat[1], quat[2]).normalized().toRotationMatrix()
