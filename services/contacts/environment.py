"""The environment of a contact plan, from the sim's scene file (§2.1, §3.1 of Escande et al.): the flat
surfaces on which contacts may be taken (the floor, a chair's seat, the tops of tables and boxes) and
the boxes the robot must not collide with (every primitive of every static object, and the floor).

Read from the scene YAML through ``sim.scene`` and ``sim.parts.parts_of`` (the same geometry the sim
builds), never from pybullet (not even imported).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.model.ground import yaw_of
from sim.parts import parts_of
from sim.scene import Layout

FLOOR_HALF_SIZE_M = 2.5  # the floor surface: a square of this half size around the robot's start [m]
FLOOR_BOX_DEPTH_M = 0.5


@dataclass(frozen=True)
class Surface:
    """A flat, convex (rectangular) contact surface: its frame in the world (origin at the centre of
    the rectangle, z = outer normal, §2.1), its half sizes along its x and y [m], the object it
    belongs to (``floor`` for the floor), its friction coefficient and the obstacle box it is a face
    of."""

    name: str
    T_world_surface: pin.SE3
    half_size_m: tuple[float, float]
    owner: str
    friction: float
    box: str = ""  # the obstacle box whose face the surface is ("" if none)

    def placement(self, x: float, y: float, theta: float) -> pin.SE3:
        """The world frame of a contact at (x [m], y [m], theta [rad]) on the surface (§2.5)."""
        c, s = math.cos(theta), math.sin(theta)
        local = pin.SE3(np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]), np.array([x, y, 0.0]))
        return self.T_world_surface * local

    def coordinates(self, T_world_frame: pin.SE3) -> tuple[float, float, float]:
        """(x, y, theta) of a frame's origin and x axis in the surface's frame."""
        local = self.T_world_surface.actInv(T_world_frame)
        return (
            float(local.translation[0]),
            float(local.translation[1]),
            yaw_of(local.rotation),
        )


@dataclass(frozen=True)
class Box:
    """An obstacle box: world placement of its centre and half extents [m]; ``owner`` is its object."""

    name: str
    T_world_box: pin.SE3
    half_extents_m: np.ndarray
    owner: str


@dataclass(frozen=True)
class Environment:
    """Surfaces and obstacle boxes of a scene."""

    surfaces: tuple[Surface, ...]
    boxes: tuple[Box, ...]

    def surface(self, name: str) -> Surface:
        for s in self.surfaces:
            if s.name == name:
                return s
        raise InvalidRequestError(f"unknown surface {name!r}; surfaces: {[s.name for s in self.surfaces]}")

    def select(self, names: Sequence[str] | None) -> tuple[Surface, ...]:
        """The surfaces named (all when None); InvalidRequestError lists the valid names."""
        if names is None:
            return self.surfaces
        return tuple(self.surface(n) for n in names)


def _yaw_se3(yaw: float, xyz: Sequence[float]) -> pin.SE3:
    return pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, yaw), np.array(xyz, dtype=float))


def _under(name: str, T_obj: pin.SE3, top_xyz: np.ndarray, top_half: np.ndarray) -> Box:
    """The space under a table's top, down to the floor, as an obstacle box (owned by the table): the
    planner keeps the robot's limbs out from under the top (a conservative convex hull of the table, as
    the paper's environment is a set of convex shapes, §2.2). A free arm hanging under the top cannot
    reach the top without passing through it: witnesses with an arm there make the interpolation (§3.3)
    drive that arm through the table."""
    top_under_z = float(T_obj.act(top_xyz)[2]) - float(top_half[2])
    floor_z = -float(T_obj.translation[2])  # the floor (z = 0) in the object's frame
    height = top_under_z - float(T_obj.translation[2]) - floor_z
    centre = np.array([top_xyz[0], top_xyz[1], floor_z + 0.5 * height])
    half = np.array([top_half[0], top_half[1], 0.5 * height])
    return Box(f"{name}[under]", T_obj * pin.SE3(np.eye(3), centre), half, name)


def environment_of(layout: Layout, floor_friction: float | None = None) -> Environment:
    """Surfaces and boxes of a laid-out scene (a table's boxes include the space under its top:
    :func:`_under`). Surfaces: ``floor``, ``<chair>.seat``, ``<table>.top``,
    ``<box>.top`` (static objects only: the planner does not handle moving objects, §3.1)."""
    friction = layout.scene.floor_friction if floor_friction is None else floor_friction
    rx, ry = layout.robot_xy
    # the floor's frame is the robot's start frame (x ahead, y to its left): the search's stance rule
    # (a left sole to the left of the right one, search.py) holds whichever way the layout turns it
    heading = layout.robot_yaw_rad
    surfaces = [
        Surface(
            "floor",
            _yaw_se3(heading, (rx, ry, 0.0)),
            (FLOOR_HALF_SIZE_M, FLOOR_HALF_SIZE_M),
            "floor",
            friction,
            "floor",
        )
    ]
    boxes = [
        Box(
            "floor",
            _yaw_se3(heading, (rx, ry, -0.5 * FLOOR_BOX_DEPTH_M)),
            np.array([FLOOR_HALF_SIZE_M + 1.0, FLOOR_HALF_SIZE_M + 1.0, 0.5 * FLOOR_BOX_DEPTH_M]),
            "floor",
        )
    ]
    for obj in layout.objects:
        spec = obj.spec
        if not spec.is_static or spec.kind not in ("box", "table", "chair"):
            continue
        T_obj = _yaw_se3(obj.yaw_rad, obj.position)
        for i, part in enumerate(parts_of(spec)):
            if part.shape != "box":
                continue
            T_part = T_obj * pin.SE3(np.eye(3), np.array(part.xyz))
            boxes.append(Box(f"{spec.name}[{i}]", T_part, np.array(part.half_extents), spec.name))
        top = parts_of(spec)[0]  # box: the box; table: the top; chair: the seat
        if spec.kind == "table":
            boxes.append(_under(spec.name, T_obj, np.array(top.xyz), np.array(top.half_extents)))
        label = {"box": "top", "table": "top", "chair": "seat"}[spec.kind]
        T_top = T_obj * pin.SE3(np.eye(3), np.array(top.xyz) + np.array([0.0, 0.0, top.half_extents[2]]))
        surfaces.append(
            Surface(
                f"{spec.name}.{label}",
                T_top,
                (top.half_extents[0], top.half_extents[1]),
                spec.name,
                spec.friction,
                f"{spec.name}[0]",  # parts_of's first part: the box's, table's or seat's top
            )
        )
    return Environment(tuple(surfaces), tuple(boxes))
