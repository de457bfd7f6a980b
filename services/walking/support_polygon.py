"""Support polygons on flat ground: convex hull of the soles in contact, and signed distances to it (the
hull and the distance are :mod:`services.model.ground`'s).

Sign convention: the signed distance of a point is > 0 outside the polygon (its Euclidean distance to
the polygon) and < 0 inside (minus its distance to the boundary). A ZMP "inside with 10 mm margin" has a
signed distance <= -0.010 m.
"""

from __future__ import annotations

import numpy as np

from services.model.ground import SolePose, convex_hull_ccw, signed_distance, sole_corners
from services.walking.timing import DOUBLE, LEFT, RIGHT


def sole_polygon(pose_xy_yaw: np.ndarray, length_m: float, width_m: float) -> np.ndarray:
    """The 4 corners (4, 2) [m] of a sole rectangle centred at (x, y) with yaw, counter-clockwise."""
    x, y, yaw = (float(v) for v in pose_xy_yaw)
    return sole_corners(SolePose(x, y, yaw), length_m, width_m)


def support_hull(
    phase: int, left_xy_yaw: np.ndarray, right_xy_yaw: np.ndarray, length_m: float, width_m: float
) -> np.ndarray:
    """Support polygon for a phase code: both soles (DOUBLE), the left sole (LEFT) or the right (RIGHT)."""
    if phase == LEFT:
        return sole_polygon(left_xy_yaw, length_m, width_m)
    if phase == RIGHT:
        return sole_polygon(right_xy_yaw, length_m, width_m)
    if phase != DOUBLE:
        raise ValueError(f"unknown support phase code {phase}")
    return convex_hull_ccw(
        np.vstack(
            [sole_polygon(left_xy_yaw, length_m, width_m), sole_polygon(right_xy_yaw, length_m, width_m)]
        )
    )


def distances_to_support(
    points_m: np.ndarray,
    phase: np.ndarray,
    left_sole: np.ndarray,
    right_sole: np.ndarray,
    length_m: float,
    width_m: float,
) -> np.ndarray:
    """Signed distance (n,) [m] of each point (n, 2) to the support polygon of its sample.

    ``left_sole`` / ``right_sole`` are (n, 4) = (x, y, z, yaw) or (n, 3) = (x, y, yaw) sole trajectories;
    the polygon is rebuilt only where the phase or the supporting sole poses change.
    """
    P = np.asarray(points_m, dtype=float)
    L = _xy_yaw(left_sole)
    R = _xy_yaw(right_sole)
    n = P.shape[0]
    key = np.column_stack([phase.astype(float), L, R])
    key[phase == LEFT, 4:] = 0.0  # the swinging foot does not change the polygon
    key[phase == RIGHT, 1:4] = 0.0
    change = np.ones(n, dtype=bool)
    change[1:] = np.any(np.abs(np.diff(key, axis=0)) > 1e-12, axis=1)
    starts = np.flatnonzero(change)
    stops = np.append(starts[1:], n)
    out = np.empty(n)
    for s, e in zip(starts, stops, strict=True):
        hull = support_hull(int(phase[s]), L[s], R[s], length_m, width_m)
        out[s:e] = signed_distance(P[s:e], hull)
    return out


def _xy_yaw(sole: np.ndarray) -> np.ndarray:
    sole = np.asarray(sole, dtype=float)
    return sole[:, [0, 1, 3]] if sole.shape[1] == 4 else sole
