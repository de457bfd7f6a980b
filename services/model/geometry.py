"""Small planar/spatial geometry helpers used by the model (no pinocchio)."""

from __future__ import annotations

import math

import numpy as np


def yaw_of(R: np.ndarray) -> float:
    """Yaw [rad] of a rotation matrix: heading of its x axis projected on the ground plane."""
    return math.atan2(float(R[1, 0]), float(R[0, 0]))


def convex_hull_ccw(points_xy: np.ndarray) -> np.ndarray:
    """Convex hull of 2-D points, counter-clockwise, without collinear points (Andrew's monotone chain)
    (M, 2)."""
    pts = np.unique(np.asarray(points_xy, dtype=float).reshape(-1, 2), axis=0)
    if len(pts) <= 2:
        return pts

    def cross(o: np.ndarray, a: np.ndarray, b: np.ndarray) -> float:
        return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))

    lower: list[np.ndarray] = []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 1e-12:
            lower.pop()
        lower.append(p)
    upper: list[np.ndarray] = []
    for p in pts[::-1]:
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 1e-12:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


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
