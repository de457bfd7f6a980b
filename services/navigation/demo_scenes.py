"""Scenes shared by the navigation tests, benchmark and examples (pure data, world frame, [m], [rad]).

- :func:`demo_room`: a 6 x 6 m room with walls, two tables, boxes and a pillar (the benchmark's
  ``room_plan_ms`` problem and the example's top view);
- :func:`bar_scenario`: the bar-carrying experiment of "Manipulating While Walking" in
  `001_771c0ce3779b0683.txt` (Figure 2 and 3), laid out as the sim's ``bar_carry`` scene: the robot walks
  past a table with a box on it; the 1.8 m bar held across the walking direction overhangs the table and
  meets the box;
- :func:`bar_rotation_scenario`: the bar scenario with a pole on the left, level with the box, where
  lifting alone does not pass;
- :func:`enclosed_goal_room`: the demo room with a closed pen around the goal;
- :func:`random_clutter`: ``n`` seeded random boxes and cylinders in an 8 x 8 m area.
"""

from __future__ import annotations

import math

import numpy as np

from services.collision.obstacles import BoxObstacle, CylinderObstacle, Obstacle, Scene
from services.navigation.geometry import Pose2D

WALL_THICKNESS_M = 0.1
WALL_HEIGHT_M = 1.0


def walls(xmin: float, xmax: float, ymin: float, ymax: float, prefix: str = "wall") -> list[BoxObstacle]:
    """Four walls whose inner faces are the rectangle (xmin, xmax, ymin, ymax) [m]."""
    t, h = WALL_THICKNESS_M, WALL_HEIGHT_M
    cx, cy = 0.5 * (xmin + xmax), 0.5 * (ymin + ymax)
    lx, ly = xmax - xmin + 2 * t, ymax - ymin + 2 * t
    return [
        BoxObstacle(f"{prefix}_south", (cx, ymin - 0.5 * t, 0.5 * h), (lx, t, h)),
        BoxObstacle(f"{prefix}_north", (cx, ymax + 0.5 * t, 0.5 * h), (lx, t, h)),
        BoxObstacle(f"{prefix}_west", (xmin - 0.5 * t, cy, 0.5 * h), (t, ly, h)),
        BoxObstacle(f"{prefix}_east", (xmax + 0.5 * t, cy, 0.5 * h), (t, ly, h)),
    ]


def demo_room_obstacles() -> list[Obstacle]:
    """Furniture of the demo room (without walls)."""
    return [
        BoxObstacle("yellow_table", (1.6, 1.3, 0.35), (1.2, 0.7, 0.7), 0.0),
        BoxObstacle("blue_table", (-0.9, 0.5, 0.35), (0.8, 0.8, 0.7), math.radians(30.0)),
        BoxObstacle("box_a", (0.6, -1.0, 0.25), (0.5, 0.5, 0.5), 0.3),
        BoxObstacle("box_b", (-0.5, -1.9, 0.2), (0.4, 0.6, 0.4), 0.0),
        BoxObstacle("shelf", (2.7, -1.0, 0.9), (0.5, 1.6, 1.8), 0.0),
        CylinderObstacle("pillar", (0.1, 1.0, 1.2), 0.2, 2.4),
    ]


def demo_room() -> tuple[Scene, Pose2D, Pose2D]:
    """The 6 x 6 m demo room, a start near the south-west corner and a goal near the north-east one."""
    scene = Scene(tuple(walls(-3.0, 3.0, -3.0, 3.0) + demo_room_obstacles()), (-3.0, 3.0, -3.0, 3.0))
    return scene, Pose2D(-2.3, -2.3, 0.0), Pose2D(2.2, 2.4, 0.0)


def enclosed_goal_room() -> tuple[Scene, Pose2D, Pose2D]:
    """The demo room with a closed 1.2 x 1.2 m pen (1 m high walls) around the goal at (-1.8, 2.0)."""
    scene, start, _ = demo_room()
    pen = walls(-2.4, -1.2, 1.4, 2.6, prefix="pen")
    return Scene(scene.obstacles + tuple(pen), scene.bounds_xy_m), start, Pose2D(-1.8, 2.0, 0.0)


# Bar scenario, as in the sim's `bar_carry` scene (sim/scenes/bar_carry.yaml): the 1.8 m bar lies across the
# walking direction on two stands 0.42 m ahead of the robot; a table (top 0.72 m) stands 0.5 m to the right
# of the walking line, 2 m ahead, with a box on it reaching 0.97 m. Held at 0.76-0.9 m, the bar's right
# half passes above the table top but meets the box. Obstacles are bounding boxes (the table's legs and
# top as one block), as perception would report them.
BAR_TABLE_TOP_M = 0.72
BAR_BOX_TOP_M = 0.97
BAR_GOAL_X_M = 3.2


