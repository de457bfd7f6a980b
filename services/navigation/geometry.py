"""The scene as the navigation planner sees it, and the 2D footprint collision checker.

Stage 1 of the two-stage planner ("Two-stage Planning Method", section "Manipulating While Walking" of
`001_771c0ce3779b0683.txt`): "the motion planner computes a collision-free walking path for the lower part
of the robot body approximated by a bounding box". This module holds:

- the obstacles it checks (vertical-axis oriented boxes, yaw only, and vertical cylinders, in the world
  frame [m, rad]) are :mod:`services.collision.obstacles`' (shared with walking);
- :class:`BodyModel`: the per-robot bounding boxes (lower body footprint on the floor, upper body box);
- :class:`FootprintChecker`: is the lower-body rectangle at (x, y, theta) free of the floor projections
  of the obstacles that reach into the lower body's height range? Exact separating-axis tests, behind a
  precomputed distance grid that answers most queries with one array lookup.

Frames: ``world`` is z-up with the floor at z = 0; the robot frame ``base`` is the midpoint between the
soles, x forward, theta its yaw in the world.
"""

from __future__ import annotations

import copy
import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from services.collision.obstacles import BoxObstacle, Scene
from services.errors import InvalidRequestError, NotFoundError
from services.model.ground import Rectangle


@dataclass(frozen=True)
class Pose2D:
    """A base pose on the floor: position (x_m, y_m) [m] in world, heading theta_rad [rad] (x forward)."""

    x_m: float
    y_m: float
    theta_rad: float

    def __post_init__(self) -> None:
        if not all(math.isfinite(v) for v in (self.x_m, self.y_m, self.theta_rad)):
            raise InvalidRequestError(
                f"pose must be finite numbers, got {(self.x_m, self.y_m, self.theta_rad)}"
            )


@dataclass(frozen=True)
class BodyModel:
    """Bounding boxes of a robot for navigation, in the ``base`` frame (x forward, centred between feet).

    - lower body: a ``footprint_length_m`` x ``footprint_width_m`` rectangle on the floor, grown by
      ``margin_m`` on every side, up to ``lower_body_height_m``: it must contain the legs and feet through
      a walking cycle (the paper's "bounding box" of the lower part of the body);
    - upper body: a box ``upper_body_size_m`` (length, width) from ``lower_body_height_m`` up to
      ``height_m``, centred on the base (checked in 3D with the carried object by :mod:`upper_body`);
    - arms: the arms stick out beyond the legs' footprint (sideways when hanging, ahead when holding a
      bar): a second rectangle ``arms_x_range_m`` (back, front) along the heading and ``arms_width_m``
      wide (+ the margin), seen by the obstacles reaching into ``arms_z_range_m`` (0 width: none). The
      defaults are the half-sitting arms; :func:`services.navigation.body_extents.with_arms_of` measures
      them in the robot's starting configuration. Stage 2 checks the real arms in 3D; without this layer
      stage 1 would send the robot's hands through a crate beside the path.
    """

    name: str
    footprint_length_m: float
    footprint_width_m: float
    margin_m: float
    lower_body_height_m: float
    upper_body_size_m: tuple[float, float]
    height_m: float
    foot_half_spacing_m: float
    arms_width_m: float = 0.0
    arms_z_range_m: tuple[float, float] = (0.0, 0.0)
    arms_x_range_m: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        if min(self.footprint_length_m, self.footprint_width_m, self.lower_body_height_m, self.height_m) <= 0:
            raise InvalidRequestError(f"body model {self.name!r}: sizes must be > 0 m")
        if self.margin_m < 0.0:
            raise InvalidRequestError(f"body model {self.name!r}: margin must be >= 0 m, got {self.margin_m}")

    @property
    def half_extents_m(self) -> tuple[float, float]:
        """Half length and half width [m] of the footprint rectangle including the margin."""
        return (0.5 * self.footprint_length_m + self.margin_m, 0.5 * self.footprint_width_m + self.margin_m)

    @property
    def arms_half_extents_m(self) -> tuple[float, float]:
        """Half length and half width [m] of the arms' rectangle including the margin."""
        x0, x1 = self.arms_x_range_m
        return (0.5 * (x1 - x0) + self.margin_m, 0.5 * self.arms_width_m + self.margin_m)

    @property
    def arms_offset_m(self) -> float:
        """Distance [m] of the arms' rectangle's centre ahead of the base origin."""
        return 0.5 * (self.arms_x_range_m[0] + self.arms_x_range_m[1])

    @property
    def max_reach_m(self) -> float:
        """Radius [m] around the base of the floor rectangles (footprint and arms, margins included)."""
        reach = math.hypot(*self.half_extents_m)
        if self.arms_width_m > 0.0:
            reach = max(reach, abs(self.arms_offset_m) + math.hypot(*self.arms_half_extents_m))
        return reach

    def with_margin(self, margin_m: float) -> BodyModel:
        """The same body with another footprint margin [m]."""
        return dataclasses.replace(self, margin_m=margin_m)


