"""The supervisor's map for navigation: obstacles built from perception's sightings (never ground truth).

Perception gives, per object, the triangulated middle of its coloured silhouette and the width and
height of its image box at that depth (services/bus/schemas/perception.py). Navigation wants boxes
on the floor (services/bus/schemas/navigation.py). The depth of an object is not seen: the footprint
is taken square (depth = seen width), facing the camera that saw it, and pushed back from the seen
point by a quarter of its depth (the silhouette of a box or table seen from above the top mixes its
front face and its top). Small objects (balls) and held objects are not obstacles.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from services.bus.schemas import navigation as nav_msg
from supervisor.memory import Memory, Sighting

#: Objects whose seen width and height are both below this are not obstacles (balls on a box) [m].
SMALL_OBJECT_M = 0.25
DEPTH_RANGE_M = (0.3, 1.2)
PUSH_BACK_FRACTION = 0.25


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

    def to_msg(self) -> nav_msg.ObstacleMsg:
        return nav_msg.ObstacleMsg(
            name=self.name, kind="box", center=list(self.center_m), size=list(self.size_m), yaw=self.yaw_rad
        )


def box_estimate(sighting: Sighting) -> BoxEstimate:
    """The footprint box of an object seen by perception (see the module docstring)."""
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


def is_obstacle(sighting: Sighting) -> bool:
    return max(sighting.size_m) >= SMALL_OBJECT_M


def obstacles(memory: Memory) -> list[nav_msg.ObstacleMsg]:
    """Navigation obstacles of every object seen, except small and held ones."""
    held = set(memory.holding.values())
    return [
        box_estimate(s).to_msg() for s in memory.sightings.values() if s.name not in held and is_obstacle(s)
    ]


def distance_to_box(box: BoxEstimate, x_m: float, y_m: float) -> float:
    """Horizontal distance from (x, y) to the box's footprint rectangle [m] (0 inside)."""
    c, s = math.cos(box.yaw_rad), math.sin(box.yaw_rad)
    dx, dy = x_m - box.center_m[0], y_m - box.center_m[1]
    local = np.array([c * dx + s * dy, -s * dx + c * dy])
    excess = np.maximum(np.abs(local) - np.array(box.size_m[:2]) / 2.0, 0.0)
    return float(np.linalg.norm(excess))
