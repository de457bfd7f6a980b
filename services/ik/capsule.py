"""Capsule (segment with a radius) attached to a frame: the simplified body model of Fig. 4 of the
footstep paper, used by the self-collision task. Field names match ``services.model.Capsule`` so
that a robot's ``capsules`` can be passed as they are."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol


class CapsuleLike(Protocol):
    """Anything with these attributes is a capsule for the IK (e.g. ``services.model.Capsule``)."""

    name: str
    frame: str
    p0_local: tuple[float, float, float]
    p1_local: tuple[float, float, float]
    radius_m: float


@dataclass(frozen=True)
class Capsule:
    """Segment [p0_local, p1_local] fixed in frame ``frame`` (coordinates in that frame [m]) with a
    forbidden radial zone of ``radius_m`` around it covering the body's geometry."""

    name: str
    frame: str
    p0_local: tuple[float, float, float]
    p1_local: tuple[float, float, float]
    radius_m: float