# hrp2_like: soles 0.24 x 0.14 m at +-0.095 m (outer width 0.33 m); the rectangle also holds the swing
# foot through a 0.2 m step (0.24 + 2 * 0.13 = 0.5 m) and the legs' lateral sway. Hip at about 0.65 m,
# pelvis box up to 0.75 m; 1.54 m tall; shoulders about 0.55 m wide. Arms hanging in half-sitting (their
# URDF collision shapes): |y| <= 0.44 m (the hands' palms), z 0.52 - 1.18 m, x -0.07 - 0.10 m.
# talos (talos_reduced): 1.76 m, soles 0.205 x 0.122 m at about +-0.085 m, hips at about 0.9 m; arms
# (collision meshes) |y| <= 0.54 m, z 0.63 - 1.43 m, x -0.12 - 0.20 m.
BODY_MODELS: dict[str, BodyModel] = {
    "hrp2_like": BodyModel(
        "hrp2_like", 0.50, 0.44, 0.05, 0.75, (0.40, 0.58), 1.54, 0.095, 0.88, (0.52, 1.18), (-0.07, 0.10)
    ),
    "talos": BodyModel(
        "talos", 0.54, 0.50, 0.05, 1.00, (0.45, 0.70), 1.76, 0.085, 1.08, (0.63, 1.43), (-0.12, 0.21)
    ),
}
_ALIASES = {"talos_reduced": "talos"}


def body_model(robot: str) -> BodyModel:
    """The navigation :class:`BodyModel` of ``robot``; NotFoundError lists the known robots."""
    try:
        return BODY_MODELS[_ALIASES.get(robot, robot)]
    except KeyError:
        raise NotFoundError(
            f"no navigation body model for robot {robot!r}; known robots: {sorted(BODY_MODELS)}",
            {"robot": robot, "known": sorted(BODY_MODELS)},
        ) from None


# ---------------------------------------------------------------------------------------------------------
# 2D primitives on the floor (pure Python floats: these run inside OMPL's validity callback).


@dataclass(frozen=True)
class _Rect2D:
    """Oriented rectangle: centre, half extents along its own axes, cos/sin of its yaw (the box's
    ``footprint`` in plain floats, for the validity callback)."""

    name: str
    cx: float
    cy: float
    hx: float
    hy: float
    c: float
    s: float
    footprint: Rectangle


@dataclass(frozen=True)
class _Circle2D:
    name: str
    cx: float
    cy: float
    r: float


