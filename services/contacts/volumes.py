"""Search volumes of a floating contact (§2.5-2.6 of Escande et al., Fig. 1).

A pair (contact spot R, environment surface E) leaves three parameters free: the point (x, y) on the
surface and the rotation theta around its normal. The possible contacts form a bounded set
C = E x ]-pi, pi] (§2.5); with a convex (rectangular) surface C is a box. After the posture generator
found a contact P in C, a small volume V around P is subtracted and C \\ V is cut into convex parts C_i
(Fig. 1, right), each searched again (§2.6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from services.errors import InvalidRequestError


@dataclass(frozen=True)
class SearchVolume:
    """An axis-aligned box of (x, y, theta) in a surface's frame: x, y [m], theta [rad] (the angle of
    the spot's x axis around the surface normal, measured from the surface's x axis)."""

    lower: tuple[float, float, float]
    upper: tuple[float, float, float]

    def __post_init__(self) -> None:
        if any(lo > hi for lo, hi in zip(self.lower, self.upper, strict=True)):
            raise InvalidRequestError(f"search volume lower {self.lower} is above upper {self.upper}")

    @property
    def size(self) -> tuple[float, float, float]:
        return tuple(hi - lo for lo, hi in zip(self.lower, self.upper, strict=True))  # type: ignore[return-value]

    def contains(self, point: tuple[float, float, float], tol: float = 1e-9) -> bool:
        return all(lo - tol <= v <= hi + tol for lo, v, hi in zip(self.lower, point, self.upper, strict=True))

    def intersect(self, other: SearchVolume) -> SearchVolume | None:
        """The common part of two boxes, None when empty."""
        lower = tuple(max(a, b) for a, b in zip(self.lower, other.lower, strict=True))
        upper = tuple(min(a, b) for a, b in zip(self.upper, other.upper, strict=True))
        if any(lo > hi for lo, hi in zip(lower, upper, strict=True)):
            return None
        return SearchVolume(lower, upper)  # type: ignore[arg-type]


def full_volume(half_x_m: float, half_y_m: float) -> SearchVolume:
    """C = E x ]-pi, pi] for a rectangular surface of half sizes (half_x_m, half_y_m) [m] (§2.6)."""
    return SearchVolume((-half_x_m, -half_y_m, -math.pi), (half_x_m, half_y_m, math.pi))


def subtract(
    volume: SearchVolume, removed: SearchVolume, min_size: tuple[float, float, float]
) -> list[SearchVolume]:
    """C \\ V cut into convex (box) parts (Fig. 1): along x, then y, then theta, the slabs of C below and
    above V, the remaining core shrinking to V's extent along the axes already cut. At most 6 parts;
    parts thinner than ``min_size`` along some axis (x, y [m], theta [rad]) are dropped (nothing new
    fits there: V is the closeness of two contacts, §2.6 (i)).
    """
    cut = volume.intersect(removed)
    if cut is None:
        return [volume]
    parts: list[SearchVolume] = []
    lower, upper = list(volume.lower), list(volume.upper)
    for axis in range(3):
        if cut.lower[axis] > lower[axis]:
            hi = list(upper)
            hi[axis] = cut.lower[axis]
            parts.append(SearchVolume(tuple(lower), tuple(hi)))  # type: ignore[arg-type]
        if cut.upper[axis] < upper[axis]:
            lo = list(lower)
            lo[axis] = cut.upper[axis]
            parts.append(SearchVolume(tuple(lo), tuple(upper)))  # type: ignore[arg-type]
        lower[axis], upper[axis] = cut.lower[axis], cut.upper[axis]
    return [p for p in parts if all(s >= m for s, m in zip(p.size, min_size, strict=True))]


def around(point: tuple[float, float, float], half_size: tuple[float, float, float]) -> SearchVolume:
    """The volume V of half sizes ``half_size`` centred on ``point`` (§2.6)."""
    return SearchVolume(
        tuple(v - h for v, h in zip(point, half_size, strict=True)),  # type: ignore[arg-type]
        tuple(v + h for v, h in zip(point, half_size, strict=True)),  # type: ignore[arg-type]
    )
