"""Obstacles in the world frame, the scene they make, their coal shapes and their bus message.

Every planner that checks a motion against the map's objects uses these: navigation's stages 1 and 2,
walking's legs sweep (``walking/goal``). Obstacles are vertical-axis boxes (yaw only) and vertical
cylinders; ``world`` is z-up with the floor at z = 0; sizes [m], angles [rad].
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import coal
import numpy as np

from services.bus.schemas.navigation import ObstacleMsg
from services.errors import InvalidRequestError, NotFoundError
from services.model.ground import Rectangle


@dataclass(frozen=True)
class BoxObstacle:
    """A box with vertical z axis: centre ``center_xyz_m`` [m] in world, full sizes [m], yaw [rad]."""

    name: str
    center_xyz_m: tuple[float, float, float]
    size_xyz_m: tuple[float, float, float]
    yaw_rad: float = 0.0

    def __post_init__(self) -> None:
        if any(not math.isfinite(v) for v in (*self.center_xyz_m, *self.size_xyz_m, self.yaw_rad)):
            raise InvalidRequestError(f"obstacle {self.name!r}: centre, size and yaw must be finite numbers")
        if min(self.size_xyz_m) <= 0.0:
            raise InvalidRequestError(
                f"obstacle {self.name!r}: sizes must be > 0 m, got {tuple(self.size_xyz_m)}"
            )

    @property
    def z_range_m(self) -> tuple[float, float]:
        """Bottom and top heights [m]."""
        cz, sz = self.center_xyz_m[2], self.size_xyz_m[2]
        return cz - 0.5 * sz, cz + 0.5 * sz

    @property
    def bounding_radius_xy_m(self) -> float:
        """Radius [m] of the smallest disc around the centre containing the floor projection."""
        return 0.5 * math.hypot(self.size_xyz_m[0], self.size_xyz_m[1])

    @property
    def footprint(self) -> Rectangle:
        """The floor projection: a rectangle of the x and y sizes, turned by the yaw."""
        return Rectangle(
            (self.center_xyz_m[0], self.center_xyz_m[1]),
            (self.size_xyz_m[0], self.size_xyz_m[1]),
            self.yaw_rad,
        )


@dataclass(frozen=True)
class CylinderObstacle:
    """A vertical cylinder: centre ``center_xyz_m`` [m] (middle of its height), radius and height [m]."""

    name: str
    center_xyz_m: tuple[float, float, float]
    radius_m: float
    height_m: float

    def __post_init__(self) -> None:
        if any(not math.isfinite(v) for v in (*self.center_xyz_m, self.radius_m, self.height_m)):
            raise InvalidRequestError(f"obstacle {self.name!r}: centre, radius and height must be finite")
        if self.radius_m <= 0.0 or self.height_m <= 0.0:
            raise InvalidRequestError(
                f"obstacle {self.name!r}: radius and height must be > 0 m, "
                f"got {self.radius_m}, {self.height_m}"
            )

    @property
    def z_range_m(self) -> tuple[float, float]:
        """Bottom and top heights [m]."""
        cz = self.center_xyz_m[2]
        return cz - 0.5 * self.height_m, cz + 0.5 * self.height_m

    @property
    def bounding_radius_xy_m(self) -> float:
        """Radius [m] of the floor projection."""
        return self.radius_m

    @property
    def footprint(self) -> Rectangle:
        """The floor projection's bounding square (side 2 ``radius_m``, yaw 0), as ``ObstacleMsg.footprint``
        gives it: the map's boxes are rectangles."""
        d = 2.0 * self.radius_m
        return Rectangle((self.center_xyz_m[0], self.center_xyz_m[1]), (d, d), 0.0)


Obstacle = BoxObstacle | CylinderObstacle


@dataclass(frozen=True)
class Scene:
    """Obstacles in the world frame and the rectangle ``bounds_xy_m`` = (xmin, xmax, ymin, ymax) [m]
    the robot's base may occupy (the planner's sampling region). Names must be unique."""

    obstacles: tuple[Obstacle, ...]
    bounds_xy_m: tuple[float, float, float, float]

    def __post_init__(self) -> None:
        names = [o.name for o in self.obstacles]
        duplicates = sorted({n for n in names if names.count(n) > 1})
        if duplicates:
            raise InvalidRequestError(f"obstacle names must be unique; repeated: {duplicates}")
        xmin, xmax, ymin, ymax = self.bounds_xy_m
        if not (xmax > xmin and ymax > ymin):
            raise InvalidRequestError(
                f"scene bounds (xmin, xmax, ymin, ymax) must be increasing, got {self.bounds_xy_m}"
            )

    def find(self, name: str) -> Obstacle:
        """The obstacle called ``name``; NotFoundError lists the known names."""
        for obstacle in self.obstacles:
            if obstacle.name == name:
                return obstacle
        raise NotFoundError(
            f"no object named {name!r} in the scene; known objects: {sorted(o.name for o in self.obstacles)}",
            {"name": name, "known": sorted(o.name for o in self.obstacles)},
        )


def obstacle_from_msg(o: ObstacleMsg, index: int | None = None) -> Obstacle:
    """An obstacle from its message (``ObstacleMsg``, the map's objects in navigation's and walking's
    requests); InvalidRequestError names the bad field (``obstacles[index].size`` when the message's
    place in the request's ``obstacles`` is given; ``details``: ``field``, ``index``)."""

    def bad(field: str, problem: str) -> InvalidRequestError:
        if index is None:
            where = f"obstacle {o.name!r}: {field}"
        else:
            where = f"obstacles[{index}].{field} ({o.name!r})"
        return InvalidRequestError(f"{where} {problem}", {"field": field, "index": index})

    if len(o.center) != 3:
        raise bad("center", f"must be [x, y, z] [m], got {o.center}")
    center = (float(o.center[0]), float(o.center[1]), float(o.center[2]))
    if o.kind == "box":
        if len(o.size) != 3:
            raise bad("size", f"must be [sx, sy, sz] [m] for a box, got {o.size}")
        return BoxObstacle(
            o.name, center, (float(o.size[0]), float(o.size[1]), float(o.size[2])), float(o.yaw)
        )
    if o.kind == "cylinder":
        return CylinderObstacle(o.name, center, float(o.radius), float(o.height))
    raise bad("kind", f"must be 'box' or 'cylinder', got {o.kind!r}")


def obstacle_geometry(o: Obstacle) -> tuple[coal.CollisionGeometry, coal.Transform3s, float]:
    """coal shape, its world placement, and the radius of its floor projection's bounding disc."""
    if isinstance(o, BoxObstacle):
        shape = coal.Box(*o.size_xyz_m)
        c, s = math.cos(o.yaw_rad), math.sin(o.yaw_rad)
        R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    else:
        shape = coal.Cylinder(o.radius_m, o.height_m)
        R = np.eye(3)
    return shape, coal.Transform3s(R, np.asarray(o.center_xyz_m, dtype=float)), o.bounding_radius_xy_m
