"""The supervisor's map for navigation: obstacles built from perception's sightings (never ground truth).

Perception gives, per object, the triangulated middle of its coloured silhouette, the width and
height of its image box at that depth and, for a box, a table or a chair, its floor rectangle from the
stereo points of its outline (``footprint``, vision/footprint.py); navigation wants boxes on the floor
(services/bus/schemas/navigation.py). The map's box is that rectangle up to the highest outline point.
What the outline cannot show stays an assumption: a rectangle thinner than ``MIN_DEPTH_FRACTION`` of its
length (a chair seen from behind: only its back) hides its depth, which is taken as long as the
rectangle, behind what was seen. Without a footprint (the outline matched in too few rows) the box is
taken square (depth = seen width), facing the camera that saw it, pushed back from the seen point by a
quarter of its depth. Small objects (balls) and held objects are not obstacles for navigation; the
balls seen near one to grasp are spheres the reaching arm keeps clear of (:func:`neighbours`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.bus.schemas import navigation as nav_msg
from services.bus.schemas.rectangle import Rectangle
from supervisor.memory import Memory, Sighting

#: Objects whose seen width and height are both below this are not obstacles (balls on a box) [m].
SMALL_OBJECT_M = 0.25
DEPTH_RANGE_M = (0.3, 1.2)
PUSH_BACK_FRACTION = 0.25
#: A footprint thinner than this fraction of its length hides its depth (see the module docstring).
MIN_DEPTH_FRACTION = 0.4


@dataclass(frozen=True)
class BoxEstimate:
    """An object's estimated footprint box: centre [m], extents (sx, sy, sz) [m], yaw [rad]."""

    name: str
    center_m: tuple[float, float, float]
    size_m: tuple[float, float, float]
    yaw_rad: float

    @property
    def top_z_m(self) -> float:
        return self.size_m[2]

    @property
    def footprint(self) -> Rectangle:
        """Its floor rectangle (the stack's one rectangle maths)."""
        return Rectangle((self.center_m[0], self.center_m[1]), (self.size_m[0], self.size_m[1]), self.yaw_rad)

    def to_msg(self) -> nav_msg.ObstacleMsg:
        return nav_msg.ObstacleMsg(
            name=self.name, kind="box", center=list(self.center_m), size=list(self.size_m), yaw=self.yaw_rad
        )


def box_estimate(sighting: Sighting) -> BoxEstimate:
    """The footprint box of an object seen by perception (see the module docstring)."""
    if sighting.footprint is not None:
        return _from_footprint(sighting)
    p = np.asarray(sighting.position_m, dtype=float)
    view = p[:2] - np.asarray(sighting.camera_m, dtype=float)[:2]
    norm = float(np.linalg.norm(view))
    u = view / norm if norm > 1e-6 else np.array([1.0, 0.0])
    width, height = sighting.size_m
    depth = float(np.clip(width, *DEPTH_RANGE_M))
    top = max(0.05, float(p[2] + height / 2.0))
    centre_xy = p[:2] + u * depth * PUSH_BACK_FRACTION
    return BoxEstimate(
        name=sighting.name,
        center_m=(float(centre_xy[0]), float(centre_xy[1]), top / 2.0),
        size_m=(depth, max(0.2, float(width)), top),
        yaw_rad=math.atan2(float(u[1]), float(u[0])),
    )


def _from_footprint(sighting: Sighting) -> BoxEstimate:
    fp = sighting.footprint
    assert fp is not None
    rect = fp.rectangle
    length, width = rect.size_m
    centre = np.asarray(rect.center_xy_m, dtype=float)
    depth = max(width, min(length, DEPTH_RANGE_M[1]))
    if width < MIN_DEPTH_FRACTION * length:  # extend across it, away from the camera that saw it
        camera_across = float(rect.to_local(np.asarray(sighting.camera_m, dtype=float)[:2])[0, 1])
        shift = (depth - width) / 2.0
        centre = rect.to_world([0.0, -shift if camera_across > 0.0 else shift])[0]
        width = depth
    top = max(0.05, fp.top_z)
    return BoxEstimate(
        name=sighting.name,
        center_m=(float(centre[0]), float(centre[1]), top / 2.0),
        size_m=(float(length), float(width), top),
        yaw_rad=fp.yaw,
    )


