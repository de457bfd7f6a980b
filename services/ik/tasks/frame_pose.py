"""Full frame pose task: position and orientation stacked, with a 6-axis selection mask."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.ik.kinematics import frame_id, frame_jacobian
from services.ik.task import Task
from services.ik.tasks._mask import axis_rows
from services.ik.tasks.frame_orientation import rotation_matrix


class FramePoseTask(Task):
    """Pose of frame ``frame_name`` equal to ``T_world_target``.

    F = [p - p_target [m]; log3(R R_target^T) [rad]], both in world axes; ``mask`` selects among
    (x, y, z, rot x, rot y, rot z). Holding a foot fixed is ``FramePoseTask(model, sole, T_now)``;
    a foot free to slide and yaw on the ground is the mask ``(False, False, True, True, True, False)``.
    """

    def __init__(
        self,
        model: pin.Model,
        frame_name: str,
        T_world_target: pin.SE3,
        mask: Sequence[bool] = (True,) * 6,
        gain: float = 1.0,
        lower: float | np.ndarray | None = None,
        upper: float | np.ndarray | None = None,
        max_step: float | None = None,
        name: str | None = None,
    ) -> None:
        super().__init__(name or f"pose:{frame_name}", gain, lower, upper, max_step)
        self.model = model
        self.frame_id = frame_id(model, frame_name)
        self.rows = axis_rows(mask, 6, self.name)
        self.all_rows = self.rows.shape[0] == 6
        self.set_target(T_world_target)

    def set_target(self, T_world_target: pin.SE3) -> None:
        """New target placement in the world frame."""
        self.p_world_target = np.array(T_world_target.translation, dtype=float)
        self.R_world_target = rotation_matrix(T_world_target.rotation, f"task {self.name!r}: target rotation")

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[0]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.compute(q, data)[1]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        T = data.oMf[self.frame_id]
        # R_e^T = R_target R^T; log3(R_e) = -log3(R_e^T) and Jlog3(R_e) R_e^T = Jlog3(R_e^T).
        R_eT = self.R_world_target.dot(T.rotation.T)
        J = frame_jacobian(self.model, data, self.frame_id)
        error = np.empty(6)
        error[:3] = T.translation - self.p_world_target
        error[3:] = -pin.log3(R_eT)
        J[3:] = pin.Jlog3(R_eT).dot(J[3:])
        if self.all_rows:
            return error, J
        return error[self.rows], J[self.rows]
