"""The one oriented rectangle on the floor of the stack (issue 15: one concept, one place).

Soles, object footprints (vision's ``Footprint``, perception's ``FootprintMsg``), the supervisor's map
boxes, the obstacles on the bus (``ObstacleMsg.footprint``) and navigation's ``BoxObstacle`` all use
this class's maths: frame changes, corners, signed distance, containment, ray entry. It lives beside
the message schemas (pure numpy, no zenoh) so that the supervisor, which may import only the bus and
its schemas, uses the same maths as the planners (``services.model.ground`` re-exports it).

Frames: world, z up; a rectangle's own frame has x along its length (its yaw), y across [m, rad].
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass(frozen=True)
class Rectangle:
    """A rectangle on the floor: centre (x, y) [m], size (length along its yaw, width across) [m] and
    yaw [rad], world frame."""

    center_xy_m: tuple[float, float]
    size_m: tuple[float, float]
    yaw_rad: float

    @property
    def half_m(self) -> np.ndarray:
        """Half the length and half the width (2,) [m]."""
        return 0.5 * np.asarray(self.size_m, dtype=float)

    def corners(self) -> np.ndarray:
        """The 4 corners (4, 2) [m], counter-clockwise from the front-left one."""
        hl, hw = 0.5 * self.size_m[0], 0.5 * self.size_m[1]
        return self.to_world(np.array([[hl, hw], [-hl, hw], [-hl, -hw], [hl, -hw]]))

    def to_local(self, points_xy_m: Any) -> np.ndarray:
        """World points (n, 2) (or (2,)) [m] in the rectangle's frame (x along its length), (n, 2)."""
        P = np.atleast_2d(np.asarray(points_xy_m, dtype=float))
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        dx, dy = P[:, 0] - self.center_xy_m[0], P[:, 1] - self.center_xy_m[1]
        return np.column_stack([c * dx + s * dy, -s * dx + c * dy])

    def to_world(self, local_xy_m: Any) -> np.ndarray:
        """Points (n, 2) (or (2,)) [m] of the rectangle's frame in the world, (n, 2)."""
        L = np.atleast_2d(np.asarray(local_xy_m, dtype=float))
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return np.column_stack(
            [self.center_xy_m[0] + c * L[:, 0] - s * L[:, 1], self.center_xy_m[1] + s * L[:, 0] + c * L[:, 1]]
        )

    def rotate_to_local(self, vectors_xy: Any) -> np.ndarray:
        """World directions (n, 2) (or (2,)) in the rectangle's frame (rotation only), (n, 2)."""
        V = np.atleast_2d(np.asarray(vectors_xy, dtype=float))
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return np.column_stack([c * V[:, 0] + s * V[:, 1], -s * V[:, 0] + c * V[:, 1]])

    def grown(self, margin_m: float) -> Rectangle:
        """The rectangle with each side moved out by ``margin_m`` [m] (in, when negative)."""
        return Rectangle(
            self.center_xy_m, (self.size_m[0] + 2.0 * margin_m, self.size_m[1] + 2.0 * margin_m), self.yaw_rad
        )

    def signed_distance(self, points_xy_m: Any) -> np.ndarray:
        """Signed distance (n,) [m] of points (n, 2) (or (2,)) to the rectangle: > 0 outside (the
        Euclidean distance), < 0 inside (minus the distance to the boundary)."""
        excess = np.abs(self.to_local(points_xy_m)) - self.half_m
        outside = np.hypot(np.maximum(excess[:, 0], 0.0), np.maximum(excess[:, 1], 0.0))
        return np.where(np.all(excess <= 0.0, axis=1), np.max(excess, axis=1), outside)

    def distance(self, point_xy_m: Any) -> float:
        """Distance [m] from one point (2,) to the rectangle (0 inside)."""
        return max(0.0, float(self.signed_distance(point_xy_m)[0]))

    def nearest_point(self, point_xy_m: Any) -> np.ndarray:
        """The point (2,) [m] of the rectangle (boundary or inside) nearest to one point (2,) [m]."""
        local = np.clip(self.to_local(point_xy_m)[0], -self.half_m, self.half_m)
        return self.to_world(local)[0]

    def contains(self, point_xy_m: Any) -> bool:
        """Whether one point (2,) [m] lies in the rectangle (its boundary included)."""
        return bool(np.all(np.abs(self.to_local(point_xy_m)[0]) <= self.half_m))

    def ray_entry(self, origin_xy_m: Any, direction_xy: Any) -> float:
        """Distance [m] along the unit ``direction_xy`` from ``origin_xy_m`` to where the ray enters the
        rectangle: 0 when the origin is inside, inf when the ray misses it (slab method)."""
        o = self.to_local(origin_xy_m)[0]
        d = self.rotate_to_local(direction_xy)[0]
        half = self.half_m
        enter, leave = -math.inf, math.inf
        for k in range(2):
            if abs(d[k]) < 1e-12:
                if abs(o[k]) > half[k]:
                    return math.inf
                continue
            t0, t1 = sorted(((-half[k] - o[k]) / d[k], (half[k] - o[k]) / d[k]))
            enter, leave = max(enter, t0), min(leave, t1)
        if enter > leave or leave < 0.0:
            return math.inf
        return max(0.0, float(enter))
