"""The reach envelope: how far in front of its shoulder a hand reaches on the robot's own support polygon,
as a function of the target height, measured with the same IK and criteria as the motions.

The support polygon planner (Fig. 5) moves the support polygon "so that the incomplete task is
fulfilled": it needs to know where the task becomes feasible. For each height of a grid, the no-step
motion of :mod:`services.reaching.tracker` is run towards a point far straight ahead of the shoulder; the
hand position when the first criterion leaves its admissible range is the reach at that height.
Computed once per robot, hand and options (a few tenths of a second), then interpolated.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from services.reaching.motion import MotionSpec, standing_frame
from services.reaching.references import body_frame_path, minimum_jerk
from services.reaching.tracker import DT_S, ReachTracker

HEIGHTS_M = (0.1, 0.4, 0.7, 1.0, 1.3, 1.6)  # grid of target heights [m]
PROBE_DISTANCE_M = 1.0  # the probe target, this far in front of the shoulder [m], reached in max_reach_s


@dataclass(frozen=True)
class ReachEnvelope:
    """Horizontal reach [m] in front of the shoulder of ``hand`` for targets at ``heights_m``, on the
    half-sitting support polygon (robot at the origin, facing x)."""

    hand: str
    heights_m: np.ndarray
    reach_m: np.ndarray

    def at(self, height_m: float) -> float:
        """Reach [m] in front of the shoulder at ``height_m`` (linear interpolation, clamped)."""
        return float(np.interp(height_m, self.heights_m, self.reach_m))


def measure_envelope(tracker: ReachTracker, hand: str, shoulder_in_mid_m: np.ndarray) -> ReachEnvelope:
    """Run the probes of the module docstring for ``hand`` (``shoulder_in_mid_m``: the shoulder (x, y)
    in the mid-feet frame of half-sitting)."""
    robot: Any = tracker.robot
    q0 = robot.q_half_sitting
    data = robot.new_data()
    left, right = robot.sole_pose(q0, "left", data), robot.sole_pose(q0, "right", data)
    hand0 = robot.frame_pose(q0, robot.frames.grasp(hand), data).translation
    com_xy = robot.com(q0, data)[:2]
    opt = tracker.options
    reach = []
    for height in HEIGHTS_M:
        target = np.array([shoulder_in_mid_m[0] + PROBE_DISTANCE_M, shoulder_in_mid_m[1], height])
        duration = float(
            np.clip(np.linalg.norm(target - hand0) / opt.hand_speed_m_s, opt.min_reach_s, opt.max_reach_s)
        )
        n = round(duration / DT_S) + 1
        frame = standing_frame(
            n,
            DT_S,
            [*left.translation[:2], 0.0, 0.0],
            [*right.translation[:2], 0.0, 0.0],
            com_xy,
            0.0,
        )
        s = minimum_jerk(frame["times_s"], 0.0, duration)
        spec = MotionSpec(
            hand_ref_m=body_frame_path(frame["com_xy_m"], frame["body_yaw_rad"], s, hand0, target),
            hand_rot=None,
            gaze_ref_m=None,
            reach_end_s=duration,
            **frame,
        )
        result = tracker.track(spec, q0, hand)
        hand_xy = result.monitors.hand_m[-1][:2]
        reach.append(max(0.0, float(hand_xy[0] - shoulder_in_mid_m[0])))
    return ReachEnvelope(hand, np.array(HEIGHTS_M), np.array(reach))
