"""Stage 1, upper part: the carried object and the upper body swept along the path, checked in 3D.

"At the first stage, the motion planner computes a collision-free walking path for the lower part of the
robot body approximated by a bounding box, as well as a collision-free path for the upper body"
("Two-stage Planning Method", `001_771c0ce3779b0683.txt`). In the bar-carrying experiment ("Experiments
with HRP-2 No. 14", Figure 2 (a)) the footprint path is free but the 1.8 m bar, held across the walking
direction, meets a box on a table; "The reshaping limits are set by identifying the anticipating,
colliding and regaining times." :func:`sweep_carried_object` finds those limits along the path's arc
length (stage 2 maps them to times through the walking pattern) and the height that clears the
obstacles, which is what the smooth reshaping of stage 2 key-frames.

Distances are exact (coal, the hpp-fcl successor): the bar is a capsule, obstacles are boxes and
cylinders, the upper body a box. Only the sampled poses are checked; between two samples the bar's ends
move at most ``SweepResult.max_sample_gap_m``; ``SweepResult.sweep_free`` asks every sample to clear the
obstacles by half of that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import coal
import numpy as np

from services.collision.carried import CarriedBar
from services.collision.obstacles import Scene, obstacle_geometry
from services.errors import InvalidRequestError
from services.navigation.geometry import BodyModel
from services.navigation.path import SampledPath


@dataclass(frozen=True)
class CollisionSegment:
    """One stretch of the path where a part meets obstacles, with its reshaping limits (arc length [m]).

    ``s_anticipate_m`` <= ``s_collide_m`` <= ``s_collide_end_m`` <= ``s_regain_m``: the collision spans
    [s_collide_m, s_collide_end_m]; the anticipating/regaining limits widen it to where the clearance is
    back above ``clearance_m``, plus ``lead_m`` (so the reshaped motion can start and end smoothly).
    ``min_distance_m`` is the deepest signed distance (< 0: penetration). ``clear_height_m`` is the bar
    height [m] that passes over all these obstacles with the clearance (None for an upper-body segment).
    """

    part: str
    obstacles: tuple[str, ...]
    s_anticipate_m: float
    s_collide_m: float
    s_collide_end_m: float
    s_regain_m: float
    min_distance_m: float
    clear_height_m: float | None


@dataclass(frozen=True, eq=False)
class SweepResult:
    """Per-sample signed distances [m] of each part to the nearest obstacle (inf: none within the broad
    phase), the collision segments, and ``max_sample_gap_m`` [m], the largest move of a bar end between
    two consecutive samples."""

    s_m: np.ndarray
    bar_distance_m: np.ndarray
    body_distance_m: np.ndarray
    segments: tuple[CollisionSegment, ...]
    max_sample_gap_m: float

    @property
    def collision_free(self) -> bool:
        """No sample of any part penetrates an obstacle."""
        return not self.segments

    @property
    def min_distance_m(self) -> float:
        """Smallest signed distance [m] of any part to any obstacle over the samples."""
        return float(min(self.bar_distance_m.min(), self.body_distance_m.min()))

    @property
    def sweep_free(self) -> bool:
        """Also free between samples: every sample clears by half the largest move between samples."""
        return self.min_distance_m >= 0.5 * self.max_sample_gap_m


def _rot_z(theta: float) -> np.ndarray:
    c, s = math.cos(theta), math.sin(theta)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


_R_X_HALF_PI = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # capsule z axis -> base y


def _segments(
    part: str,
    s: np.ndarray,
    distance: np.ndarray,
    nearest: list[list[str]],
    clearance_m: float,
    lead_m: float,
    tops: dict[str, float],
    bar: CarriedBar | None,
) -> list[CollisionSegment]:
    colliding = distance < 0.0
    near = distance < clearance_m
    out: list[CollisionSegment] = []
    n = len(s)
    k = 0
    while k < n:
        if not colliding[k]:
            k += 1
            continue
        c0 = k
        while k + 1 < n and colliding[k + 1]:
            k += 1
        c1 = k
        a0, a1 = c0, c1
        while a0 > 0 and near[a0 - 1]:
            a0 -= 1
        while a1 + 1 < n and near[a1 + 1]:
            a1 += 1
        names = sorted({name for j in range(a0, a1 + 1) for name in nearest[j]})
        clear_height = None
        if bar is not None:
            clear_height = max(tops[name] for name in names) + bar.radius_m + clearance_m
        out.append(
            CollisionSegment(
                part=part,
                obstacles=tuple(names),
                s_anticipate_m=max(float(s[a0]) - lead_m, 0.0),
                s_collide_m=float(s[c0]),
                s_collide_end_m=float(s[c1]),
                s_regain_m=min(float(s[a1]) + lead_m, float(s[-1])),
                min_distance_m=float(distance[c0 : c1 + 1].min()),
                clear_height_m=clear_height,
            )
        )
        k = a1 + 1
    # merge segments whose reshaping windows overlap (one smooth reshaping covers both)
    merged: list[CollisionSegment] = []
    for seg in out:
        if merged and seg.s_anticipate_m <= merged[-1].s_regain_m:
            prev = merged[-1]
            heights = [h for h in (prev.clear_height_m, seg.clear_height_m) if h is not None]
            merged[-1] = CollisionSegment(
                part=part,
                obstacles=tuple(sorted(set(prev.obstacles) | set(seg.obstacles))),
                s_anticipate_m=prev.s_anticipate_m,
                s_collide_m=prev.s_collide_m,
                s_collide_end_m=seg.s_collide_end_m,
                s_regain_m=seg.s_regain_m,
                min_distance_m=min(prev.min_distance_m, seg.min_distance_m),
                clear_height_m=max(heights) if heights else None,
            )
        else:
            merged.append(seg)
    return merged


def sweep_carried_object(
    scene: Scene,
    path: SampledPath,
    bar: CarriedBar | None = None,
    body: BodyModel | None = None,
    bar_height_m: float | np.ndarray | None = None,
    clearance_m: float = 0.05,
    lead_m: float = 0.3,
) -> SweepResult:
    """Sweep the carried bar (and the upper-body box of ``body``, when given) along ``path`` in 3D.

    ``bar_height_m``: the bar's height [m], a constant or one value per path sample (a reshaped height
    profile); default ``bar.height_m``. A part is colliding where its signed distance to an obstacle is
    < 0; ``clearance_m`` [m] sets the anticipating/regaining limits and the clearing height, ``lead_m``
    [m] widens them (see :class:`CollisionSegment`).
    """
    bar = bar or CarriedBar()
    n = len(path.s_m)
    heights = np.broadcast_to(np.asarray(bar.height_m if bar_height_m is None else bar_height_m, float), (n,))
    if not np.all(np.isfinite(heights)):
        raise InvalidRequestError("bar heights must be finite")
    if clearance_m < 0.0 or lead_m < 0.0:
        raise InvalidRequestError(f"clearance_m and lead_m must be >= 0, got {clearance_m}, {lead_m}")

    obstacles = [(o, *obstacle_geometry(o)) for o in scene.obstacles]
    tops = {o.name: o.z_range_m[1] for o in scene.obstacles}
    theta = path.theta_rad
    heading = np.column_stack([np.cos(theta), np.sin(theta)])
    bar_xy = path.xy_m + bar.forward_m * heading
    request = coal.DistanceRequest()
    result = coal.DistanceResult()

    def sweep_part(
        shape: coal.CollisionGeometry,
        centres_xy: np.ndarray,
        z_centre: np.ndarray,
        half_reach_xy: float,
        half_height: float,
        R_base_part: np.ndarray,
    ) -> tuple[np.ndarray, list[list[str]]]:
        distance = np.full(n, np.inf)
        nearest: list[list[str]] = [[] for _ in range(n)]
        for o, o_shape, T_world_o, o_radius in obstacles:
            z0, z1 = o.z_range_m
            ox, oy = o.center_xyz_m[0], o.center_xyz_m[1]
            # broad phase on the floor and in height, vectorized over the samples
            gap_xy = np.hypot(centres_xy[:, 0] - ox, centres_xy[:, 1] - oy) - half_reach_xy - o_radius
            gap_z = np.maximum(z0 - (z_centre + half_height), (z_centre - half_height) - z1)
            candidates = np.nonzero((gap_xy < clearance_m) & (gap_z < clearance_m))[0]
            for k in candidates:
                T_world_part = coal.Transform3s(
                    _rot_z(float(theta[k])) @ R_base_part,
                    np.array([centres_xy[k, 0], centres_xy[k, 1], z_centre[k]]),
                )
                result.clear()
                d = coal.distance(shape, T_world_part, o_shape, T_world_o, request, result)
                if d < clearance_m:
                    nearest[k].append(o.name)
                if d < distance[k]:
                    distance[k] = d
        return distance, nearest

    bar_shape = coal.Capsule(bar.radius_m, bar.length_m)
    R_base_bar = _rot_z(bar.yaw_in_base_rad - math.pi / 2) @ _R_X_HALF_PI
    bar_distance, bar_nearest = sweep_part(
        bar_shape,
        bar_xy,
        np.asarray(heights, float),
        0.5 * bar.length_m + bar.radius_m,
        bar.radius_m,
        R_base_bar,
    )
    segments = _segments("bar", path.s_m, bar_distance, bar_nearest, clearance_m, lead_m, tops, bar)

    body_distance = np.full(n, np.inf)
    if body is not None:
        lx, ly = body.upper_body_size_m
        hz = body.height_m - body.lower_body_height_m
        body_shape = coal.Box(lx, ly, hz)
        z_mid = np.full(n, body.lower_body_height_m + 0.5 * hz)
        body_distance, body_nearest = sweep_part(
            body_shape, path.xy_m, z_mid, 0.5 * math.hypot(lx, ly), 0.5 * hz, np.eye(3)
        )
        segments += _segments(
            "upper_body", path.s_m, body_distance, body_nearest, clearance_m, lead_m, tops, None
        )

    # largest move of a bar end between consecutive samples (chord), height changes included
    axis_yaw = theta + bar.yaw_in_base_rad
    half = 0.5 * bar.length_m * np.column_stack([np.cos(axis_yaw), np.sin(axis_yaw)])
    gap = 0.0
    for end_xy in (bar_xy + half, bar_xy - half):
        if n > 1:
            step = np.column_stack([np.diff(end_xy, axis=0), np.diff(heights)])
            gap = max(gap, float(np.linalg.norm(step, axis=1).max()))
    segments.sort(key=lambda seg: seg.s_anticipate_m)
    return SweepResult(path.s_m, bar_distance, body_distance, tuple(segments), gap)
