"""The robot's own body in its head images, from its model (never from the simulator's segmentation).

A robot that holds an object in front of its chest sees its own arm and hand in front of what it looks
at: the table it is about to put the ball on, 1 m away, is cut by the gripper's dark fingers in one or
both images. Those pixels are not a colour model perception has learned (unlike another object of the
scene, :mod:`vision.localize`'s ``occluders``), yet the robot knows where its links are: the URDF's visual
shapes placed at the configuration ``q`` (forward kinematics) and projected through the head camera
that took the image. An outline edge of an object next to these pixels is the arm's contour, not the
object's: vision.footprint drops it as it drops an edge next to another object (a table seen end-on
from 1 m got the gripper's contour as its near right edge and was mapped 1.47 m long instead of 1.0 m,
its centre 0.2 m toward the robot; the put then lowered the ball beside it: 16 of 60 fetches of
session 8).

Each shape is drawn as the filled convex hull of the projection of points whose hull holds it
(:func:`services.model.geometry.shape_points`: exact for boxes, circumscribed for cylinders and
spheres, the vertices of a mesh), grown by ``margin_px``; shapes not wholly in front of the camera (the
head around the cameras) are left out.

Frames: world (z up) [m]; the left optical frame (x right, y down, z forward); pixels in vision's
convention (pixel centres at integer coordinates).
"""

from __future__ import annotations

import cv2
import numpy as np
import pinocchio as pin

from services.model import RobotModel
from services.model.geometry import shape_points
from vision.camera import CameraIntrinsics

#: Shapes with a point nearer the camera plane than this are not drawn (the head holding the cameras) [m].
MIN_DEPTH_M = 0.05


class OwnBody:
    """The pixels of a robot's links in its head images (see the module docstring)."""

    def __init__(self, robot: RobotModel, margin_px: int = 2) -> None:
        self.robot = robot
        self.margin_px = margin_px
        self._geometry = robot.build_geometry_model("visual")
        self._points = [shape_points(obj.geometry) for obj in self._geometry.geometryObjects]

    def world_shapes(self, q: np.ndarray) -> list[np.ndarray]:
        """Each visual shape's points (m, 3) in the world frame at configuration ``q`` [m]."""
        robot = self.robot
        data = robot.model.createData()
        gdata = pin.GeometryData(self._geometry)
        pin.updateGeometryPlacements(robot.model, data, self._geometry, gdata, robot.check_q(q))
        return [
            points @ gdata.oMg[i].rotation.T + gdata.oMg[i].translation
            for i, points in enumerate(self._points)
        ]

    def mask(
        self, shapes: list[np.ndarray], intrinsics: CameraIntrinsics, T_world_camera: np.ndarray
    ) -> np.ndarray:
        """Boolean (H, W) mask of the pixels the ``shapes`` (world points, :meth:`world_shapes`) cover in
        the image of a camera with ``intrinsics`` at ``T_world_camera`` (4x4 optical frame pose)."""
        T = np.asarray(T_world_camera, dtype=float)
        mask = np.zeros((intrinsics.height, intrinsics.width), dtype=np.uint8)
        for points in shapes:
            p = (points - T[:3, 3]) @ T[:3, :3]  # in the camera frame
            if p[:, 2].min() < MIN_DEPTH_M:
                continue
            uv = intrinsics.project(p)
            lo, hi = uv.min(axis=0), uv.max(axis=0)
            if hi[0] < 0 or hi[1] < 0 or lo[0] >= intrinsics.width or lo[1] >= intrinsics.height:
                continue  # out of view
            hull = cv2.convexHull(np.round(uv).astype(np.int32))
            cv2.fillConvexPoly(mask, hull, 1)
        if self.margin_px > 0:
            size = 2 * self.margin_px + 1
            mask = cv2.dilate(mask, np.ones((size, size), np.uint8))
        return mask.astype(bool)

    def stereo_masks(
        self, q: np.ndarray, intrinsics: CameraIntrinsics, T_world_left: np.ndarray, baseline_m: float
    ) -> tuple[np.ndarray, np.ndarray]:
        """The masks (:meth:`mask`) of the left and right images of a rectified pair whose left optical
        frame is at ``T_world_left`` (the right one ``baseline_m`` [m] along its x axis) at ``q``."""
        shapes = self.world_shapes(q)
        T_left = np.asarray(T_world_left, dtype=float)
        T_right = T_left.copy()
        T_right[:3, 3] = T_left[:3, 3] + T_left[:3, 0] * baseline_m
        return self.mask(shapes, intrinsics, T_left), self.mask(shapes, intrinsics, T_right)
