"""Small planar/spatial geometry helpers used by the model (no pinocchio)."""

from __future__ import annotations

import math

import numpy as np


def yaw_of(R: np.ndarray) -> float:
    """Yaw [rad] of a rotation matrix: heading of its x axis projected on the ground plane."""
    return math.atan2(float(R[1, 0]), float(R[0, 0]))


HULL_GRID_M = 1e-9
"""Grid [m] onto which :func:`convex_hull_ccw` snaps its points, and its collinearity tolerance: points
that differ by float noise are one point; a vertex closer than this to the segment joining its neighbours
on the hull is dropped."""


def convex_hull_ccw(points_xy: np.ndarray, grid_m: float = HULL_GRID_M) -> np.ndarray:
    """Convex hull of 2-D points, counter-clockwise, without collinear points (Andrew's monotone chain)
    (M, 2) [m]; the vertices are input points.

    Robust to float noise: the points are snapped to a ``grid_m`` grid first, so that copies of a point
    that differ by rounding (a sole corner computed twice, through different transforms) are one point,
    and a left-turning vertex is dropped only if it lies within ``grid_m`` of the segment joining its
    neighbours (a distance to the segment, not an area: with near-duplicate neighbours the former test,
    cross product <= 1e-12 m^2, dropped real corners of a rectangle). A rectangle keeps its four
    corners.
    """
    pts = np.asarray(points_xy, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(pts)):
        raise ValueError("convex_hull_ccw: points must be finite")
    snapped, first = np.unique(np.round(pts / grid_m), axis=0, return_index=True)
    if len(snapped) <= 2:
        return pts[first]

    grid = snapped.tolist()  # Python floats: a few times faster than numpy scalars here

    def keep(o: list[float], a: list[float], b: list[float]) -> bool:
        """True if o -> a -> b turns left and a is farther than one grid step from the segment o-b
        (grid units; o and b are distinct grid points)."""
        bx, by, ax, ay = b[0] - o[0], b[1] - o[1], a[0] - o[0], a[1] - o[1]
        if ax * by - ay * bx <= 0.0:
            return False
        t = min(max((ax * bx + ay * by) / (bx * bx + by * by), 0.0), 1.0)
        return math.hypot(ax - t * bx, ay - t * by) > 1.0

    def chain(order: range) -> list[int]:
        out: list[int] = []
        for i in order:
            while len(out) >= 2 and not keep(grid[out[-2]], grid[out[-1]], grid[i]):
                out.pop()
            out.append(i)
        return out

    n = len(grid)
    lower, upper = chain(range(n)), chain(range(n - 1, -1, -1))
    hull = lower[:-1] + upper[:-1]
    return pts[first[hull]]


def polygon_signed_margin(polygon_ccw: np.ndarray, point_xy: np.ndarray) -> float:
    """Distance [m] from ``point_xy`` to the boundary of a convex CCW polygon, positive inside."""
    poly = np.asarray(polygon_ccw, dtype=float)
    p = np.asarray(point_xy, dtype=float)[:2]
    margin = math.inf
    for i in range(len(poly)):
        a, b = poly[i], poly[(i + 1) % len(poly)]
        edge = b - a
        length = float(np.hypot(*edge))
        # Left normal of a CCW edge points inside.
        inside = float(edge[0] * (p[1] - a[1]) - edge[1] * (p[0] - a[0])) / length
        margin = min(margin, inside)
    return margin


def segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> float:
    """Shortest distance [m] between segments [p0, p1] and [q0, q1] in 3-D."""
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = float(d1 @ d1)
    e = float(d2 @ d2)
    f = float(d2 @ r)
    eps = 1e-12
    if a <= eps and e <= eps:
        return float(np.linalg.norm(r))
    if a <= eps:
        s, t = 0.0, min(max(f / e, 0.0), 1.0)
    else:
        c = float(d1 @ r)
        if e <= eps:
            t, s = 0.0, min(max(-c / a, 0.0), 1.0)
        else:
            b = float(d1 @ d2)
            denom = a * e - b * b
            s = min(max((b * f - c * e) / denom, 0.0), 1.0) if denom > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                t, s = 0.0, min(max(-c / a, 0.0), 1.0)
            elif t > 1.0:
                t, s = 1.0, min(max((b - c) / a, 0.0), 1.0)
    return float(np.linalg.norm((p0 + d1 * s) - (q0 + d2 * t)))
