"""The support polygon planner: the geometric module of Figs. 4-5 of the reaching paper.

"A geometric module determines the direction and position of the deformation of support polygon so
that the incomplete task is fulfilled" ... "This simple algorithm allows the humanoid robot to make a
step motion, keeping a large margin of accessible area for the task by facing the upper body to the
target direction" (section "Support Polygon Reshaping", ``001_771c0ce3779b0683.txt``).

Geometry: the *comfort stance* is the mid-feet pose (x, y, yaw) from which the target lies straight in
front of the reaching shoulder, ``comfort_reach_ratio`` of the arm length ahead of it, the body facing
the target. Reshaping moves the support polygon towards it:

* **one step** (the paper's reshaping): the foot on the target's side steps towards the comfort stance
  and turns towards the target, as far as the footstep bounds allow (the final stance is the new,
  larger support polygon whose centre carries the CoM towards the target);
* **a walk** when one step cannot get close enough: both feet step alternately along the straight line
  from the current stance to the comfort stance, turning linearly, in the fewest steps within the
  bounds (the Fig. 4 loop repeated: each step reshapes the polygon further).

Every footstep is checked against the robot's stepping bounds (``params.footstep_bounds``, the left sole
in the right sole frame, mirrored) shrunk by ``step_bound_ratio``, and for overlapping soles.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from services.errors import HumanoidError
from services.model.ground import mid_feet
from services.walking.footsteps import (
    Footstep,
    FootstepBounds,
    FootstepSequence,
    SolePose,
    other_side,
    validate_footsteps,
    wrap_angle,
)

# Outward offsets [m] tried for the opening foot of a turning step (its heel must clear the other sole).
TURN_OUTWARD_M = (0.0, 0.02, 0.04)
# Samples of dx, dy and dyaw across the stepping bounds of the candidate single steps.
SINGLE_STEP_GRID = (11, 5, 9)


@dataclass(frozen=True)
class StepPlan:
    """A reshaping of the support polygon: ``footsteps`` (``kind`` "single" or "walk") bring the
    mid-feet frame to ``final_mid`` (x [m], y [m], yaw [rad]); ``comfort_mid`` is the stance aimed at."""

    kind: str
    footsteps: FootstepSequence
    final_mid: tuple[float, float, float]
    comfort_mid: tuple[float, float, float]

    @property
    def n_steps(self) -> int:
        return len(self.footsteps.steps)


def shrunk_limits(limits: FootstepBounds, ratio: float) -> FootstepBounds:
    """``limits`` with a margin for the pattern generator and the sim: the forward and yaw ranges scaled
    towards zero by ``ratio``, the lateral range shrunk about its middle to ``ratio`` of its width (the
    sole size is kept)."""
    mid, half = 0.5 * (limits.dy_min_m + limits.dy_max_m), 0.5 * (limits.dy_max_m - limits.dy_min_m) * ratio
    return FootstepBounds(
        dx_min_m=limits.dx_min_m * ratio,
        dx_max_m=limits.dx_max_m * ratio,
        dy_min_m=mid - half,
        dy_max_m=mid + half,
        dtheta_min_rad=limits.dtheta_min_rad * ratio,
        dtheta_max_rad=limits.dtheta_max_rad * ratio,
        sole_length_m=limits.sole_length_m,
        sole_width_m=limits.sole_width_m,
    )


def mid_pose(left: SolePose, right: SolePose) -> tuple[float, float, float]:
    """(x, y, yaw) of the mid-feet frame of two soles (:func:`services.model.ground.mid_feet`)."""
    mid = mid_feet(left, right)
    return mid.x_m, mid.y_m, mid.yaw_rad


def _is_valid(seq: FootstepSequence, limits: FootstepBounds) -> bool:
    """``seq`` within ``limits`` and without overlapping soles (cheap bound test first)."""
    feet = {"left": seq.left_start, "right": seq.right_start}
    bounds = {side: limits.limits_for(side) for side in ("left", "right")}
    for step in seq.steps:
        rel = step.pose.relative_to(feet[other_side(step.side)])
        lim = bounds[step.side]
        for value, key in zip(rel, ("dx", "dy", "dyaw"), strict=True):
            if not lim[key][0] - 1e-9 <= value <= lim[key][1] + 1e-9:
                return False
        feet[step.side] = step.pose
    try:
        validate_footsteps(seq, limits)
    except HumanoidError:
        return False
    return True


class SupportPolygonPlanner:
    """Chooses the footsteps of a support polygon reshaping for one robot (Fig. 5).

    Args:
        robot: a ``services.model.RobotModel`` (stepping bounds, sole size, arm geometry).
        step_bound_ratio: fraction of the stepping bounds used.
        comfort_reach_ratio: target distance in front of the shoulder, as a fraction of the arm length.
    """

    def __init__(self, robot: Any, step_bound_ratio: float = 0.9, comfort_reach_ratio: float = 0.55) -> None:
        self.robot = robot
        self.limits = shrunk_limits(FootstepBounds.from_robot(robot), step_bound_ratio)
        self.comfort_reach_ratio = comfort_reach_ratio
        q = robot.q_half_sitting
        data = robot.forward(q, robot.new_data())
        mid_x, mid_y, _ = robot.mid_feet_pose(q, data)
        self.shoulder_in_mid: dict[str, np.ndarray] = {}
        self.arm_length_m: dict[str, float] = {}
        for side in ("left", "right"):
            arm = robot.arm_joints(side)
            shoulder = data.oMi[robot.model.getJointId(arm[0])].translation
            self.shoulder_in_mid[side] = np.array([shoulder[0] - mid_x, shoulder[1] - mid_y])
            self.arm_length_m[side] = arm_length(robot, side)
        self._single_cache: dict[tuple[float, ...], list[tuple[str, float, float, float]]] = {}

    # ---------------------------------------------------------------------------------- geometry
    def comfort_stance(
        self,
        left: SolePose,
        right: SolePose,
        target_world_m: np.ndarray,
        hand: str,
        reach_m: float | None = None,
    ) -> tuple[float, float, float]:
        """Mid-feet pose (x, y, yaw) facing the target (Fig. 5), the target ``reach_m`` (default
        ``comfort_reach_ratio`` of the arm length) straight in front of the ``hand`` shoulder,
        horizontally; the robot gets there by turning and walking forwards."""
        x0, y0, yaw0 = mid_pose(left, right)
        x_c, y_c = self.shoulder_in_mid[hand]
        x_c += self.comfort_reach_ratio * self.arm_length_m[hand] if reach_m is None else reach_m
        dx, dy = float(target_world_m[0]) - x0, float(target_world_m[1]) - y0
        rho = max(math.hypot(dx, dy), 1e-9)
        # Heading from which the target is y_c to the side of the line walked from the current stance.
        yaw = math.atan2(dy, dx) - math.asin(max(-1.0, min(1.0, y_c / rho)))
        yaw = yaw0 + wrap_angle(yaw - yaw0)
        c, s = math.cos(yaw), math.sin(yaw)
        gx = float(target_world_m[0]) - (c * x_c - s * y_c)
        gy = float(target_world_m[1]) - (s * x_c + c * y_c)
        return gx, gy, yaw

    @property
    def comfort_reach_m(self) -> dict[str, float]:
        """The default horizontal shoulder-to-target distance of :meth:`comfort_stance` per hand [m]."""
        return {side: self.comfort_reach_ratio * length for side, length in self.arm_length_m.items()}

    def from_shoulder(
        self, mid: tuple[float, float, float], point_world_m: np.ndarray, hand: str
    ) -> tuple[float, float]:
        """(horizontal distance [m], bearing [rad] from straight ahead) of ``point_world_m`` seen from
        the ``hand`` shoulder of a robot standing on ``mid`` (x, y, yaw), shoulder as in half-sitting."""
        c, s = math.cos(mid[2]), math.sin(mid[2])
        sx, sy = self.shoulder_in_mid[hand]
        dx = float(point_world_m[0]) - (mid[0] + c * sx - s * sy)
        dy = float(point_world_m[1]) - (mid[1] + s * sx + c * sy)
        return math.hypot(dx, dy), wrap_angle(math.atan2(dy, dx) - mid[2])

    # ---------------------------------------------------------------------------------- one step
    def single_steps(self, left: SolePose, right: SolePose) -> list[StepPlan]:
        """Every single step of either foot on a grid over the (shrunk) stepping bounds
        (``SINGLE_STEP_GRID`` samples of dx, dy, dyaw relative to the other sole) that lands within
        them without overlapping the other sole: the candidates of Fig. 5's one step (the planner
        chooses among them with the reach envelope)."""
        rel = left.relative_to(right)
        key = tuple(round(v, 4) for v in rel)
        if key not in self._single_cache:
            if len(self._single_cache) >= 16:
                self._single_cache.pop(next(iter(self._single_cache)))
            self._single_cache[key] = self._valid_single_steps(SolePose(*rel), SolePose(0.0, 0.0, 0.0))
        plans: list[StepPlan] = []
        for side, dx, dy, dyaw in self._single_cache[key]:
            stance = right if side == "left" else left
            pose = stance.compose(dx, dy, dyaw)
            seq = FootstepSequence(left, right, (Footstep(side, pose),))
            new_left, new_right = (pose, right) if side == "left" else (left, pose)
            final = mid_pose(new_left, new_right)
            plans.append(StepPlan("single", seq, final, final))
        return plans

    def _valid_single_steps(self, left: SolePose, right: SolePose) -> list[tuple[str, float, float, float]]:
        """(side, dx, dy, dyaw) of the grid's valid single steps from the stance ``left``, ``right``
        (relative to the other sole; they depend only on the relative placement of the soles)."""
        out = []
        for side in ("left", "right"):
            stance = right if side == "left" else left
            lim = self.limits.limits_for(side)
            grids = [
                np.linspace(*lim[k], n) for k, n in zip(("dx", "dy", "dyaw"), SINGLE_STEP_GRID, strict=True)
            ]
            for dx, dy, dyaw in itertools.product(*grids):
                pose = stance.compose(float(dx), float(dy), float(dyaw))
                if _is_valid(FootstepSequence(left, right, (Footstep(side, pose),)), self.limits):
                    out.append((side, float(dx), float(dy), float(dyaw)))
        return out

    # ---------------------------------------------------------------------------------- walk
    def walk(
        self, left: SolePose, right: SolePose, goal_mid: tuple[float, float, float], hand: str, max_steps: int
    ) -> StepPlan | None:
        """The fewest steps (at most ``max_steps``) bringing both feet side by side onto ``goal_mid``;
        None if no walk within ``max_steps`` is valid.

        The mid-feet frame turns to the goal's yaw over the first ``n_turn`` pairs of steps and
        translates over the last ``pairs - lag`` pairs, both linearly: since the comfort stance lies in
        the direction the robot turns to, the translation is mostly forward in the turned frame (the
        bounds allow 0.2 m forward but only a few centimetres sideways per step). During a turn the
        opening foot may land a little outward so that its heel clears the other sole.
        """
        x0, y0, yaw0 = mid_pose(left, right)
        c, s = math.cos(yaw0), math.sin(yaw0)
        gx, gy = goal_mid[0] - x0, goal_mid[1] - y0
        rel = (c * gx + s * gy, -s * gx + c * gy, wrap_angle(goal_mid[2] - yaw0))
        n_turn_min = max(1, math.ceil(abs(rel[2]) / self.limits.dtheta_max_rad - 1e-9))
        for pairs in range(self.steps_needed(left, right, goal_mid) // 2, max_steps // 2 + 1):
            for n_turn in range(min(n_turn_min, pairs), min(n_turn_min + 1, pairs) + 1):
                for lag in sorted({0, n_turn // 2, n_turn} - {pairs}):
                    for outward in TURN_OUTWARD_M:
                        seq = self._walk_sequence(left, right, rel, hand, pairs, n_turn, lag, outward)
                        if seq is not None:
                            final_left, final_right = seq.final_stance()
                            return StepPlan("walk", seq, mid_pose(final_left, final_right), goal_mid)
        return None

    def steps_needed(self, left: SolePose, right: SolePose, goal_mid: tuple[float, float, float]) -> int:
        """A lower bound on the steps of a walk to ``goal_mid`` (from the bounds alone)."""
        x0, y0, yaw0 = mid_pose(left, right)
        distance = math.hypot(goal_mid[0] - x0, goal_mid[1] - y0)
        turn = abs(wrap_angle(goal_mid[2] - yaw0))
        pairs = max(distance / max(self.limits.dx_max_m, 1e-6), turn / max(self.limits.dtheta_max_rad, 1e-6))
        return 2 * max(1, math.ceil(pairs - 1e-9))

    def _walk_sequence(
        self,
        left: SolePose,
        right: SolePose,
        rel: tuple[float, float, float],
        hand: str,
        pairs: int,
        n_turn: int,
        lag: int,
        outward_m: float,
    ) -> FootstepSequence | None:
        """Footsteps of a walk of ``pairs`` pairs (turn over ``n_turn``, translate after ``lag``), or
        None if one of them leaves the bounds or overlaps the other sole."""
        x0, y0, yaw0 = mid_pose(left, right)
        start = SolePose(x0, y0, yaw0)
        spacing = left.relative_to(start)[1] - right.relative_to(start)[1]
        # The foot on the turning side opens first (its yaw bound allows the turn), else the one on the
        # side of the displacement, else the reaching hand's.
        if abs(rel[2]) > 0.05:
            first = "left" if rel[2] > 0 else "right"
        elif abs(rel[1]) > 0.02:
            first = "left" if rel[1] > 0 else "right"
        else:
            first = hand
        for opening in (first, other_side(first)):
            steps: list[Footstep] = []
            for j in range(1, pairs + 1):
                a_turn = min(1.0, j / n_turn)
                a_move = max(0.0, (j - lag) / (pairs - lag))
                frame = start.compose(a_move * rel[0], a_move * rel[1], 0.0)
                frame = SolePose(frame.x_m, frame.y_m, yaw0 + a_turn * rel[2])
                turning = j <= n_turn and abs(rel[2]) > 0.05
                for side in (opening, other_side(opening)):
                    sign = 1.0 if side == "left" else -1.0
                    out = outward_m if (turning and side == opening and j < pairs) else 0.0
                    steps.append(Footstep(side, frame.compose(0.0, sign * (0.5 * spacing + out), 0.0)))
            seq = FootstepSequence(left, right, tuple(steps))
            if _is_valid(seq, self.limits):
                return seq
        return None


def arm_length(robot: Any, side: str) -> float:
    """Distance [m] from the first arm joint (shoulder) to the grasp frame with every arm joint at zero
    (the stretched arm of both supported models): the arm's reach."""
    q = robot.q_half_sitting.copy()
    for joint in robot.arm_joints(side):
        q[robot.joint_index(joint).idx_q] = 0.0
    data = robot.forward(q, robot.new_data())
    shoulder = data.oMi[robot.model.getJointId(robot.arm_joints(side)[0])].translation
    grasp = data.oMf[robot.frame_id(robot.frames.grasp(side))].translation
    return float(np.linalg.norm(grasp - shoulder))
