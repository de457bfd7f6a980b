"""The reply of the reaching planner (frozen dataclasses; arrays are numpy)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from services.reaching.monitors import MonitorSeries, Thresholds, Violation
from services.walking.footsteps import Footstep


@dataclass(frozen=True)
class Attempt:
    """One whole-body motion computed by the Fig. 4 loop.

    ``kind`` is "no_step" (the current support polygon), "single" (one reshaping step) or "walk";
    ``violation`` is the criterion that made the planner discard it (None: the motion was kept).
    """

    kind: str
    n_steps: int
    violation: Violation | None
    wall_time_s: float


@dataclass(frozen=True)
class ReachResult:
    """A whole-body reaching motion on the 5 ms grid and what was monitored.

    Attributes:
        robot, hand: robot model name and reaching hand.
        target_world_m: (3,) the target [m].
        times_s: (n,) sample times [s], every ``dt_s``; q: (n, nq) configurations (full model).
        stepped: whether the support polygon was reshaped; footsteps: the steps taken (world frame).
        monitors: the criteria at the IK knots of the returned motion (manipulability eq. 5, end-effector
            error, arm joint-limit margin).
        no_step_monitors: the same for the motion computed on the initial support polygon (discarded at
            its violation when ``stepped``): "manipulability with and without reshaping" (Fig. 7).
        attempts: every motion computed, in order.
        thresholds: the admissible ranges of the criteria used.
        left_sole, right_sole: (n, 4) planned sole poses x, y, z [m], yaw [rad]; phase: (n,) support
            phase codes (``services.walking.timing``: 0 double, 1 left, 2 right support).
        com_m: (n, 3) CoM of the trajectory [m]; zmp_planned_m: (n, 2) ZMP of the planned CoM (pattern
            generator); zmp_multibody_m: (n, 2) ZMP of the whole-body trajectory [m];
            zmp_distance_m: (n,) signed distance of the multibody ZMP to the support polygon (< 0
            inside) [m].
        corrections: passes of the second preview stage (multibody ZMP correction).
        hand_error_m: distance of the hand to the target at the end of the plan [m].
        max_sole_slide_m: largest horizontal drift of a supporting sole from its planned pose [m].
        reach_end_s: when the hand reference arrives at the target [s].
        wall_time_s: planning time [s].
    """

    robot: str
    hand: str
    target_world_m: np.ndarray
    times_s: np.ndarray
    q: np.ndarray = field(repr=False)
    stepped: bool
    footsteps: tuple[Footstep, ...]
    monitors: MonitorSeries = field(repr=False)
    no_step_monitors: MonitorSeries = field(repr=False)
    attempts: tuple[Attempt, ...]
    thresholds: Thresholds
    left_sole: np.ndarray = field(repr=False)
    right_sole: np.ndarray = field(repr=False)
    phase: np.ndarray = field(repr=False)
    com_m: np.ndarray = field(repr=False)
    zmp_planned_m: np.ndarray = field(repr=False)
    zmp_multibody_m: np.ndarray = field(repr=False)
    zmp_distance_m: np.ndarray = field(repr=False)
    corrections: int
    hand_error_m: float
    max_sole_slide_m: float
    reach_end_s: float
    wall_time_s: float

    @property
    def dt_s(self) -> float:
        """Sample period [s]."""
        return float(self.times_s[1] - self.times_s[0])

    @property
    def duration_s(self) -> float:
        """Duration of the motion [s]."""
        return float(self.times_s[-1])

    @property
    def min_zmp_margin_m(self) -> float:
        """Smallest distance of the multibody ZMP inside the support polygon [m] (< 0: it left it)."""
        return float(-self.zmp_distance_m.max())

    def summary(self) -> dict[str, Any]:
        """Plain-data figures (benchmarks, logs)."""
        return {
            "robot": self.robot,
            "hand": self.hand,
            "stepped": self.stepped,
            "steps": len(self.footsteps),
            "duration_s": self.duration_s,
            "planning_s": self.wall_time_s,
            "hand_error_mm": 1e3 * self.hand_error_m,
            "min_zmp_margin_mm": 1e3 * self.min_zmp_margin_m,
            "max_sole_slide_mm": 1e3 * self.max_sole_slide_m,
            "min_manipulability": float(self.monitors.manipulability.min()),
            "max_ee_error_m": float(self.monitors.ee_error_m.max()),
            "attempts": [
                {
                    "kind": a.kind,
                    "steps": a.n_steps,
                    "violation": None if a.violation is None else a.violation.criterion,
                    "wall_time_s": a.wall_time_s,
                }
                for a in self.attempts
            ],
        }
