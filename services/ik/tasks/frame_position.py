"""Frame position task: p_world_frame(q) - p_target = 0 on selected world axes."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.ik.kinematics import frame_id, frame_jacobian
from services.ik.task import Task
from services.ik.tasks._mask import axis_rows, vector3


class FramePositionTask(Task):
    """Position of frame ``frame_name`` at ``target_world_m`` [m] (world axes, masked by ``mask``).

    F = p - p_target (selected rows), J = rows of the LOCAL_WORLD_ALIGNED linear Jacobian. Pass
    ``lower``/``upper`` [m] to keep the frame inside a box around the target instead.
    """

    def __init__(
        self,
        model: pin.Model,
        frame_name: str,
        target_world_m: Sequence[float] | np.ndarray,
        mask: Sequence[bool] = (True, True, True),
        gain: float = 1.0,
        lower: float | np.ndarray | None = None,
        upper: float | np.ndarray | None = None,
        max_step: float | None = None,
        name: str | None = None,
    ) -> None:
        super().__init__(name or f"position:{frame_name}", gain, lower, upper, max_step)
        self.model = model
        self.frame_id = frame_id(model, frame_name)
        self.rows = axis_rows(mask, 3, self.name)
        self.all_rows = self.rows.shape[0] == 3
        self.set_target(target_world_m)

    def set_target(self, target_world_m: Sequence[float] | np.ndarray) -> None:
        """New target position [m] in the world frame."""
        self.target_world_m = vector3(target_world_m, f"task {self.name!r}: target")

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return (data.oMf[self.frame_id].translation - self.target_world_m)[self.rows]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return frame_jacobian(self.model, data, self.frame_id)[self.rows]

    def compute(self, q: np.ndarray, data: pin.Data) -> tuple[np.ndarray, np.ndarray]:
        J = frame_jacobian(self.model, data, self.frame_id)
        error = data.oMf[self.frame_id].translation - self.target_world_m
        if self.all_rows:
            return error, J[:3]
        return error[self.rows], J[self.rows]
