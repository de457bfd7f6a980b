"""Gaze task: the camera's optical axis passes through a point (OG x OB = 0, footstep paper 4.3)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.ik.kinematics import frame_id, frame_jacobian, skew
from services.ik.task import Task
from services.ik.tasks._mask import vector3


class GazeTask(Task):
    """F = u x (B - O) = 0 [m]: O the origin of ``camera_frame``, u the unit optical axis
    (``axis_in_camera``, default the camera z axis, in world axes), B ``target_world_m``.

    With w the angular velocity and v_O the velocity of O (world axes),
    dF = [B - O]x [u]x w - [u]x v_O. F has three rows but rank two (F is orthogonal to u). Like the
    paper's formulation it is also zero when the camera looks exactly away from B; start from a
    configuration facing the target's half-space.
    """

    def __init__(
        self,
        model: pin.Model,
        camera_frame: str,
        target_world_m: Sequence[float] | np.ndarray,
        axis_in_camera: Sequence[float] = (0.0, 0.0, 1.0),
        gain: float = 1.0,
        max_step: float | None = None,
        name: str | None = None,
    ) -> None:
        super().__init__(name or f"gaze:{camera_frame}", gain, max_step=max_step)
        self.model = model
        self.frame_id = frame_id(model, camera_frame)
        axis = vector3(axis_in_camera, f"task {self.name!r}: axis_in_camera")
        self.axis_in_camera = axis / np.linalg.norm(axis)
        self.set_target(target_world_m)

    def set_target(self, target_world_m: Sequence[float] | np.ndarray) -> None:
        """New point B to look at [m], world frame."""
        self.target_world_m = vector3(target_world_m, f"task {self.name!r}: target")

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        T = data.oMf[self.frame_id]
        u = T.rotation @ self.axis_in_camera
        v = self.target_world_m - T.translation
        J = frame_jacobian(self.model, data, self.frame_id)
        u_x = skew(u)
        return np.cross(u, v), skew(v) @ u_x @ J[3:] - u_x @ J[:3]
