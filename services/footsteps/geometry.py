"""Planar geometry of the virtual chain's footprints: relative poses of two footprints and the
non-overlap rows of Fig. 5 of the footstep paper (Kanoun, Laumond, Yoshida) with their derivatives. Sole
poses, rectangles and their distances are the ground geometry of :mod:`services.model.ground`.

A footprint is a sole rectangle of length ``L`` (along the sole x axis) and width ``W`` (along y) centred
on its sole frame, flat on the ground z = 0, posed by (x [m], y [m], yaw [rad]) in the world frame.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from services.model.ground import Rectangle, SolePose, wrap_angle


def se3_of(pose: SolePose) -> pin.SE3:
    """The flat sole frame (z = 0, z axis up) of a footprint pose."""
    c, s = math.cos(pose.yaw_rad), math.sin(pose.yaw_rad)
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return pin.SE3(R, np.array([pose.x_m, pose.y_m, 0.0]))


def relative_pose(child: SolePose, parent: SolePose) -> np.ndarray:
    """(dx [m], dy [m], dtheta [rad]) of ``child`` in the frame of ``parent``: the Q_i of eq. (8) when
    ``parent`` is footprint i-1 and ``child`` footprint i."""
    return np.array(child.relative_to(parent))


def compose(parent: SolePose, Q: np.ndarray) -> SolePose:
    """The footprint at relative pose Q = (dx, dy, dtheta) from ``parent`` (inverse of
    :func:`relative_pose`)."""
    return parent.compose(float(Q[0]), float(Q[1]), float(Q[2]))


def non_overlap_rows(
    r: np.ndarray, child_is_left: bool, length_m: float, width_m: float, margin_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """The half-plane constraints of Fig. 5 for one support polygon, G <= 0, and dG/dr (4 x 3).

    ``r`` = (dx, dy, dtheta) is the pose of the child footprint B in the parent footprint A's frame;
    ``child_is_left`` says B is the left foot (so A is the right one and B lies on A's +y side).

    Each footprint lies in a half-plane bounded by the line through its inner edge; the other foot
    must keep both of its inner corners at least ``margin_m`` beyond that line:

    - rows 0-1: B's inner corners (x = +-L/2, y = -sigma W/2 in B) expressed in A, sigma * y >= W/2 + margin;
    - rows 2-3: A's inner corners (x = +-L/2, y = +sigma W/2 in A) expressed in B, -sigma * y >= W/2 + margin;

    with sigma = +1 when B is the left foot. With |dtheta| < pi/2 the inner corners are the points of
    each rectangle closest to the other's line, so these rows keep the two rectangles disjoint.
    """
    G, dG = non_overlap_rows_many(
        np.asarray(r, dtype=float).reshape(1, 3), np.array([child_is_left]), length_m, width_m, margin_m
    )
    return G[0], dG[0]


def non_overlap_rows_many(
    r: np.ndarray, child_is_left: np.ndarray, length_m: float, width_m: float, margin_m: float
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`non_overlap_rows` of n support polygons at once: ``r`` (n, 3), ``child_is_left`` (n,)
    booleans; G (n, 4) and dG/dr (n, 4, 3)."""
    sigma = np.where(child_is_left, 1.0, -1.0)[:, None]  # (n, 1), against the two corners (2,)
    dx, dy, th = r[:, 0:1], r[:, 1:2], r[:, 2:3]
    c, s = np.cos(th), np.sin(th)
    hl, hw = 0.5 * length_m, 0.5 * width_m
    ax = np.array([hl, -hl])  # the two inner corners of a foot, x in its own frame
    ay = -sigma * hw  # B's inner edge in B; A's inner edge in A is at -ay
    n = r.shape[0]
    G = np.empty((n, 4))
    dG = np.zeros((n, 4, 3))
    # rows 0-1, B's inner corners (ax, ay) in A: y = dy + s ax + c ay
    G[:, :2] = hw + margin_m - sigma * (dy + s * ax + c * ay)
    dG[:, :2, 1] = -sigma
    dG[:, :2, 2] = -sigma * (c * ax - s * ay)
    # rows 2-3, A's inner corners (ax, -ay) in B: y' = -s (ax - dx) + c (-ay - dy)
    ex, ey = ax - dx, -ay - dy
    G[:, 2:] = hw + margin_m + sigma * (c * ey - s * ex)
    dG[:, 2:, 0] = sigma * s
    dG[:, 2:, 1] = -sigma * c
    dG[:, 2:, 2] = -sigma * (c * ex + s * ey)
    return G, dG


def same_pose(a: SolePose, b: SolePose, tol_m: float = 1e-3, tol_rad: float = 1e-3) -> bool:
    """True when two footprints coincide within ``tol_m`` and ``tol_rad``."""
    return (
        math.hypot(a.x_m - b.x_m, a.y_m - b.y_m) <= tol_m
        and abs(wrap_angle(a.yaw_rad - b.yaw_rad)) <= tol_rad
    )


def disks_covering(rect: Rectangle) -> list[tuple[float, float, float]]:
    """(x, y, radius) [m] of disks covering the floor rectangle ``rect`` (the planner's obstacles are
    disks, section 4.1 of the paper): as many as the rectangle is times longer than wide, each the
    circumscribed disk of its square-ish cell along the length."""
    length, width = float(rect.size_m[0]), float(rect.size_m[1])
    long_side, short_side = max(length, width), min(length, width)
    n = max(1, math.ceil(long_side / short_side - 1e-9))
    cell = long_side / n
    radius = 0.5 * math.hypot(cell, short_side)
    offsets = [(k + 0.5) * cell - long_side / 2.0 for k in range(n)]
    local = [(o, 0.0) if length >= width else (0.0, o) for o in offsets]
    centres = rect.to_world(np.array(local))
    return [(float(x), float(y), radius) for x, y in centres]