def bar_scenario() -> tuple[Scene, Pose2D, Pose2D]:
    """The bar-carrying scene: two stands holding the bar, a table with a box on it across the bar's
    sweep; start at the origin facing +x, goal ``BAR_GOAL_X_M`` ahead."""
    stands = [
        BoxObstacle(f"{side}_stand", (0.42, y, 0.375), (0.12, 0.12, 0.75))
        for side, y in (("left", 0.62), ("right", -0.62))
    ]
    table = BoxObstacle("table", (2.0, -0.75, 0.5 * BAR_TABLE_TOP_M), (0.8, 0.5, BAR_TABLE_TOP_M))
    box_height = BAR_BOX_TOP_M - BAR_TABLE_TOP_M
    box = BoxObstacle("box", (2.0, -0.65, BAR_TABLE_TOP_M + 0.5 * box_height), (0.3, 0.3, box_height))
    scene = Scene((*stands, table, box), (-0.5, 4.5, -1.5, 1.5))
    return scene, Pose2D(0.0, 0.0, 0.0), Pose2D(BAR_GOAL_X_M, 0.0, 0.0)


BAR_POLE_XY_M = (2.0, 0.93)
BAR_POLE_RADIUS_M = 0.04
BAR_POLE_HEIGHT_M = 1.8


def bar_rotation_scenario() -> tuple[Scene, Pose2D, Pose2D]:
    """The bar scenario with a pole beside the walking line, level with the box: the pole (1.8 m high,
    out of lifting range) stands 0.89 m left of the line (its near side), inside the 0.9 m half length
    of the bar, and the box on the table stands under the bar's right half. Lifting alone does not pass
    (the pole is too high to lift over, and the arms shift the bar at most 5 cm sideways
    (``SamplingOptions.max_left_m``): its left end must come 9 cm in); the bar must rotate (yaw, or
    tilt: both shorten its reach across the walk) and its right half rise over the box: the case of
    the smooth reshaping over the bar's pose ("Smooth Motion Reshaping", `001_771c0ce3779b0683.txt`)."""
    scene, start, goal = bar_scenario()
    x, y = BAR_POLE_XY_M
    pole = CylinderObstacle("pole", (x, y, 0.5 * BAR_POLE_HEIGHT_M), BAR_POLE_RADIUS_M, BAR_POLE_HEIGHT_M)
    return Scene((*scene.obstacles, pole), scene.bounds_xy_m), start, goal


BAR_ON_STANDS_CENTRE_M = (0.42, 0.0, 0.762)
"""Centre [m] of the bar lying on its stands (axis along world y), as in the sim's ``bar_carry`` scene."""


def bar_scenario_start(robot: object) -> np.ndarray:
    """A starting configuration (nq) of ``robot`` (a ``RobotModel``) standing at the origin and holding the
    bar on its stands in both hands (the grasp of the pick-up, :func:`bar_grasp_configuration`), for plans
    made without the sim (tests, benchmark, examples)."""
    from services.navigation.bar_pickup import bar_grasp_configuration

    q0 = robot.half_sitting_at(0.0, 0.0, 0.0)  # type: ignore[attr-defined]
    return bar_grasp_configuration(robot, q0, np.array(BAR_ON_STANDS_CENTRE_M), np.array([0.0, 1.0, 0.0]))


def random_clutter(n: int, seed: int, clear_radius_m: float = 0.6) -> tuple[Scene, Pose2D, Pose2D]:
    """``n`` random boxes/cylinders (seeded) in an 8 x 8 m area, none within ``clear_radius_m`` of the
    start (-3.5, -3.5) and goal (3.5, 3.5) positions."""
    rng = np.random.default_rng(seed)
    start, goal = Pose2D(-3.5, -3.5, math.pi / 4), Pose2D(3.5, 3.5, math.pi / 4)
    obstacles: list[Obstacle] = []
    while len(obstacles) < n:
        x, y = rng.uniform(-4.0, 4.0, size=2)
        k = len(obstacles)
        if rng.random() < 0.7:
            sx, sy = rng.uniform(0.2, 0.9, size=2)
            height = rng.uniform(0.3, 1.5)
            o: Obstacle = BoxObstacle(
                f"box_{k}", (x, y, 0.5 * height), (sx, sy, height), rng.uniform(-math.pi, math.pi)
            )
        else:
            r = rng.uniform(0.1, 0.35)
            height = rng.uniform(0.5, 2.0)
            o = CylinderObstacle(f"cyl_{k}", (x, y, 0.5 * height), r, height)
        reach = o.bounding_radius_xy_m + clear_radius_m
        if min(math.hypot(x - p.x_m, y - p.y_m) for p in (start, goal)) < reach:
            continue
        obstacles.append(o)
    return Scene(tuple(obstacles), (-4.0, 4.0, -4.0, 4.0)), start, goal
