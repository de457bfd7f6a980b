"""Small spatial geometry helpers used by the model (no pinocchio): segment distances, the points whose
convex hull holds a URDF shape; the ground geometry (hulls, polygon distances, sole poses) is
:mod:`services.model.ground`."""

from __future__ import annotations

import itertools
import math

import coal
import numpy as np


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


_CORNERS = np.array(list(itertools.product((-1.0, 1.0), repeat=3)))


def shape_points(geometry: coal.CollisionGeometry) -> np.ndarray:
    """Points (m, 3) in the shape's frame whose convex hull contains the shape (boxes, cylinders,
    capsules, spheres: exact corners or a 16-gon circumscribed to the circles; meshes: their vertices)."""
    if isinstance(geometry, coal.Box):
        return _CORNERS * np.asarray(geometry.halfSide)
    if isinstance(geometry, coal.Sphere):
        return _CORNERS * geometry.radius
    if isinstance(geometry, coal.Cylinder | coal.Capsule):
        r = geometry.radius / math.cos(math.pi / 16)  # circumscribed polygon
        h = geometry.halfLength + (geometry.radius if isinstance(geometry, coal.Capsule) else 0.0)
        a = np.linspace(0.0, 2.0 * math.pi, 16, endpoint=False)
        ring = np.column_stack([r * np.cos(a), r * np.sin(a)])
        return np.vstack([np.column_stack([ring, np.full(16, z)]) for z in (-h, h)])
    return np.asarray(geometry.vertices())