def _rect_rect_overlap(
    a: _Rect2D, bx: float, by: float, bhx: float, bhy: float, bc: float, bs: float
) -> bool:
    """Separating-axis test of two oriented rectangles (closed sets: touching counts as overlap)."""
    dx, dy = bx - a.cx, by - a.cy
    # dot products between the four axes
    c_aa = abs(a.c * bc + a.s * bs)  # |ax . bx| = |ay . by|
    c_ab = abs(a.c * bs - a.s * bc)  # |ax . by| = |ay . bx|
    # axes of a
    if abs(dx * a.c + dy * a.s) > a.hx + bhx * c_aa + bhy * c_ab:
        return False
    if abs(-dx * a.s + dy * a.c) > a.hy + bhx * c_ab + bhy * c_aa:
        return False
    # axes of b
    if abs(dx * bc + dy * bs) > bhx + a.hx * c_aa + a.hy * c_ab:
        return False
    return not abs(-dx * bs + dy * bc) > bhy + a.hx * c_ab + a.hy * c_aa


def _rect_circle_overlap(
    bx: float, by: float, bhx: float, bhy: float, bc: float, bs: float, o: _Circle2D
) -> bool:
    dx, dy = o.cx - bx, o.cy - by
    lx, ly = dx * bc + dy * bs, -dx * bs + dy * bc
    qx = max(abs(lx) - bhx, 0.0)
    qy = max(abs(ly) - bhy, 0.0)
    return qx * qx + qy * qy <= o.r * o.r


def _distance_grid(shapes: list[_Rect2D | _Circle2D], xs: np.ndarray, ys: np.ndarray) -> np.ndarray:
    """Exact Euclidean distance [m] from each grid node to the nearest shape (0 inside), shape (ny, nx)."""
    X, Y = np.meshgrid(xs, ys)
    nodes = np.column_stack([X.ravel(), Y.ravel()])
    dist = np.full(X.shape, np.inf)
    for o in shapes:
        if isinstance(o, _Rect2D):
            d = np.maximum(o.footprint.signed_distance(nodes), 0.0).reshape(X.shape)
        else:
            d = np.maximum(np.hypot(X - o.cx, Y - o.cy) - o.r, 0.0)
        np.minimum(dist, d, out=dist)
    return dist


