"""The reach envelope: how far in front of its shoulder a hand reaches on the robot's own support polygon,
as a function of the target height, measured with the same IK, criteria and motions as the planner's.

The support polygon planner (Fig. 5) moves the support polygon "so that the incomplete task is
fulfilled": it needs to know where the task becomes feasible. For each height of a grid:

1. a *probe*: the no-step motion of :mod:`services.reaching.tracker` towards a point far straight ahead
   of the shoulder; the hand position when the first criterion leaves its admissible range bounds the
   reach from above (the hand passes there on its way, the body leaning while it moves);
2. a *bisection* on the distance of a target straight ahead of the shoulder, each target reached by the
   planner's own no-step motion (``standing_spec``: the hand decelerating onto the target, then the
   final hold): the reach is the farthest target whose motion keeps every criterion in range.

The probe alone overestimated the reach by up to 0.13 m (issue 19): a hand that arrives slowly lets the
IK's rest level (the waist upright, below the four tasks) straighten the trunk while the arm stretches
out to its singular configuration, so that the motion to a target the probe passed fails at its end.
Each grid height is measured once per robot, hand and options, when first needed (about 0.9 s on
this machine), then interpolated.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from services.reaching.motion import MotionSpec, standing_frame
from services.reaching.references import body_frame_path, minimum_jerk
from services.reaching.tracker import DT_S, ReachTracker

HEIGHTS_M = (0.1, 0.4, 0.7, 1.0, 1.3, 1.6)  # grid of target heights [m]
PROBE_DISTANCE_M = 1.0  # the probe target, this far in front of the shoulder [m], reached in max_reach_s
BRACKET_M = 0.32  # the bisection searches [probe - BRACKET_M, probe] first [m]
BISECTIONS = 5  # halvings of the bracket: 1 cm resolution


class ReachEnvelope:
    """Horizontal reach [m] in front of the shoulder of ``hand`` for targets at a height, on the
    half-sitting support polygon (robot at the origin, facing x), interpolated on the grid
    ``HEIGHTS_M``; a grid height is measured (``measure(height) -> (reach, probe)``) the first time an
    interpolation needs it, so that a planner pays only for the heights it reaches to."""

    def __init__(self, hand: str, measure: Callable[[float], tuple[float, float]]) -> None:
        self.hand = hand
        self.heights_m = np.array(HEIGHTS_M)
        self._measure = measure
        self._measured: dict[int, tuple[float, float]] = {}

    def grid(self, i: int) -> tuple[float, float]:
        """(reach [m], probe [m]) at the grid height ``heights_m[i]`` (measured at the first call)."""
        if i not in self._measured:
            self._measured[i] = self._measure(float(self.heights_m[i]))
        return self._measured[i]

    def at(self, height_m: float) -> float:
        """Reach [m] in front of the shoulder at ``height_m`` (linear interpolation, clamped)."""
        h = self.heights_m
        i = int(np.clip(np.searchsorted(h, height_m), 1, len(h) - 1))
        a = float(np.clip((height_m - h[i - 1]) / (h[i] - h[i - 1]), 0.0, 1.0))
        return (1.0 - a) * self.grid(i - 1)[0] + a * self.grid(i)[0]

    @property
    def reach_m(self) -> np.ndarray:
        """The reach [m] at every grid height (measures those not measured yet)."""
        return np.array([self.grid(i)[0] for i in range(len(self.heights_m))])

    @property
    def probe_m(self) -> np.ndarray:
        """The probes' upper bounds [m] at every grid height (measures those not measured yet)."""
        return np.array([self.grid(i)[1] for i in range(len(self.heights_m))])


def _probe(tracker: ReachTracker, hand: str, target: np.ndarray) -> float:
    """x [m] of the hand (robot frame) when the first criterion fails on the way to ``target``."""
    robot: Any = tracker.robot
    q0 = robot.q_half_sitting
    data = robot.new_data()
    left, right = robot.sole_pose(q0, "left", data), robot.sole_pose(q0, "right", data)
    hand0 = robot.frame_pose(q0, robot.frames.grasp(hand), data).translation
    opt = tracker.options
    duration = float(
        np.clip(np.linalg.norm(target - hand0) / opt.hand_speed_m_s, opt.min_reach_s, opt.max_reach_s)
    )
    n = round(duration / DT_S) + 1
    frame = standing_frame(
        n,
        DT_S,
        [*left.translation[:2], 0.0, 0.0],
        [*right.translation[:2], 0.0, 0.0],
        robot.com(q0, data)[:2],
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
    return float(tracker.track(spec, q0, hand).monitors.hand_m[-1][0])


def measure_envelope(
    tracker: ReachTracker,
    hand: str,
    shoulder_in_mid_m: np.ndarray,
    standing_spec: Callable[[np.ndarray], MotionSpec],
) -> ReachEnvelope:
    """Run the probes and bisections of the module docstring for ``hand`` (``shoulder_in_mid_m``: the
    shoulder (x, y) in the mid-feet frame of half-sitting; ``standing_spec(target)``: the planner's
    no-step motion of ``hand`` to ``target`` from half-sitting at the origin)."""
    q0 = tracker.robot.q_half_sitting
    sx, sy = float(shoulder_in_mid_m[0]), float(shoulder_in_mid_m[1])

    def reached(distance_m: float, height_m: float) -> bool:
        target = np.array([sx + distance_m, sy, height_m])
        return tracker.track(standing_spec(target), q0, hand).violation is None

    def measure(height_m: float) -> tuple[float, float]:
        probe = max(0.0, _probe(tracker, hand, np.array([sx + PROBE_DISTANCE_M, sy, height_m])) - sx)
        lo, hi = max(0.0, probe - BRACKET_M), probe
        if not reached(lo, height_m):
            lo, hi = 0.0, lo
            if not reached(lo, height_m):
                return 0.0, probe
        for _ in range(BISECTIONS):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if reached(mid, height_m) else (lo, mid)
        return lo, probe

    return ReachEnvelope(hand, measure)