def is_obstacle(sighting: Sighting) -> bool:
    return max(sighting.size_m) >= SMALL_OBJECT_M


def boxes(memory: Memory) -> list[BoxEstimate]:
    """The map: the box of every object seen, except small and held ones."""
    held = set(memory.holding.values())
    return [box_estimate(s) for s in memory.sightings.values() if s.name not in held and is_obstacle(s)]


#: A small object's sphere radius is half its largest seen size, within these bounds [m].
SPHERE_RADIUS_RANGE_M = (0.01, 0.06)


def sphere_radius(sighting: Sighting) -> float:
    """The radius [m] of a small object (a ball) as perception saw it: half its largest seen size."""
    return float(np.clip(max(sighting.size_m) / 2.0, *SPHERE_RADIUS_RANGE_M))


def neighbours(
    memory: Memory, point_m: np.ndarray, within_m: float, exclude: set[str]
) -> list[tuple[np.ndarray, float]]:
    """The small objects seen (balls, not held, not ``exclude``) whose centre lies within ``within_m``
    [m] of ``point_m`` horizontally, as spheres (centre [m] world, radius [m]), nearest first: what a
    hand reaching ``point_m`` keeps clear of (perception reports every learned object a look sees, so
    the balls beside the one to grasp are known before the first touch)."""
    held = set(memory.holding.values())
    p = np.asarray(point_m, dtype=float)
    near = []
    for s in memory.sightings.values():
        if s.name in exclude or s.name in held or is_obstacle(s):
            continue
        d = float(np.linalg.norm(s.position_m[:2] - p[:2]))
        if d < within_m:
            near.append((d, np.asarray(s.position_m, dtype=float), sphere_radius(s)))
    return [(centre, radius) for _, centre, radius in sorted(near, key=lambda n: n[0])]


def obstacles(memory: Memory) -> list[nav_msg.ObstacleMsg]:
    """The map as navigation obstacles."""
    return [box.to_msg() for box in boxes(memory)]


def ray_entry(box: BoxEstimate, origin_xy: np.ndarray, direction_xy: np.ndarray) -> float:
    """Distance [m] along the unit ``direction_xy`` from ``origin_xy`` to where the ray enters the box's
    footprint rectangle (0 inside; inf if the ray misses it): :meth:`Rectangle.ray_entry`."""
    return box.footprint.ray_entry(origin_xy, direction_xy)


def distance_to_box(box: BoxEstimate, x_m: float, y_m: float) -> float:
    """Horizontal distance from (x, y) to the box's footprint rectangle [m] (0 inside):
    :meth:`Rectangle.distance`."""
    return box.footprint.distance((x_m, y_m))


def viewpoints_past(
    box: BoxEstimate, from_xy: np.ndarray, margin_m: float
) -> list[tuple[float, float, float]]:
    """Two poses (x [m], y [m], yaw [rad]) from which to look past ``box`` (an object that may hide
    another from ``from_xy``, where the robot looked from): stepped sideways from ``from_xy``,
    perpendicular to the sight line to the box's middle, far enough that the same sight line from
    there passes beside the box's floor rectangle by ``margin_m``, facing along it; its left side
    first. Where to look from is perception's concern; the walk there is navigation's."""
    start = np.asarray(from_xy, dtype=float)[:2]
    centre = np.asarray(box.center_m[:2], dtype=float)
    sight = centre - start
    norm = float(np.linalg.norm(sight))
    u = sight / norm if norm > 1e-6 else np.array([1.0, 0.0])
    n = np.array([-u[1], u[0]])
    half = float(np.abs((box.footprint.corners() - centre) @ n).max())
    yaw = math.atan2(float(u[1]), float(u[0]))
    return [
        (float(p[0]), float(p[1]), yaw)
        for p in (start + side * (half + margin_m) * n for side in (1.0, -1.0))
    ]