class FootprintChecker:
    """Collision checker of the lower-body footprint at (x, y, theta) against a scene's floor projections.

    Only obstacles whose height range meets [0, ``body.lower_body_height_m``] are seen (a shelf above the
    hips does not block the legs; the upper body and carried object are checked in 3D by
    :mod:`services.navigation.upper_body`). Being outside ``scene.bounds_xy_m`` also counts as a collision.

    A distance grid with spacing ``resolution_m`` is precomputed; since the distance field is 1-Lipschitz,
    a query whose nearest node is farther than the footprint's circumradius (+ half a cell diagonal) is free
    and one nearer than its inradius (- half a diagonal) collides, without testing any obstacle. The rest
    go to the exact separating-axis tests against the obstacles close enough to matter.
    """

    def __init__(
        self, scene: Scene, body: BodyModel, resolution_m: float = 0.05, layer: str = "lower_body"
    ) -> None:
        if not (math.isfinite(resolution_m) and resolution_m > 0.0):
            raise InvalidRequestError(f"checker resolution must be > 0 m, got {resolution_m}")
        self.scene = scene
        self.body = body
        self.resolution_m = resolution_m
        self.layer = layer
        bottom, top = (0.0, body.lower_body_height_m) if layer == "lower_body" else body.arms_z_range_m
        self._shapes: list[_Rect2D | _Circle2D] = []
        for o in scene.obstacles:
            z0, z1 = o.z_range_m
            if z1 < bottom or z0 > top:
                continue
            cx, cy = o.center_xyz_m[0], o.center_xyz_m[1]
            if isinstance(o, BoxObstacle):
                hx, hy = 0.5 * o.size_xyz_m[0], 0.5 * o.size_xyz_m[1]
                self._shapes.append(
                    _Rect2D(o.name, cx, cy, hx, hy, math.cos(o.yaw_rad), math.sin(o.yaw_rad), o.footprint)
                )
            else:
                self._shapes.append(_Circle2D(o.name, cx, cy, o.radius_m))
        xmin, xmax, ymin, ymax = scene.bounds_xy_m
        h = resolution_m
        self._nx = math.ceil((xmax - xmin) / h) + 1
        self._ny = math.ceil((ymax - ymin) / h) + 1
        self._x0, self._y0 = xmin, ymin
        xs = xmin + h * np.arange(self._nx)
        ys = ymin + h * np.arange(self._ny)
        self._grid = _distance_grid(self._shapes, xs, ys)
        self._grid_list = self._grid.tolist()  # list-of-lists lookups are faster than numpy scalars
        self._slack = h * math.sqrt(0.5)
        # the arms' layer: a second checker with the arms' rectangle and the obstacles at arm height
        self._arms: FootprintChecker | None = None
        self._union_list = self._grid_list
        if layer == "lower_body" and body.arms_width_m > 0.0:
            self._arms = FootprintChecker(scene, body, resolution_m, layer="arms")
            # distance to the nearest obstacle of either layer: one lookup clears most poses of both
            self._union_list = np.minimum(self._grid, self._arms._grid).tolist()
        self._set_body(body)

    def _set_body(self, body: BodyModel) -> None:
        self.body = body
        if self.layer == "lower_body":
            self.hx, self.hy = body.half_extents_m
            self.offset_m = 0.0
        else:
            self.hx, self.hy = body.arms_half_extents_m
            self.offset_m = body.arms_offset_m
        self.r_in = min(self.hx, self.hy)
        self.r_circ = math.hypot(self.hx, self.hy)
        self._free_above = self.r_circ + self._slack
        self._hit_below = self.r_in - self._slack
        # farthest point of either rectangle from the base (margins included), plus the grid error
        self._all_free_above = max(self._free_above, body.max_reach_m + self._slack)

    def with_margin(self, margin_m: float) -> FootprintChecker:
        """The same checker, sharing the distance grids, for the footprint margin ``margin_m`` [m]."""
        other = copy.copy(self)
        other._set_body(self.body.with_margin(margin_m))
        if self._arms is not None:
            other._arms = self._arms.with_margin(margin_m)
        return other

    # -- queries ------------------------------------------------------------------------------------------

    @property
    def lower_body_obstacles(self) -> list[str]:
        """Names of the obstacles the footprint is checked against."""
        return [o.name for o in self._shapes]

    @property
    def arm_obstacles(self) -> list[str]:
        """Names of the obstacles the arms' rectangle is checked against."""
        return [] if self._arms is None else self._arms.lower_body_obstacles

    def in_bounds(self, x: float, y: float) -> bool:
        """Is the base position inside the scene bounds?"""
        xmin, xmax, ymin, ymax = self.scene.bounds_xy_m
        return xmin <= x <= xmax and ymin <= y <= ymax

    def centre_distance_m(self, x: float, y: float) -> float:
        """Distance [m] from (x, y) to the nearest floor projection, read on the grid.

        The error is at most half a cell diagonal."""
        i = round((y - self._y0) / self.resolution_m)
        j = round((x - self._x0) / self.resolution_m)
        i = min(max(i, 0), self._ny - 1)
        j = min(max(j, 0), self._nx - 1)
        return self._grid_list[i][j]

    def _union_distance_m(self, x: float, y: float) -> float:
        i = min(max(round((y - self._y0) / self.resolution_m), 0), self._ny - 1)
        j = min(max(round((x - self._x0) / self.resolution_m), 0), self._nx - 1)
        return self._union_list[i][j]

    def is_free(self, x: float, y: float, theta: float) -> bool:
        """True when the footprint rectangle (and the arms' one) at base pose (x [m], y [m], theta [rad])
        touches nothing."""
        if self.offset_m == 0.0:
            cx, cy = x, y
        else:  # the rectangle's centre, ahead of the base
            cx, cy = x + self.offset_m * math.cos(theta), y + self.offset_m * math.sin(theta)
        if self.in_bounds(cx, cy):
            d = self.centre_distance_m(cx, cy)
            if self._arms is not None and self._union_distance_m(x, y) >= self._all_free_above:
                return True  # no obstacle of either layer within reach of the base
        elif self.layer == "lower_body":
            return False
        else:  # beyond the grid: no distance shortcut
            d = 0.5 * (self._hit_below + self._free_above)
        if d <= self._hit_below:
            return False
        if d < self._free_above and self._colliding(cx, cy, theta, first_only=True):
            return False
        return self._arms is None or self._arms.is_free(x, y, theta)

    def colliding_obstacles(self, x: float, y: float, theta: float) -> list[str]:
        """Names of the obstacles the footprint (or the arms' rectangle) at (x, y, theta) overlaps (exact;
        empty when free)."""
        cx, cy = x + self.offset_m * math.cos(theta), y + self.offset_m * math.sin(theta)
        hits = self._colliding(cx, cy, theta, first_only=False)
        if self._arms is not None:
            hits += [name for name in self._arms.colliding_obstacles(x, y, theta) if name not in hits]
        return hits

    def _colliding(self, x: float, y: float, theta: float, first_only: bool) -> list[str]:
        c, s = math.cos(theta), math.sin(theta)
        hx, hy = self.hx, self.hy
        r_circ = self.r_circ
        hits: list[str] = []
        for o in self._shapes:
            if isinstance(o, _Rect2D):
                # cheap bounding-disc rejection first
                if math.hypot(o.cx - x, o.cy - y) > r_circ + math.hypot(o.hx, o.hy):
                    continue
                if _rect_rect_overlap(o, x, y, hx, hy, c, s):
                    hits.append(o.name)
            else:
                if math.hypot(o.cx - x, o.cy - y) > r_circ + o.r:
                    continue
                if _rect_circle_overlap(x, y, hx, hy, c, s, o):
                    hits.append(o.name)
            if hits and first_only:
                return hits
        return hits

    def free_mask(self, min_distance_m: float) -> np.ndarray:
        """Boolean grid (ny, nx): nodes whose distance to the floor projections may be >= ``min_distance_m``.

        Conservative in the "may be free" direction (grid error subtracted), so a continuous curve of
        base positions at distance >= ``min_distance_m`` only crosses cells marked True.
        """
        return self._grid >= min_distance_m - self._slack

    def reachable_mask(self) -> np.ndarray:
        """Boolean grid (ny, nx): nodes a collision-free base may occupy, as far as the inscribed discs
        tell: at least the footprint's inradius from the lower-body obstacles and the arms' inradius from
        the obstacles at arm height (conservative: every free base position is marked True)."""
        mask = self.free_mask(self.r_in)
        if self._arms is not None:  # the base is within |offset| of the arms' rectangle's centre
            mask &= self._arms.free_mask(self._arms.r_in - abs(self._arms.offset_m))
        return mask

    def cell_of(self, x: float, y: float) -> tuple[int, int]:
        """Grid indices (row i along y, column j along x) of the node nearest to (x, y)."""
        i = min(max(round((y - self._y0) / self.resolution_m), 0), self._ny - 1)
        j = min(max(round((x - self._x0) / self.resolution_m), 0), self._nx - 1)
        return i, j

    def node_xy(self, i: int, j: int) -> tuple[float, float]:
        """World position [m] of grid node (i, j)."""
        return self._x0 + j * self.resolution_m, self._y0 + i * self.resolution_m

    def obstacles_near(self, x: float, y: float, radius_m: float) -> list[str]:
        """Names of the obstacles (lower body and arms) whose floor projection comes within ``radius_m`` of
        (x, y)."""
        names = [] if self._arms is None else self._arms.obstacles_near(x, y, radius_m)
        for o in self._shapes:
            if isinstance(o, _Rect2D):
                dx, dy = x - o.cx, y - o.cy
                qx = max(abs(dx * o.c + dy * o.s) - o.hx, 0.0)
                qy = max(abs(-dx * o.s + dy * o.c) - o.hy, 0.0)
                d = math.hypot(qx, qy)
            else:
                d = max(math.hypot(x - o.cx, y - o.cy) - o.r, 0.0)
            if d <= radius_m and o.name not in names:
                names.append(o.name)
        return names
