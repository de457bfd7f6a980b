"""Joint limits as a prioritized inequality task (eq. 4 form, section 3.2 of the footstep paper)."""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from services.errors import InvalidRequestError
from services.ik.dofs import bounded_dofs
from services.ik.task import Task


class JointLimitsTask(Task):
    """q_min + margin <= q <= q_max - margin on every bounded vector-space coordinate.

    F = q[bounded], J = the matching rows of the identity, so the rows are eq. (4)'s
    lambda (q_min + margin - q) <= dq <= lambda (q_max - margin - q): the velocity towards a limit
    decreases linearly with the distance to it. (The solver also enforces the limits themselves as
    hard bounds at level 0; this task adds a margin at any priority.)
    """

    def __init__(
        self,
        model: pin.Model,
        margin_rad: float = 0.0,
        q_lower: np.ndarray | None = None,
        q_upper: np.ndarray | None = None,
        gain: float = 1.0,
        name: str = "joint_limits",
    ) -> None:
        q_lower = model.lowerPositionLimit if q_lower is None else np.asarray(q_lower, dtype=float)
        q_upper = model.upperPositionLimit if q_upper is None else np.asarray(q_upper, dtype=float)
        self.q_idx, self.v_idx = bounded_dofs(model, q_lower, q_upper)
        lower = q_lower[self.q_idx] + margin_rad
        upper = q_upper[self.q_idx] - margin_rad
        if np.any(lower > upper):
            raise InvalidRequestError(f"task {name!r}: margin {margin_rad} rad leaves an empty range")
        super().__init__(name, gain, lower=lower, upper=upper)
        self.jacobian = np.zeros((self.q_idx.shape[0], model.nv))
        self.jacobian[np.arange(self.q_idx.shape[0]), self.v_idx] = 1.0

    def compute_error(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return q[self.q_idx]

    def compute_jacobian(self, q: np.ndarray, data: pin.Data) -> np.ndarray:
        return self.jacobian
