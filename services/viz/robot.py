"""The robot in Foxglove's 3D panel: its frames (transforms) and its body (scene entities on them).

Frames: ``world`` -> the base frame (the free-flyer, e.g. ``base_link``) -> every frame that carries
geometry, the soles, the grasp frames and the head cameras' optical frames (flat under the base: the
panel only needs each frame's pose). Poses come from pinocchio forward kinematics of a configuration
``q`` (pinocchio layout, as ``sim/joint_state`` publishes it).

Body: the URDF's primitive shapes (boxes, cylinders, spheres: the generated ``hrp2_like`` is made of
them), else the model's collision capsules (TALOS: its URDF uses meshes), as ``frame_locked`` entities
on the frames above, so the body follows the transforms without being re-sent.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from foxglove.messages import (
    Color,
    CubePrimitive,
    CylinderPrimitive,
    FrameTransform,
    FrameTransforms,
    Pose,
    Quaternion,
    SceneEntity,
    SceneUpdate,
    SpherePrimitive,
    Vector3,
)

from services.model import RobotModel
from services.viz.common import WORLD, stamp

ROBOT_COLOR = Color(r=0.72, g=0.75, b=0.82, a=1.0)
CAPSULE_COLOR = Color(r=0.55, g=0.62, b=0.78, a=0.9)


def _vector_quaternion(T: pin.SE3) -> tuple[Vector3, Quaternion]:
    x, y, z, w = pin.Quaternion(T.rotation).coeffs()
    p = T.translation
    return (
        Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
        Quaternion(x=float(x), y=float(y), z=float(z), w=float(w)),
    )


def pose_of(T: pin.SE3) -> Pose:
    """A Foxglove pose from a pinocchio placement."""
    position, orientation = _vector_quaternion(T)
    return Pose(position=position, orientation=orientation)


def transform(parent: str, child: str, T: pin.SE3, stamp_ns: int) -> FrameTransform:
    """``T_parent_child`` as a Foxglove transform."""
    translation, rotation = _vector_quaternion(T)
    return FrameTransform(
        timestamp=stamp(stamp_ns),
        parent_frame_id=parent,
        child_frame_id=child,
        translation=translation,
        rotation=rotation,
    )


@dataclass(frozen=True)
class _Shape:
    frame: str
    kind: str  # cube, cylinder, sphere
    T_frame_shape: pin.SE3
    size: tuple[float, float, float]  # full extents [m]


class RobotView:
    """Transforms and body of one robot model (``services.model.load_robot``)."""

    def __init__(self, robot: RobotModel) -> None:
        self.robot = robot
        self.base = robot.frames.base
        self._data = robot.new_data()
        self._shapes = self._primitives() or self._capsules()
        frames = {s.frame for s in self._shapes}
        frames |= {robot.frames.left_sole, robot.frames.right_sole, robot.frames.left_grasp}
        frames |= {robot.frames.right_grasp, robot.frames.gaze, robot.frames.torso}
        frames |= {cam.frame for cam in robot.cameras.values()}
        frames.discard(self.base)
        self.frames: tuple[str, ...] = tuple(sorted(frames))
        self._frame_ids = [robot.frame_id(f) for f in self.frames]
        self._base_id = robot.frame_id(self.base)

    # Geometry --------------------------------------------------------------------------------------
    def _primitives(self) -> list[_Shape]:
        """The URDF's boxes, cylinders and spheres (placed on their link's frame); [] if it uses meshes."""
        robot = self.robot
        geometry = robot.build_geometry_model("collision")
        data = robot.forward(robot.neutral(), self._data)
        shapes: list[_Shape] = []
        for obj in geometry.geometryObjects:
            geom = obj.geometry
            kind = type(geom).__name__
            frame = robot.model.frames[obj.parentFrame].name
            # Placement of the shape in its frame: both are fixed to the same joint.
            T = data.oMf[obj.parentFrame].inverse() * data.oMi[obj.parentJoint] * obj.placement
            if kind == "Box":
                size = tuple(float(2 * v) for v in geom.halfSide)
                shapes.append(_Shape(frame, "cube", T, size))  # type: ignore[arg-type]
            elif kind == "Cylinder":
                d, h = 2 * float(geom.radius), 2 * float(geom.halfLength)
                shapes.append(_Shape(frame, "cylinder", T, (d, d, h)))
            elif kind == "Sphere":
                d = 2 * float(geom.radius)
                shapes.append(_Shape(frame, "sphere", T, (d, d, d)))
            else:  # a mesh: this robot is drawn with its capsules instead
                return []
        return shapes

    def _capsules(self) -> list[_Shape]:
        """Each collision capsule as a cylinder between two spheres."""
        shapes: list[_Shape] = []
        for capsule in self.robot.capsules:
            p0, p1 = np.array(capsule.p0_local), np.array(capsule.p1_local)
            d = 2 * capsule.radius_m
            axis = p1 - p0
            length = float(np.linalg.norm(axis))
            R = _rotation_z_to(axis) if length > 1e-9 else np.eye(3)
            shapes.append(_Shape(capsule.frame, "cylinder", pin.SE3(R, (p0 + p1) / 2), (d, d, length)))
            for p in (p0, p1):
                shapes.append(_Shape(capsule.frame, "sphere", pin.SE3(np.eye(3), p), (d, d, d)))
        return shapes

    # Messages --------------------------------------------------------------------------------------
    def transforms(self, q: np.ndarray, stamp_ns: int) -> FrameTransforms:
        """``world`` -> base -> every frame at configuration ``q``."""
        data = self.robot.forward(q, self._data)
        T_world_base = data.oMf[self._base_id]
        T_base_world = T_world_base.inverse()
        out = [transform(WORLD, self.base, T_world_base, stamp_ns)]
        for name, fid in zip(self.frames, self._frame_ids, strict=True):
            out.append(transform(self.base, name, T_base_world * data.oMf[fid], stamp_ns))
        return FrameTransforms(transforms=out)

    def body(self, stamp_ns: int) -> SceneUpdate:
        """One entity per frame with shapes, locked to that frame."""
        by_frame: dict[str, list[_Shape]] = {}
        for shape in self._shapes:
            by_frame.setdefault(shape.frame, []).append(shape)
        entities = []
        color = ROBOT_COLOR if self._shapes and self._shapes[0].kind == "cube" else CAPSULE_COLOR
        for frame, shapes in sorted(by_frame.items()):
            cubes, cylinders, spheres = [], [], []
            for s in shapes:
                size = Vector3(x=s.size[0], y=s.size[1], z=s.size[2])
                pose = pose_of(s.T_frame_shape)
                if s.kind == "cube":
                    cubes.append(CubePrimitive(pose=pose, size=size, color=color))
                elif s.kind == "cylinder":
                    cylinders.append(
                        CylinderPrimitive(pose=pose, size=size, bottom_scale=1.0, top_scale=1.0, color=color)
                    )
                else:
                    spheres.append(SpherePrimitive(pose=pose, size=size, color=color))
            entities.append(
                SceneEntity(
                    timestamp=stamp(stamp_ns),
                    frame_id=frame,
                    id=f"robot/{frame}",
                    frame_locked=True,
                    cubes=cubes,
                    cylinders=cylinders,
                    spheres=spheres,
                )
            )
        return SceneUpdate(entities=entities)


def _rotation_z_to(axis: np.ndarray) -> np.ndarray:
    """A rotation taking +z onto ``axis`` (Foxglove cylinders stand along z)."""
    z = axis / np.linalg.norm(axis)
    return pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), z).toRotationMatrix()
