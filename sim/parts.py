"""The primitives of each scene object (boxes, spheres, cylinders) in the object's frame: the geometry the
sim builds its pybullet bodies from (``sim/objects.py``) and the contact planner reads its surfaces from
(``services/contacts/environment.py``). No pybullet here: a planner reading a scene does not load the
simulator."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from sim.scene import (
    CHAIR_BACK_THICKNESS_M,
    DISK_THICKNESS_M,
    TABLE_LEG_WIDTH_M,
    TABLE_TOP_THICKNESS_M,
    ObjectSpec,
)

Shape = Literal["box", "sphere", "cylinder"]


@dataclass(frozen=True)
class Part:
    """One primitive of a compound object, in the object's frame: ``xyz`` [m], ``quat`` xyzw."""

    shape: Shape  # "box" (half_extents), "sphere" (radius), "cylinder" (radius, length along z)
    half_extents: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.0
    length: float = 0.0
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


def parts_of(spec: ObjectSpec) -> list[Part]:
    """The primitives of an object in its own frame (origin at its reference point, see ObjectSpec)."""
    if spec.kind == "ball":
        return [Part("sphere", radius=spec.radius_m)]
    if spec.kind == "box":
        return [Part("box", half_extents=tuple(0.5 * s for s in spec.size_m))]
    if spec.kind == "bar":  # pybullet cylinders run along z: turn the axis onto x
        quat = (0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4))
        return [Part("cylinder", radius=spec.radius_m, length=spec.length_m, quat=quat)]
    if spec.kind == "disk":
        return [Part("cylinder", radius=spec.radius_m, length=DISK_THICKNESS_M)]
    sx, sy, height = spec.size_m
    if spec.kind == "table":
        top = Part(
            "box",
            half_extents=(0.5 * sx, 0.5 * sy, 0.5 * TABLE_TOP_THICKNESS_M),
            xyz=(0.0, 0.0, height - 0.5 * TABLE_TOP_THICKNESS_M),
        )
        return [top, *_legs(sx, sy, height - TABLE_TOP_THICKNESS_M)]
    if spec.kind == "chair":
        seat_t = TABLE_TOP_THICKNESS_M
        seat = Part(
            "box", half_extents=(0.5 * sx, 0.5 * sy, 0.5 * seat_t), xyz=(0.0, 0.0, height - 0.5 * seat_t)
        )
        back = Part(
            "box",
            half_extents=(0.5 * CHAIR_BACK_THICKNESS_M, 0.5 * sy, 0.5 * spec.back_height_m),
            xyz=(-0.5 * sx + 0.5 * CHAIR_BACK_THICKNESS_M, 0.0, height + 0.5 * spec.back_height_m),
        )
        return [seat, back, *_legs(sx, sy, height - seat_t)]
    raise ValueError(f"unknown object kind {spec.kind!r}")


def _legs(sx: float, sy: float, leg_height: float) -> list[Part]:
    w = TABLE_LEG_WIDTH_M
    half = (0.5 * w, 0.5 * w, 0.5 * leg_height)
    return [
        Part(
            "box",
            half_extents=half,
            xyz=(ix * (0.5 * sx - 0.5 * w), iy * (0.5 * sy - 0.5 * w), 0.5 * leg_height),
        )
        for ix in (-1, 1)
        for iy in (-1, 1)
    ]
