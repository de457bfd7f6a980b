"""Capsule (segment with a radius) attached to a frame: the simplified body model of Fig. 4 of the
footstep paper, used by the self-collision and capsule-box tasks. The type is the model's
(``services.model.Capsule``, re-exported here): a robot's ``capsules`` are passed as they are, and
anything with the same attributes (:class:`CapsuleLike`) is a capsule for the IK."""

from __future__ import annotations

from typing import Protocol

from services.model.specs import Capsule as Capsule


class CapsuleLike(Protocol):
    """Anything with these attributes is a capsule for the IK (e.g. ``services.model.Capsule``)."""

    name: str
    frame: str
    p0_local: tuple[float, float, float]
    p1_local: tuple[float, float, float]
    radius_m: float
