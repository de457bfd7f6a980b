"""Build the pybullet bodies of a laid-out scene: the floor and every object (primitive shapes only)."""

from __future__ import annotations

import pybullet as p

from sim.parts import Part, parts_of
from sim.scene import Layout, PlacedObject

FLOOR_HALF_SIZE_M = 15.0
FLOOR_NAME = "floor"
_BALL_ROLLING_FRICTION = 2e-4  # [m]: a ball on a flat top settles instead of rolling forever
_BALL_SPINNING_FRICTION = 1e-3
_GEOM = {"box": p.GEOM_BOX, "sphere": p.GEOM_SPHERE, "cylinder": p.GEOM_CYLINDER}  # sim.parts' shapes


def _shape_kwargs(part: Part) -> dict:
    if part.shape == "sphere":
        return {"radius": part.radius}
    if part.shape == "box":
        return {"halfExtents": list(part.half_extents)}
    return {"radius": part.radius, "height": part.length}  # createCollisionShape calls it "height"


def _visual_kwargs(part: Part) -> dict:
    if part.shape == "cylinder":  # ... and createVisualShape "length"
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
                _GEOM[parts[0].shape],
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
        shapeTypes=[_GEOM[q.shape] for q in parts],
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
            _GEOM[q.shape],
            rgbaColor=list(rgba),
            specularColor=[0.1, 0.1, 0.1],
            visualFramePosition=list(q.xyz),
            visualFrameOrientation=list(q.quat),
            physicsClientId=client,
            **_visual_kwargs(q),
        )
    return p.createVisualShapeArray(
        shapeTypes=[_GEOM[q.shape] for q in parts],
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
