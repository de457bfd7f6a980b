"""Centre-of-mass position task."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pinocchio as pin

from services.ik.task import Task
from services.ik.tasks._mask import axis_rows, vector3


class ComPositionTask(Task):
    """Centre of mass at ``target_world_m`` [m] on the axes selected by ``mask``.

    F = c(q) - c_target, J = rows of the CoM Jacobian (``data.Jcom``). The CoM motion produced by a
    walking pattern generator is tracked with this task (reaching paper, support polygon reshaping).
    """

    needs_com = True

    def __init__(
        self,
        model: pin.Model,
        target_world_m: Sequence[float] | np.ndarray,
        mask: Sequence[bool] = (True, True, True),
        gain: float = 1.0,
        lower: float | np.ndarray | None = None,
        upper: float | np.ndarray | None = None,
        max_step: float | None = None,
        name: str = "com",
    ) -> None:
        super().__init__(name, gain, lower, upper, max_step)
        self.model = model
        self.rows = axis_rows(mask, 3, self.name)
        self.set_target(target_world_m)

    def set_target(self, target_world_m: Sequence[float] | np.ndarray) -> None:
        """New CoM target [m] in the world frame."""
        self.target_world_m = vector3(target_world_m, f"task {self.name!r}: target")

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return (data.com[0] - self.target_world_m)[self.rows]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return data.Jcom[self.rows]
