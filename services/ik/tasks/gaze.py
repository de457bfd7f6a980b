"""Gaze task: the camera's optical axis passes through a point, in one of two error forms.

- ``form="cross"`` (default): F = u x (B - O) = 0 [m], the footstep paper's OG x OB = 0
  (``000_49c4a782ba599e49.txt`` §4.3): three rows of rank two, in metres (the footstep planner's
  tolerances are in metres).
- ``form="direction"``: F = (b1 . m, b2 . m) (2,) dimensionless, the reaching paper's task (iv) "gaze
  direction" (``001_771c0ce3779b0683.txt``): m = R^T (B - O) / |B - O| is the target direction in the
  camera frame and b1, b2 complete the unit axis a to an orthonormal basis (for a = x: (m_y, m_z)).
  The cross form's third singular value is proportional to the error itself, so the rank a hierarchy
  detects flips as the error crosses its rank threshold, and with it the null space left to the levels
  below (the posture jumps); this form has exactly two rows.

Both are also zero when the camera looks exactly away from B: start from a configuration facing the
target's half-space.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Literal

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.kinematics import frame_id, frame_jacobian, skew
from services.ik.task import Task
from services.ik.tasks._mask import vector3

GazeForm = Literal["cross", "direction"]
GAZE_FORMS: tuple[str, ...] = ("cross", "direction")


class GazeTask(Task):
    """Point the unit axis ``axis_in_camera`` (default the camera z axis) of ``camera_frame`` at
    ``target_world_m`` [m, world frame]; ``form`` selects the error (module docstring).

    With w the angular velocity and v_O the velocity of O (world axes), u = R a and d = B - O:
    cross: dF = [d]x [u]x w - [u]x v_O; direction: dm = R^T ([n]x w - (I - n n^T) v_O / |d|), n = d/|d|.
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
        form: GazeForm = "cross",
    ) -> None:
        super().__init__(name or f"gaze:{camera_frame}", gain, max_step=max_step)
        if form not in GAZE_FORMS:
            raise InvalidRequestError(f"task {self.name!r}: form must be one of {GAZE_FORMS}, got {form!r}")
        self.model = model
        self.form = form
        self.frame_id = frame_id(model, camera_frame)
        axis = vector3(axis_in_camera, f"task {self.name!r}: axis_in_camera")
        self.axis_in_camera = axis / np.linalg.norm(axis)
        # rows of the direction form: b1, b2 completing the axis a (a = x: y, z; a = z: x, y)
        a = self.axis_in_camera
        e = np.eye(3)[(int(np.argmax(np.abs(a))) + 1) % 3]
        b1 = e - float(a @ e) * a
        b1 /= np.linalg.norm(b1)
        self._basis = np.vstack([b1, np.cross(a, b1)])
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
        J = frame_jacobian(self.model, data, self.frame_id)
        d = self.target_world_m - T.translation
        if self.form == "cross":
            u = T.rotation @ self.axis_in_camera
            u_x = skew(u)
            return np.cross(u, d), skew(d) @ u_x @ J[3:] - u_x @ J[:3]
        distance = float(np.linalg.norm(d))
        if distance < 1e-6:
            raise InvalidRequestError(f"task {self.name!r}: the target is at the gaze frame's origin")
        n = d / distance
        Rt = T.rotation.T
        dm = Rt @ (skew(n) @ J[3:] - (np.eye(3) - np.outer(n, n)) @ J[:3] / distance)
        return self._basis @ (Rt @ n), self._basis @ dm
