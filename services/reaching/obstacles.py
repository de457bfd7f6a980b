"""The reaching arm, its gripper and wrist included, kept out of the request's spheres over the whole motion
(``ReachRequest.hand_obstacles``: a ball beside the one to grasp).

The constraint is the footstep paper's eqs. (12)-(13) on the arm's capsules against the spheres
(``000_49c4a782ba599e49.txt``; obstacles as inequalities), the rows of ``services.ik.hand_obstacles``
shared with the footstep planner: inequalities in level (i) of the reaching hierarchy with the feet, so
the hand, CoM and gaze tasks only use motions that keep the arm ``clearance + slack`` away. Where they
cannot (the hand's path itself passes by the sphere), the hand falls behind its reference while the
rows hold the arm off: the criterion that fires then is attributed to the sphere (``hand_obstacle``).
The executed trajectory (the 5 ms spline between the IK knots) is checked against the clearance
itself (:meth:`ArmClearance.path_violation`).

A pair that starts closer than the clearance (the hand already beside a ball) may not come closer than
it started; every other pair stays at least the clearance away.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from services.bus.schemas.reaching import CRITERION_HAND_OBSTACLE
from services.ik.hand_obstacles import (
    HandCapsules,
    SphereDistances,
    hand_capsules,
    sphere_pairs,
    sphere_tasks,
)
from services.ik.task import Task
from services.reaching.monitors import Violation

# A knot whose closest pair is within this much [m] of the rows' margin has them binding: a criterion
# failing there is the sphere's doing.
BINDING_M = 0.003
# Slack [m] of the comparison with a pair's distance at the start (numerical noise of the IK).
START_TOLERANCE_M = 0.001
ROW_GAIN = 0.5  # the rows' gain (eq. 13's lambda): half the violation removed per Gauss-Newton step
PATH_STRIDE = 2  # the executed trajectory is checked every this many 5 ms samples


@dataclass(frozen=True)
class ArmClearance:
    """One request's spheres for the reaching ``hand``: the arm's capsules (``arm``), the checked
    (capsule, sphere) ``pairs`` (the gripper not against the sphere the target lies in or above),
    ``clearance_m`` to keep [m] and ``slack_m`` more kept by the IK's rows [m]."""

    robot: Any
    hand: str
    spheres: tuple[Any, ...]
    arm: HandCapsules
    pairs: tuple[tuple[int, int], ...]
    clearance_m: float
    slack_m: float

    @staticmethod
    def of(robot: Any, request: Any, options: Any) -> ArmClearance | None:
        """The clearance of a validated ``ReachRequest`` with ``ReachingOptions`` ``options``; None
        without spheres (the motion as without the field)."""
        if not request.hand_obstacles:
            return None
        arm = hand_capsules(robot, request.hand)
        pairs = sphere_pairs(arm, request.hand_obstacles, request.target_world_m)
        clearance = options.hand_clearance_m if request.hand_clearance_m is None else request.hand_clearance_m
        return ArmClearance(
            robot,
            request.hand,
            tuple(request.hand_obstacles),
            arm,
            tuple(pairs),
            float(clearance),
            float(options.hand_clearance_slack_m),
        )

    def tasks(self, model: Any, start_distances_m: np.ndarray) -> list[Task]:
        """The inequality rows on the IK's ``model`` (level i): every pair kept ``clearance + slack``
        apart, but a pair that starts closer than that (``start_distances_m``, :meth:`distances` at
        the start) only kept from coming closer (pushed out at once, the hand would lag behind)."""
        margin = self.clearance_m + self.slack_m
        capsules = self.arm.capsules
        near = [k for k, d in enumerate(start_distances_m) if d - START_TOLERANCE_M < margin]
        pairs = [p for k, p in enumerate(self.pairs) if k not in set(near)]
        tasks = list(sphere_tasks(model, capsules, self.spheres, pairs, margin, ROW_GAIN))
        for k in near:
            at_start = float(start_distances_m[k]) - START_TOLERANCE_M
            tasks += sphere_tasks(model, capsules, self.spheres, [self.pairs[k]], at_start, ROW_GAIN)
        return tasks

    def distances(self, model: Any) -> SphereDistances:
        """The pairs' distances on ``model`` (the IK's reduced one or the robot's)."""
        return SphereDistances(model, self.arm.capsules, self.spheres, self.pairs)

    def allowed(self, start_distances_m: np.ndarray) -> np.ndarray:
        """(pairs,) the smallest admissible distance of each pair [m]: the clearance, or less than the
        distance it starts at."""
        return np.minimum(self.clearance_m, start_distances_m - START_TOLERANCE_M)

    def violation(
        self, distances_m: np.ndarray, allowed_m: np.ndarray, time_s: float, held_back: str = ""
    ) -> Violation:
        """The ``hand_obstacle`` violation of the pair that is closest to its admissible distance
        (``held_back``: the criterion that failed while the rows held the arm off)."""
        k = int(np.argmin(distances_m - allowed_m))
        i, j = self.pairs[k]
        return Violation(
            CRITERION_HAND_OBSTACLE,
            float(time_s),
            float(distances_m[k]),
            float(self.clearance_m),
            sphere=j,
            link=self.arm.capsules[i].name,
            held_back=held_back,
        )

    def at_knot(
        self,
        distances_m: np.ndarray,
        allowed_m: np.ndarray,
        time_s: float,
        violation: Violation | None,
    ) -> Violation | None:
        """A knot's violation with the spheres: a pair closer than admissible, or a criterion
        (``violation``) failing while the rows bind (the hand held back by the sphere); else
        ``violation``."""
        if not distances_m.size:
            return violation
        excess = distances_m - allowed_m
        if violation is None and excess.min() < 0.0:
            return self.violation(distances_m, allowed_m, time_s)
        if violation is not None and excess.min() <= self.slack_m + BINDING_M:
            return self.violation(distances_m, allowed_m, time_s, held_back=violation.criterion)
        return violation

    def path_violation(self, q: np.ndarray, times_s: np.ndarray) -> Violation | None:
        """The first sample (every ``PATH_STRIDE``) of the trajectory ``q`` (n, nq of the robot's model)
        where a pair is closer than admissible, or None."""
        check = self.distances(self.robot.model)
        allowed = self.allowed(check.at(q[0]))
        samples = [*range(0, q.shape[0], PATH_STRIDE), q.shape[0] - 1]
        for k in samples:
            d = check.at(q[k])
            if (d < allowed).any():
                return self.violation(d, allowed, float(times_s[k]))
        return None
