"""Near goals walked straight instead of along a car-like detour (stage 1's alternative for short walks).

The forward-preferring Dubins / Reeds-Shepp curves of stage 1 loop around to shift the robot sideways
by half a metre; a humanoid steps sideways. A goal nearer than ``short_walk_m`` whose path is longer
than ``detour_factor`` x the straight line + ``detour_slack_m`` (or that stage 1 found no path to within
its budget) is walked straight, stepping forward, sideways and turning together
(``services.walking.goals``: the footsteps within the robot's bounds), when the straight walk is clear
of the scene's obstacles (:func:`services.walking.goals.check_clear`). Stage 2 then plans it as it
plans a path's footsteps: one whole-body motion per walk, checked in 3D.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from services.collision.obstacles import Scene
from services.errors import InfeasibleError
from services.model.ground import FootstepBounds, SolePose
from services.navigation.footsteps_along_path import PathFootsteps
from services.navigation.geometry import Pose2D
from services.navigation.path import SampledPath
from services.walking.goals import MapBox, check_clear, walk_to_steps

SAMPLE_STEP_M = 0.02
"""Spacing of the straight path's samples [m] (as stage 1's paths)."""


@dataclass(frozen=True)
class StraightWalkOptions:
    """When a near goal is walked straight (module docstring) and how far it keeps from the obstacles:
    the mid-feet line ``clearance_m`` [m] (or as far as its start or end is), every sole
    ``sole_margin_m`` [m]."""

    short_walk_m: float = 1.5
    detour_factor: float = 1.5
    detour_slack_m: float = 0.5
    clearance_m: float = 0.35
    sole_margin_m: float = 0.03

    def is_detour(self, start: Pose2D, goal: Pose2D, path_length_m: float) -> bool:
        """Whether a path of ``path_length_m`` [m] from ``start`` to a near ``goal`` is a detour."""
        straight = math.hypot(goal.x_m - start.x_m, goal.y_m - start.y_m)
        return straight <= self.short_walk_m and path_length_m > (
            self.detour_factor * straight + self.detour_slack_m
        )

    def is_near(self, start: Pose2D, goal: Pose2D) -> bool:
        return math.hypot(goal.x_m - start.x_m, goal.y_m - start.y_m) <= self.short_walk_m


def floor_boxes(scene: Scene) -> list[MapBox]:
    """The scene's obstacles as floor rectangles (a cylinder as its bounding square)."""
    return [MapBox(o.name, o.footprint) for o in scene.obstacles]


def straight_walk(
    robot: Any,
    scene: Scene,
    soles: tuple[SolePose, SolePose],
    start: Pose2D,
    goal: Pose2D,
    options: StraightWalkOptions,
) -> tuple[SampledPath, PathFootsteps] | None:
    """The straight walk from ``start`` (the mid-feet pose of ``soles`` = (left, right)) to ``goal``: its
    path (the straight line, heading interpolated) and footsteps, or None when it does not fit the
    robot's bounds or passes too near an obstacle."""
    c, s = math.cos(start.theta_rad), math.sin(start.theta_rad)
    ex, ey = goal.x_m - start.x_m, goal.y_m - start.y_m
    dx, dy = c * ex + s * ey, -s * ex + c * ey
    dyaw = math.remainder(goal.theta_rad - start.theta_rad, 2.0 * math.pi)
    limits = FootstepBounds.from_robot(robot)
    try:
        sequence = walk_to_steps(
            {"left": soles[0], "right": soles[1]}, dx, dy, dyaw, limits, face_the_way=True
        )
        check_clear(
            sequence,
            floor_boxes(scene),
            clearance_m=options.clearance_m,
            sole_margin_m=options.sole_margin_m,
            sole_size_m=(limits.sole_length_m, limits.sole_width_m),
        )
    except InfeasibleError:
        return None
    length = math.hypot(ex, ey)
    n = max(2, math.ceil(length / SAMPLE_STEP_M) + 1)
    t = np.linspace(0.0, 1.0, n)
    xy = np.stack([start.x_m + t * ex, start.y_m + t * ey], axis=1)
    theta = start.theta_rad + t * dyaw
    path = SampledPath(
        xy_m=xy,
        theta_rad=theta,
        s_m=t * length,
        forward=np.full(n, dx >= 0.0),
        waypoints=np.array([[start.x_m, start.y_m, start.theta_rad], [goal.x_m, goal.y_m, goal.theta_rad]]),
        turning_radius_m=0.0,
        curve="straight",
        planner="straight",
    )
    k = len(sequence.steps)
    return path, PathFootsteps(sequence, tuple(length * min(i + 1, k) / k for i in range(k)))
