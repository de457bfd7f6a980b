"""Ground geometry shared by every planner: sole poses and footstep sequences on the flat floor, the
stepping bounds, rectangles (:class:`Rectangle`, defined beside the bus schemas so that the supervisor
shares it, re-exported here), convex hulls, signed distances to convex polygons and the quintic
smoothstep. One concept, one place: walking, footsteps, navigation, reaching, the IK tasks and vision
use these and keep no copy of their own.

Frames: world, z up, flat ground z = 0; poses (x [m], y [m], yaw [rad]); polygons (k, 2) [m]
counter-clockwise seen from above.

The stepping bounds are those of the footstep paper (``000_49c4a782ba599e49.txt``, Kanoun et al., §5):
the left sole expressed in the right sole frame satisfies ``-0.22 < dx < 0.22 m``,
``0.07 < dy < 0.25 m``, ``-0.1 < dtheta < pi/4 rad``; the right sole in the left sole frame satisfies the
mirrored bounds (``-0.25 < dy < -0.07``, ``-pi/4 < dtheta < 0.1``). :func:`validate_footsteps` checks them
inclusive of the limit itself, up to ``BOUND_TOLERANCE`` (0.1 mm, 1e-4 rad): a 90-degree turn in 4 steps
(pi/4 per opening step) is admissible, also from soles measured on a standing robot (the simulated robot
stands with its soles yawed by a few 1e-5 rad, which puts such a turn 2e-5 rad "beyond" the bound).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from services.bus.schemas.rectangle import Rectangle
from services.errors import InfeasibleError, InvalidRequestError

Side = Literal["left", "right"]
SIDES: tuple[Side, Side] = ("left", "right")
BOUND_TOLERANCE = 1e-4
"""Tolerance of the bounds check [m or rad]: measurement noise, not a relaxation of the bounds."""
BOUND_QUANTITIES = ("dx", "dy", "dyaw")
"""Names of the three bounded quantities (dx [m], dy [m], dtheta [rad]) in messages and ``details``."""


def wrap_angle(angle_rad: float) -> float:
    """Wrap an angle to [-pi, pi) [rad]."""
    return (angle_rad + math.pi) % (2.0 * math.pi) - math.pi


def other_side(side: Side) -> Side:
    """The other foot."""
    return "right" if side == "left" else "left"


# ------------------------------------------------------------------------------------------ sole poses


@dataclass(frozen=True)
class SolePose:
    """A sole frame on the flat ground: position [m] and yaw [rad] in the world frame (z = 0)."""

    x_m: float
    y_m: float
    yaw_rad: float

    def relative_to(self, other: SolePose) -> tuple[float, float, float]:
        """(dx [m], dy [m], dyaw [rad]) of this sole expressed in the frame of ``other``."""
        c, s = math.cos(other.yaw_rad), math.sin(other.yaw_rad)
        ex, ey = self.x_m - other.x_m, self.y_m - other.y_m
        return c * ex + s * ey, -s * ex + c * ey, wrap_angle(self.yaw_rad - other.yaw_rad)

    def compose(self, dx_m: float, dy_m: float, dyaw_rad: float) -> SolePose:
        """The pose reached by moving (dx, dy) in this frame and turning by dyaw."""
        c, s = math.cos(self.yaw_rad), math.sin(self.yaw_rad)
        return SolePose(
            self.x_m + c * dx_m - s * dy_m, self.y_m + s * dx_m + c * dy_m, self.yaw_rad + dyaw_rad
        )

    def as_array(self) -> np.ndarray:
        """[x, y, yaw] as a float array."""
        return np.array([self.x_m, self.y_m, self.yaw_rad])


def yaw_of(R: np.ndarray) -> float:
    """Yaw [rad] of a rotation matrix: heading of its x axis projected on the ground plane."""
    return math.atan2(float(R[1, 0]), float(R[0, 0]))


def sole_pose_of(T_world_sole: Any) -> SolePose:
    """Ground footprint (x, y, yaw) of a sole frame (a ``pinocchio.SE3``): its origin projected on the
    ground and the heading of its x axis."""
    return SolePose(
        float(T_world_sole.translation[0]), float(T_world_sole.translation[1]), yaw_of(T_world_sole.rotation)
    )


def sole_pose_at(robot: Any, q: np.ndarray, side: str, data: Any = None) -> SolePose:
    """The ground pose of the ``side`` sole of a ``services.model`` robot at configuration ``q``
    (``robot.sole_pose`` projected by :func:`sole_pose_of`; ``data``: optional pinocchio data)."""
    return sole_pose_of(robot.sole_pose(q, side, data))


def mid_feet(left: SolePose, right: SolePose) -> SolePose:
    """The mid-feet frame of two soles: the middle of their origins, the right sole's yaw turned by half
    the (wrapped) yaw of the left one relative to it."""
    yaw = right.yaw_rad + 0.5 * wrap_angle(left.yaw_rad - right.yaw_rad)
    return SolePose(0.5 * (left.x_m + right.x_m), 0.5 * (left.y_m + right.y_m), yaw)


# ------------------------------------------------------------------------------------ footstep sequences


@dataclass(frozen=True)
class Footstep:
    """One step: foot ``side`` lifts off and lands with its sole at ``pose`` (world frame)."""

    side: Side
    pose: SolePose


@dataclass(frozen=True)
class FootstepSequence:
    """Starting sole poses and the ordered landings. ``steps[0].side`` is the first moving foot."""

    left_start: SolePose
    right_start: SolePose
    steps: tuple[Footstep, ...]

    @property
    def first_moving_side(self) -> Side:
        """The foot that moves first."""
        if not self.steps:
            raise InvalidRequestError("the footstep sequence has no step")
        return self.steps[0].side

    def stances(self) -> list[tuple[SolePose, SolePose]]:
        """(left, right) sole poses before the first step and after each step (len = n_steps + 1)."""
        left, right = self.left_start, self.right_start
        out = [(left, right)]
        for step in self.steps:
            if step.side == "left":
                left = step.pose
            else:
                right = step.pose
            out.append((left, right))
        return out

    def final_stance(self) -> tuple[SolePose, SolePose]:
        """(left, right) sole poses after the last step."""
        return self.stances()[-1]

    def to_dict(self) -> dict[str, Any]:
        """Plain-data form (for messages and the placo worker)."""

        def pose(p: SolePose) -> list[float]:
            return [p.x_m, p.y_m, p.yaw_rad]

        return {
            "left_start": pose(self.left_start),
            "right_start": pose(self.right_start),
            "steps": [{"side": s.side, "pose": pose(s.pose)} for s in self.steps],
        }

    @staticmethod
    def from_dict(data: dict[str, Any]) -> FootstepSequence:
        """Inverse of :meth:`to_dict`; raises InvalidRequestError on a malformed dict."""
        try:
            steps = []
            for i, s in enumerate(data["steps"]):
                if s["side"] not in SIDES:
                    raise InvalidRequestError(f"step {i}: side {s['side']!r} is not one of {SIDES}")
                steps.append(Footstep(s["side"], SolePose(*map(float, s["pose"]))))
            return FootstepSequence(
                SolePose(*map(float, data["left_start"])),
                SolePose(*map(float, data["right_start"])),
                tuple(steps),
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InvalidRequestError(
                f"malformed footstep sequence ({exc!r}); expected keys left_start=[x,y,yaw], "
                "right_start=[x,y,yaw], steps=[{side: left|right, pose: [x,y,yaw]}]"
            ) from exc


# ------------------------------------------------------------------------------------------ the bounds


@dataclass(frozen=True)
class FootstepBounds:
    """Admissible pose of the left sole in the right sole frame (footstep paper §3.3, values of §4; the
    right sole in the left sole frame is mirrored: dy and dtheta change sign) [m, rad], and the sole rectangle
    (length along the sole x, width) [m] that must not overlap the other one. The defaults are HRP-2's
    (the paper's bounds and a 0.24 x 0.14 m sole); a robot's own are ``robot.params.footstep_bounds``
    (:meth:`from_robot`)."""

    dx_min_m: float = -0.22
    dx_max_m: float = 0.22
    dy_min_m: float = 0.07
    dy_max_m: float = 0.25
    dtheta_min_rad: float = -0.1
    dtheta_max_rad: float = math.pi / 4
    sole_length_m: float = 0.24
    sole_width_m: float = 0.14

    @staticmethod
    def from_robot(robot: Any) -> FootstepBounds:
        """The bounds of a ``services.model`` robot: ``robot.params.footstep_bounds`` (the robot's YAML
        bounds with its sole size, ``sole_size_m``)."""
        return robot.params.footstep_bounds

    def for_swing(
        self, swing_side: str
    ) -> tuple[tuple[float, float], tuple[float, float], tuple[float, float]]:
        """((dx_min, dx_max), (dy_min, dy_max), (dtheta_min, dtheta_max)) of the ``swing_side`` sole in
        the frame of the other sole."""
        if swing_side not in SIDES:
            raise InvalidRequestError(f"side must be one of {SIDES}, got {swing_side!r}")
        if swing_side == "left":
            return (
                (self.dx_min_m, self.dx_max_m),
                (self.dy_min_m, self.dy_max_m),
                (self.dtheta_min_rad, self.dtheta_max_rad),
            )
        return (
            (self.dx_min_m, self.dx_max_m),
            (-self.dy_max_m, -self.dy_min_m),
            (-self.dtheta_max_rad, -self.dtheta_min_rad),
        )

    def limits_for(self, side: str) -> dict[str, tuple[float, float]]:
        """:meth:`for_swing` keyed by :data:`BOUND_QUANTITIES` ("dx", "dy", "dyaw")."""
        return dict(zip(BOUND_QUANTITIES, self.for_swing(side), strict=True))


# ------------------------------------------------------------------------------------------ rectangles


def sole_corners(pose: SolePose, length_m: float, width_m: float) -> np.ndarray:
    """The 4 corners (4, 2) [m] of the sole rectangle centred on the sole frame, counter-clockwise."""
    return Rectangle((pose.x_m, pose.y_m), (length_m, width_m), pose.yaw_rad).corners()


def rectangles_overlap_depth(a: np.ndarray, b: np.ndarray) -> float:
    """Penetration depth [m] of two convex polygons (separating axis test); <= 0 when they do not overlap
    (then minus their separation along the best axis)."""
    depth = math.inf
    for poly in (a, b):
        edges = np.roll(poly, -1, axis=0) - poly
        normals = np.stack([edges[:, 1], -edges[:, 0]], axis=1)
        normals /= np.linalg.norm(normals, axis=1, keepdims=True)
        pa, pb = a @ normals.T, b @ normals.T
        overlap = np.minimum(pa.max(0), pb.max(0)) - np.maximum(pa.min(0), pb.min(0))
        depth = min(depth, float(overlap.min()))
    return depth


# ------------------------------------------------------------------------------- hulls and distances

HULL_GRID_M = 1e-9
"""Grid [m] onto which :func:`convex_hull_indices` snaps its points, and its collinearity tolerance:
points that differ by float noise are one point; a vertex closer than this to the segment joining its
neighbours on the hull is dropped."""


def convex_hull_indices(points_xy: np.ndarray, grid_m: float = HULL_GRID_M) -> np.ndarray:
    """Indices (h,) into ``points_xy`` (M, 2) [m] of their convex hull, counter-clockwise from the
    lowest-x point, without repeated or collinear points (Andrew's monotone chain).

    Robust to float noise: the points are snapped to a ``grid_m`` grid first, so that copies of a point
    that differ by rounding (a sole corner computed twice, through different transforms) are one point,
    and a left-turning vertex is dropped only if it lies within ``grid_m`` of the segment joining its
    neighbours (a distance to the segment, not an area: with near-duplicate neighbours an area test,
    cross product <= 1e-12 m^2, dropped real corners of a rectangle). A rectangle keeps its four
    corners.
    """
    # Snap to the grid and keep the first of each grid point, sorted by (x, y): np.unique(np.round(...),
    # axis=0, return_index=True) in plain Python, several times faster for the few corners of two soles
    # (the IK evaluates it at every iteration).
    first_of: dict[tuple[float, float], int] = {}
    try:
        for i, (x, y) in enumerate(np.asarray(points_xy, dtype=float).reshape(-1, 2).tolist()):
            first_of.setdefault((float(round(x / grid_m)), float(round(y / grid_m))), i)
    except (OverflowError, ValueError):  # round(inf), round(nan)
        raise ValueError("convex hull: points must be finite") from None
    grid = sorted(first_of)
    first = [first_of[key] for key in grid]
    if len(grid) <= 2:
        return np.array(first, dtype=int)

    def chain(order: range) -> list[int]:
        """One half of the hull: a vertex a between o and the next point b is kept when o -> a -> b turns
        left and a is farther than one grid step from the segment o-b (grid units)."""
        out: list[int] = []
        for i in order:
            px, py = grid[i]
            while len(out) >= 2:
                ox, oy = grid[out[-2]]
                ax, ay = grid[out[-1]]
                bx, by, ax, ay = px - ox, py - oy, ax - ox, ay - oy
                cross = ax * by - ay * bx
                if cross > 0.0:
                    bb = bx * bx + by * by
                    if cross * cross > 4.0 * bb:  # 2 steps from the line o-b, so from the segment
                        break
                    t = min(max((ax * bx + ay * by) / bb, 0.0), 1.0)
                    if math.hypot(ax - t * bx, ay - t * by) > 1.0:
                        break
                out.pop()
            out.append(i)
        return out

    n = len(grid)
    lower, upper = chain(range(n)), chain(range(n - 1, -1, -1))
    return np.array([first[k] for k in lower[:-1] + upper[:-1]], dtype=int)


def convex_hull_ccw(points_xy: np.ndarray, grid_m: float = HULL_GRID_M) -> np.ndarray:
    """Convex hull (h, 2) [m] of 2-D points (M, 2), counter-clockwise, without repeated or collinear
    points; the vertices are input points (:func:`convex_hull_indices`)."""
    pts = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    return pts[convex_hull_indices(pts, grid_m)]


def signed_distance(points: np.ndarray, hull: np.ndarray) -> np.ndarray:
    """Signed distance [m] of points (n, 2) (or one point (2,)) to a convex CCW polygon (h >= 3, 2):
    > 0 outside (the Euclidean distance to the polygon), < 0 inside (minus the distance to the
    boundary). Returns (n,), or (1,) for one point."""
    P = np.atleast_2d(np.asarray(points, dtype=float))[:, :2]
    a = np.asarray(hull, dtype=float)
    b = np.roll(a, -1, axis=0)
    e = b - a  # (h, 2)
    ap = P[:, None, :] - a[None, :, :]  # (n, h, 2)
    t = np.clip(np.einsum("nhk,hk->nh", ap, e) / np.einsum("hk,hk->h", e, e), 0.0, 1.0)
    closest = a[None] + t[..., None] * e[None]
    dist = np.linalg.norm(P[:, None, :] - closest, axis=2).min(axis=1)
    cross = e[None, :, 0] * ap[..., 1] - e[None, :, 1] * ap[..., 0]
    inside = np.all(cross >= 0.0, axis=1)
    out = np.where(inside, -dist, dist)
    return out if np.ndim(points) > 1 else out[:1]


# ------------------------------------------------------------------------------------------ smoothstep


def smoothstep5(tau: np.ndarray) -> np.ndarray:
    """Quintic 0 -> 1 on tau in [0, 1] (clipped outside), s = 10 tau^3 - 15 tau^4 + 6 tau^5, with zero
    first and second derivatives at both ends."""
    t = np.clip(tau, 0.0, 1.0)
    return t * t * t * (10.0 + t * (-15.0 + 6.0 * t))


def smoothstep5_derivatives(tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`smoothstep5` and its first two derivatives with respect to tau (tau clipped to [0, 1])."""
    t = np.clip(tau, 0.0, 1.0)
    return smoothstep5(t), 30.0 * t * t * (1.0 - t) ** 2, 60.0 * t * (1.0 - t) * (1.0 - 2.0 * t)


# ------------------------------------------------------------------------------------------ validation


def validate_footsteps(seq: FootstepSequence, bounds: FootstepBounds) -> None:
    """Check a sequence: at least one step, finite poses, no overlapping soles, and every landing within
    the stepping bounds relative to the stance foot.

    Raises:
        InvalidRequestError: empty sequence, non-finite value, overlapping feet (at the start or after
            a step).
        InfeasibleError: a landing outside the bounds; the message names the step, the quantity, the
            bound and the excess, and ``details`` carries them.
    """
    if not seq.steps:
        raise InvalidRequestError("the footstep sequence has no step; give at least one footstep")
    for name, pose in (("left_start", seq.left_start), ("right_start", seq.right_start)):
        if not np.all(np.isfinite(pose.as_array())):
            raise InvalidRequestError(f"{name} has a non-finite value: {pose}")
    for i, step in enumerate(seq.steps):
        if step.side not in SIDES:
            raise InvalidRequestError(f"step {i}: side {step.side!r} is not one of {SIDES}")
        if not np.all(np.isfinite(step.pose.as_array())):
            raise InvalidRequestError(f"step {i} ({step.side} foot) has a non-finite pose: {step.pose}")

    L, W = bounds.sole_length_m, bounds.sole_width_m
    stances = seq.stances()
    for i, (left, right) in enumerate(stances):
        depth = rectangles_overlap_depth(sole_corners(left, L, W), sole_corners(right, L, W))
        if depth > 1e-6:
            where = "at the start" if i == 0 else f"after step {i - 1} ({seq.steps[i - 1].side} foot)"
            raise InvalidRequestError(
                f"the feet overlap {where} by {1000 * depth:.1f} mm (soles {L:.3f} x {W:.3f} m): "
                f"left sole at ({left.x_m:.3f}, {left.y_m:.3f}, {left.yaw_rad:.3f} rad), "
                f"right sole at ({right.x_m:.3f}, {right.y_m:.3f}, {right.yaw_rad:.3f} rad)",
                {"step_index": i - 1, "overlap_m": depth},
            )

    for i, step in enumerate(seq.steps):
        left, right = stances[i]
        stance = right if step.side == "left" else left
        rel = dict(zip(BOUND_QUANTITIES, step.pose.relative_to(stance), strict=True))
        for name, (lo, hi) in bounds.limits_for(step.side).items():
            value = rel[name]
            unit = "rad" if name == "dyaw" else "m"
            if value < lo - BOUND_TOLERANCE or value > hi + BOUND_TOLERANCE:
                bound, excess = (lo, lo - value) if value < lo else (hi, value - hi)
                word = "below" if value < lo else "above"
                raise InfeasibleError(
                    f"step {i} ({step.side} foot): {name}={value:.4f} {unit} relative to the "
                    f"{other_side(step.side)} sole is {word} the bound {bound:.4f} {unit} by {excess:.4f} "
                    f"{unit} (admissible {lo:.4f} .. {hi:.4f} {unit})",
                    {
                        "step_index": i,
                        "side": step.side,
                        "quantity": name,
                        "value": value,
                        "bound": bound,
                        "excess": excess,
                    },
                )
