"""Small geometric kernels for the tasks: 2-D convex hulls and closest points between segments."""

from __future__ import annotations

import numpy as np


def convex_hull_2d(points: np.ndarray) -> np.ndarray:
    """Indices of the convex hull of ``points`` (k x 2), counter-clockwise, without collinear points
    (Andrew's monotone chain, in plain Python: k is small, the corners of one or two soles)."""
    xy = points.tolist()
    order = sorted(range(len(xy)), key=lambda i: (xy[i][0], xy[i][1]))

    def turns_left(o: int, a: int, b: int) -> bool:
        (ox, oy), (ax, ay), (bx, by) = xy[o], xy[a], xy[b]
        return (ax - ox) * (by - oy) - (ay - oy) * (bx - ox) > 1e-12

    lower: list[int] = []
    for i in order:
        while len(lower) >= 2 and not turns_left(lower[-2], lower[-1], i):
            lower.pop()
        lower.append(i)
    upper: list[int] = []
    for i in reversed(order):
        while len(upper) >= 2 and not turns_left(upper[-2], upper[-1], i):
            upper.pop()
        upper.append(i)
    return np.array(lower[:-1] + upper[:-1], dtype=int)


def closest_points_segments(
    p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray, eps: float = 1e-12
) -> tuple[np.ndarray, np.ndarray]:
    """Parameters (s, t) in [0, 1] of the closest points p0 + s (p1 - p0) and q0 + t (q1 - q0)
    between segments, vectorized over the leading axis (arrays k x 3).

    Ericson, Real-Time Collision Detection, 5.1.9; degenerate (point) segments and parallel
    segments are handled (parallel: s chosen 0, t the matching clamp).
    """
    d1 = p1 - p0
    d2 = q1 - q0
    r = p0 - q0
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    denom = a * e - b * b
    safe_a = np.where(a > eps, a, 1.0)
    safe_e = np.where(e > eps, e, 1.0)
    # Non-parallel: closest point of the infinite lines, clamped to segment 1.
    s = np.where(
        denom > eps * np.maximum(a * e, eps),
        np.clip((b * f - c * e) / np.where(denom > 0, denom, 1.0), 0, 1),
        0.0,
    )
    t = (b * s + f) / safe_e
    # t outside [0, 1]: clamp it and recompute s for the clamped t.
    s = np.where(
        t < 0.0, np.clip(-c / safe_a, 0.0, 1.0), np.where(t > 1.0, np.clip((b - c) / safe_a, 0.0, 1.0), s)
    )
    t = np.clip(t, 0.0, 1.0)
    # Degenerate segments.
    point1 = a <= eps
    point2 = e <= eps
    s = np.where(point1, 0.0, s)
    t = np.where(point1 & ~point2, np.clip(f / safe_e, 0.0, 1.0), t)
    s = np.where(point2 & ~point1, np.clip(-c / safe_a, 0.0, 1.0), s)
    t = np.where(point2, 0.0, t)
    return s, t


def closest_point_on_segment(p: np.ndarray, q0: np.ndarray, q1: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """Parameter t in [0, 1] of the point of segment [q0, q1] closest to p (vectorized, k x 3)."""
    d = q1 - q0
    dd = np.einsum("ij,ij->i", d, d)
    t = np.einsum("ij,ij->i", p - q0, d) / np.where(dd > eps, dd, 1.0)
    return np.clip(np.where(dd > eps, t, 0.0), 0.0, 1.0)
