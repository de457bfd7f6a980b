"""Small geometric kernels for the tasks: closest points between segments (the ground geometry, convex
hulls included, is :mod:`services.model.ground`)."""

from __future__ import annotations

import numpy as np


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
    return closest_parameters(d1, d2, p0 - q0, eps)


def closest_parameters(
    d1: np.ndarray, d2: np.ndarray, r: np.ndarray, eps: float = 1e-12
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`closest_points_segments` from the segment directions ``d1 = p1 - p0``,
    ``d2 = q1 - q0`` and ``r = p0 - q0`` [m] (k x 3 each, e.g. already at hand)."""
    a = np.einsum("ij,ij->i", d1, d1)
    e = np.einsum("ij,ij->i", d2, d2)
    f = np.einsum("ij,ij->i", d2, r)
    c = np.einsum("ij,ij->i", d1, r)
    b = np.einsum("ij,ij->i", d1, d2)
    ae = a * e
    denom = ae - b * b
    long1, long2 = a > eps, e > eps
    degenerate = np.count_nonzero(long1 & long2) != a.shape[0]
    if degenerate:
        safe_a = np.where(long1, a, 1.0)
        safe_e = np.where(long2, e, 1.0)
    else:  # the common case (no point segment): every test on them below is false
        safe_a, safe_e = a, e
    # Non-parallel: closest point of the infinite lines, clamped to segment 1.
    s = np.where(
        denom > eps * np.maximum(ae, eps),
        unit_clip((b * f - c * e) / np.where(denom > 0, denom, 1.0)),
        0.0,
    )
    t = (b * s + f) / safe_e
    # t outside [0, 1]: clamp it and recompute s for the clamped t.
    s = np.where(t < 0.0, unit_clip(-c / safe_a), np.where(t > 1.0, unit_clip((b - c) / safe_a), s))
    t = unit_clip(t)
    if degenerate:
        point1, point2 = a <= eps, e <= eps
        s = np.where(point1, 0.0, s)
        t = np.where(point1 & ~point2, unit_clip(f / safe_e), t)
        s = np.where(point2 & ~point1, unit_clip(-c / safe_a), s)
        t = np.where(point2, 0.0, t)
    return s, t


def unit_clip(x: np.ndarray) -> np.ndarray:
    """``np.clip(x, 0, 1)`` by two ufuncs (without ``np.clip``'s Python overhead; the same values,
    signed zeros and NaN included)."""
    return np.minimum(np.maximum(0.0, x), 1.0)


def closest_point_on_segment(p: np.ndarray, q0: np.ndarray, q1: np.ndarray, eps: float = 1e-12) -> np.ndarray:
    """Parameter t in [0, 1] of the point of segment [q0, q1] closest to p (vectorized, k x 3)."""
    d = q1 - q0
    dd = np.einsum("ij,ij->i", d, d)
    t = np.einsum("ij,ij->i", p - q0, d) / np.where(dd > eps, dd, 1.0)
    return unit_clip(np.where(dd > eps, t, 0.0))
