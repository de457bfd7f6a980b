"""A ball partly hidden by the robot's own arm: its image circle from the free part of its outline.

After a grasp that failed, the hand backs off above and in front of the ball, between the head cameras
and it: the ball's silhouette is cut by the gripper in one image or both (fetch seeds 73 and 77 of
session 9: the look after the failure did not find the ball). The centroid of a cut silhouette is not
the ball's centre (it moves away from the cut, by a different amount in each image: a wrong depth),
and its size differs between the images (the match is refused). The robot knows which pixels are its
own (services/perception/own_body.py); the rest of the ball's outline still lies on the ball's circle.
A circle fitted to it (least squares, Kasa's algebraic fit) gives the centre and radius the whole
silhouette would have: stereo then uses those (vision.localize), as it uses the silhouette's centroid
for a ball seen whole.

Pixels in vision's convention (pixel centres at integer coordinates); windows are (x, y, w, h) [px].
"""

from __future__ import annotations

import math
from typing import NamedTuple

import cv2
import numpy as np

#: The outline pixels this near the robot's own pixels [px] are its contour, not the ball's.
HIDDEN_MARGIN_PX = 2
#: Fewest free outline pixels, and the smallest arc of the circle they must span [rad], for a fit.
MIN_FREE_POINTS = 12
MIN_FREE_ARC_RAD = math.radians(150.0)


class Circle(NamedTuple):
    """A circle in an image: centre (u, v) [px], radius [px]."""

    u_px: float
    v_px: float
    radius_px: float


def _outline(silhouette: np.ndarray, window: tuple[int, int, int, int]) -> np.ndarray:
    """(n, 2) integer (u, v) image pixels of the largest region's outer boundary in ``silhouette`` (a
    boolean mask of the window ``window``)."""
    contours, _ = cv2.findContours(silhouette.astype(np.uint8), cv2.RETR_EXTERNAL, cv2.CHAIN_APPROX_NONE)
    if not contours:
        return np.zeros((0, 2), dtype=int)
    largest = max(contours, key=cv2.contourArea)
    return largest[:, 0, :].astype(int) + np.array(window[:2], dtype=int)


def _near(mask: np.ndarray, margin_px: int) -> np.ndarray:
    size = 2 * margin_px + 1
    return cv2.dilate(mask.astype(np.uint8), np.ones((size, size), np.uint8)) > 0


def touches(silhouette: np.ndarray, window: tuple[int, int, int, int], hidden: np.ndarray) -> bool:
    """Whether the outline of ``silhouette`` (boolean mask of ``window``) runs along ``hidden`` pixels
    (boolean (H, W) mask of the image: the robot's own body) within ``HIDDEN_MARGIN_PX``."""
    x, y, w, h = window
    m = HIDDEN_MARGIN_PX
    x0, y0 = max(0, x - m), max(0, y - m)
    near = hidden[y0 : y + h + m, x0 : x + w + m]
    if not near.any():
        return False
    points = _outline(silhouette, window)
    if len(points) == 0:
        return False
    grown = _near(hidden[y0 : y + h + m, x0 : x + w + m], m)
    u, v = points[:, 0] - x0, points[:, 1] - y0
    inside = (u >= 0) & (v >= 0) & (u < grown.shape[1]) & (v < grown.shape[0])
    return bool(grown[v[inside], u[inside]].any())


def fit_circle(points: np.ndarray) -> Circle | None:
    """Least-squares circle through (n, 2) points [px] (Kasa: u^2 + v^2 + D u + E v + F = 0); None
    when they are too few or collinear."""
    if len(points) < 3:
        return None
    p = np.asarray(points, dtype=float)
    A = np.column_stack([p[:, 0], p[:, 1], np.ones(len(p))])
    b = -(p[:, 0] ** 2 + p[:, 1] ** 2)
    (D, E, F), _, rank, _ = np.linalg.lstsq(A, b, rcond=None)
    if rank < 3:
        return None
    u, v = -D / 2.0, -E / 2.0
    r2 = u * u + v * v - F
    if not np.isfinite(r2) or r2 <= 0:
        return None
    return Circle(float(u), float(v), float(math.sqrt(r2)))


def free_circle(
    silhouette: np.ndarray, window: tuple[int, int, int, int], hidden: np.ndarray
) -> Circle | None:
    """The circle of a ball's silhouette (boolean mask of ``window``) fitted to its outline pixels away
    from the ``hidden`` pixels (boolean (H, W) mask of the image: the robot's own body) and from the
    image border; None when fewer than ``MIN_FREE_POINTS`` remain or they span less than
    ``MIN_FREE_ARC_RAD`` of it. The boundary pixels' centres lie half a pixel inside the silhouette's
    edge: the radius gets it back."""
    points = _outline(silhouette, window)
    if len(points) == 0:
        return None
    H, W = hidden.shape
    keep = ~_near(hidden, HIDDEN_MARGIN_PX)[points[:, 1], points[:, 0]]
    keep &= (points[:, 0] > 0) & (points[:, 1] > 0) & (points[:, 0] < W - 1) & (points[:, 1] < H - 1)
    free = points[keep]
    if len(free) < MIN_FREE_POINTS:
        return None
    circle = fit_circle(free)
    if circle is None:
        return None
    angles = np.sort(np.arctan2(free[:, 1] - circle.v_px, free[:, 0] - circle.u_px))
    gaps = np.diff(np.concatenate([angles, angles[:1] + 2.0 * math.pi]))
    if 2.0 * math.pi - float(gaps.max()) < MIN_FREE_ARC_RAD:
        return None
    return Circle(circle.u_px, circle.v_px, circle.radius_px + 0.5)
