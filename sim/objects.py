"""Build the pybullet bodies of a laid-out scene: the floor and every object (primitive shapes only)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import pybullet as p

from sim.scene import (
    CHAIR_BACK_THICKNESS_M,
    DISK_THICKNESS_M,
    TABLE_LEG_WIDTH_M,
    TABLE_TOP_THICKNESS_M,
    Layout,
    ObjectSpec,
    PlacedObject,
)

FLOOR_HALF_SIZE_M = 15.0
FLOOR_NAME = "floor"
_BALL_ROLLING_FRICTION = 2e-4  # [m]: a ball on a flat top settles instead of rolling forever
_BALL_SPINNING_FRICTION = 1e-3


@dataclass(frozen=True)
class Part:
    """One primitive of a compound object, in the object's frame: ``xyz`` [m], ``quat`` xyzw."""

    shape: int  # pybullet GEOM_BOX / GEOM_SPHERE / GEOM_CYLINDER
    half_extents: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.0
    length: float = 0.0
    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    quat: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 1.0)


def parts_of(spec: ObjectSpec) -> list[Part]:
    """The primitives of an object in its own frame (origin at its reference point, see ObjectSpec)."""
    if spec.kind == "ball":
        return [Part(p.GEOM_SPHERE, radius=spec.radius_m)]
    if spec.kind == "box":
        return [Part(p.GEOM_BOX, half_extents=tuple(0.5 * s for s in spec.size_m))]
    if spec.kind == "bar":  # pybullet cylinders run along z: turn the axis onto x
        quat = (0.0, math.sin(math.pi / 4), 0.0, math.cos(math.pi / 4))
        return [Part(p.GEOM_CYLINDER, radius=spec.radius_m, length=spec.length_m, quat=quat)]
    if spec.kind == "disk":
        return [Part(p.GEOM_CYLINDER, radius=spec.radius_m, length=DISK_THICKNESS_M)]
    sx, sy, height = spec.size_m
    if spec.kind == "table":
        top = Part(
            p.GEOM_BOX,
            half_extents=(0.5 * sx, 0.5 * sy, 0.5 * TABLE_TOP_THICKNESS_M),
            xyz=(0.0, 0.0, height - 0.5 * TABLE_TOP_THICKNESS_M),
        )
        return [top, *_legs(sx, sy, height - TABLE_TOP_THICKNESS_M)]
    if spec.kind == "chair":
        seat_t = TABLE_TOP_THICKNESS_M
        seat = Part(
            p.GEOM_BOX, half_extents=(0.5 * sx, 0.5 * sy, 0.5 * seat_t), xyz=(0.0, 0.0, height - 0.5 * seat_t)
        )
        back = Part(
            p.GEOM_BOX,
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
            p.GEOM_BOX,
            half_extents=half,
            xyz=(ix * (0.5 * sx - 0.5 * w), iy * (0.5 * sy - 0.5 * w), 0.5 * leg_height),
        )
        for ix in (-1, 1)
        for iy in (-1, 1)
    ]


def _shape_kwargs(part: Part) -> dict:
    if part.shape == p.GEOM_SPHERE:
        return {"radius": part.radius}
    if part.shape == p.GEOM_BOX:
        return {"halfExtents": list(part.half_extents)}
    return {"radius": part.radius, "height": part.length}  # createCollisionShape calls it "height"


def _visual_kwargs(part: Part) -> dict:
    if part.shape == p.GEOM_CYLINDER:  # ... and createVisualShape "length"
        return {"radius": part.radius, "length": part.length}
    return _shape_kwargs(part)


def create_object(obj: PlacedObject, client: int) -> int:
    """Create the pybullet body of ``obj``; returns its body id."""
    spec = obj.spec
    parts = parts_of(spec)
    collision = -1
    if spec.kind != "disk":  # disks are regions drawn on the floor, not obstacles to touch
        if len(parts) == 1:
            collision = p.createCollisionShape(
                parts[0].shape,
                collisionFramePosition=list(parts[0].xyz),
                collisionFrameOrientation=list(parts[0].quat),
                physicsClientId=client,
                **_shape_kwargs(parts[0]),
            )
        else:
            collision = _compound_collision(parts, client)
    visual = _compound_visual(parts, spec.colour, client)
    quat = p.getQuaternionFromEuler([0.0, 0.0, obj.yaw_rad])
    body = p.createMultiBody(
        baseMass=spec.mass_kg,
        baseCollisionShapeIndex=collision,
        baseVisualShapeIndex=visual,
        basePosition=list(obj.position),
        baseOrientation=quat,
        physicsClientId=client,
    )
    dynamics = {"lateralFriction": spec.friction}
    if spec.kind == "ball":
        dynamics |= {"rollingFriction": _BALL_ROLLING_FRICTION, "spinningFriction": _BALL_SPINNING_FRICTION}
    p.changeDynamics(body, -1, physicsClientId=client, **dynamics)
    return body


def _compound_collision(parts: list[Part], client: int) -> int:
    return p.createCollisionShapeArray(
        shapeTypes=[q.shape for q in parts],
        halfExtents=[list(q.half_extents) for q in parts],
        radii=[q.radius for q in parts],
        lengths=[q.length for q in parts],
        collisionFramePositions=[list(q.xyz) for q in parts],
        collisionFrameOrientations=[list(q.quat) for q in parts],
        physicsClientId=client,
    )


def _compound_visual(parts: list[Part], rgba: tuple[float, ...], client: int) -> int:
    if len(parts) == 1:
        q = parts[0]
        return p.createVisualShape(
            q.shape,
            rgbaColor=list(rgba),
            specularColor=[0.1, 0.1, 0.1],
            visualFramePosition=list(q.xyz),
            visualFrameOrientation=list(q.quat),
            physicsClientId=client,
            **_visual_kwargs(q),
        )
    return p.createVisualShapeArray(
        shapeTypes=[q.shape for q in parts],
        halfExtents=[list(q.half_extents) for q in parts],
        radii=[q.radius for q in parts],
        lengths=[q.length for q in parts],
        visualFramePositions=[list(q.xyz) for q in parts],
        visualFrameOrientations=[list(q.quat) for q in parts],
        rgbaColors=[list(rgba) for _ in parts],
        physicsClientId=client,
    )


def create_floor(layout: Layout, client: int) -> int:
    """A static floor: an infinite plane for contacts, drawn as a large thin slab (top at z = 0)."""
    collision = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=client)
    visual = p.createVisualShape(
        p.GEOM_BOX,
        halfExtents=[FLOOR_HALF_SIZE_M, FLOOR_HALF_SIZE_M, 0.005],
        visualFramePosition=[0.0, 0.0, -0.005],
        rgbaColor=list(layout.scene.floor_colour),
        specularColor=[0.0, 0.0, 0.0],
        physicsClientId=client,
    )
    body = p.createMultiBody(0.0, collision, visual, [0.0, 0.0, 0.0], physicsClientId=client)
    p.changeDynamics(body, -1, lateralFriction=layout.scene.floor_friction, physicsClientId=client)
    return body


def build_scene(layout: Layout, client: int) -> tuple[int, dict[str, int]]:
    """Create the floor and every object; returns (floor body id, {object name: body id})."""
    floor = create_floor(layout, client)
    bodies = {obj.name: create_object(obj, client) for obj in layout.objects}
    return floor, bodies
