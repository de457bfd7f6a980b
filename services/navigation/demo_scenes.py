"""Scenes shared by the navigation tests, benchmark and examples (pure data, world frame, [m], [rad]).

- :func:`demo_room`: a 6 x 6 m room with walls, two tables, boxes and a pillar (the benchmark's
  ``room_plan_ms`` problem and the example's top view);
- :func:`bar_scenario`: the bar-carrying experiment of "Manipulating While Walking" in
  `001_771c0ce3779b0683.txt` (Figure 2 and 3): the robot walks past a table with a box on it; the 1.8 m
  bar held across the walking direction overhangs the table and meets the box;
- :func:`enclosed_goal_room`: the demo room with a closed pen around the goal;
- :func:`random_clutter`: ``n`` seeded random boxes and cylinders in an 8 x 8 m area.
"""

from __future__ import annotations

import math

import numpy as np

from services.navigation.geometry import BoxObstacle, CylinderObstacle, Obstacle, Pose2D, Scene

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
        BoxObstacle("yellow_table", (1.6, 1.5, 0.35), (1.2, 0.7, 0.7), 0.0),
        BoxObstacle("blue_table", (-1.2, 0.6, 0.35), (0.8, 0.8, 0.7), math.radians(30.0)),
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


# Bar scenario: walk 4 m along +x; a 0.7 m table beside the path (its near edge 0.45 m from the walking
# line), a box on it reaching 1.0 m; the bar held at 0.9 m spans +-0.9 m across the walking direction.
BAR_TABLE_TOP_M = 0.7
BAR_BOX_TOP_M = 1.0


def bar_scenario() -> tuple[Scene, Pose2D, Pose2D]:
    """The bar-carrying scene: start, goal and a table with a box on it across the bar's sweep."""
    table = BoxObstacle("table", (2.0, 0.8, 0.5 * BAR_TABLE_TOP_M), (0.8, 0.7, BAR_TABLE_TOP_M))
    box_height = BAR_BOX_TOP_M - BAR_TABLE_TOP_M
    box = BoxObstacle(
        "box_on_table", (2.0, 0.62, BAR_TABLE_TOP_M + 0.5 * box_height), (0.3, 0.25, box_height)
    )
    scene = Scene((table, box), (-0.5, 4.5, -1.5, 1.5))
    return scene, Pose2D(0.0, 0.0, 0.0), Pose2D(4.0, 0.0, 0.0)


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
